//! Accuracy of the wear estimator on held-out simulated records (not a timing benchmark).
//!
//! `cargo bench --bench accuracy` (env: `ACC_N` records, default 200; `ACC_SEED` base seed,
//! default 0xE7A1; `ACC_TABLE` table path, default the committed one; `ACC_OUT` JSON rows, default
//! `target/bench/accuracy-rows.json`, under `CARGO_TARGET_DIR` when set).
//! The gearbox is the table's own (its header carries the description): for another gearbox,
//! `gearwear precompute --gearbox G.toml --output T.json` then `ACC_TABLE=T.json`.
//! Records: ea ~ U[0.1, 1], Ω1 from a few speeds inside the table band (the paper rig's 0.62,
//! 0.87, 1, 1.13, 1.38; another table's at 10, 30, 50, 70, 90 % of its band), random initial state,
//! random gain (log-uniform 1e-2 … 1e2), white noise at 20 dB SNR, 25.6 kHz, 1 s, seeds the
//! table never used. Prints MAE, 90 % coverage, the single-ratio baseline, per-region numbers
//! and the time of one `diagnose` (median over repeats).

use std::time::Instant;

use gearwear::diagnosis::{DiagnoseOptions, Matcher, diagnose_with};
use gearwear::gearbox::Gearbox;
use gearwear::model::Wear;
use gearwear::signature::precompute::{MeasurementSpec, simulate_measurement_with};
use gearwear::signature::{SensorQuantity, SignatureTable, SplitMix64, mix_seed};
use rayon::prelude::*;

#[path = "common/out.rs"]
mod out;

fn env<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

#[derive(Debug, Clone, serde::Serialize)]
struct Row {
    ea: f64,
    omega1: f64,
    known_speed: bool,
    estimate: f64,
    lower: f64,
    upper: f64,
    baseline: f64,
    f1_error_rel: f64,
    planetary_flag: bool,
    motion: String,
    chi2_per_feature: f64,
    error: Option<String>,
}

/// The bench's setup: the table, its gearbox, the options and the operating points.
struct Bench {
    table: SignatureTable,
    table_path: String,
    cfg: Gearbox,
    opts: DiagnoseOptions,
    /// Ω1 of the held-out records, cycled through.
    speeds: Vec<f64>,
    /// Number of held-out records and their base seed.
    n: usize,
    base: u64,
}

/// Sample rate of every record (Hz).
const FS: f64 = 25_600.0;

impl Bench {
    fn from_env() -> Self {
        // `cargo bench` passes `--bench`; ignore arguments.
        let n: usize = env("ACC_N", 200);
        let base: u64 = env("ACC_SEED", 0xE7A1);
        let table_path: String = env(
            "ACC_TABLE",
            concat!(env!("CARGO_MANIFEST_DIR"), "/signatures/model_a_accel.json").to_string(),
        );
        let table = SignatureTable::load(std::path::Path::new(&table_path)).expect("table loads");
        let cfg = table.gearbox().clone();
        if let Err(e) = table.check_model(&cfg) {
            eprintln!("warning: {e}");
        }
        println!(
            "gearbox {} (table {table_path}), Ω1 band {:?}",
            cfg.name(),
            table.omega_band()
        );
        let mut opts = DiagnoseOptions::default();
        if let Ok(v) = std::env::var("ACC_TEMP") {
            opts.temperature = v.parse().unwrap();
        }
        if let Ok(v) = std::env::var("ACC_SIGMA") {
            opts.feature_sigma = v.parse().unwrap();
        }
        if let Ok(v) = std::env::var("ACC_FLOOR") {
            opts.floor_db = v.parse().unwrap();
        }
        let speeds: Vec<f64> = if cfg.hash == gearwear::gearbox::Gearbox::paper_rig().hash {
            vec![0.62, 0.87, 1.0, 1.13, 1.38]
        } else {
            let (lo, hi) = table.omega_band();
            [0.1, 0.3, 0.5, 0.7, 0.9]
                .iter()
                .map(|u| lo + u * (hi - lo))
                .collect()
        };
        Bench {
            table,
            table_path,
            cfg,
            opts,
            speeds,
            n,
            base,
        }
    }

    /// Input-shaft rate (Hz) at an operating point.
    fn shaft_at(&self, om: f64) -> f64 {
        om * self.cfg.reference_frequency_hz() / self.cfg.f1_hz(1.0)
    }
}

fn main() {
    let b = Bench::from_env();
    let t0 = Instant::now();
    let rows = held_out_rows(&b);
    let wall = t0.elapsed().as_secs_f64();
    print_summary(&b, &rows);
    print_checks(&b, &rows);
    println!(
        "simulation + diagnosis wall time: {wall:.1} s on {} threads",
        rayon::current_num_threads()
    );
    planetary_sensitivity(&b);
    time_diagnose(&b);
    let p = out::out_path("ACC_OUT", "accuracy-rows.json");
    std::fs::write(&p, serde_json::to_string_pretty(&rows).unwrap()).unwrap();
    println!("rows written to {}", p.display());
}

