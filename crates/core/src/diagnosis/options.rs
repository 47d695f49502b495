//! The tuning of [`diagnose`](super::diagnose).

use serde::Serialize;

/// Tuning of [`diagnose`](super::diagnose). The defaults are the calibrated values documented in
/// `docs/diagnosis.md`.
#[derive(Debug, Clone, Serialize)]
pub struct DiagnoseOptions {
    /// Input (motor) shaft rate in Hz; `None`: find f1 in the spectrum.
    pub shaft_hz: Option<f64>,
    /// Credible level of the interval (0.9 → 5 % … 95 %).
    pub credible_level: f64,
    /// Standard deviation of the Gaussian prior on Ω1 around the measured value (absorbs the
    /// model's speed calibration; the measured f1 itself is far more precise).
    pub omega1_sigma: f64,
    /// Floor (dB re the f1 line) below which line ratios are clipped, in both the record and
    /// the table: lines under it are treated as "absent" (noise decides their level).
    pub floor_db: f64,
    /// Measurement-noise floor of every feature (natural-log units), added in quadrature to
    /// the table's spread.
    pub feature_sigma: f64,
    /// Likelihood temperature (≥ 1 flattens an over-confident product of correlated features).
    pub temperature: f64,
    /// z-score of the f3 line above which the planetary clearance is flagged as elevated.
    pub planetary_z: f64,
    /// Step of the fine ea grid of the posterior.
    pub ea_step: f64,
    /// Goodness-of-fit warning threshold on χ² per feature (see [`Fit`](super::Fit)).
    pub max_chi2_per_feature: f64,
    /// Tacho-less only: above this χ² per feature the other f1 candidates of the spectral
    /// search are tried and the best-fitting one is kept (held-out simulations stay below ≈ 1.7,
    /// a wrong f1 gave 30–150).
    pub reselect_chi2_per_feature: f64,
    /// Track the input shaft from the f1 line and compute every shaft's TSA
    /// ([`Diagnosis::order`](super::Diagnosis)); `false` when the caller has the shaft's angle
    /// already (a tachometer) and computes them from it.
    pub track_orders: bool,
}

/// Relative tolerance on the table's Ω1 band edges for a measured f1.
pub const BAND_EDGE_TOLERANCE: f64 = 0.002;

/// True if `v` is NaN or above `limit` (a NaN fit statistic counts as a bad fit).
pub(super) fn nan_or_above(v: f64, limit: f64) -> bool {
    v.is_nan() || v > limit
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            shaft_hz: None,
            credible_level: 0.9,
            omega1_sigma: 0.01,
            floor_db: -40.0,
            feature_sigma: 0.25,
            temperature: 1.5,
            planetary_z: 3.0,
            ea_step: 0.0025,
            max_chi2_per_feature: 5.0,
            reselect_chi2_per_feature: 2.0,
            track_orders: true,
        }
    }
}
