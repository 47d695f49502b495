//! Timing of one `diagnose_with` call (the per-request cost of the service), and a dump of the
//! diagnoses of held-out records for before/after regression checks.
//!
//! `cargo bench --bench diagnose` (plain program, `harness = false`). Env:
//! `DIAG_REPS` calls per case (default 101; the median and p99 are reported);
//! `DIAG_DUMP` path (default `target/bench/diagnose-dump.json`, under `CARGO_TARGET_DIR` when
//! set): where to write the JSON diagnoses of `DIAG_DUMP_N` (default 20) held-out
//! records (the accuracy benchmark's generator: ea ~ U[0.1, 1], Ω1 cycling through five speeds,
//! random gain, 20 dB SNR, 25.6 kHz, 1 s; every second record with the shaft rate given);
//! `DIAG_TABLE` table path (default the committed one).
//!
//! The timed record: 1 s at 25.6 kHz, Ω1 = 1, ea = 0.8, seed 1 (the accuracy benchmark's
//! timing record), with a `Matcher` prepared once outside the timed loop, as the service does.

use std::time::Instant;

#[path = "common/four_sines.rs"]
mod four_sines;
#[path = "common/out.rs"]
mod out;

use gearwear::diagnosis::{DiagnoseOptions, Matcher, diagnose_with};
use gearwear::gearbox::Gearbox;
use gearwear::model::Wear;
use gearwear::record::Record;
use gearwear::signature::precompute::{MeasurementSpec, simulate_measurement_with};
use gearwear::signature::{SensorQuantity, SignatureTable, SplitMix64, mix_seed};

fn env<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

fn record(cfg: &Gearbox, ea: f64, om: f64, gain: f64, seed: u64) -> Record {
    let model = cfg
        .assembly(Wear::fixed_axis(ea))
        .unwrap()
        .resolve()
        .unwrap();
    simulate_measurement_with(
        &model,
        &MeasurementSpec {
            ea,
            omega1: om,
            sample_rate: 25_600.0,
            duration: 1.0,
            gain,
            snr_db: Some(20.0),
            seed,
            sensor: SensorQuantity::Accel,
            planetary: None,
        },
    )
    .expect("simulation")
}

fn main() {
    let reps: usize = env("DIAG_REPS", 101).max(1);
    let table_path: String = env(
        "DIAG_TABLE",
        concat!(env!("CARGO_MANIFEST_DIR"), "/signatures/model_a_accel.json").to_string(),
    );
    let cfg = Gearbox::paper_rig();
    let table = SignatureTable::load(std::path::Path::new(&table_path)).expect("table loads");
    let opts = DiagnoseOptions::default();
    let t = Instant::now();
    let matcher = Matcher::new(&table, &opts).expect("matcher");
    println!(
        "Matcher::new: {:.2} ms (once per table)",
        1e3 * t.elapsed().as_secs_f64()
    );

    dump_diagnoses(&cfg, &table, &matcher, &opts);

    let rec = record(&cfg, 0.8, 1.0, 1.0, 1);
    // The load generator's record: a poor fit, the service's worst case.
    let poor_fit = Record {
        samples: four_sines::samples(),
        sample_rate: four_sines::SAMPLE_RATE_HZ,
    };
    println!(
        "record: {} samples at {} Hz; {reps} calls per case",
        rec.samples.len(),
        rec.sample_rate
    );
    println!("| case | median | p99 | min | max |");
    println!("| --- | --- | --- | --- | --- |");
    for (label, shaft, rec) in [
        ("model record, tacho-less", None, &rec),
        ("model record, speed given", Some(30.0), &rec),
        ("four sines (poor fit), tacho-less", None, &poor_fit),
    ] {
        let o = DiagnoseOptions {
            shaft_hz: shaft,
            ..opts.clone()
        };
        // Warm-up (plans, caches).
        for _ in 0..3 {
            std::hint::black_box(diagnose_with(rec, &table, &matcher, &o).unwrap());
        }
        let mut times: Vec<f64> = (0..reps)
            .map(|_| {
                let t = Instant::now();
                let d = diagnose_with(rec, &table, &matcher, &o).unwrap();
                let dt = t.elapsed().as_secs_f64();
                std::hint::black_box(d);
                dt
            })
            .collect();
        times.sort_by(f64::total_cmp);
        let q = |p: f64| 1e3 * times[((times.len() - 1) as f64 * p).round() as usize];
        println!(
            "| diagnose_with, {label} | {:.2} ms | {:.2} ms | {:.2} ms | {:.2} ms |",
            q(0.5),
            q(0.99),
            q(0.0),
            q(1.0)
        );
    }
}

/// Write the JSON diagnoses of `DIAG_DUMP_N` held-out records to `DIAG_DUMP` (default
/// `target/bench/diagnose-dump.json`), for before/after regression checks.
fn dump_diagnoses(
    cfg: &Gearbox,
    table: &SignatureTable,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) {
    let path = out::out_path("DIAG_DUMP", "diagnose-dump.json");
    let n: usize = env("DIAG_DUMP_N", 20);
    let base: u64 = 0xD1A6;
    let speeds = [0.62, 0.87, 1.0, 1.13, 1.38];
    let mut rng = SplitMix64::new(base);
    let mut out = Vec::new();
    for k in 0..n {
        let ea = rng.range(0.1, 1.0);
        let om = speeds[k % speeds.len()];
        let gain = 10f64.powf(rng.range(-2.0, 2.0));
        let rec = record(cfg, ea, om, gain, mix_seed(&[base, 0xACC, k as u64]));
        let known = k % 2 == 0;
        let o = DiagnoseOptions {
            shaft_hz: known.then(|| om * cfg.reference_frequency_hz() / cfg.f1_hz(1.0)),
            ..opts.clone()
        };
        let d = diagnose_with(&rec, table, matcher, &o)
            .map(|d| serde_json::to_value(d).unwrap())
            .unwrap_or_else(|e| serde_json::json!({ "error": e.to_string() }));
        out.push(
            serde_json::json!({ "ea": ea, "omega1": om, "known_speed": known, "diagnosis": d }),
        );
    }
    std::fs::write(&path, serde_json::to_string_pretty(&out).unwrap()).unwrap();
    println!("{n} diagnoses written to {}", path.display());
}