/// Simulate and diagnose the held-out records: ea ~ U[0.1, 1], Ω1 cycling through the speeds,
/// log-uniform gain, every second record with the shaft rate given.
fn held_out_rows(b: &Bench) -> Vec<Row> {
    let (cfg, speeds, base) = (&b.cfg, &b.speeds, b.base);
    let mut rng = SplitMix64::new(base);
    let cases: Vec<(f64, f64, f64, u64)> = (0..b.n)
        .map(|k| {
            let ea = rng.range(0.1, 1.0);
            let om = speeds[k % speeds.len()];
            let gain = 10f64.powf(rng.range(-2.0, 2.0));
            (ea, om, gain, mix_seed(&[base, 0xACC, k as u64]))
        })
        .collect();
    cases
        .par_iter()
        .enumerate()
        .map(|(k, &(ea, om, gain, seed))| {
            let model = cfg
                .assembly(Wear::fixed_axis(ea))
                .unwrap()
                .resolve()
                .unwrap();
            let spec = MeasurementSpec {
                ea,
                omega1: om,
                sample_rate: FS,
                duration: 1.0,
                gain,
                snr_db: Some(20.0),
                seed,
                sensor: SensorQuantity::Accel,
                planetary: None,
            };
            let rec = simulate_measurement_with(&model, &spec).expect("simulation");
            let known = k % 2 == 0;
            let matcher = Matcher::new(&b.table, &b.opts).unwrap();
            let o = DiagnoseOptions {
                shaft_hz: known.then(|| b.shaft_at(om)),
                ..b.opts.clone()
            };
            row(
                &b.cfg,
                ea,
                om,
                known,
                diagnose_with(&rec, &b.table, &matcher, &o),
            )
        })
        .collect()
}

/// One held-out record's row from its diagnosis (or its error).
fn row(
    cfg: &Gearbox,
    ea: f64,
    om: f64,
    known: bool,
    d: gearwear::Result<gearwear::diagnosis::Diagnosis>,
) -> Row {
    let f_ref = cfg.reference_frequency_hz();
    match d {
        Ok(d) => Row {
            ea,
            omega1: om,
            known_speed: known,
            estimate: d.wear_degree.estimate,
            lower: d.wear_degree.lower,
            upper: d.wear_degree.upper,
            baseline: d.baseline_single_ratio.map_or(f64::NAN, |b| b.ea),
            f1_error_rel: d.f1_hz / (om * f_ref) - 1.0,
            planetary_flag: d.planetary_clearance_elevated,
            motion: d.motion_state,
            chi2_per_feature: d.fit.chi2_per_feature,
            error: None,
        },
        Err(e) => Row {
            ea,
            omega1: om,
            known_speed: known,
            estimate: f64::NAN,
            lower: f64::NAN,
            upper: f64::NAN,
            baseline: f64::NAN,
            f1_error_rel: f64::NAN,
            planetary_flag: false,
            motion: String::new(),
            chi2_per_feature: f64::NAN,
            error: Some(e.to_string()),
        },
    }
}

