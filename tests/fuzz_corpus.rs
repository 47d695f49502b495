//! Replays every committed fuzz input through the fuzz harnesses (`fuzz/harness.rs`, the
//! same functions the `cargo fuzz` targets call): `fuzz/seeds/<target>/` (hand-made, from
//! `scripts/fuzz_seeds.py`), `fuzz/corpus/<target>/` (the minimised corpus of the long runs)
//! and `fuzz/regressions/<target>/` (every input that once crashed a target or broke an
//! invariant). A harness panics on a crash or a broken invariant, so this is the short,
//! deterministic version of `scripts/fuzz.sh` that `cargo test` runs. See
//! docs/reliability/fuzzing.md.

use std::path::{Path, PathBuf};

// The fuzz targets' own harness, one file for both drivers; each target uses only its function.
#[allow(dead_code)]
#[path = "../fuzz/harness.rs"]
mod harness;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz")
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut v: Vec<PathBuf> = rd
        .map(|e| e.expect("readable directory entry").path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    v
}

/// Every seed and corpus file of `target`, then every regression file; returns how many of
/// each were replayed.
fn replay(target: &str) -> (usize, usize) {
    let harness = harness::TARGETS
        .iter()
        .find(|(name, _)| *name == target)
        .map(|(_, f)| *f)
        .expect("a known target");
    let (mut inputs, mut regressions) = (0, 0);
    for kind in ["seeds", "corpus", "regressions"] {
        for path in files(&root().join(kind).join(target)) {
            let data = std::fs::read(&path).expect("readable fuzz input");
            let outcome = std::panic::catch_unwind(|| harness(&data));
            assert!(outcome.is_ok(), "{} fails its harness", path.display());
            if kind == "regressions" {
                regressions += 1;
            } else {
                inputs += 1;
            }
        }
    }
    (inputs, regressions)
}

macro_rules! replay_test {
    ($name:ident) => {
        #[test]
        fn $name() {
            let (corpus, regressions) = replay(stringify!($name));
            // The seeds are committed: none means the test lost its inputs.
            assert!(corpus > 0, "no seeds or corpus for {}", stringify!($name));
            eprintln!(
                "{}: {corpus} corpus + {regressions} regression inputs replayed",
                stringify!($name)
            );
        }
    };
}

replay_test!(json_body);
replay_test!(csv);
replay_test!(csv_gz);
replay_test!(f32_raw);
replay_test!(wav);
replay_test!(model_config);
replay_test!(quality);

/// Every harness has committed seeds and a cargo-fuzz target, and every input folder a
/// harness (a target added or renamed on one side only would silently lose its replay).
#[test]
fn every_target_has_a_corpus_and_every_corpus_a_target() {
    let names: Vec<&str> = harness::TARGETS.iter().map(|(n, _)| *n).collect();
    for kind in ["seeds", "corpus", "regressions"] {
        if let Ok(rd) = std::fs::read_dir(root().join(kind)) {
            for e in rd {
                let name = e.expect("entry").file_name().to_string_lossy().into_owned();
                assert!(
                    names.contains(&name.as_str()),
                    "{kind}/{name} has no harness"
                );
            }
        }
    }
    for n in &names {
        assert!(root().join("seeds").join(n).is_dir(), "no seeds for {n}");
        assert!(
            root()
                .join("fuzz_targets")
                .join(format!("{n}.rs"))
                .is_file(),
            "no cargo-fuzz target for {n}"
        );
    }
}

/// The invariant checks the harnesses apply do fail on a bad record (a check that can never
/// fail would make every replay above pass vacuously): an infinite sample rate, as the CSV
/// time-column path returned before its fix.
#[test]
#[should_panic(expected = "sample rate inf returned")]
fn the_record_check_refuses_an_infinite_rate() {
    let r = gearwear::record::Record {
        samples: vec![1.0, 2.0],
        sample_rate: f64::INFINITY,
    };
    harness::check_record(&r, &Default::default(), 2, "test");
}

#[test]
#[should_panic(expected = "samples from an input that can hold at most")]
fn the_record_check_refuses_invented_samples() {
    let r = gearwear::record::Record {
        samples: vec![0.0; 5],
        sample_rate: 1.0,
    };
    harness::check_record(&r, &Default::default(), 4, "test");
}

/// Random edits of valid bodies (bytes inserted, deleted or replaced, drawn from JSON's
/// punctuation, digits and letters): the fast path and serde_json agree on every one — the
/// same record (numbers to one ulp) or the same error message
/// (`json_fast_path_agrees` in `fuzz/harness.rs`, the `json_body` fuzz harness's check).
#[test]
fn mutated_bodies_get_serde_json_s_answer() {
    const ALPHABET: &[u8] = b"0123456789-+.eE ,[]{}:\"nultrfasxyz\\\n\t\x7f\xc3\xa9";
    let bases = [
        r#"{"sample_rate_hz": 25600, "samples": [0.5, -1.25e-3, 7, 0, -0.0]}"#,
        r#"{"samples":[1,2,3],"sample_rate_hz":1e4,"shaft_hz":30,"sensor":"s","recorded_at":"2026-11-22T08:30:00Z"}"#,
        r#"{"sample_rate_hz": 25600, "samples": [], "shaft_hz": null, "sensor": null}"#,
    ];
    let mut rng = gearwear::signature::SplitMix64::new(99);
    let mut pick = |n: usize| (rng.next_u64() % n as u64) as usize;
    let (mut taken, mut total) = (0, 0);
    for _ in 0..30_000 {
        let mut b = bases[pick(bases.len())].as_bytes().to_vec();
        for _ in 0..1 + pick(3) {
            let i = pick(b.len() + 1);
            let c = ALPHABET[pick(ALPHABET.len())];
            match pick(3) {
                0 => b.insert(i, c),
                1 if i < b.len() => {
                    b.remove(i);
                }
                _ if i < b.len() => b[i] = c,
                _ => b.push(c),
            }
        }
        total += 1;
        if gearwear::service::wire::fast_json_record(&b).is_some() {
            taken += 1;
        }
        harness::json_fast_path_agrees(&b);
    }
    // The edits leave a good share of bodies valid, so the fast path is exercised too.
    assert!(taken * 30 > total, "fast path took {taken} of {total}");
}
