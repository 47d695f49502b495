//! Record quality and the set-up check on the real records (`docs/diagnosis.md`, "Record
//! quality"; `docs/service.md`, "Set-up"): every accelerometer channel of every SpectraQuest,
//! PHM 2009 helical and PHM 2009 spur (high load) file in `../shared/data`, inspected as
//! received ([`inspect`]: no finding is expected), then set-up-checked
//! ([`gearwear::condition::setup`]) with its sample rate declared right and declared × ½, 2,
//! 0.9, 1.1 — without the tachometer, and (PHM 2009) with it — and (PHM 2009, rate right) with
//! the tachometer's pulses per revolution declared 1, 5 or 20 instead of 10. A mis-declared
//! rate must be named with its likely value (within 3 %: the motor's slip), a wrong pulse count
//! with the right one; a correct record must get no finding.
//!
//! ```sh
//! cargo run --release --example real_data_quality            # all three sets
//! cargo run --release --example real_data_quality -- phm09-spur-high
//! ```
//! The declared shaft rate is what a sender knows from outside the record: the motor's setting
//! (SpectraQuest 30 Hz; PHM 2009 the file name's 30–50 Hz, 1–2.5 % above the true rate).

use std::path::{Path, PathBuf};

use gearwear::condition::Parts;
use gearwear::condition::lines::LineMap;
use gearwear::condition::setup::{Cause, SetupCheck, check_tacho_less, check_tachometer};
use gearwear::gearbox::Gearbox;
use gearwear::record::{ReadOptions, inspect, read_record_channels};
use gearwear::signal::order::track_tachometer;
use rayon::prelude::*;

const DECLARED: [f64; 5] = [1.0, 0.5, 2.0, 0.9, 1.1];
const PPR: [usize; 3] = [1, 5, 20];

/// Right, wrong, nothing said.
type Tally = [usize; 3];

/// One channel's verdicts: `(row label, tally index)` per check, and lines to print.
struct Verdicts {
    rows: Vec<(String, usize)>,
    log: Vec<String>,
    findings: usize,
}

fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn main() {
    let only = std::env::args().nth(1);
    let sets = [
        (
            "spectraquest-gfd",
            12_900.0,
            "configs/gearboxes/spectraquest-gfd.toml",
        ),
        (
            "phm09-helical",
            200_000.0 / 3.0,
            "configs/gearboxes/phm09-helical.toml",
        ),
        (
            "phm09-spur-high",
            200_000.0 / 3.0,
            "configs/gearboxes/phm09-spur.toml",
        ),
    ];
    let mut tallies: std::collections::BTreeMap<String, Tally> = Default::default();
    let (mut findings, mut channels) = (0usize, 0usize);
    for (dir, fs, config) in sets {
        if only.as_deref().is_some_and(|o| o != dir) {
            continue;
        }
        let gb = Gearbox::from_file(&manifest(config)).expect("gearbox description");
        let map = LineMap::of(&Parts::of(&gb));
        let mut files: Vec<PathBuf> = std::fs::read_dir(manifest(&format!("../shared/data/{dir}")))
            .expect("shared data")
            .map(|e| e.expect("entry").path())
            .filter(|p| p.to_string_lossy().ends_with(".csv.gz"))
            .collect();
        files.sort();
        let verdicts: Vec<Verdicts> = files
            .par_iter()
            .flat_map_iter(|path| file_verdicts(path, fs, &map))
            .collect();
        for v in verdicts {
            channels += 1;
            findings += v.findings;
            for l in v.log {
                println!("{dir} {l}");
            }
            for (row, k) in v.rows {
                tallies.entry(format!("{dir} {row}")).or_default()[k] += 1;
            }
        }
    }
    println!("{channels} channels, {findings} quality findings on the originals");
    println!("set, check | right (no finding on a correct record) | wrong | nothing said");
    for (row, t) in tallies {
        println!("{row} | {} | {} | {}", t[0], t[1], t[2]);
    }
}

