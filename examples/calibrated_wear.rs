//! Wear read against the model calibrated to a machine, on a simulated machine whose transfer
//! path, gain, speed, noise **and physics** the calibration must discover (`cargo run
//! --release --example calibrated_wear`, ≈ 1 min a seed on 2 cores).
//!
//! The machine: the paper's rig (its committed table `signatures/model_a_accel.json`) built
//! with each of its ten meshes' own stiffness (× 0.6–1.6), damping (× 0.5–2), stiffness
//! fluctuation (× 0.6–1.4) and transmission error (× 0.5–2, log-uniform), drawn per seed and
//! per mesh (so unlike the calibration's per-stage factors), seen through a housing mode fixed
//! in Hz (1.3 × the description's reference mesh frequency, ζ = 0.05, peak gain 5), an unknown
//! gain (37), white noise at 25 dB SNR, 16 kHz, 0.6 s, each record from its own random
//! initial state and at its own speed. `CW_PHYSICS=0` keeps the description's physics (the
//! path alone unknown). Chosen before any run:
//! - healthy baseline: wear ea = 0.1 (the table's lowest) at Ω1 = 0.7, 0.85, 1.0, 1.15, 1.3
//!   (the description's Ω1: the input rates), two records each;
//! - judged: ea = 0.2, 0.3, …, 1.0, two records each at Ω1 drawn in [0.75, 1.25]; and three
//!   records with a damaged input-pinion tooth (stiffness loss 0.6, ea = 0.3) and three with the
//!   input shaft modulating mesh 1 (eccentricity 0.1 b, ea = 0.3), which must get no wear
//!   figure;
//! - read four times: the plain diagnosis, the diagnosis through the calibrated path
//!   ([`gearwear::diagnosis::machine_path`]), against the machine's own model (its physics
//!   fitted to the healthy records, [`gearwear::diagnosis::machine_physics`], and its own
//!   table), and the product's assessment of a machine whose baseline is the healthy records
//!   (state-aware, its path calibrated, its own model); a figure, its error, whether the truth
//!   lies in its 90 % interval.
//!
//! Every record's speed is read by a tachometer (the diagnosis is given the shaft's rate);
//! `CW_TACHOLESS=1` finds it in the spectrum instead. Env: `CW_SEED` (default 1) moves every
//! draw; `CW_PEAK` the mode's peak gain; `CW_TOOTH_LOSS` the damaged tooth's stiffness loss;
//! `CW_DEBUG=1` prints each judged record's findings.

use std::collections::BTreeMap;

use gearwear::assessment::{
    Baselines, Machine, OwnModel, RecordFacts, TableDiagnoser, TachoChannel, assess,
    baseline_features,
};
use gearwear::closed_loop::effects::reference_gears;
use gearwear::closed_loop::virtual_rig::{
    MeshPhysics, RigEffects, RigSpec, generate, tachometer, with_mesh_physics,
};
use gearwear::diagnosis::machine_path::{LineRatios, PathCalibration};
use gearwear::diagnosis::machine_physics::{MachinePhysics, PhysicsFitOptions};
use gearwear::diagnosis::{DiagnoseOptions, Diagnosis, diagnose};
use gearwear::gearbox::Gearbox;
use gearwear::novelty::RecordFeatures;
use gearwear::record::Record;
use gearwear::signature::precompute::precompute;
use gearwear::signature::table::default_table_path;
use gearwear::signature::{SignatureTable, SplitMix64};
use rayon::prelude::*;

const FS: f64 = 16_000.0;
const DURATION: f64 = 0.6;
const GAIN: f64 = 37.0;
const SNR_DB: f64 = 25.0;
/// The record's one channel as the assessment takes it.
const CHANNEL: &str = "a1";
/// Tachometer pulses per revolution of the input shaft.
const PULSES_PER_REV: usize = 10;

/// A record's truth (`omega1` in the description's units: the input rate).
#[derive(Clone, Copy)]
struct Truth {
    ea: f64,
    omega1: f64,
    part: Part,
    seed: u64,
}

