//! The PHM 2009 helical records (`../shared/data/phm09-helical/`, env `PHM_DIR`): baseline =
//! case 1 run 1 at all ten states (5 speeds × 2 loads), judged = case 1 run 2 (false alarms)
//! and cases 2–6 run 1 (detection and findings), with the tachometer and without it
//! (tacho-less around the motor setting). Each record is assessed exactly as
//! `gearwear diagnose --baseline-manifest … --tacho-column tach --tacho-ppr 10 --load L` does
//! (both accelerometers; the more severe decides), the baseline's features computed once.
//!
//! Output: one row per judged record and a summary; rows also go to
//! `target/bench/real_data_helical.csv` (or `HELICAL_OUT`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use gearwear::assessment::{
    Assessment, GearboxRef, Machine, RecordFacts, TableDiagnoser, TachoChannel, Thresholds, assess,
    baseline_features, fit_baselines,
};
use gearwear::condition::Load;
use gearwear::diagnosis::DiagnoseOptions;
use gearwear::gearbox::Gearbox;
use gearwear::novelty::RecordFeatures;
use gearwear::record::{ReadOptions, read_record_channels};
use gearwear::signature::SignatureTable;
use rayon::prelude::*;

const FS: f64 = 200_000.0 / 3.0;
const SPEEDS: [u32; 5] = [30, 35, 40, 45, 50];
const LOADS: [&str; 2] = ["High", "Low"];

/// What the labels say of a case.
fn truth(case: u32) -> &'static str {
    match case {
        1 => "healthy",
        2 | 3 | 5 => "gear (24T on idler)",
        _ => "bearing/shaft only",
    }
}

struct File {
    case: u32,
    speed: u32,
    load: &'static str,
    run: u32,
    path: PathBuf,
}

fn files(dir: &Path) -> Vec<File> {
    let mut v = Vec::new();
    for case in 1..=6 {
        for speed in SPEEDS {
            for load in LOADS {
                for run in 1..=2 {
                    let path = dir.join(format!("helical{case}_{speed}hz_{load}_{run}.csv.gz"));
                    if path.exists() {
                        v.push(File {
                            case,
                            speed,
                            load,
                            run,
                            path,
                        });
                    }
                }
            }
        }
    }
    v
}

fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// A file's channels `(name, samples)`, the accelerometers to assess and its facts.
fn load(f: &File, tacho: bool, healthy: bool) -> (Vec<(String, Vec<f64>)>, RecordFacts) {
    let opts = ReadOptions {
        sample_rate: Some(FS),
        ..Default::default()
    };
    let m = read_record_channels(&f.path, &opts).expect("record");
    let channels = m
        .channels
        .into_iter()
        .map(|c| (c.name, c.samples))
        .collect();
    let facts = RecordFacts {
        sample_rate_hz: FS,
        shaft_hz: Some(f.speed as f64),
        sensor: None,
        declared_healthy: healthy,
        load: Load::parse(f.load),
        tacho: tacho.then(|| TachoChannel {
            name: "tach".into(),
            pulses_per_rev: 10,
        }),
    };
    (channels, facts)
}

const CHOSEN: [usize; 2] = [0, 1];

fn machine<'a>(gb: &'a Gearbox, diagnoser: Option<&'a TableDiagnoser>) -> Machine<'a> {
    static EMPTY_P: std::sync::OnceLock<BTreeMap<String, gearwear::novelty::MachineBaseline>> =
        std::sync::OnceLock::new();
    static EMPTY_S: std::sync::OnceLock<BTreeMap<String, gearwear::condition::StateBaseline>> =
        std::sync::OnceLock::new();
    static EMPTY_C: std::sync::OnceLock<BTreeMap<String, usize>> = std::sync::OnceLock::new();
    Machine {
        gearbox: gb,
        gearbox_ref: GearboxRef {
            id: "phm09-helical".into(),
            name: gb.name().into(),
            hash: gb.hash.clone(),
            table_status: "ready".into(),
            table_progress: 1.0,
        },
        described: true,
        diagnoser,
        table_note: None,
        input_shaft_hz: None,
        baselines: EMPTY_P.get_or_init(BTreeMap::new),
        state_baselines: EMPTY_S.get_or_init(BTreeMap::new),
        baseline_counts: EMPTY_C.get_or_init(BTreeMap::new),
        calibration: None,
        thresholds: Thresholds::default(),
        units: Default::default(),
    }
}

