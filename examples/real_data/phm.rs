//! The PHM 2009 gearbox records, helical train (`../shared/data/phm09-helical/`, env `PHM_DIR`)
//! and spur train at high load (`../shared/data/phm09-spur-high/`, env `PHM_SPUR_DIR`):
//! baseline = case 1 run 1 at every state the train's files hold, judged = case 1 run 2
//! (false alarms) and every other case's run 1 (detection and findings), with the tachometer
//! and without it (tacho-less around the motor setting). Each record is assessed exactly as
//! `gearwear diagnose --baseline-manifest … --tacho-column tach --tacho-ppr 10 --load L` does
//! (both accelerometers; the more severe decides), the baseline's features computed once.
//!
//! Output: one row per judged record, per case and per load, and a summary; rows also go to
//! `target/bench/real_data_<train>.csv` (or `PHM_OUT_DIR`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use gearwear::assessment::OwnModel;
use gearwear::assessment::{
    Assessment, Baselines, Machine, RecordFacts, TableDiagnoser, TachoChannel, assess,
    baseline_features,
};
use gearwear::condition::Load;
use gearwear::diagnosis::DiagnoseOptions;
use gearwear::diagnosis::machine_path::LineRatios;
use gearwear::diagnosis::machine_physics::{MachinePhysics, PhysicsFitOptions};
use gearwear::gearbox::Gearbox;
use gearwear::novelty::RecordFeatures;
use gearwear::record::{ReadOptions, read_record_channels};
use gearwear::signature::SignatureTable;
use gearwear::signature::precompute::precompute;
use rayon::prelude::*;

pub const FS: f64 = 200_000.0 / 3.0;
const SPEEDS: [u32; 5] = [30, 35, 40, 45, 50];
const LOADS: [&str; 2] = ["High", "Low"];

/// A gear train of the rig: its files, description and what its labels say.
pub struct Train {
    pub name: &'static str,
    prefix: &'static str,
    pub dir_env: &'static str,
    pub default_dir: &'static str,
    pub config: &'static str,
    pub table: &'static str,
    cases: u32,
    /// Shafts carrying a damaged gear, per case (empty: no gear damage).
    pub gear_shafts: fn(u32) -> &'static [&'static str],
    /// Shafts carrying any labelled fault (gear, bearing, shaft), per case.
    pub fault_shafts: fn(u32) -> &'static [&'static str],
}

/// The helical train (README of its data).
pub const HELICAL: Train = Train {
    name: "helical",
    prefix: "helical",
    dir_env: "PHM_DIR",
    default_dir: "../shared/data/phm09-helical",
    config: "configs/gearboxes/phm09-helical.toml",
    table: "signatures/phm09-helical.json",
    cases: 6,
    gear_shafts: |c| match c {
        2 | 3 | 5 => &["idler"],
        _ => &[],
    },
    fault_shafts: |c| match c {
        2 => &["idler"],
        3 => &["in", "idler"],
        4 => &["in", "idler"],
        5 => &["idler"],
        6 => &["in"],
        _ => &[],
    },
};

/// The spur train at high load (README of its data).
pub const SPUR: Train = Train {
    name: "spur",
    prefix: "spur",
    dir_env: "PHM_SPUR_DIR",
    default_dir: "../shared/data/phm09-spur-high",
    config: "configs/gearboxes/phm09-spur.toml",
    table: "signatures/phm09-spur.json",
    cases: 8,
    gear_shafts: |c| match c {
        2 => &["in", "idler"],
        3 => &["idler"],
        4 => &["idler", "out"],
        5 => &["in", "idler", "out"],
        6 => &["out"],
        _ => &[],
    },
    fault_shafts: |c| match c {
        2 => &["in", "idler"],
        3 => &["idler"],
        4 => &["in", "idler", "out"],
        5 | 6 => &["in", "idler", "out"],
        7 => &["in", "out"],
        8 => &["in", "idler", "out"],
        _ => &[],
    },
};

pub struct File {
    pub case: u32,
    pub speed: u32,
    pub load: &'static str,
    pub run: u32,
    pub path: PathBuf,
}

