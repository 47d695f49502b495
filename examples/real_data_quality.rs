//! Record quality and sample-rate consistency on the real records (`docs/diagnosis.md`,
//! "Record quality"): every accelerometer channel of every SpectraQuest and PHM 2009 helical
//! file in `../shared/data`, inspected as received ([`inspect`]: no finding is expected), then
//! sample-rate-checked ([`check_rate`]) with its rate declared right and declared × ½, 2, 0.9,
//! 1.1: a mis-declared rate must be found and the likely true rate named (within 1 %).
//!
//! ```sh
//! cargo run --release --example real_data_quality
//! ```
//! The shaft rate given to the check is what a sender knows from outside the record:
//! SpectraQuest, the motor's 30 Hz setting (the rotation line is within 0.4 % of it);
//! PHM 2009, the input-shaft rate counted from the file's own tachometer (10 pulses per
//! revolution) at the true rate (the setting is 1–2.5 % off: motor slip).

use std::path::{Path, PathBuf};

use gearwear::assessment::rate::check_rate;
use gearwear::gearbox::Gearbox;
use gearwear::record::{ReadOptions, inspect, read_record_channels};
use gearwear::signal::order::track_tachometer;

const DECLARED: [f64; 5] = [1.0, 0.5, 2.0, 0.9, 1.1];

fn manifest(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn main() {
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
    ];
    // [declared factor] → (right rate named, wrong rate named, nothing said)
    let mut counts = [[0usize; 3]; DECLARED.len()];
    let mut findings = 0usize;
    let mut channels = 0usize;
    for (dir, fs, config) in sets {
        let gb = Gearbox::from_file(&manifest(config)).expect("gearbox description");
        let mut files: Vec<PathBuf> = std::fs::read_dir(manifest(&format!("../shared/data/{dir}")))
            .expect("shared data")
            .map(|e| e.expect("entry").path())
            .filter(|p| p.to_string_lossy().ends_with(".csv.gz"))
            .collect();
        files.sort();
        for path in files {
            let opts = ReadOptions {
                sample_rate: Some(fs),
                ..Default::default()
            };
            let rec = read_record_channels(&path, &opts).expect("record");
            let shaft = match rec.channels.iter().find(|c| c.name == "tach") {
                Some(t) => {
                    let a = track_tachometer(&t.samples, fs, 10).expect("tachometer");
                    let (i, j) = a.usable;
                    (a.revs[j] - a.revs[i]) / ((j - i) as f64 / fs)
                }
                None => 30.0,
            };
            for c in rec.channels.iter().filter(|c| c.name != "tach") {
                channels += 1;
                if let Err(e) = inspect(&c.samples, fs, None).map(|i| {
                    findings += i.findings.len();
                    for f in &i.findings {
                        println!("{} {}: {}", path.display(), c.name, f.message);
                    }
                }) {
                    findings += 1;
                    println!("{} {}: REFUSED {e}", path.display(), c.name);
                }
                for (k, d) in DECLARED.iter().enumerate() {
                    let declared = fs * d;
                    match check_rate(&c.samples, declared, &gb, shaft) {
                        Some(m) if (m.likely_hz / fs - 1.0).abs() < 0.01 && *d != 1.0 => {
                            counts[k][0] += 1
                        }
                        Some(m) => {
                            counts[k][1] += 1;
                            println!(
                                "{} {} declared ×{d}: {} (scores {:.1} / {:.1} dB)",
                                path.display(),
                                c.name,
                                m.message(),
                                m.score_db,
                                m.score_at_1_db
                            );
                        }
                        None if *d == 1.0 => counts[k][0] += 1,
                        None => {
                            counts[k][2] += 1;
                            println!("{} {} declared ×{d}: nothing found", path.display(), c.name);
                        }
                    }
                }
            }
        }
    }
    println!("{channels} channels, {findings} quality findings on the originals");
    println!("declared × | right (no warning at ×1) | wrong | nothing said");
    for (k, d) in DECLARED.iter().enumerate() {
        println!(
            "{d} | {} | {} | {}",
            counts[k][0], counts[k][1], counts[k][2]
        );
    }
}