/// The accuracy table: MAE, coverage, interval width and the baseline, over all records and
/// per subset (speed given or not, per Ω1, per ea range).
fn print_summary(b: &Bench, rows: &[Row]) {
    let summarise = |label: &str, sel: &dyn Fn(&Row) -> bool| {
        let r: Vec<&Row> = rows
            .iter()
            .filter(|r| sel(r) && r.error.is_none())
            .collect();
        let failed = rows.iter().filter(|r| sel(r) && r.error.is_some()).count();
        if r.is_empty() {
            println!("| {label} | 0 | – | – | – | – | {failed} |");
            return;
        }
        let m = r.len() as f64;
        let mae = r.iter().map(|r| (r.estimate - r.ea).abs()).sum::<f64>() / m;
        let cov = r
            .iter()
            .filter(|r| r.lower <= r.ea && r.ea <= r.upper)
            .count() as f64
            / m;
        let width = r.iter().map(|r| r.upper - r.lower).sum::<f64>() / m;
        let base = r.iter().map(|r| (r.baseline - r.ea).abs()).sum::<f64>() / m;
        println!(
            "| {label} | {} | {mae:.3} | {:.0} % | {width:.3} | {base:.3} | {failed} |",
            r.len(),
            100.0 * cov
        );
    };
    let (n, base, table_path, opts) = (b.n, b.base, &b.table_path, &b.opts);
    println!("\nheld-out records: {n}, base seed {base:#x}, table {table_path}, options {opts:?}");
    println!(
        "| subset | records | MAE ea | 90 % coverage | mean interval width | baseline MAE (f1:f2) | errors |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    summarise("all", &|_| true);
    summarise("speed given", &|r| r.known_speed);
    summarise("tacho-less", &|r| !r.known_speed);
    for &s in &b.speeds {
        summarise(&format!("Ω1 = {s}"), &|r| (r.omega1 - s).abs() < 1e-9);
    }
    for (lo, hi) in [(0.1, 0.3), (0.3, 0.5), (0.5, 0.7), (0.7, 0.85), (0.85, 1.0)] {
        summarise(&format!("ea ∈ [{lo}, {hi})"), &|r| {
            r.ea >= lo && r.ea < hi
        });
    }
}

/// False planetary flags, f1 errors, the χ² quantiles and the first errors.
fn print_checks(b: &Bench, rows: &[Row]) {
    let n = b.n;
    let flags = rows.iter().filter(|r| r.planetary_flag).count();
    let bad_f1 = rows
        .iter()
        .filter(|r| r.error.is_none() && r.f1_error_rel.abs() > 1e-3)
        .count();
    println!(
        "\nplanetary flag raised (false positives, planetary error is 0.1 in every record): {flags}/{n}"
    );
    println!("f1 off by more than 0.1 %: {bad_f1}/{n}");
    let mut chi: Vec<f64> = rows
        .iter()
        .filter(|r| r.error.is_none())
        .map(|r| r.chi2_per_feature)
        .collect();
    chi.sort_by(f64::total_cmp);
    if !chi.is_empty() {
        let q = |p: f64| chi[((chi.len() - 1) as f64 * p).round() as usize];
        println!(
            "χ² per feature at the best point: median {:.2}, 90 % {:.2}, 99 % {:.2}, max {:.2}",
            q(0.5),
            q(0.9),
            q(0.99),
            q(1.0)
        );
    }
    for r in rows.iter().filter(|r| r.error.is_some()).take(5) {
        println!(
            "error: ea {:.3} Ω1 {}: {}",
            r.ea,
            r.omega1,
            r.error.as_ref().unwrap()
        );
    }
}

/// Planetary flag sensitivity: records with an elevated planetary error (only for a gearbox
/// with a planetary stage the wear does not act on).
fn planetary_sensitivity(b: &Bench) {
    let (cfg, speeds, base) = (&b.cfg, &b.speeds, b.base);
    let n_planet: usize = if cfg.planetary_ratio().is_some() {
        env("ACC_PLANET_N", 40)
    } else {
        0
    };
    for pe in [0.2, 0.3, 0.5].into_iter().filter(|_| n_planet > 0) {
        let flagged: Vec<(bool, f64)> = (0..n_planet)
            .into_par_iter()
            .map(|k| {
                let mut r = SplitMix64::new(mix_seed(&[base, 0x9A7E, k as u64]));
                let ea = r.range(0.1, 1.0);
                let om = speeds[k % speeds.len()];
                let rec = gearwear::signature::precompute::simulate_measurement(
                    cfg,
                    &MeasurementSpec {
                        ea,
                        omega1: om,
                        sample_rate: FS,
                        duration: 1.0,
                        gain: 1.0,
                        snr_db: Some(20.0),
                        seed: r.next_u64(),
                        sensor: SensorQuantity::Accel,
                        planetary: Some(pe),
                    },
                )
                .expect("simulation");
                let o = DiagnoseOptions {
                    shaft_hz: Some(b.shaft_at(om)),
                    ..b.opts.clone()
                };
                match gearwear::diagnosis::diagnose(&rec, &b.table, &o) {
                    Ok(d) => (
                        d.planetary_clearance_elevated,
                        (d.wear_degree.estimate - ea).abs(),
                    ),
                    Err(_) => (false, f64::NAN),
                }
            })
            .collect();
        let hits = flagged.iter().filter(|f| f.0).count();
        let mae = flagged.iter().map(|f| f.1).sum::<f64>() / flagged.len().max(1) as f64;
        println!(
            "planetary error {pe}: flag raised on {hits}/{n_planet} records (speed given); ea MAE on them {mae:.3}"
        );
    }
}

/// Time of one diagnose, 1 s at 25.6 kHz, mid-band Ω1, tacho-less and with the speed.
fn time_diagnose(b: &Bench) {
    let om_mid = b.speeds[b.speeds.len() / 2];
    let model = b
        .cfg
        .assembly(Wear::fixed_axis(0.8))
        .unwrap()
        .resolve()
        .unwrap();
    let rec = simulate_measurement_with(
        &model,
        &MeasurementSpec {
            ea: 0.8,
            omega1: om_mid,
            sample_rate: FS,
            duration: 1.0,
            gain: 1.0,
            snr_db: Some(20.0),
            seed: 1,
            sensor: SensorQuantity::Accel,
            planetary: None,
        },
    )
    .unwrap();
    for (label, shaft) in [
        ("tacho-less", None),
        ("speed given", Some(b.shaft_at(om_mid))),
    ] {
        let o = DiagnoseOptions {
            shaft_hz: shaft,
            ..b.opts.clone()
        };
        let mut times = Vec::new();
        for _ in 0..21 {
            let t = Instant::now();
            let d = gearwear::diagnosis::diagnose(&rec, &b.table, &o).unwrap();
            times.push(t.elapsed().as_secs_f64());
            std::hint::black_box(d);
        }
        times.sort_by(f64::total_cmp);
        println!(
            "diagnose, 1 s at 25.6 kHz, {label} (incl. table statistics): median {:.1} ms over 21 runs",
            1e3 * times[10]
        );
    }
}