pub fn files(t: &Train, dir: &Path) -> Vec<File> {
    let mut v = Vec::new();
    for case in 1..=t.cases {
        for speed in SPEEDS {
            for load in LOADS {
                for run in 1..=2 {
                    let path =
                        dir.join(format!("{}{case}_{speed}hz_{load}_{run}.csv.gz", t.prefix));
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

pub fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// A file's channels `(name, samples)` and its facts.
pub fn load(f: &File, tacho: bool, healthy: bool) -> (Vec<(String, Vec<f64>)>, RecordFacts) {
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

pub const CHOSEN: [usize; 2] = [0, 1];

pub fn machine<'a>(
    t: &Train,
    gb: &'a Gearbox,
    diagnoser: Option<&'a TableDiagnoser>,
    baselines: &'a Baselines,
) -> Machine<'a> {
    Machine::described(&format!("phm09-{}", t.name), gb, diagnoser, baselines)
}

/// One judged record's outcome.
struct Row {
    case: u32,
    speed: u32,
    load: &'static str,
    run: u32,
    level: String,
    score_ratio: f64,
    /// Kind and shaft of the first finding.
    first: (String, Option<String>),
    /// Shaft of the first finding that names one.
    first_shaft: Option<String>,
    first_gear_shaft: Option<String>,
    findings: String,
    /// The deciding channel's largest departures.
    top: String,
    measured_hz: Option<f64>,
    seconds: f64,
}

fn describe(a: &Assessment) -> String {
    a.findings
        .iter()
        .map(|x| {
            format!(
                "{}:{}{}{} {:.0}%",
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
                100.0 * x.share
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

fn row(f: &File, a: &Assessment, seconds: f64) -> Row {
    let first = a.findings.first().map_or(("-".to_string(), None), |x| {
        (x.kind.to_string(), x.shaft.clone())
    });
    let first_shaft = a.findings.iter().find_map(|x| x.shaft.clone());
    let first_gear_shaft = a
        .findings
        .iter()
        .find(|x| x.kind.is_gear())
        .and_then(|x| x.shaft.clone());
    let score_ratio = a
        .deciding_channel()
        .novelty
        .as_ref()
        .map_or(f64::NAN, |n| n.score / n.threshold);
    Row {
        case: f.case,
        speed: f.speed,
        load: f.load,
        run: f.run,
        level: a.level().to_string(),
        score_ratio,
        first,
        first_shaft,
        first_gear_shaft,
        findings: describe(a),
        top: a
            .deciding_channel()
            .novelty
            .as_ref()
            .map(|n| {
                n.top_features
                    .iter()
                    .take(if std::env::var("PHM_DEBUG").is_ok() {
                        5
                    } else {
                        3
                    })
                    .map(|f| format!("{} {:.1}", f.name, f.z))
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .unwrap_or_default(),
        measured_hz: a.operating_state.as_ref().map(|s| s.shaft_hz),
        seconds,
    }
}

fn flagged(r: &Row) -> bool {
    r.level == "warning" || r.level == "alarm"
}

fn rate(n: usize, d: usize) -> String {
    if d == 0 {
        return "–".into();
    }
    format!("{n}/{d} ({:.0} %)", 100.0 * n as f64 / d as f64)
}

fn within(s: &Option<String>, set: &[&str]) -> bool {
    s.as_deref().is_some_and(|s| set.contains(&s))
}

/// The summary figures of a set of rows.
struct Tally {
    healthy: usize,
    false_alarms: usize,
    gear: usize,
    detected: usize,
    first_on_gear: usize,
    first_on_fault: usize,
    first_shaft_on_gear: usize,
    gear_finding_on_gear: usize,
    other: usize,
    other_flagged: usize,
    other_not_gear: usize,
}

fn tally(t: &Train, rows: &[&Row]) -> Tally {
    let healthy: Vec<&&Row> = rows.iter().filter(|r| r.case == 1).collect();
    let gear: Vec<&&Row> = rows
        .iter()
        .filter(|r| !(t.gear_shafts)(r.case).is_empty())
        .collect();
    let other: Vec<&&Row> = rows
        .iter()
        .filter(|r| r.case > 1 && (t.gear_shafts)(r.case).is_empty())
        .collect();
    let count = |v: &[&&Row], p: &dyn Fn(&Row) -> bool| v.iter().filter(|r| p(r)).count();
    Tally {
        healthy: healthy.len(),
        false_alarms: count(&healthy, &|r| flagged(r)),
        gear: gear.len(),
        detected: count(&gear, &|r| flagged(r)),
        first_on_gear: count(&gear, &|r| {
            flagged(r) && within(&r.first.1, (t.gear_shafts)(r.case))
        }),
        first_on_fault: count(&gear, &|r| {
            flagged(r) && within(&r.first.1, (t.fault_shafts)(r.case))
        }),
        first_shaft_on_gear: count(&gear, &|r| {
            flagged(r) && within(&r.first_shaft, (t.gear_shafts)(r.case))
        }),
        gear_finding_on_gear: count(&gear, &|r| {
            flagged(r) && within(&r.first_gear_shaft, (t.gear_shafts)(r.case))
        }),
        other: other.len(),
        other_flagged: count(&other, &|r| flagged(r)),
        other_not_gear: count(&other, &|r| flagged(r) && !r.first.0.starts_with("gear")),
    }
}

fn tally_line(label: &str, x: &Tally) -> String {
    format!(
        "| {label} | {} | {} | {} | {} | {} | {} | {} (flagged {}) |",
        rate(x.false_alarms, x.healthy),
        rate(x.detected, x.gear),
        rate(x.first_on_gear, x.gear),
        rate(x.first_on_fault, x.gear),
        rate(x.first_shaft_on_gear, x.gear),
        rate(x.gear_finding_on_gear, x.gear),
        rate(x.other_not_gear, x.other),
        x.other_flagged,
    )
}

const TALLY_HEAD: &str = "| rows | false alarms (case 1 run 2) | damaged gear flagged | first finding on a damaged gear's shaft | first finding on a faulted shaft | first finding naming a shaft: on a damaged gear's | strongest gear finding on a damaged gear's shaft | bearing/shaft only: flagged, first finding not a gear |\n| --- | --- | --- | --- | --- | --- | --- | --- |";

/// With `PHM_DEBUG_RECORD=<file stem>`: every departure of that record's channels beyond
/// |z| = 2 and its findings, on standard error.
fn debug_record(t: &Train, f: &File, a: &Assessment, baselines: &Baselines) {
    let stem = format!("{}{}_{}hz_{}_{}", t.prefix, f.case, f.speed, f.load, f.run);
    if std::env::var("PHM_DEBUG_RECORD").ok().as_deref() != Some(stem.as_str()) {
        return;
    }
    for c in &a.assessed {
        let (Some(b), Some(state)) = (baselines.states.get(&c.name), c.features.state.as_ref())
        else {
            continue;
        };
        let Ok(s) = b.score(state, &c.features.evidence) else {
            continue;
        };
        eprintln!(
            "{stem} {}: score {:.2} / {:.2}",
            c.name, s.score, s.threshold
        );
        for d in s.departures.iter().filter(|d| d.z.abs() >= 2.0) {
            eprintln!(
                "  {:<28} {:+6.1} dB  z {:+5.1}",
                d.feature,
                20.0 * d.change / std::f64::consts::LN_10,
                d.z
            );
        }
        for x in &c.findings {
            eprintln!("  -> {} ({:.0} %)", x.summary, 100.0 * x.share);
        }
    }
}

/// The baseline of one mode: case 1 run 1 at every state.
fn fit_baseline(
    t: &Train,
    all: &[File],
    gb: &Gearbox,
    diagnoser: Option<&TableDiagnoser>,
    tacho: bool,
) -> (Baselines, BTreeMap<String, Vec<LineRatios>>, f64) {
    let base_files: Vec<&File> = all.iter().filter(|f| f.case == 1 && f.run == 1).collect();
    let empty = Default::default();
    let m0 = machine(t, gb, diagnoser, &empty);
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
    let b = Baselines::fit(&by_channel)
        .require_all()
        .expect("baseline")
        .with_paths(&by_channel, diagnoser);
    let ratios = gearwear::novelty::line_ratios(&by_channel);
    (b, ratios, t0.elapsed().as_secs_f64())
}

/// The machine's own model fitted to the baseline's line ratios (`PHM_OWN_MODEL=1`), with its
/// own table and its gears' fault signatures; `None` otherwise or when refused (said).
fn own_model(
    gb: &Gearbox,
    diagnoser: Option<&TableDiagnoser>,
    ratios: &BTreeMap<String, Vec<LineRatios>>,
) -> Option<OwnModel> {
    if std::env::var("PHM_OWN_MODEL").map_or(true, |v| v == "0") {
        return None;
    }
    let d = diagnoser?;
    let t0 = Instant::now();
    let fit = MachinePhysics::fit(
        gb,
        d.table(),
        &d.options(None),
        ratios,
        &PhysicsFitOptions::default(),
    );
    let physics = match fit {
        Ok(p) => p,
        Err(e) => {
            println!("the machine's own model: refused ({e})\n");
            return None;
        }
    };
    let spec = physics.table_spec(gb, d.table()).ok()?;
    let own = precompute(&spec, None, &|| {}).ok()?;
    let model = OwnModel::new(physics, TableDiagnoser::new(own, d.options(None)).ok()?);
    println!(
        "the machine's own model: fitted with its table and its gears' signatures in {:.0} s \
         (a left-out speed's lines to {:.2} dB against {} dB for the empirical path)\n",
        t0.elapsed().as_secs_f64(),
        model.physics.left_out_db,
        model
            .physics
            .yardstick_db
            .map_or("–".into(), |y| format!("{y:.2}"))
    );
    Some(model)
}

/// Run one mode (with or without the tachometer): print its rows, per case and per load, and
/// return its summary line and CSV rows.
fn run_mode(
    t: &Train,
    all: &[File],
    gb: &Gearbox,
    diagnoser: Option<&TableDiagnoser>,
    tacho: bool,
) -> (String, String) {
    let mode = if tacho { "tachometer" } else { "tacho-less" };
    let (baselines, ratios, baseline_s) = fit_baseline(t, all, gb, diagnoser, tacho);
    let own = own_model(gb, diagnoser, &ratios);
    let mut m = machine(t, gb, diagnoser, &baselines);
    m.own_model = own.as_ref();
    let judged: Vec<&File> = all
        .iter()
        .filter(|f| !(f.case == 1 && f.run == 1))
        .collect();
    let rows: Vec<Row> = judged
        .par_iter()
        .map(|f| {
            let (mut ch, facts) = load(f, tacho, false);
            let t0 = Instant::now();
            let a = assess(&mut ch, &CHOSEN, &facts, &m, &mut |_| {}).expect("assess");
            let seconds = t0.elapsed().as_secs_f64();
            debug_record(t, f, &a, &baselines);
            row(f, &a, seconds)
        })
        .collect();
    println!("### {} train, {mode}\n", t.name);
    for (ch, b) in &baselines.states {
        println!("baseline `{ch}`: threshold at a state {:.2}", b.threshold());
        if std::env::var("PHM_DEBUG").is_ok() {
            let mut sc: Vec<f64> = b.loo_scores().to_vec();
            sc.sort_by(|a, b| b.total_cmp(a));
            println!("  its healthy comparisons' scores: {sc:.2?}");
            let mut sp = b.spreads();
            sp.sort_by(|a, b| b.1.total_cmp(&a.1));
            for (k, h, bt, a) in sp.iter().take(12) {
                println!("  {k}: half noise {h:.3}, between {bt:.3?}, across {a:.3?}");
            }
        }
    }
    println!(
        "(baseline features of {} records: {baseline_s:.1} s)\n",
        all.iter().filter(|f| f.case == 1 && f.run == 1).count()
    );
    println!("| record | level | score/threshold | findings | largest departures | measured Hz |");
    println!("| --- | --- | --- | --- | --- | --- |");
    let mut csv = String::new();
    for r in &rows {
        println!(
            "| {}{}_{}hz_{}_{} | {} | {:.2} | {} | {} | {} |",
            t.prefix,
            r.case,
            r.speed,
            r.load,
            r.run,
            r.level,
            r.score_ratio,
            r.findings,
            r.top,
            r.measured_hz.map_or("-".into(), |v| format!("{v:.2}"))
        );
        csv += &format!(
            "{mode},{},{},{},{},{},{:.3},{},{},{},{},{},{:.3}\n",
            r.case,
            r.speed,
            r.load,
            r.run,
            r.level,
            r.score_ratio,
            r.first.0,
            r.first.1.clone().unwrap_or_default(),
            r.first_gear_shaft.clone().unwrap_or_default(),
            r.findings.replace(',', " "),
            r.measured_hz.map_or(String::new(), |v| format!("{v:.3}")),
            r.seconds
        );
    }
    let all_rows: Vec<&Row> = rows.iter().collect();
    println!("\nPer case:\n\n{TALLY_HEAD}");
    let cases: BTreeSet<u32> = rows.iter().map(|r| r.case).collect();
    for c in cases {
        let v: Vec<&Row> = rows.iter().filter(|r| r.case == c).collect();
        println!("{}", tally_line(&format!("case {c}"), &tally(t, &v)));
    }
    println!("\nPer load:\n\n{TALLY_HEAD}");
    for l in LOADS {
        let v: Vec<&Row> = rows.iter().filter(|r| r.load == l).collect();
        if !v.is_empty() {
            println!("{}", tally_line(l, &tally(t, &v)));
        }
    }
    let mut secs: Vec<f64> = rows.iter().map(|r| r.seconds).collect();
    secs.sort_by(f64::total_cmp);
    println!();
    let summary = format!(
        "{} median {:.2} s/record",
        tally_line(&format!("{} {mode}", t.name), &tally(t, &all_rows)),
        secs[secs.len() / 2]
    );
    (summary, csv)
}

/// The evaluation of one train (see the module docs); its summary lines.
pub fn run(t: &Train) -> Vec<String> {
    let dir = std::env::var(t.dir_env)
        .map(PathBuf::from)
        .unwrap_or_else(|_| manifest(t.default_dir));
    let all = files(t, &dir);
    if all.is_empty() {
        eprintln!(
            "no {} records in {}: set {}",
            t.name,
            dir.display(),
            t.dir_env
        );
        return Vec::new();
    }
    let gb = Gearbox::from_file(&manifest(t.config)).expect("description");
    let table = SignatureTable::load(&manifest(t.table)).ok();
    let diagnoser =
        table.map(|tb| TableDiagnoser::new(tb, DiagnoseOptions::default()).expect("table"));
    println!("## PHM 2009 {} train ({} records)\n", t.name, all.len());
    let (summary, rows): (Vec<String>, Vec<String>) = [true, false]
        .iter()
        .map(|&tacho| run_mode(t, &all, &gb, diagnoser.as_ref(), tacho))
        .unzip();
    let out_dir = std::env::var("PHM_OUT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| manifest("target/bench"));
    let path = out_dir.join(format!("real_data_{}.csv", t.name));
    let _ = std::fs::create_dir_all(&out_dir);
    let head = "mode,case,speed,load,run,level,score_ratio,first_kind,first_shaft,first_gear_shaft,findings,measured_hz,seconds\n";
    match std::fs::write(&path, format!("{head}{}", rows.concat())) {
        Ok(()) => eprintln!("rows in {}", path.display()),
        Err(e) => eprintln!("could not write {}: {e}", path.display()),
    }
    summary
}

/// Print the summary of the trains run.
pub fn print_summary(lines: &[String]) {
    println!("### Summary\n\n{TALLY_HEAD}");
    for s in lines {
        println!("{s}");
    }
}
