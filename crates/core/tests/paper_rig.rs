//! The first paper's rig against the original hand-written references that do not share the
//! gearbox code: `configs/gearboxes/wang2019.toml` must resolve to the model of the Model A
//! configuration (`configs/model_a.toml`, `tests/support/rig_a.rs`), and its line set must be
//! the original one (`tests/support/line_set_a.rs`, on the three-mesh kinematics of
//! `tests/support/kinematics_a.rs`, whose own tests run here too).

use std::f64::consts::TAU;

use gearwear_core::gearbox::Gearbox;
use gearwear_core::model::Wear;
use gearwear_core::signal::lines::{LineMeasurement, measure_lines};
use gearwear_core::signature::line_set::gearbox_line_set;
use gearwear_core::signature::{feature_names, line_ratios};

// The oracles are kept whole; each test uses part of them.
#[allow(dead_code)]
#[path = "support/kinematics_a.rs"]
mod kinematics_a;
#[allow(dead_code)]
#[path = "support/line_set_a.rs"]
mod line_set_a;
#[allow(dead_code)]
#[path = "support/rig_a.rs"]
mod rig_a;

use line_set_a::legacy_line_set;
use rig_a::ModelAConfig;

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-300)
}

#[test]
fn paper_rig_resolves_to_the_hand_written_model() {
    let gb = Gearbox::paper_rig();
    let cfg = ModelAConfig::default_rig();
    for (ea, pl) in [
        (0.1, None),
        (0.8, None),
        (0.45, Some(0.6)),
        (0.0, Some(0.0)),
    ] {
        let w = Wear { ea, planetary: pl };
        let new = gb.assembly(w).unwrap().resolve().unwrap();
        let old = cfg.assembly(w).unwrap().resolve().unwrap();
        assert_eq!(new.names, old.names);
        let n = old.n();
        for i in 0..n {
            for j in 0..n {
                assert!(
                    close(new.a[(i, j)], old.a[(i, j)], 1e-12),
                    "A[{i},{j}] {} vs {}",
                    new.a[(i, j)],
                    old.a[(i, j)]
                );
            }
            assert!(close(new.k_ratio[i], old.k_ratio[i], 1e-12), "k_ratio[{i}]");
            assert!(close(new.c[i], old.c[i], 1e-12), "c[{i}]");
            assert!(
                (new.f[i] - old.f[i]).abs()
                    <= 1e-12 * old.f.iter().fold(0.0_f64, |m, v| m.max(v.abs())),
                "F[{i}] {} vs {}",
                new.f[i],
                old.f[i]
            );
            // The ratios are computed with the same operations: bit for bit.
            assert_eq!(new.omega_ratio[i], old.omega_ratio[i], "omega_ratio[{i}]");
            assert!(
                close(new.backlash[i], old.backlash[i], 1e-12),
                "backlash[{i}]"
            );
            assert_eq!(new.phase[i], old.phase[i]);
            assert_eq!(new.shape[i], old.shape[i]);
            assert_eq!(new.error[i].len(), old.error[i].len());
            for (a, b) in new.error[i].iter().zip(&old.error[i]) {
                assert!(close(a.amplitude, b.amplitude, 1e-12), "error[{i}]");
                assert_eq!(a.freq_ratio, b.freq_ratio);
            }
        }
        assert!(close(new.omega_h, old.omega_h, 1e-12));
    }
    assert_eq!(gb.reference_frequency_hz(), 870.0);
    assert_eq!(gb.f1_hz(30.0), cfg.f1_hz(30.0));
    assert_eq!(gb.planetary_baseline(), Some(0.1));
    assert!(!gb.dynamics_estimated());
    assert_eq!(gb.wear_stages(), vec![1, 2]);
}

#[test]
fn paper_rig_gets_the_original_fourteen_lines() {
    let gb = Gearbox::paper_rig();
    let new = gearbox_line_set(&gb);
    let old = legacy_line_set(&ModelAConfig::default_rig().tooth_counts().frequencies());
    assert_eq!(new, old);
}

#[test]
fn measures_known_lines_gain_invariantly() {
    let fr = ModelAConfig::default_rig().tooth_counts().frequencies();
    let lines = gearbox_line_set(&Gearbox::paper_rig());
    let (fs, f1) = (25_600.0, 870.0);
    let n = 25_600;
    let sig = |gain: f64| -> Vec<f64> {
        (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                gain * (2.0 * (TAU * f1 * t).sin()
                    + 0.5 * (TAU * fr.f2 * f1 * t + 0.3).sin()
                    + 0.1 * (TAU * 2.0 * f1 * t).cos()
                    + 7.0)
            })
            .collect()
    };
    let m = measure_lines(&sig(1.0), fs, f1, &line_ratios(&lines)).unwrap();
    let a = |name: &str| m.amplitudes[LineMeasurement::index(&lines, name).unwrap()];
    assert!((a("f1") - 2.0).abs() < 1e-3, "{}", a("f1"));
    assert!((a("f2") - 0.5).abs() < 1e-3);
    assert!((a("2f1") - 0.1).abs() < 1e-3);
    assert!(a("f1/2") < 1e-3);
    // Band power: (2² + 0.5² + 0.1²)/2.
    assert!((m.band_power - (4.0 + 0.25 + 0.01) / 2.0).abs() < 0.01 * m.band_power);
    let f = m.features(&lines);
    let g = measure_lines(&sig(37.0), fs, f1, &line_ratios(&lines))
        .unwrap()
        .features(&lines);
    for (x, y) in f.iter().zip(&g) {
        assert!((x - y).abs() < 1e-9);
    }
    assert_eq!(f.len(), feature_names(&lines).len());
}
