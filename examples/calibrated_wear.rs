//! Wear read against the model calibrated to a machine, on a simulated machine whose transfer
//! path, gain, speed and noise the calibration must discover (`cargo run --release --example
//! calibrated_wear`, ≈ 1 min on 2 cores).
//!
//! The machine: the paper's rig (its committed table `signatures/model_a_accel.json`) seen
//! through a housing mode fixed in Hz (1.3 × the reference mesh frequency, ζ = 0.05, peak
//! gain 5), an unknown gain (37), white noise at 25 dB SNR, 16 kHz, 0.6 s, each record from its
//! own random initial state and at its own speed. Chosen before any run:
//! - healthy baseline: wear ea = 0.1 (the table's lowest) at Ω1 = 0.7, 0.85, 1.0, 1.15, 1.3,
//!   two records each;
//! - judged: ea = 0.2, 0.3, …, 1.0, two records each at Ω1 drawn in [0.75, 1.25]; and three
//!   records with a damaged input-pinion tooth (stiffness loss 0.6, ea = 0.3) and three with the
//!   input shaft modulating mesh 1 (eccentricity 0.1 b, ea = 0.3), which must get no wear
//!   figure;
//! - read three times: the plain diagnosis, the diagnosis through the calibrated path
//!   ([`gearwear::diagnosis::machine_path`]), and the product's assessment of a machine whose
//!   baseline is the healthy records (state-aware, its path calibrated; the wear withheld when
//!   the record's change is mostly one part's); a figure, its error, whether the truth lies in
//!   its 90 % interval.
//!
//! Every record's speed is read by a tachometer (the diagnosis is given the shaft's rate);
//! `CW_TACHOLESS=1` finds it in the spectrum instead. Env: `CW_SEED` (default 1) moves every
//! draw; `CW_PEAK` the mode's peak gain; `CW_TOOTH_LOSS` the damaged tooth's stiffness loss;
//! `CW_DEBUG=1` prints each judged record's fit (χ² per
//! feature) and its shafts' TSA FM4.

use std::collections::BTreeMap;

use gearwear::assessment::{
    Baselines, Machine, RecordFacts, TableDiagnoser, TachoChannel, assess, baseline_features,
};
use gearwear::closed_loop::effects::reference_gears;
use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec, generate, tachometer};
use gearwear::diagnosis::machine_path::{LineRatios, PathCalibration};
use gearwear::diagnosis::{DiagnoseOptions, Diagnosis, diagnose};
use gearwear::gearbox::Gearbox;
use gearwear::novelty::RecordFeatures;
use gearwear::record::Record;
use gearwear::signature::SignatureTable;
use gearwear::signature::SplitMix64;
use gearwear::signature::table::default_table_path;
use rayon::prelude::*;

const FS: f64 = 16_000.0;
const DURATION: f64 = 0.6;
const GAIN: f64 = 37.0;
const SNR_DB: f64 = 25.0;

/// A record's truth.
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

/// The damaged tooth's stiffness loss: `CW_TOOTH_LOSS`, 0.6 by default.
fn tooth_loss() -> f64 {
    std::env::var("CW_TOOTH_LOSS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.6)
}

fn spec(t: Truth, f_ref: f64, peak: f64, pinion_ratio: f64) -> RigSpec {
    let mode_hz = 1.3 * f_ref;
    let f1 = t.omega1 * f_ref;
    RigSpec {
        ea: t.ea,
        omega1: t.omega1,
        sample_rate: FS,
        duration: DURATION,
        gain: GAIN,
        snr_db: SNR_DB,
        seed: t.seed,
        effects: RigEffects {
            path_peak: Some((mode_hz / f1, 0.05, peak)),
            tooth: (t.part == Part::Tooth).then_some((pinion_ratio, tooth_loss())),
            eccentricity: (t.part == Part::Shaft).then_some(0.1),
            ..Default::default()
        },
    }
}

/// A wear figure `(estimate, lower, upper)`, `None` when withheld.
type Reading = Option<(f64, f64, f64)>;

/// A judged record: its truth, the plain reading, the calibrated one and the assessment's.
struct Row {
    truth: Truth,
    plain: Reading,
    calibrated: Reading,
    assessed: Reading,
}

/// The record's one channel as the assessment takes it.
const CHANNEL: &str = "a1";

/// The machine as the product holds it: the rig's gearbox described, its table, and the
/// baselines fitted from the healthy records.
fn machine<'a>(gb: &'a Gearbox, d: &'a TableDiagnoser, b: &'a Baselines) -> Machine<'a> {
    Machine::described("calibrated-wear-rig", gb, Some(d), b)
}