/// The part a judged record's change is made of besides its wear.
#[derive(Clone, Copy, PartialEq)]
enum Part {
    /// Wear alone.
    None,
    /// A damaged input-pinion tooth.
    Tooth,
    /// The input shaft's modulation of mesh 1 (eccentricity, 0.1 b).
    Shaft,
}

impl Part {
    fn label(self) -> &'static str {
        match self {
            Part::None => "–",
            Part::Tooth => "damaged tooth",
            Part::Shaft => "shaft modulation",
        }
    }
}

fn env_f64(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// The simulated machine: the description, the machine's own physics, its path.
struct Rig {
    gb: Gearbox,
    machine: Gearbox,
    meshes: Vec<MeshPhysics>,
    peak: f64,
    pinion_ratio: f64,
    tooth_loss: f64,
}

impl Rig {
    /// Each mesh's physics drawn from `seed` (or the description's with `physics: false`).
    fn new(gb: &Gearbox, seed: u64, physics: bool, peak: f64) -> Rig {
        let mut rng = SplitMix64::new(seed * 104_729 + 17);
        let log_uniform =
            |rng: &mut SplitMix64, lo: f64, hi: f64| rng.range(f64::ln(lo), f64::ln(hi)).exp();
        let meshes: Vec<MeshPhysics> = gb
            .physics
            .meshes
            .iter()
            .map(|_| {
                if physics {
                    MeshPhysics {
                        stiffness: rng.range(0.6, 1.6),
                        damping: log_uniform(&mut rng, 0.5, 2.0),
                        fluctuation: rng.range(0.6, 1.4),
                        error: log_uniform(&mut rng, 0.5, 2.0),
                    }
                } else {
                    MeshPhysics {
                        stiffness: 1.0,
                        damping: 1.0,
                        fluctuation: 1.0,
                        error: 1.0,
                    }
                }
            })
            .collect();
        Rig {
            machine: with_mesh_physics(gb, &meshes).expect("the machine resolves"),
            gb: gb.clone(),
            meshes,
            peak,
            pinion_ratio: reference_gears(gb)[0].shaft_ratio,
            tooth_loss: env_f64("CW_TOOTH_LOSS", 0.6),
        }
    }

    /// The record of `t`: its input rate is the description's Ω1 × f_ref / z1, the machine's
    /// own Ω1 follows from its own reference frequency.
    fn record(&self, t: &Truth) -> Record {
        let f_ref = self.gb.reference_frequency_hz();
        let f1 = t.omega1 * f_ref;
        let spec = RigSpec {
            ea: t.ea,
            omega1: f1 / self.machine.reference_frequency_hz(),
            sample_rate: FS,
            duration: DURATION,
            gain: GAIN,
            snr_db: SNR_DB,
            seed: t.seed,
            effects: RigEffects {
                path_peak: Some((1.3 * f_ref / f1, 0.05, self.peak)),
                tooth: (t.part == Part::Tooth).then_some((self.pinion_ratio, self.tooth_loss)),
                eccentricity: (t.part == Part::Shaft).then_some(0.1),
                ..Default::default()
            },
        };
        generate(&self.machine, &spec).expect("rig")
    }

    fn shaft_hz(&self, t: &Truth) -> f64 {
        t.omega1 * self.gb.reference_frequency_hz() / self.gb.f1_per_input_hz
    }
}

/// A wear figure `(estimate, lower, upper)`, `None` when withheld.
type Reading = Option<(f64, f64, f64)>;

/// A judged record: its truth and its four readings.
struct Row {
    truth: Truth,
    plain: Reading,
    path: Reading,
    own: Reading,
    assessed: Reading,
}

/// The record's vibration channel and, with a shaft rate known (`shaft_hz`), a tachometer
/// channel of [`PULSES_PER_REV`] square pulses per revolution, with its facts.
fn channels(
    rec: &Record,
    shaft_hz: Option<f64>,
    healthy: bool,
) -> (Vec<(String, Vec<f64>)>, RecordFacts) {
    let mut ch = vec![(CHANNEL.to_string(), rec.samples.clone())];
    if let Some(f) = shaft_hz {
        let pulses = tachometer(rec.samples.len(), rec.sample_rate, f, PULSES_PER_REV);
        ch.push(("tach".into(), pulses));
    }
    let facts = RecordFacts {
        sample_rate_hz: rec.sample_rate,
        shaft_hz,
        declared_healthy: healthy,
        tacho: shaft_hz.map(|_| TachoChannel {
            name: "tach".into(),
            pulses_per_rev: PULSES_PER_REV,
        }),
        ..Default::default()
    };
    (ch, facts)
}

/// The wear the product's assessment gives the record (none when it withholds it or refuses
/// the record), and its novelty, findings and withheld reason in a line.
fn assessed(rec: &Record, shaft_hz: Option<f64>, m: &Machine) -> (Reading, String) {
    let (mut ch, facts) = channels(rec, shaft_hz, false);
    let a = match assess(&mut ch, &[0], &facts, m, &mut |_| {}) {
        Ok(a) => a,
        Err(e) => return (None, format!("refused: {e}")),
    };
    let novelty = a.novelty.as_ref().map_or("none".into(), |n| {
        format!("{:.2}/{:.2}", n.score, n.threshold)
    });
    let findings: Vec<String> = a
        .findings
        .iter()
        .map(|f| format!("{} {:.2}", f.kind, f.share))
        .collect();
    let withheld = a
        .deciding_channel()
        .reading
        .as_ref()
        .and_then(|r| r.diagnosis.wear_degree.withheld_reason())
        .map_or(String::new(), |w| format!(" withheld: {}", w.as_str()));
    (
        a.wear().map(|w| (w.estimate, w.lower, w.upper)),
        format!("novelty {novelty} [{}]{withheld}", findings.join(", ")),
    )
}

/// Mean absolute error, interval coverage and count of the figures given.
fn score(rows: &[(Truth, Reading)]) -> String {
    let given: Vec<(f64, f64, f64, f64)> = rows
        .iter()
        .filter_map(|(t, w)| w.map(|(e, lo, hi)| (t.ea, e, lo, hi)))
        .collect();
    let n = given.len().max(1) as f64;
    let mae = given.iter().map(|g| (g.1 - g.0).abs()).sum::<f64>() / n;
    let cover = given.iter().filter(|g| g.2 <= g.0 && g.0 <= g.3).count();
    format!(
        "a figure on {}/{} ({:.0} %), MAE {mae:.3}, truth in the 90 % interval {cover}/{} ({:.0} %)",
        given.len(),
        rows.len(),
        100.0 * given.len() as f64 / rows.len().max(1) as f64,
        given.len(),
        100.0 * cover as f64 / n
    )
}

/// The figure as the product gives it: none where the model does not fit.
fn wear(d: &gearwear::Result<Diagnosis>) -> Reading {
    let d = d.as_ref().ok()?;
    let w = &d.wear_degree;
    (w.withheld.is_none() && !d.fit.inflated).then_some((w.estimate, w.lower, w.upper))
}

/// The healthy records' truths and the judged ones' (chosen before any run; see the module
/// docs), each draw moved by `seed`.
fn truths(seed: u64) -> (Vec<Truth>, Vec<Truth>) {
    let mut rng = SplitMix64::new(seed * 7919);
    let mut healthy = Vec::new();
    for (i, om) in [0.7, 0.85, 1.0, 1.15, 1.3].into_iter().enumerate() {
        for k in 0..2 {
            healthy.push(Truth {
                ea: 0.1,
                omega1: om,
                part: Part::None,
                seed: seed * 1000 + (2 * i + k) as u64,
            });
        }
    }
    let mut judged = Vec::new();
    for i in 0..9 {
        for k in 0..2 {
            judged.push(Truth {
                ea: 0.2 + 0.1 * i as f64,
                omega1: rng.range(0.75, 1.25),
                part: Part::None,
                seed: seed * 1000 + 100 + (2 * i + k) as u64,
            });
        }
    }
    for (part, first) in [(Part::Tooth, 200), (Part::Shaft, 300)] {
        for k in 0..3 {
            judged.push(Truth {
                ea: 0.3,
                omega1: rng.range(0.75, 1.25),
                part,
                seed: seed * 1000 + first + k,
            });
        }
    }
    (healthy, judged)
}

/// The machine's baselines from its healthy records as the product fits them (state-aware,
/// each channel's path calibrated), posted with a tachometer when `shaft_hz` gives the rate.
fn machine_baselines(
    records: &[Record],
    shaft_hz: &[Option<f64>],
    gb: &Gearbox,
    diagnoser: &TableDiagnoser,
) -> Baselines {
    let empty = Baselines::default();
    let m0 = Machine::described("calibrated-wear-rig", gb, Some(diagnoser), &empty);
    let feats: Vec<RecordFeatures> = records
        .par_iter()
        .zip(shaft_hz)
        .map(|(r, hz)| {
            let (mut ch, facts) = channels(r, *hz, true);
            baseline_features(&mut ch, &[0], &facts, &m0)
                .expect("healthy features")
                .remove(0)
        })
        .collect();
    let by_channel = BTreeMap::from([(CHANNEL.to_string(), feats)]);
    Baselines::fit(&by_channel).with_paths(&by_channel, Some(diagnoser))
}

/// The machine's own model fitted to the healthy records' plain line ratios, and its table.
fn own_model(gb: &Gearbox, table: &SignatureTable, ratios: &[LineRatios]) -> Option<OwnModel> {
    let opts = DiagnoseOptions::default();
    let by = BTreeMap::from([(CHANNEL.to_string(), ratios.to_vec())]);
    let t0 = std::time::Instant::now();
    let physics = match MachinePhysics::fit(gb, table, &opts, &by, &PhysicsFitOptions::default()) {
        Ok(p) => p,
        Err(e) => {
            println!("the machine's own model: refused ({e})");
            return None;
        }
    };
    println!(
        "the machine's own model: fitted in {:.0} s ({} simulations), a left-out speed's lines \
         to {:.2} dB (in sample {:.2}) against {:.2} dB for the empirical path, {:.2} dB plain",
        t0.elapsed().as_secs_f64(),
        physics.simulations,
        physics.left_out_db,
        physics.in_sample_db,
        physics.yardstick_db.unwrap_or(f64::NAN),
        physics.plain_db
    );
    for p in &physics.parameters {
        println!(
            "  {:22} {:.3} [{:.3}, {:.3}]{}",
            p.name,
            p.value,
            p.lower,
            p.upper,
            if p.identified { "" } else { " (prior)" }
        );
    }
    let spec = physics.table_spec(gb, table).expect("the own table's spec");
    let own = precompute(&spec, None, &|| {}).expect("the own table");
    let diagnoser = TableDiagnoser::new(own, opts).expect("the own table");
    Some(OwnModel::new(physics, diagnoser))
}

/// Every judged record's truth and its readings, a Markdown table.
fn print_rows(rows: &[Row]) {
    println!(
        "\n| ea | Ω1 | part | plain | path | own model | assessed |\n| --- | --- | --- | --- | --- | --- | --- |"
    );
    let cell = |w: &Reading| {
        w.map_or("no figure".into(), |(e, lo, hi)| {
            format!("{e:.3} [{lo:.3}, {hi:.3}]")
        })
    };
    for r in rows {
        let t = &r.truth;
        println!(
            "| {:.2} | {:.3} | {} | {} | {} | {} | {} |",
            t.ea,
            t.omega1,
            t.part.label(),
            cell(&r.plain),
            cell(&r.path),
            cell(&r.own),
            cell(&r.assessed)
        );
    }
}

/// The wear records' scores and how many of the records with a part's change got no figure.
fn print_scores(rows: &[Row]) {
    let pick = |f: fn(&Row) -> Reading| -> Vec<(Truth, Reading)> {
        rows.iter()
            .filter(|r| r.truth.part == Part::None)
            .map(|r| (r.truth, f(r)))
            .collect()
    };
    println!("\nwear records, plain: {}", score(&pick(|r| r.plain)));
    println!("wear records, path: {}", score(&pick(|r| r.path)));
    println!("wear records, own model: {}", score(&pick(|r| r.own)));
    println!("wear records, assessed: {}", score(&pick(|r| r.assessed)));
    for part in [Part::Tooth, Part::Shaft] {
        let of: Vec<&Row> = rows.iter().filter(|r| r.truth.part == part).collect();
        let null = |f: fn(&Row) -> Reading| of.iter().filter(|r| f(r).is_none()).count();
        println!(
            "{} records with no figure: own model {}/{}, assessed {}/{}",
            part.label(),
            null(|r| r.own),
            of.len(),
            null(|r| r.assessed),
            of.len()
        );
    }
}

fn main() {
    let seed = env_f64("CW_SEED", 1.0) as u64;
    let peak = env_f64("CW_PEAK", 5.0);
    let physics = std::env::var("CW_PHYSICS").map_or(true, |v| v != "0");
    let tacho_less = std::env::var("CW_TACHOLESS").is_ok();
    let table = SignatureTable::load(&default_table_path()).expect("the paper rig's table");
    let gb = table.gearbox().clone();
    let rig = Rig::new(&gb, seed, physics, peak);
    println!(
        "seed {seed}: machine meshes (stiffness, damping, fluctuation, error) {}",
        rig.meshes
            .iter()
            .take(3)
            .map(|m| format!(
                "({:.2}, {:.2}, {:.2}, {:.2})",
                m.stiffness, m.damping, m.fluctuation, m.error
            ))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let opts_for = |t: &Truth| DiagnoseOptions {
        shaft_hz: (!tacho_less).then(|| rig.shaft_hz(t)),
        ..DiagnoseOptions::default()
    };
    let opts = DiagnoseOptions::default();
    let (healthy, judged) = truths(seed);
    let t0 = std::time::Instant::now();
    let healthy_records: Vec<Record> = healthy.par_iter().map(|t| rig.record(t)).collect();
    let ratios: Vec<LineRatios> = healthy_records
        .par_iter()
        .zip(&healthy)
        .map(|(r, t)| LineRatios::of(&diagnose(r, &table, &opts_for(t)).expect("healthy")))
        .collect();
    let path = PathCalibration::fit(&table, &opts, &ratios);
    match &path {
        Ok(p) => println!(
            "the calibrated path: left-out residual {:.2} dB (plain {:.2} dB)",
            p.residual_after_db, p.residual_before_db
        ),
        Err(e) => println!("the calibrated path: refused ({e})"),
    }
    let own = own_model(&gb, &table, &ratios);
    let diagnoser = TableDiagnoser::new(table.clone(), opts.clone()).expect("table");
    let hz: Vec<Option<f64>> = healthy.iter().map(|t| opts_for(t).shaft_hz).collect();
    let baselines = machine_baselines(&healthy_records, &hz, &gb, &diagnoser);
    let mut m = Machine::described("calibrated-wear-rig", &gb, Some(&diagnoser), &baselines);
    m.own_model = own.as_ref();
    let rows: Vec<Row> = judged
        .par_iter()
        .map(|t| {
            let r = rig.record(t);
            let o = opts_for(t);
            let plain_d = diagnose(&r, &table, &o);
            let own_reading = own.as_ref().and_then(|om| {
                let first = diagnose(&r, om.diagnoser.table(), &o).ok()?;
                let d = om
                    .physics
                    .reread(&r, CHANNEL, om.diagnoser.table(), &opts, &first)
                    .ok()??;
                wear(&Ok(d))
            });
            let (assessed, line) = assessed(&r, o.shaft_hz, &m);
            if std::env::var("CW_DEBUG").is_ok() {
                eprintln!("ea {:.2} {}: {line}", t.ea, t.part.label());
            }
            Row {
                truth: *t,
                plain: wear(&plain_d),
                path: path
                    .as_ref()
                    .ok()
                    .and_then(|p| wear(&p.diagnose(&r, &table, &o))),
                own: own_reading,
                assessed,
            }
        })
        .collect();
    print_rows(&rows);
    print_scores(&rows);
    println!("({:.0} s)", t0.elapsed().as_secs_f64());
}
