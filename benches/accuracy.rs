//! Accuracy of the wear estimator on held-out simulated records (not a timing benchmark).
//!
//! `cargo bench --bench accuracy` (env: `ACC_N` records, default 200; `ACC_SEED` base seed,
//! default 0xE7A1; `ACC_TABLE` table path, default the committed one; `ACC_OUT` JSON output).
//! The gearbox is the table's own (its header carries the description): for another gearbox,
//! `gearwear precompute --gearbox G.toml --output T.json` then `ACC_TABLE=T.json`.
//! Records: ea ~ U[0.1, 1], Ω1 from a few speeds inside the table band (the paper rig's 0.62,
//! 0.87, 1, 1.13, 1.38; another table's at 10, 30, 50, 70, 90 % of its band), random initial state,
//! random gain (log-uniform 1e-2 … 1e2), white noise at 20 dB SNR, 25.6 kHz, 1 s, seeds the
//! table never used. Prints MAE, 90 % coverage, the single-ratio baseline, per-region numbers
//! and the time of one `diagnose` (median over repeats).

use std::time::Instant;

use gearwear::diagnosis::{DiagnoseOptions, Matcher, diagnose_with};
use gearwear::model::Wear;
use gearwear::signature::precompute::{MeasurementSpec, simulate_measurement_with};
use gearwear::signature::{SensorQuantity, SignatureTable, SplitMix64, mix_seed};
use rayon::prelude::*;

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

fn main() {
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
    let f_ref = cfg.reference_frequency_hz();
    // Input-shaft rate (Hz) at an operating point.
    let shaft_at = |om: f64| om * f_ref / cfg.f1_hz(1.0);
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
    let fs = 25_600.0;
    let mut rng = SplitMix64::new(base);
    let cases: Vec<(f64, f64, f64, u64)> = (0..n)
        .map(|k| {
            let ea = rng.range(0.1, 1.0);
            let om = speeds[k % speeds.len()];
            let gain = 10f64.powf(rng.range(-2.0, 2.0));
            (ea, om, gain, mix_seed(&[base, 0xACC, k as u64]))
        })
        .collect();
    let t0 = Instant::now();
    let rows: Vec<Row> = cases
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
                sample_rate: fs,
                duration: 1.0,
                gain,
                snr_db: Some(20.0),
                seed,
                sensor: SensorQuantity::Accel,
                planetary: None,
            };
            let rec = simulate_measurement_with(&model, &spec).expect("simulation");
            let known = k % 2 == 0;
            let matcher = Matcher::new(&table, &opts).unwrap();
            let o = DiagnoseOptions {
                shaft_hz: known.then(|| shaft_at(om)),
                ..opts.clone()
            };
            match diagnose_with(&rec, &table, &matcher, &o) {
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
        })
        .collect();
    let wall = t0.elapsed().as_secs_f64();
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
    println!("\nheld-out records: {n}, base seed {base:#x}, table {table_path}, options {opts:?}");
    println!(
        "| subset | records | MAE ea | 90 % coverage | mean interval width | baseline MAE (f1:f2) | errors |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    summarise("all", &|_| true);
    summarise("speed given", &|r| r.known_speed);
    summarise("tacho-less", &|r| !r.known_speed);
    for &s in &speeds {
        summarise(&format!("Ω1 = {s}"), &|r| (r.omega1 - s).abs() < 1e-9);
    }
    for (lo, hi) in [(0.1, 0.3), (0.3, 0.5), (0.5, 0.7), (0.7, 0.85), (0.85, 1.0)] {
        summarise(&format!("ea ∈ [{lo}, {hi})"), &|r| {
            r.ea >= lo && r.ea < hi
        });
    }
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
    println!(
        "simulation + diagnosis wall time: {wall:.1} s on {} threads",
        rayon::current_num_threads()
    );

    // Planetary flag sensitivity: records with an elevated planetary error (only for a
    // gearbox with a planetary stage the wear does not act on).
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
                    &cfg,
                    &MeasurementSpec {
                        ea,
                        omega1: om,
                        sample_rate: fs,
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
                    shaft_hz: Some(shaft_at(om)),
                    ..opts.clone()
                };
                match gearwear::diagnosis::diagnose(&rec, &table, &o) {
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

    // Time of one diagnose, 1 s at 25.6 kHz, mid-band Ω1, tacho-less and with the speed.
    let om_mid = speeds[speeds.len() / 2];
    let model = cfg
        .assembly(Wear::fixed_axis(0.8))
        .unwrap()
        .resolve()
        .unwrap();
    let rec = simulate_measurement_with(
        &model,
        &MeasurementSpec {
            ea: 0.8,
            omega1: om_mid,
            sample_rate: fs,
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
        ("speed given", Some(shaft_at(om_mid))),
    ] {
        let o = DiagnoseOptions {
            shaft_hz: shaft,
            ..opts.clone()
        };
        let mut times = Vec::new();
        for _ in 0..21 {
            let t = Instant::now();
            let d = gearwear::diagnosis::diagnose(&rec, &table, &o).unwrap();
            times.push(t.elapsed().as_secs_f64());
            std::hint::black_box(d);
        }
        times.sort_by(f64::total_cmp);
        println!(
            "diagnose, 1 s at 25.6 kHz, {label} (incl. table statistics): median {:.1} ms over 21 runs",
            1e3 * times[10]
        );
    }
    if let Ok(p) = std::env::var("ACC_OUT") {
        std::fs::write(&p, serde_json::to_string_pretty(&rows).unwrap()).unwrap();
        println!("rows written to {p}");
    }
}