/// Tachometer pulses per revolution of the input shaft.
const PULSES_PER_REV: usize = 10;

/// The record's vibration channel and, with a shaft rate known (`shaft_hz`), a tachometer
/// channel of [`PULSES_PER_REV`] square pulses per revolution (0/5 V, half duty), with its
/// facts: the product measures the speed from those pulses, as from a machine's tachometer.
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
/// the record), and its novelty and findings (kind, share) in a line.
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
        .and_then(|r| r.diagnosis.wear_degree.withheld.as_ref())
        .map(|w| w.note.as_str())
        .map_or(String::new(), |w| format!(" withheld: {w}"));
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
    truths: &[Truth],
    gb: &Gearbox,
    diagnoser: &TableDiagnoser,
    shaft_hz: &(dyn Fn(&Truth) -> Option<f64> + Sync),
) -> Baselines {
    let empty = Baselines::default();
    let m0 = machine(gb, diagnoser, &empty);
    let feats: Vec<RecordFeatures> = records
        .par_iter()
        .zip(truths)
        .map(|(r, t)| {
            let (mut ch, facts) = channels(r, shaft_hz(t), true);
            baseline_features(&mut ch, &[0], &facts, &m0)
                .expect("healthy features")
                .remove(0)
        })
        .collect();
    let by_channel = BTreeMap::from([(CHANNEL.to_string(), feats)]);
    let baselines = Baselines::fit(&by_channel).with_paths(&by_channel, Some(diagnoser));
    println!(
        "the machine's baseline: state-aware {}, path {}",
        if baselines.states.contains_key(CHANNEL) {
            "fitted"
        } else {
            "not fitted"
        },
        baselines
            .path_refusals
            .get(CHANNEL)
            .map_or("calibrated".to_string(), |why| format!("refused ({why})"))
    );
    baselines
}

/// Every judged record's truth and its three readings, a Markdown table.
fn print_rows(rows: &[Row]) {
    println!(
        "\n| ea | Ω1 | part | plain: ea [90 %] | calibrated: ea [90 %] | assessed: ea [90 %] |\n| --- | --- | --- | --- | --- | --- |"
    );
    let cell = |w: &Option<(f64, f64, f64)>| {
        w.map_or("no figure".into(), |(e, lo, hi)| {
            format!("{e:.3} [{lo:.3}, {hi:.3}]")
        })
    };
    for Row {
        truth: t,
        plain: p,
        calibrated: c,
        assessed: a,
    } in rows
    {
        println!(
            "| {:.2} | {:.3} | {} | {} | {} | {} |",
            t.ea,
            t.omega1,
            t.part.label(),
            cell(p),
            cell(c),
            cell(a)
        );
    }
}

