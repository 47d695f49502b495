//! The load generator's default record, shared by `examples/loadgen.rs` and
//! `benches/diagnose.rs` (included in both with `#[path]`): 1 s at 25.6 kHz, f1 = 1.07·870 Hz
//! with three partner sines at the rig's mesh ratios and a little deterministic noise. It is not
//! a model output — a poor fit (χ²/feature ≈ 87) that makes a tacho-less diagnosis try every
//! f1 candidate: the service's slowest path.

/// Sample rate of [`samples`] (Hz).
pub const SAMPLE_RATE_HZ: f64 = 25_600.0;

/// The 25 600 samples.
pub fn samples() -> Vec<f64> {
    use std::f64::consts::TAU;
    let f1 = 1.07 * 870.0;
    (0..25_600)
        .map(|i| {
            let t = i as f64 / SAMPLE_RATE_HZ;
            (TAU * f1 * t).sin()
                + 0.2 * (TAU * 0.36 * f1 * t).sin()
                + 0.05 * (TAU * 0.0875 * f1 * t).sin()
                + 0.3 * (TAU * 2.0 * f1 * t).sin()
                + 0.01 * ((i * 7919 % 1000) as f64 / 1000.0 - 0.5)
        })
        .collect()
}
