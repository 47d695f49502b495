//! Spectral signatures of the simulated gearbox: the lines and features shared by the offline
//! table ([`precompute`]) and the diagnosis of a measured record ([`crate::diagnosis`]).
//!
//! # The feature definition (read this first)
//!
//! The lines of [`line_set`] (normalised frequencies `r_ℓ`, multiples of the stage-1 mesh
//! frequency f1) are measured by the line estimator of [`crate::signal::lines`]
//! ([`measure_lines`](crate::signal::lines::measure_lines): Welch segments of
//! `SEGMENT_PERIODS` mesh periods, Hann DTFT at exactly `r_ℓ f1`, power average), giving peak
//! amplitudes `A_ℓ` (unit of the record) and the band power `P_band` of
//! `[BAND_LO, BAND_HI] · f1`.
//!
//! Features used for matching are **invariant to the sensor's overall gain** (a measured record
//! is housing acceleration in unknown units):
//!
//! * `ln(A_ℓ / A_f1)` for every line `ℓ ≠ f1` (natural log of the amplitude ratio to the
//!   stage-1 mesh line; divide by `ln 10 / 20` for dB). The diagnosis clips these from below at
//!   a noise floor before comparing ([`crate::diagnosis::DiagnoseOptions::floor_db`]);
//! * `f1_power_fraction = ln((A_f1² / 2) / P_band)`: the share of the band power `P_band` that
//!   the f1 line carries. Near 0 for a clean periodic mesh, strongly negative for a broadband
//!   (chaotic) response.
//!
//! The sensor quantity of the simulation is configurable ([`SensorQuantity`]); the default is the
//! stage-1 relative acceleration `ẍ̄1`.

pub mod coverage;
pub mod line_set;
pub mod precompute;
pub mod status;
pub mod table;

use std::f64::consts::TAU;

use serde::{Deserialize, Serialize};

use crate::signal::lines::LineMeasurement;

pub use status::TableStatus;
pub use table::{SignatureTable, SimulationSettings, model_hash};

/// What the simulated "sensor" measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SensorQuantity {
    /// Stage-1 relative displacement `x̄1` (the paper's figures).
    X1,
    /// Stage-1 relative acceleration `x̄1''` (closest to a housing accelerometer; default).
    #[default]
    Accel,
    /// Stage-1 dynamic mesh force `k̄1(τ) f(x̄1) + c̄1 x̄1'`.
    MeshForce,
}

impl SensorQuantity {
    /// Label used in files and the CLI.
    pub fn label(&self) -> &'static str {
        match self {
            SensorQuantity::X1 => "x1",
            SensorQuantity::Accel => "accel",
            SensorQuantity::MeshForce => "mesh-force",
        }
    }
}

/// One spectral line of the model, at `ratio × f1`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineDef {
    /// Name, e.g. `f2`, `2f2`, `f1-f2`.
    pub name: String,
    /// Frequency over the stage-1 mesh frequency f1.
    pub ratio: f64,
    /// True for lines of the planetary stage (f3 and its sidebands): they are kept out of the
    /// wear likelihood and drive the planetary-clearance flag instead.
    pub planetary: bool,
}

/// The ratios of a line set, in its order (what
/// [`measure_lines`](crate::signal::lines::measure_lines) measures).
pub fn line_ratios(lines: &[LineDef]) -> Vec<f64> {
    lines.iter().map(|l| l.ratio).collect()
}

/// The signature's side of a [`LineMeasurement`] (which the line estimator of
/// [`crate::signal::lines`] defines): lines by name, and the features of the [module docs](self).
impl LineMeasurement {
    /// Index of a line by name in `lines`.
    pub fn index(lines: &[LineDef], name: &str) -> Option<usize> {
        lines.iter().position(|l| l.name == name)
    }

    /// The gain-invariant feature vector: `ln(A_ℓ/A_f1)` for every line except f1 (line-set
    /// order), then `f1_power_fraction`. Unclipped; non-finite values (a zero line) become a very
    /// negative number (−50, i.e. −434 dB) so that clipping handles them.
    pub fn features(&self, lines: &[LineDef]) -> Vec<f64> {
        let i1 = Self::index(lines, "f1").unwrap_or(0);
        let a1 = self.amplitudes[i1];
        let mut out = Vec::with_capacity(lines.len());
        for (i, a) in self.amplitudes.iter().enumerate() {
            if i == i1 {
                continue;
            }
            out.push(finite_or((a / a1).ln(), -50.0));
        }
        out.push(finite_or((0.5 * a1 * a1 / self.band_power).ln(), -50.0).min(0.0));
        out
    }
}

fn finite_or(v: f64, alt: f64) -> f64 {
    if v.is_finite() { v.max(alt) } else { alt }
}

/// Names of the features returned by [`LineMeasurement::features`].
pub fn feature_names(lines: &[LineDef]) -> Vec<String> {
    let mut v: Vec<String> = lines
        .iter()
        .filter(|l| l.name != "f1")
        .map(|l| format!("ln({}/f1)", l.name))
        .collect();
    v.push("f1_power_fraction".into());
    v
}

/// SplitMix64: a tiny, well-mixed deterministic generator for seeds and initial states (no
/// external dependency; not for cryptography).
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

/// Mix several integers into one seed.
pub fn mix_seed(parts: &[u64]) -> u64 {
    let mut g = SplitMix64::new(0x6765_6172_7765_6172);
    let mut s = 0u64;
    for &p in parts {
        g.0 ^= p.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        s = g.next_u64();
    }
    s
}
