//! The real-data evaluation of `docs/real-data.md`: the SpectraQuest gearbox records
//! (`../shared/data/spectraquest-gfd/`, 12.9 kHz inferred, motor 30 Hz), healthy and broken tooth
//! at loads 0, 20, 40, 60, 80 %.
//!
//! ```sh
//! cargo run --release --example real_data                 # both datasets
//! cargo run --release --example real_data -- helical      # the PHM 2009 helical records only
//! cargo run --release --example real_data -- spur         # the PHM 2009 spur records only
//! cargo run --release --example real_data -- phm          # both PHM 2009 trains
//! cargo run --release --example real_data -- spur-physics # the machine's own model (physics)
//! cargo run --release --example real_data -- a1 a3        # SpectraQuest, some channels
//! ```
//! Env: `GFD_DIR` (default `../shared/data/spectraquest-gfd` next to the crate),
//! `GFD_SEGMENTS` (segments per file, default 4).
//!
//! Protocol (fixed before any score was looked at, see the doc): each file is cut into
//! `GFD_SEGMENTS` equal records. For each channel and each load L, the baseline is the healthy
//! segments of the four *other* loads (grouped by file for the leave-one-out threshold), and
//! the healthy and broken segments at load L are scored. Twice: with the gearbox description
//! `configs/gearboxes/spectraquest-gfd.toml` (order tracking, TSA metrics) and without
//! (description-free features only). A file counts as anomalous when the median of its
//! segments' score / threshold exceeds 1.
//!
//! Then, per whole file: the wear degree and fit of the model-based diagnosis with the default
//! table (paper rig) and with the described gearbox's table (`signatures/spectraquest-gfd.json`),
//! and the TSA metrics of both shafts.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gearwear::diagnosis::{DiagnoseOptions, diagnose};
use gearwear::gearbox::Gearbox;
use gearwear::novelty::{
    MachineBaseline, RecordFeatures, order_analysis, record_features, split_record,
};
use gearwear::record::{Column, ReadOptions, Record, read_record};
use gearwear::signature::SignatureTable;
use rayon::prelude::*;

const LOADS: [u32; 5] = [0, 20, 40, 60, 80];
const FS: f64 = 12_900.0;
const SHAFT_HZ: f64 = 30.0;

fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// AUC of `pos` over `neg` (ties count half).
fn auc(pos: &[f64], neg: &[f64]) -> f64 {
    let mut s = 0.0;
    for p in pos {
        for n in neg {
            s += if p > n {
                1.0
            } else if p == n {
                0.5
            } else {
                0.0
            };
        }
    }
    s / (pos.len() * neg.len()) as f64
}

fn median(mut v: Vec<f64>) -> f64 {
    gearwear::signal::median(&mut v)
}

struct FileData {
    healthy: bool,
    load: u32,
    whole: Record,
    /// Segment features with and without the description.
    with: Vec<RecordFeatures>,
    without: Vec<RecordFeatures>,
}

fn f2(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.2}"))
}

#[path = "real_data/calibration.rs"]
mod calibration;
#[path = "real_data/phm.rs"]
mod phm;
#[path = "real_data/physics.rs"]
mod physics;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("helical-model") => return calibration::run(&phm::HELICAL),
        Some("helical-physics") => return physics::run(&phm::HELICAL),
        Some("spur-physics") => return physics::run(&phm::SPUR),
        Some("spur-model") => return calibration::run(&phm::SPUR),
        _ => {}
    }
    let trains: Vec<&phm::Train> = match args.first().map(String::as_str) {
        Some("helical") => vec![&phm::HELICAL],
        Some("spur") => vec![&phm::SPUR],
        Some("phm") => vec![&phm::HELICAL, &phm::SPUR],
        _ => Vec::new(),
    };
    if !trains.is_empty() {
        let summary: Vec<String> = trains.into_iter().flat_map(phm::run).collect();
        phm::print_summary(&summary);
        return;
    }
    spectraquest(args.clone());
    if args.is_empty() {
        let summary: Vec<String> = [&phm::HELICAL, &phm::SPUR]
            .into_iter()
            .flat_map(phm::run)
            .collect();
        phm::print_summary(&summary);
    }
}

