//! Cost of judging a record against a state-aware baseline, against today's diagnosis of the
//! same record.
//!
//! `cargo bench --bench condition` (plain program, `harness = false`). Needs the PHM 2009
//! helical records (`PHM_DIR`, default `../shared/data/phm09-helical`) and the committed
//! `signatures/phm09-helical.json`. Env `COND_REPS` (default 21): timed calls per case; the
//! median is reported.
//!
//! The record: 4 s at 66.7 kHz, 3 channels (input, output, tachometer) — the two healthy
//! 2 s runs at 40 Hz, high load, one after the other. The baseline: case 1 run 1 at all ten
//! states, its features computed **once** (outside the timed loop, as the service stores them
//! with each baseline record) and fitted.
//!
//! * **before** — what `diagnose` did per channel before the state-aware baseline: the
//!   table's reading at the nominal speed and the novelty features reusing its order
//!   analysis (`TableDiagnoser::read` + `record_features_with`), for both accelerometers;
//! * **after** — `assess` with the tachometer, the load and the state-aware baseline: speed
//!   measured, both accelerometers read, their evidence computed and judged, findings.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use gearwear::assessment::{
    Baselines, GearboxRef, Machine, RecordFacts, TableDiagnoser, TachoChannel, Thresholds, assess,
    baseline_features,
};
use gearwear::condition::Load;
use gearwear::diagnosis::DiagnoseOptions;
use gearwear::gearbox::Gearbox;
use gearwear::novelty::{RecordFeatures, record_features_with};
use gearwear::record::{ReadOptions, Record, read_record_channels};
use gearwear::signature::SignatureTable;

const FS: f64 = 200_000.0 / 3.0;

fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn channels(dir: &Path, name: &str) -> Vec<(String, Vec<f64>)> {
    let opts = ReadOptions {
        sample_rate: Some(FS),
        ..Default::default()
    };
    read_record_channels(&dir.join(name), &opts)
        .unwrap_or_else(|e| panic!("{name}: {e} (set PHM_DIR)"))
        .channels
        .into_iter()
        .map(|c| (c.name, c.samples))
        .collect()
}

fn facts(speed: f64, load: &str, healthy: bool) -> RecordFacts {
    RecordFacts {
        sample_rate_hz: FS,
        shaft_hz: Some(speed),
        sensor: None,
        declared_healthy: healthy,
        load: Load::parse(load),
        tacho: Some(TachoChannel {
            name: "tach".into(),
            pulses_per_rev: 10,
        }),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let dir = std::env::var("PHM_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| manifest("../shared/data/phm09-helical"));
    let reps: usize = std::env::var("COND_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(21);
    let gb = Gearbox::from_file(&manifest("configs/gearboxes/phm09-helical.toml")).unwrap();
    let table = SignatureTable::load(&manifest("signatures/phm09-helical.json")).unwrap();
    let diagnoser = TableDiagnoser::new(table, DiagnoseOptions::default()).unwrap();
    let empty_p = BTreeMap::new();
    let empty_s = BTreeMap::new();
    let empty_c = BTreeMap::new();
    let empty_paths = BTreeMap::new();
    let machine = Machine {
        gearbox: &gb,
        gearbox_ref: GearboxRef {
            id: "phm09-helical".into(),
            name: gb.name().into(),
            hash: gb.hash.clone(),
            table_status: gearwear::signature::TableStatus::Ready,
            table_progress: 1.0,
        },
        described: true,
        diagnoser: Some(&diagnoser),
        table_note: None,
        input_shaft_hz: None,
        baselines: &empty_p,
        state_baselines: &empty_s,
        baseline_counts: &empty_c,
        calibration: None,
        paths: &empty_paths,
        own_model: None,
        extends_tables: false,
        thresholds: Thresholds::default(),
        units: Default::default(),
    };
    let t0 = Instant::now();
    let mut by_channel: BTreeMap<String, Vec<RecordFeatures>> = BTreeMap::new();
    for speed in [30, 35, 40, 45, 50] {
        for load in ["High", "Low"] {
            let mut ch = channels(&dir, &format!("helical1_{speed}hz_{load}_1.csv.gz"));
            let f = baseline_features(&mut ch, &[0, 1], &facts(speed as f64, load, true), &machine)
                .unwrap();
            for (name, x) in ["input", "output"].iter().zip(f) {
                by_channel.entry(name.to_string()).or_default().push(x);
            }
        }
    }
    let fitted = Baselines::fit(&by_channel)
        .require_all()
        .unwrap()
        .with_paths(&by_channel, Some(&diagnoser));
    eprintln!(
        "baseline: 10 records' features and fit in {:.2} s (once)",
        t0.elapsed().as_secs_f64()
    );
    let judged = Machine {
        baselines: &fitted.pooled,
        state_baselines: &fitted.states,
        baseline_counts: &fitted.counts,
        paths: &fitted.paths,
        own_model: None,
        extends_tables: false,
        ..machine
    };
    // The 4 s record: run 1 then run 2 of the healthy 40 Hz high-load state.
    let mut rec = channels(&dir, "helical1_40hz_High_1.csv.gz");
    for (c, more) in rec
        .iter_mut()
        .zip(channels(&dir, "helical1_40hz_High_2.csv.gz"))
    {
        c.1.extend(more.1);
    }
    let f = facts(40.0, "High", false);
    let before = |rec: &[(String, Vec<f64>)]| {
        for (_, x) in &rec[..2] {
            let r = Record {
                samples: x.clone(),
                sample_rate: FS,
            };
            let reading = diagnoser.read(&r, Some(40.0), None).unwrap();
            let order = reading.order.as_ref();
            record_features_with(&r, Some(&gb), Some(40.0), order).unwrap();
        }
    };
    let mut t_before = Vec::new();
    let mut t_after = Vec::new();
    for _ in 0..reps {
        let t = Instant::now();
        before(&rec);
        t_before.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let a = assess(&mut rec, &[0, 1], &f, &judged, &mut |_| {}).unwrap();
        t_after.push(t.elapsed().as_secs_f64());
        assert!(a.operating_state.is_some());
    }
    let (b, a) = (median(t_before), median(t_after));
    println!(
        "4 s, 66.7 kHz, 3 channels (2 accelerometers + tachometer), {reps} reps, medians:\n\
         before (table reading + features, 2 channels): {:.3} s\n\
         after (tachometer, state-aware baseline of 10 records, findings): {:.3} s\n\
         ratio after/before: {:.2}",
        b,
        a,
        a / b
    );
}