/// One judged record's outcome.
struct Row {
    case: u32,
    speed: u32,
    load: &'static str,
    run: u32,
    level: String,
    score_ratio: f64,
    first: String,
    first_gear_shaft: Option<String>,
    findings: String,
    wear: String,
    measured_hz: Option<f64>,
    seconds: f64,
}

fn row(f: &File, a: &Assessment, seconds: f64) -> Row {
    let first = a
        .findings
        .first()
        .map(|x| x.kind.to_string())
        .unwrap_or_else(|| "-".into());
    let first_gear_shaft = a
        .findings
        .iter()
        .find(|x| x.kind.starts_with("gear"))
        .and_then(|x| x.shaft.clone());
    let findings = a
        .findings
        .iter()
        .map(|x| {
            format!(
                "{}:{}{}{} {:.1}",
                x.kind,
                x.shaft.clone().unwrap_or_default(),
                x.gear
                    .as_ref()
                    .map(|g| format!("/{}T", g.teeth))
                    .unwrap_or_default(),
                x.detail
                    .as_ref()
                    .map(|d| format!(" ({d})"))
                    .unwrap_or_default(),
                x.strength
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    let d = a.deciding_channel();
    let score_ratio = d
        .novelty
        .as_ref()
        .map(|n| n.score / n.threshold)
        .unwrap_or(f64::NAN);
    let wear = match &d.reading {
        Some(r) => match &r.diagnosis.wear_degree.withheld {
            Some(_) => format!("null (χ²/feature {:.0})", r.diagnosis.fit.chi2_per_feature),
            None => format!("{:.2}", r.diagnosis.wear_degree.estimate),
        },
        None => "no table".into(),
    };
    Row {
        case: f.case,
        speed: f.speed,
        load: f.load,
        run: f.run,
        level: a.level().to_string(),
        score_ratio,
        first,
        first_gear_shaft,
        findings,
        wear,
        measured_hz: a.operating_state.as_ref().map(|s| s.shaft_hz),
        seconds,
    }
}

fn flagged(r: &Row) -> bool {
    r.level == "warning" || r.level == "alarm"
}

fn rate(n: usize, d: usize) -> String {
    format!("{n}/{d} ({:.0} %)", 100.0 * n as f64 / d.max(1) as f64)
}

/// Run one mode (with or without the tachometer) and print its rows and summary line.
fn run_mode(
    all: &[File],
    gb: &Gearbox,
    diagnoser: Option<&TableDiagnoser>,
    tacho: bool,
) -> (String, String) {
    let mode = if tacho { "tachometer" } else { "tacho-less" };
    let base_files: Vec<&File> = all.iter().filter(|f| f.case == 1 && f.run == 1).collect();
    let m0 = machine(gb, diagnoser);
    let t0 = Instant::now();
    let feats: Vec<Vec<RecordFeatures>> = base_files
        .par_iter()
        .map(|f| {
            let (mut ch, facts) = load(f, tacho, true);
            baseline_features(&mut ch, &CHOSEN, &facts, &m0).expect("baseline features")
        })
        .collect();
    let mut by_channel: BTreeMap<String, Vec<RecordFeatures>> = BTreeMap::new();
    for fs in feats {
        for (name, f) in ["input", "output"].iter().zip(fs) {
            by_channel.entry(name.to_string()).or_default().push(f);
        }
    }
    let (pooled, states, counts) = fit_baselines(&by_channel).expect("baseline");
    let baseline_s = t0.elapsed().as_secs_f64();
    let m = Machine {
        baselines: &pooled,
        state_baselines: &states,
        baseline_counts: &counts,
        ..machine(gb, diagnoser)
    };
    let judged: Vec<&File> = all
        .iter()
        .filter(|f| !(f.case == 1 && f.run == 1))
        .collect();
    let rows: Vec<Row> = judged
        .par_iter()
        .map(|f| {
            let (mut ch, facts) = load(f, tacho, false);
            let t = Instant::now();
            let a = assess(&mut ch, &CHOSEN, &facts, &m, &mut |_| {}).expect("assess");
            row(f, &a, t.elapsed().as_secs_f64())
        })
        .collect();
    println!("### {mode}\n");
    for (ch, b) in &states {
        println!(
            "baseline `{ch}`: threshold {:.2}, leave-one-out scores {:?}",
            b.threshold(),
            b.loo_scores()
                .iter()
                .map(|v| (v * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        );
    }
    println!("(baseline features of 10 records: {baseline_s:.1} s)\n");
    println!("| record | truth | level | score/threshold | findings | wear | measured Hz |");
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let mut out = String::new();
    for r in &rows {
        println!(
            "| {}_{}hz_{}_{} | {} | {} | {:.2} | {} | {} | {} |",
            r.case,
            r.speed,
            r.load,
            r.run,
            truth(r.case),
            r.level,
            r.score_ratio,
            r.findings,
            r.wear,
            r.measured_hz.map_or("-".into(), |v| format!("{v:.2}"))
        );
        out += &format!(
            "{mode},{},{},{},{},{},{:.3},{},{},{},{},{:.3}\n",
            r.case,
            r.speed,
            r.load,
            r.run,
            r.level,
            r.score_ratio,
            r.first,
            r.first_gear_shaft.clone().unwrap_or_default(),
            r.wear,
            r.measured_hz.map_or(String::new(), |v| format!("{v:.3}")),
            r.seconds
        );
    }
    let healthy: Vec<&Row> = rows.iter().filter(|r| r.case == 1).collect();
    let gear: Vec<&Row> = rows
        .iter()
        .filter(|r| [2, 3, 5].contains(&r.case))
        .collect();
    let other: Vec<&Row> = rows.iter().filter(|r| [4, 6].contains(&r.case)).collect();
    let fa = healthy.iter().filter(|r| flagged(r)).count();
    let det = gear.iter().filter(|r| flagged(r)).count();
    let located = gear
        .iter()
        .filter(|r| flagged(r) && r.first_gear_shaft.as_deref() == Some("idler"))
        .count();
    let other_ok = other
        .iter()
        .filter(|r| flagged(r) && !r.first.starts_with("gear"))
        .count();
    let other_flagged = other.iter().filter(|r| flagged(r)).count();
    let wear_null = rows.iter().filter(|r| r.wear.starts_with("null")).count();
    let mut secs: Vec<f64> = rows.iter().map(|r| r.seconds).collect();
    secs.sort_by(f64::total_cmp);
    println!();
    let summary = format!(
        "| {mode} | {} | {} | {} | {} (flagged {}) | {} | {:.2} s |",
        rate(fa, healthy.len()),
        rate(det, gear.len()),
        rate(located, gear.len()),
        rate(other_ok, other.len()),
        other_flagged,
        rate(wear_null, rows.len()),
        secs[secs.len() / 2]
    );
    (summary, out)
}

/// The helical evaluation (see the module docs).
pub fn run() {
    let dir = std::env::var("PHM_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| manifest("../shared/data/phm09-helical"));
    let all = files(&dir);
    if all.is_empty() {
        eprintln!("no helical records in {}: set PHM_DIR", dir.display());
        return;
    }
    let gb =
        Gearbox::from_file(&manifest("configs/gearboxes/phm09-helical.toml")).expect("description");
    let table = SignatureTable::load(&manifest("signatures/phm09-helical.json")).ok();
    let diagnoser =
        table.map(|t| TableDiagnoser::new(t, DiagnoseOptions::default()).expect("table"));
    println!("## PHM 2009 helical gearbox ({} records)\n", all.len());
    let (summary, rows): (Vec<String>, Vec<String>) = [true, false]
        .iter()
        .map(|&t| run_mode(&all, &gb, diagnoser.as_ref(), t))
        .unzip();
    let path = std::env::var("HELICAL_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|_| manifest("target/bench/real_data_helical.csv"));
    let _ = std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")));
    let head = "mode,case,speed,load,run,level,score_ratio,first,first_gear_shaft,wear,measured_hz,seconds\n";
    match std::fs::write(&path, format!("{head}{}", rows.concat())) {
        Ok(()) => eprintln!("rows in {}", path.display()),
        Err(e) => eprintln!("could not write {}: {e}", path.display()),
    }
    println!("### Summary\n");
    println!(
        "| speed from | false alarms (case 1 run 2) | damaged gear flagged | strongest gear finding on `idler` | bearing/shaft only: flagged, not blamed on a gear | wear withheld | median s/record |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for s in summary {
        println!("{s}");
    }
}