/// The SpectraQuest evaluation, channels `channels` (all four when empty).
fn spectraquest(mut channels: Vec<String>) {
    let dir = std::env::var("GFD_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| manifest("../shared/data/spectraquest-gfd"));
    let segments: usize = std::env::var("GFD_SEGMENTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4);
    if channels.is_empty() {
        channels = ["a1", "a2", "a3", "a4"].map(String::from).to_vec();
    }
    let gb = Gearbox::from_file(&manifest("configs/gearboxes/spectraquest-gfd.toml"))
        .expect("description");
    let paper_table =
        SignatureTable::load(&manifest("signatures/model_a_accel.json")).expect("table");
    let sq_table = SignatureTable::load(&manifest("signatures/spectraquest-gfd.json")).ok();
    println!(
        "# SpectraQuest records, {segments} segments per file, baseline = healthy segments of the other loads\n"
    );
    let mut summary = Vec::new();
    for ch in &channels {
        let data = read_channel(&dir, ch, segments, &gb);
        println!("## Channel {ch}\n");
        for (label, pick) in [
            ("with the description", true),
            ("without a description", false),
        ] {
            summary.push(novelty_table(ch, label, pick, &data));
        }
        whole_files(ch, &data, &gb, &paper_table, sq_table.as_ref());
    }
    println!("## Summary\n");
    println!(
        "| channel | features | AUC | false alarms (segments) | misses (segments) | false alarms (files) | misses (files) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for s in summary {
        println!("{s}");
    }
}

/// Every file of channel `ch` (healthy and broken at each load), cut into `segments` records,
/// with their features with and without the description `gb`.
fn read_channel(dir: &Path, ch: &str, segments: usize, gb: &Gearbox) -> Vec<FileData> {
    let files: Vec<(bool, u32)> = LOADS
        .iter()
        .flat_map(|&l| [(true, l), (false, l)])
        .collect();
    files
        .par_iter()
        .map(|&(healthy, load)| {
            let name = format!("{}30hz{load}.csv.gz", if healthy { "h" } else { "b" });
            let rec = read_record(
                &dir.join(&name),
                &ReadOptions {
                    sample_rate: Some(FS),
                    column: Some(Column::Name(ch.to_string())),
                    ..Default::default()
                },
            )
            .unwrap_or_else(|e| panic!("{name}: {e}"));
            let segs = split_record(&rec, segments);
            let with = segs
                .iter()
                .map(|s| {
                    record_features(s, Some(gb), Some(SHAFT_HZ))
                        .expect("features")
                        .with_group(name.clone())
                })
                .collect();
            let without = segs
                .iter()
                .map(|s| {
                    record_features(s, None, None)
                        .expect("features")
                        .with_group(name.clone())
                })
                .collect();
            FileData {
                healthy,
                load,
                whole: rec,
                with,
                without,
            }
        })
        .collect()
}

/// The novelty table of one channel, with the description's features (`pick`) or without:
/// per load, the baseline of the other loads' healthy segments scores that load's healthy and
/// broken segments. Prints the table and the AUC; returns the summary row.
fn novelty_table(ch: &str, label: &str, pick: bool, data: &[FileData]) -> String {
    let feats = |d: &FileData| {
        if pick {
            d.with.clone()
        } else {
            d.without.clone()
        }
    };
    println!("### Novelty, {label}\n");
    println!(
        "| load | threshold | healthy segment scores | broken segment scores | healthy file | broken file | top features of the broken file |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let (mut hs, mut bs) = (Vec::new(), Vec::new());
    let (mut fa_seg, mut miss_seg, mut fa_file, mut miss_file) = (0, 0, 0, 0);
    let mut n_seg = 0;
    for &l in &LOADS {
        let base: Vec<RecordFeatures> = data
            .iter()
            .filter(|d| d.healthy && d.load != l)
            .flat_map(feats)
            .collect();
        let b = MachineBaseline::fit(&base).expect("baseline");
        eprintln!(
            "{ch} {label} load {l}: leave-one-file-out scores {:?}",
            b.loo_scores
                .iter()
                .map(|s| (s * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        );
        let score = |healthy: bool| -> (Vec<f64>, Vec<bool>, Vec<String>) {
            let d = data
                .iter()
                .find(|d| d.healthy == healthy && d.load == l)
                .unwrap();
            let nv: Vec<_> = feats(d).iter().map(|f| b.score(f)).collect();
            let top: Vec<String> = nv[0]
                .top_features
                .iter()
                .take(3)
                .map(|z| format!("{} {:+.1}", z.name, z.z))
                .collect();
            (
                nv.iter().map(|n| n.score / n.threshold).collect(),
                nv.iter().map(|n| n.anomalous).collect(),
                top,
            )
        };
        let (h, ha, _) = score(true);
        let (k, ka, top) = score(false);
        let fmt = |v: &[f64]| {
            v.iter()
                .map(|r| format!("{:.2}", r * b.threshold))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let hf = median(h.clone()) > 1.0;
        let kf = median(k.clone()) > 1.0;
        fa_seg += ha.iter().filter(|a| **a).count();
        miss_seg += ka.iter().filter(|a| !**a).count();
        n_seg += ha.len();
        fa_file += hf as usize;
        miss_file += (!kf) as usize;
        println!(
            "| {l} % | {:.2} | {} | {} | {} | {} | {} |",
            b.threshold,
            fmt(&h),
            fmt(&k),
            if hf { "**anomalous**" } else { "ok" },
            if kf { "anomalous" } else { "**ok (miss)**" },
            top.join(", ")
        );
        hs.extend(h);
        bs.extend(k);
    }
    let a = auc(&bs, &hs);
    println!(
        "\nAUC (broken vs healthy segments, score/threshold) = {a:.3}; segments: {fa_seg} false alarms of {n_seg}, {miss_seg} misses of {n_seg}; files: {fa_file} false alarms of 5, {miss_file} misses of 5\n"
    );
    format!(
        "| {ch} | {label} | {a:.3} | {fa_seg}/{n_seg} | {miss_seg}/{n_seg} | {fa_file}/5 | {miss_file}/5 |"
    )
}

/// Whole files: the model-based diagnosis and the TSA metrics.
fn whole_files(
    ch: &str,
    data: &[FileData],
    gb: &Gearbox,
    paper_table: &SignatureTable,
    sq_table: Option<&SignatureTable>,
) {
    println!("### Whole files: wear degree, fit, TSA metrics ({ch})\n");
    println!(
        "| file | wear (paper table) | χ²/feature | wear (described table) | χ²/feature | input FM0 | FM4 | NA4 | NB4 | M6A | M8A | ER | SLF | output FM4 | NA4 | SLF |"
    );
    println!(
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    let rows: Vec<String> = data
        .par_iter()
        .map(|d| {
            let name = format!("{}30hz{}", if d.healthy { "h" } else { "b" }, d.load);
            let opts = DiagnoseOptions::default();
            let w = |t: &SignatureTable| match diagnose(&d.whole, t, &opts) {
                Ok(x) => (
                    format!("{:.2}", x.wear_degree.estimate),
                    format!("{:.1}", x.fit.chi2_per_feature),
                ),
                Err(e) => (format!("error: {e}"), "–".into()),
            };
            let (wp, cp) = w(paper_table);
            let (ws, cs) = sq_table.map_or(("no table".into(), "–".into()), w);
            let oa = order_analysis(&d.whole.samples, FS, gb, gb.f1_hz(SHAFT_HZ), 0.03);
            let m: BTreeMap<String, _> = oa
                .map(|a| {
                    a.shafts
                        .into_iter()
                        .map(|s| (s.shaft, s.metrics))
                        .collect()
                })
                .unwrap_or_default();
            let i = m.get("input");
            let o = m.get("output");
            format!(
                "| {name} | {wp} | {cp} | {ws} | {cs} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                f2(i.and_then(|m| m.fm0)),
                f2(i.and_then(|m| m.fm4)),
                f2(i.and_then(|m| m.na4)),
                f2(i.and_then(|m| m.nb4)),
                f2(i.and_then(|m| m.m6a)),
                f2(i.and_then(|m| m.m8a)),
                f2(i.and_then(|m| m.er)),
                f2(i.and_then(|m| m.slf)),
                f2(o.and_then(|m| m.fm4)),
                f2(o.and_then(|m| m.na4)),
                f2(o.and_then(|m| m.slf)),
            )
        })
        .collect();
    for r in rows {
        println!("{r}");
    }
    println!();
}