/// The declared shaft rate: the motor setting in the file name (`…_30hz_…`), else 30 Hz.
fn setting_hz(path: &Path) -> f64 {
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    name.split('_')
        .find_map(|p| p.strip_suffix("hz").and_then(|v| v.parse().ok()))
        .unwrap_or(30.0)
}

/// Grade a check: `truth` is the factor the rate was declared wrong by (1: right).
fn grade(c: Option<&SetupCheck>, truth: f64, fs: f64) -> (usize, String) {
    match c.and_then(|c| c.cause.as_ref()) {
        None if truth == 1.0 => (0, String::new()),
        None => (2, "nothing said".into()),
        Some(Cause::SampleRate { likely_hz, .. }) if truth != 1.0 => {
            if (likely_hz / fs - 1.0).abs() <= 0.03 {
                (0, String::new())
            } else {
                (1, format!("named {likely_hz:.0} Hz"))
            }
        }
        Some(cause) => (1, format!("{cause:?}")),
    }
}

fn file_verdicts(path: &Path, fs: f64, map: &LineMap) -> Vec<Verdicts> {
    let opts = ReadOptions {
        sample_rate: Some(fs),
        ..Default::default()
    };
    let rec = read_record_channels(path, &opts).expect("record");
    let setting = setting_hz(path);
    let tach = rec.channels.iter().find(|c| c.name == "tach");
    let stem = path.file_name().unwrap_or_default().to_string_lossy();
    rec.channels
        .iter()
        .filter(|c| c.name != "tach")
        .map(|c| {
            let mut v = Verdicts {
                rows: Vec::new(),
                log: Vec::new(),
                findings: 0,
            };
            match inspect(&c.samples, fs, None) {
                Ok(i) => {
                    v.findings += i.findings.len();
                    v.log.extend(
                        i.findings
                            .iter()
                            .map(|f| format!("{stem} {}: {}", c.name, f.message)),
                    );
                }
                Err(e) => {
                    v.findings += 1;
                    v.log.push(format!("{stem} {}: REFUSED {e}", c.name));
                }
            }
            for d in DECLARED {
                let declared = fs * d;
                let check = check_tacho_less(&c.samples, declared, map, setting);
                let (k, why) = grade(check.as_ref(), d, fs);
                v.rows.push((format!("tacho-less ×{d}"), k));
                if k != 0 {
                    v.log
                        .push(format!("{stem} {} tacho-less ×{d}: {why}", c.name));
                }
                let Some(t) = tach else { continue };
                let Ok(a) = track_tachometer(&t.samples, declared, 10) else {
                    v.rows.push((format!("tachometer ×{d}"), 2));
                    continue;
                };
                let check =
                    check_tachometer(&c.samples, declared, map, setting, a.summary.mean_hz, 10);
                let (k, why) = grade(Some(&check), d, fs);
                v.rows.push((format!("tachometer ×{d}"), k));
                if k != 0 {
                    v.log
                        .push(format!("{stem} {} tachometer ×{d}: {why}", c.name));
                }
            }
            if let Some(t) = tach {
                for ppr in PPR {
                    let k = match track_tachometer(&t.samples, fs, ppr) {
                        Ok(a) => {
                            let check = check_tachometer(
                                &c.samples,
                                fs,
                                map,
                                setting,
                                a.summary.mean_hz,
                                ppr,
                            );
                            match check.cause {
                                Some(Cause::PulsesPerRevolution { likely: 10, .. }) => 0,
                                None => 2,
                                Some(other) => {
                                    v.log
                                        .push(format!("{stem} {} ppr {ppr}: {other:?}", c.name));
                                    1
                                }
                            }
                        }
                        Err(_) => 2,
                    };
                    v.rows.push((format!("tachometer ppr {ppr} (true 10)"), k));
                }
            }
            v
        })
        .collect()
}