fn main() {
    let seed: u64 = std::env::var("CW_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let peak: f64 = std::env::var("CW_PEAK")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5.0);
    let table = SignatureTable::load(&default_table_path()).expect("the paper rig's table");
    let gb = table.gearbox().clone();
    let f_ref = gb.reference_frequency_hz();
    let pinion = reference_gears(&gb)[0].shaft_ratio;
    let tacho_less = std::env::var("CW_TACHOLESS").is_ok();
    // A tachometer reads the shaft's true rate; without one the speed is found in the spectrum.
    let opts_for = |t: &Truth| DiagnoseOptions {
        shaft_hz: (!tacho_less).then(|| t.omega1 * f_ref / gb.f1_per_input_hz),
        ..DiagnoseOptions::default()
    };
    let opts = DiagnoseOptions::default();
    let (healthy, judged) = truths(seed);
    let t0 = std::time::Instant::now();
    let shaft_hz = |t: &Truth| opts_for(t).shaft_hz;
    let healthy_records: Vec<Record> = healthy
        .par_iter()
        .map(|t| generate(&gb, &spec(*t, f_ref, peak, pinion)).expect("rig"))
        .collect();
    let base: Vec<Diagnosis> = healthy_records
        .par_iter()
        .zip(&healthy)
        .map(|(r, t)| diagnose(r, &table, &opts_for(t)).expect("healthy diagnosis"))
        .collect();
    let ratios: Vec<LineRatios> = base.iter().map(LineRatios::of).collect();
    let cal = match PathCalibration::fit(&table, &opts, &ratios) {
        Ok(c) => c,
        Err(e) => {
            println!("calibration refused: {e}");
            return;
        }
    };
    println!(
        "calibration: {} healthy records at f1 {:.0?} Hz, λ = {}, left-out residual {:.2} dB (against the plain model {:.2} dB)",
        cal.records, cal.f1_hz, cal.lambda, cal.residual_after_db, cal.residual_before_db
    );
    let plain_base = base
        .iter()
        .filter(|d| d.wear_degree.withheld.is_none())
        .count();
    println!(
        "healthy records with a plain wear figure: {plain_base}/{}",
        base.len()
    );
    let diagnoser = TableDiagnoser::new(table.clone(), opts.clone()).expect("table");
    let baselines = machine_baselines(&healthy_records, &healthy, &gb, &diagnoser, &shaft_hz);
    let m = machine(&gb, &diagnoser, &baselines);
    let rows: Vec<Row> = judged
        .par_iter()
        .map(|t| {
            let r = generate(&gb, &spec(*t, f_ref, peak, pinion)).expect("rig");
            let plain = wear(&diagnose(&r, &table, &opts_for(t)));
            let cd = cal.diagnose(&r, &table, &opts_for(t));
            let (assessed, leading) = assessed(&r, shaft_hz(t), &m);
            if std::env::var("CW_DEBUG").is_ok()
                && let Ok(d) = &cd
            {
                let fm4: Vec<String> = d
                    .order
                    .iter()
                    .flat_map(|o| &o.shafts)
                    .map(|s| format!("{}:{:.1}", s.shaft, s.metrics.fm4.unwrap_or(f64::NAN)))
                    .collect();
                eprintln!(
                    "ea {:.2} {} chi2/f {:.2} fm4 {} finding {leading}",
                    t.ea,
                    t.part.label(),
                    d.fit.chi2_per_feature,
                    fm4.join(" ")
                );
            }
            let calibrated = wear(&cd);
            Row {
                truth: *t,
                plain,
                calibrated,
                assessed,
            }
        })
        .collect();
    print_rows(&rows);
    print_scores(&rows);
    println!("({:.0} s)", t0.elapsed().as_secs_f64());
}

/// The wear records' scores (plain, calibrated, assessed) and how many of the records with a
/// part's change got no figure.
fn print_scores(rows: &[Row]) {
    let wear_rows = |pick: fn(&Row) -> Reading| -> Vec<(Truth, Reading)> {
        rows.iter()
            .filter(|r| r.truth.part == Part::None)
            .map(|r| (r.truth, pick(r)))
            .collect()
    };
    println!("\nwear records, plain: {}", score(&wear_rows(|r| r.plain)));
    println!(
        "wear records, calibrated: {}",
        score(&wear_rows(|r| r.calibrated))
    );
    println!(
        "wear records, assessed: {}",
        score(&wear_rows(|r| r.assessed))
    );
    for part in [Part::Tooth, Part::Shaft] {
        let of: Vec<&Row> = rows.iter().filter(|r| r.truth.part == part).collect();
        let null = |pick: fn(&Row) -> Reading| of.iter().filter(|r| pick(r).is_none()).count();
        println!(
            "{} records with no figure: calibrated {}/{}, assessed {}/{}",
            part.label(),
            null(|r| r.calibrated),
            of.len(),
            null(|r| r.assessed),
            of.len()
        );
    }
}
