//! Replays every committed fuzz input through the fuzz harnesses (`gearwear::fuzzing`, the
//! same functions the `cargo fuzz` targets call): `fuzz/seeds/<target>/` (hand-made, from
//! `scripts/fuzz_seeds.py`), `fuzz/corpus/<target>/` (the minimised corpus of the long runs)
//! and `fuzz/regressions/<target>/` (every input that once crashed a target or broke an
//! invariant). A harness panics on a crash or a broken invariant, so this is the short,
//! deterministic version of `scripts/fuzz.sh` that `cargo test` runs. See
//! docs/reliability/fuzzing.md.

use std::path::{Path, PathBuf};

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
    let harness = gearwear::fuzzing::TARGETS
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

/// Every harness has committed seeds and a cargo-fuzz target, and every input folder a
/// harness (a target added or renamed on one side only would silently lose its replay).
#[test]
fn every_target_has_a_corpus_and_every_corpus_a_target() {
    let names: Vec<&str> = gearwear::fuzzing::TARGETS.iter().map(|(n, _)| *n).collect();
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
    gearwear::fuzzing::check_record(&r, &Default::default(), 2, "test");
}

#[test]
#[should_panic(expected = "samples from an input that can hold at most")]
fn the_record_check_refuses_invented_samples() {
    let r = gearwear::record::Record {
        samples: vec![0.0; 5],
        sample_rate: 1.0,
    };
    gearwear::fuzzing::check_record(&r, &Default::default(), 4, "test");
}
