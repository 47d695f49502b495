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
//!   records with a damaged input-pinion tooth (stiffness loss 0.6, ea = 0.3), which must get
//!   no wear figure;
//! - read twice: the plain diagnosis and the diagnosis through the calibrated path
//!   ([`gearwear::diagnosis::machine_path`]); a figure, its error, whether the truth lies in
//!   its 90 % interval.
//!
//! Every record's speed is read by a tachometer (the diagnosis is given the shaft's rate);
//! `CW_TACHOLESS=1` finds it in the spectrum instead. Env: `CW_SEED` (default 1) moves every
//! draw; `CW_PEAK` the mode's peak gain; `CW_DEBUG=1` prints each judged record's fit (χ² per
//! feature) and its shafts' TSA FM4.

use gearwear::closed_loop::effects::reference_gears;
use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
use gearwear::diagnosis::machine_path::{LineRatios, PathCalibration};
use gearwear::diagnosis::{DiagnoseOptions, Diagnosis, diagnose};
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
    tooth: bool,
    seed: u64,
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
            tooth: t.tooth.then_some((pinion_ratio, 0.6)),
            ..Default::default()
        },
    }
}

/// A wear figure `(estimate, lower, upper)`, `None` when withheld.
type Reading = Option<(f64, f64, f64)>;

/// A judged record: its truth, the plain reading and the calibrated one.
struct Row {
    truth: Truth,
    plain: Reading,
    calibrated: Reading,
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
    let mut rng = SplitMix64::new(seed * 7919);
    let mut healthy = Vec::new();
    for (i, om) in [0.7, 0.85, 1.0, 1.15, 1.3].into_iter().enumerate() {
        for k in 0..2 {
            healthy.push(Truth {
                ea: 0.1,
                omega1: om,
                tooth: false,
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
                tooth: false,
                seed: seed * 1000 + 100 + (2 * i + k) as u64,
            });
        }
    }
    for k in 0..3 {
        judged.push(Truth {
            ea: 0.3,
            omega1: rng.range(0.75, 1.25),
            tooth: true,
            seed: seed * 1000 + 200 + k,
        });
    }
    let t0 = std::time::Instant::now();
    let base: Vec<Diagnosis> = healthy
        .par_iter()
        .map(|t| {
            let r = generate(&gb, &spec(*t, f_ref, peak, pinion)).expect("rig");
            diagnose(&r, &table, &opts_for(t)).expect("healthy diagnosis")
        })
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
    let rows: Vec<Row> = judged
        .par_iter()
        .map(|t| {
            let r = generate(&gb, &spec(*t, f_ref, peak, pinion)).expect("rig");
            let plain = wear(&diagnose(&r, &table, &opts_for(t)));
            let cd = cal.diagnose(&r, &table, &opts_for(t));
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
                    "ea {:.2} tooth {} chi2/f {:.2} fm4 {}",
                    t.ea,
                    t.tooth,
                    d.fit.chi2_per_feature,
                    fm4.join(" ")
                );
            }
            let calibrated = wear(&cd);
            Row {
                truth: *t,
                plain,
                calibrated,
            }
        })
        .collect();
    println!(
        "\n| ea | Ω1 | tooth | plain: ea [90 %] | calibrated: ea [90 %] |\n| --- | --- | --- | --- | --- |"
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
    } in &rows
    {
        println!(
            "| {:.2} | {:.3} | {} | {} | {} |",
            t.ea,
            t.omega1,
            if t.tooth { "damaged" } else { "–" },
            cell(p),
            cell(c)
        );
    }
    print_scores(&rows);
    println!("({:.0} s)", t0.elapsed().as_secs_f64());
}

/// The wear records' scores, plain and calibrated, and the damaged-tooth records' figures.
fn print_scores(rows: &[Row]) {
    let wear_rows = |calibrated: bool| -> Vec<(Truth, Reading)> {
        rows.iter()
            .filter(|r| !r.truth.tooth)
            .map(|r| (r.truth, if calibrated { r.calibrated } else { r.plain }))
            .collect()
    };
    println!("\nwear records, plain: {}", score(&wear_rows(false)));
    println!("wear records, calibrated: {}", score(&wear_rows(true)));
    let tooth: Vec<&Row> = rows.iter().filter(|r| r.truth.tooth).collect();
    let null = tooth.iter().filter(|r| r.calibrated.is_none()).count();
    println!(
        "damaged-tooth records with no calibrated figure: {null}/{}",
        tooth.len()
    );
}
