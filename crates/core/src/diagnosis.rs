//! Diagnosis: from one accelerometer record to a wear degree with a credible interval.
//!
//! Steps of [`diagnose`]:
//! 1. **Validate** the record (non-empty, finite, a usable sample rate).
//! 2. **Locate f1** (stage-1 mesh frequency, Hz). With a shaft rate: `f1 = z1 × shaft_hz`
//!    (29 × on the paper's rig), refined to the spectral peak within ±0.3 %. Without
//!    (tacho-less): every prominent peak of the record's spectrum inside the table's speed band
//!    is scored by its own prominence plus the prominence of its kinematic partners
//!    (`f2 = 0.36 f1`, `2f2`, `f1 − f2`, `f3 = 0.0875 f1`, `f1 + f2`, `2 f1`); the best
//!    candidate wins and is refined to the maximum of the record's Hann DTFT. `Ω1 = f1 / f_ref`.
//! 3. **Measure** the model's lines and the gain-invariant features
//!    ([`crate::signal::lines::measure_lines`]; the same code made the table).
//! 4. **Match**: a Gaussian likelihood in the clipped log-ratio features with the table's
//!    per-grid-point mean and spread plus a measurement floor, bilinearly interpolated in
//!    `(ea, Ω1)`, tempered, marginalised over `Ω1` with a narrow Gaussian prior around the
//!    measured value; uniform prior on `ea` over the table's range. The posterior gives the
//!    estimate (median), the 90 % credible interval (5 % and 95 % quantiles), the motion state
//!    the table expects there and the nearest table entries.
//! 5. **Planetary flag**: the z-score of the measured `ln(A_f3/A_f1)` against what the table
//!    (planetary error 0.1) expects at the estimate; above `planetary_z` → elevated.
//! 6. **Condition indicators** (RMS, kurtosis, crest factor, FM0, FM4, NA4; tacho-less, see
//!    [`crate::signal::features`]).
//! 7. **Baseline** (the paper's method): the single ratio `A_f2/A_f1` matched to the table's
//!    mean curve at the measured Ω1; reported for comparison.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signal::features::{ConditionIndicators, condition_indicators};
use crate::signal::lines::{
    LineMeasurement, SEGMENT_PERIODS, highest_ratio, measure_lines, segment_len,
};
use crate::signal::{Spectrum, Window, amplitude_spectrum, welch};
use crate::signature::{LineDef, SignatureTable, line_ratios};

/// Tuning of [`diagnose`]. The defaults are the calibrated values documented in
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
    /// Goodness-of-fit warning threshold on χ² per feature (see [`Fit`]).
    pub max_chi2_per_feature: f64,
    /// Tacho-less only: above this χ² per feature the other f1 candidates of the spectral
    /// search are tried and the best-fitting one is kept (held-out simulations stay below ≈ 1.7,
    /// a wrong f1 gave 30–150).
    pub reselect_chi2_per_feature: f64,
}

/// Relative tolerance on the table's Ω1 band edges for a measured f1.
pub const BAND_EDGE_TOLERANCE: f64 = 0.002;

/// True if `v` is NaN or above `limit` (a NaN fit statistic counts as a bad fit).
fn nan_or_above(v: f64, limit: f64) -> bool {
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
        }
    }
}

/// The wear estimate.
#[derive(Debug, Clone, Serialize)]
pub struct WearDegree {
    /// Posterior median of ea (units of b = 5 µm).
    pub estimate: f64,
    /// Lower end of the credible interval.
    pub lower: f64,
    /// Upper end.
    pub upper: f64,
    /// Credible level of `[lower, upper]`.
    pub level: f64,
    /// Posterior mode.
    pub mode: f64,
}

/// How f1 was found.
#[derive(Debug, Clone, Serialize)]
pub struct F1Detection {
    /// `shaft-speed` or `spectrum` (tacho-less).
    pub method: &'static str,
    /// Starting value before refinement (Hz).
    pub initial_hz: f64,
    /// Prominence of the f1 peak over the local spectral floor (dB).
    pub prominence_db: f64,
    /// Kinematic partner lines seen at ≥ 6 dB over the floor, by name.
    pub partners_found: Vec<String>,
    /// Score of the chosen candidate (tacho-less) and of the runner-up.
    pub score: f64,
    pub runner_up_hz: Option<f64>,
    pub runner_up_score: Option<f64>,
    /// Best candidates `(Hz, score, partners found)` of the tacho-less search.
    pub candidates: Vec<(f64, f64, Vec<String>)>,
}

/// One measured line.
#[derive(Debug, Clone, Serialize)]
pub struct MatchedLine {
    pub name: String,
    /// Frequency over f1.
    pub normalised_frequency: f64,
    pub frequency_hz: f64,
    /// Peak amplitude (unit of the record).
    pub amplitude: f64,
    /// 20 log10(A / A_f1).
    pub level_db: f64,
    /// What the table expects at the estimate (dB re f1, after clipping), and its spread.
    pub expected_db: Option<f64>,
    pub expected_std_db: Option<f64>,
}

/// A table entry near the answer.
#[derive(Debug, Clone, Serialize)]
pub struct NearEntry {
    pub ea: f64,
    pub omega1: f64,
    /// Log-likelihood of the record at this entry (tempered).
    pub log_likelihood: f64,
    pub motion_state: String,
}

/// The planetary-stage check.
#[derive(Debug, Clone, Serialize)]
pub struct PlanetaryCheck {
    /// Measured ln(A_f3/A_f1) after clipping.
    pub f3_log_ratio: f64,
    /// Expected at the estimate with planetary error 0.1, and the combined spread.
    pub expected: f64,
    pub sigma: f64,
    pub z: f64,
    pub threshold: f64,
}

/// The paper's single-ratio method.
#[derive(Debug, Clone, Serialize)]
pub struct Baseline {
    pub method: &'static str,
    pub ea: f64,
}

/// How well the best table point explains the record.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    /// `Σ_d (y_d − μ_d)² / (σ_d² + feature_sigma²)` over the wear features at (mode, Ω1).
    pub chi2: f64,
    /// Number of features in the sum.
    pub features: usize,
    /// `chi2 / features`; ≈ 1 for a record the model explains. Above
    /// [`DiagnoseOptions::max_chi2_per_feature`] a warning says the record does not look like
    /// this model's output (another gearbox, another sensor position, a fault the model lacks).
    pub chi2_per_feature: f64,
    /// True when the fit was poor and the likelihood was flattened by `chi2_per_feature`.
    pub inflated: bool,
}

fn fit_is_poor(chi2_per_feature: f64, opts: &DiagnoseOptions) -> bool {
    nan_or_above(chi2_per_feature, opts.max_chi2_per_feature)
}

/// Record facts.
#[derive(Debug, Clone, Serialize)]
pub struct RecordInfo {
    pub samples: usize,
    pub sample_rate_hz: f64,
    pub duration_s: f64,
    pub f1_periods: f64,
    pub welch_segments: usize,
    pub segment_len: usize,
}

/// The answer of [`diagnose`] (also the JSON of `gearwear diagnose`).
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub wear_degree: WearDegree,
    /// Stage-1 mesh frequency (Hz).
    pub f1_hz: f64,
    /// Input-shaft rate implied by f1 (Hz), `f1 / z1`.
    pub shaft_hz: f64,
    /// Ω1 = f1 / f_ref of the measured f1.
    pub omega1: f64,
    /// Posterior mean of Ω1.
    pub omega1_posterior: f64,
    pub f1_detection: F1Detection,
    /// Motion state of x1 the table expects at (estimate, Ω1).
    pub motion_state: String,
    /// Share of the table's seeds in that state at the nearest entry.
    pub motion_state_share: f64,
    pub planetary_clearance_elevated: bool,
    /// Absent for a gearbox without a planetary stage that the wear leaves out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planetary: Option<PlanetaryCheck>,
    pub lines: Vec<MatchedLine>,
    pub condition_indicators: ConditionIndicators,
    pub nearest_entries: Vec<NearEntry>,
    /// Posterior density over ea on a 0.01 grid: `(ea, density)`.
    pub posterior: Vec<(f64, f64)>,
    /// The paper's single-ratio method; absent for a gearbox with no second wear stage (its
    /// line `f2` is what the method reads).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baseline_single_ratio: Option<Baseline>,
    pub fit: Fit,
    pub record: RecordInfo,
    /// Table identity.
    pub table_model_hash: String,
    pub sensor: String,
    pub warnings: Vec<String>,
    /// Order tracking of the input shaft from the phase of the f1 line, the time-synchronous
    /// average of every shaft it reaches and the gear condition metrics on it (FM0, FM4, NA4,
    /// NB4, M6A, M8A, ER, SLF; [`crate::novelty::order_analysis`]). Absent when the tracking
    /// fails (`order_error` says why).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order: Option<crate::novelty::OrderAnalysis>,
    /// Why there is no `order` (e.g. a record of fewer than 16 revolutions).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order_error: Option<String>,
}

/// Per-entry statistics of the clipped features.
#[derive(Debug, Clone)]
pub struct Matcher {
    /// Feature indices used for ea.
    wear_features: Vec<usize>,
    /// The first other wear stage's mesh line (`f2` of the paper's rig): the single-ratio
    /// baseline reads it.
    f2_feature: Option<usize>,
    /// The first planetary stage's mesh line when the wear leaves that stage out (`f3` of the
    /// paper's rig): the planetary check reads it.
    f3_feature: Option<usize>,
    /// mean and variance per entry per feature (entry-major).
    mean: Vec<Vec<f64>>,
    var: Vec<Vec<f64>>,
    /// The same statistics of the wear features only, flat (`entry × wear_features.len()`,
    /// in `wear_features` order): what the posterior's inner loop reads.
    wear_mean: Vec<f64>,
    wear_var: Vec<f64>,
    floor: f64,
    n_ea: usize,
    n_om: usize,
    ea: Vec<f64>,
    om: Vec<f64>,
}

/// Feature index of a line (features skip f1).
fn feature_index(lines: &[LineDef], name: &str) -> Option<usize> {
    let i1 = lines.iter().position(|l| l.name == "f1")?;
    let i = lines.iter().position(|l| l.name == name)?;
    if i == i1 {
        None
    } else if i < i1 {
        Some(i)
    } else {
        Some(i - 1)
    }
}

impl Matcher {
    /// Precompute the clipped statistics of a table.
    pub fn new(table: &SignatureTable, opts: &DiagnoseOptions) -> Result<Self> {
        let lines = &table.features.lines;
        let nf = table.features.names.len();
        let floor = opts.floor_db * std::f64::consts::LN_10 / 20.0;
        let mut wear_features = Vec::new();
        for (k, l) in lines.iter().filter(|l| l.name != "f1").enumerate() {
            if !l.planetary {
                wear_features.push(k);
            }
        }
        wear_features.push(nf - 1); // f1_power_fraction
        // Mesh lines of other stages are named `f<stage>` (see signature::line_set).
        let is_mesh_line = |l: &&LineDef| {
            l.name.len() > 1
                && l.name.starts_with('f')
                && l.name[1..].chars().all(|c| c.is_ascii_digit())
                && l.name != "f1"
        };
        let first_mesh = |planetary: bool| {
            lines
                .iter()
                .filter(is_mesh_line)
                .filter(|l| l.planetary == planetary)
                .min_by_key(|l| l.name[1..].parse::<usize>().unwrap_or(usize::MAX))
                .and_then(|l| feature_index(lines, &l.name))
        };
        let f2_feature = first_mesh(false);
        let f3_feature = first_mesh(true);
        let mut mean = Vec::with_capacity(table.entries.len());
        let mut var = Vec::with_capacity(table.entries.len());
        for e in &table.entries {
            let n = e.samples.len() as f64;
            let mut m = vec![0.0; nf];
            let mut v = vec![0.0; nf];
            for s in &e.samples {
                for d in 0..nf {
                    m[d] += s[d].max(floor);
                }
            }
            for x in m.iter_mut() {
                *x /= n;
            }
            for s in &e.samples {
                for d in 0..nf {
                    v[d] += (s[d].max(floor) - m[d]).powi(2);
                }
            }
            for x in v.iter_mut() {
                // Unbiased; one seed gives no spread.
                *x /= (n - 1.0).max(1.0);
            }
            mean.push(m);
            var.push(v);
        }
        let wear_mean = mean
            .iter()
            .flat_map(|m| wear_features.iter().map(|&d| m[d]))
            .collect();
        let wear_var = var
            .iter()
            .flat_map(|v| wear_features.iter().map(|&d| v[d]))
            .collect();
        Ok(Matcher {
            wear_features,
            f2_feature,
            f3_feature,
            mean,
            var,
            wear_mean,
            wear_var,
            floor,
            n_ea: table.grid.ea.len(),
            n_om: table.grid.omega1.len(),
            ea: table.grid.ea.clone(),
            om: table.grid.omega1.clone(),
        })
    }

    /// This matcher with the variance of every feature `d` raised by `extra[d]` at every
    /// entry (same length as the features; non-finite or negative values count as 0): a
    /// feature known less well than the table says — one an effect outside the table changes
    /// by an uncertain amount ([`diagnose_shifted`]) — weighs less in the likelihood.
    pub fn with_extra_variance(&self, extra: &[f64]) -> Matcher {
        let add = |d: usize| extra.get(d).copied().filter(|v| *v > 0.0).unwrap_or(0.0);
        let mut m = self.clone();
        for v in m.var.iter_mut() {
            for (d, x) in v.iter_mut().enumerate() {
                *x += add(d);
            }
        }
        let nw = m.wear_features.len();
        for (i, x) in m.wear_var.iter_mut().enumerate() {
            *x += add(m.wear_features[i % nw]);
        }
        m
    }

    /// Clip a measured feature vector at the floor.
    pub fn clip(&self, y: &[f64]) -> Vec<f64> {
        y.iter().map(|v| v.max(self.floor)).collect()
    }

    /// Bracketing index and weight of `v` on an ascending axis (clamped).
    fn bracket(axis: &[f64], v: f64) -> (usize, f64) {
        if axis.len() == 1 || v <= axis[0] {
            return (0, 0.0);
        }
        let last = axis.len() - 1;
        if v >= axis[last] {
            return (last - 1, 1.0);
        }
        let i = axis.partition_point(|&a| a <= v) - 1;
        (i, (v - axis[i]) / (axis[i + 1] - axis[i]))
    }

    /// Bracket of `ea` on the ea axis.
    fn ea_bracket(&self, ea: f64) -> (usize, f64) {
        Self::bracket(&self.ea, ea)
    }

    /// Bracket of `om` on the Ω1 axis (a one-column table: column 0).
    fn om_bracket(&self, om: f64) -> (usize, f64) {
        if self.n_om > 1 {
            Self::bracket(&self.om, om)
        } else {
            (0, 0.0)
        }
    }

    /// The four bilinear corners `(entry, weight)` of the brackets `(i, u)` (ea) and `(j, w)`
    /// (Ω1), in the fixed summation order every interpolation here uses.
    fn corners(&self, (i, u): (usize, f64), (j, w): (usize, f64)) -> [(usize, f64); 4] {
        let j1 = (j + 1).min(self.n_om - 1);
        let i1 = (i + 1).min(self.n_ea - 1);
        let at = |a: usize, b: usize| a * self.n_om + b;
        [
            (at(i, j), (1.0 - u) * (1.0 - w)),
            (at(i1, j), u * (1.0 - w)),
            (at(i, j1), (1.0 - u) * w),
            (at(i1, j1), u * w),
        ]
    }

    /// Bilinear mean and variance of feature `d` at `(ea, Ω1)`.
    pub fn stats_at(&self, d: usize, ea: f64, om: f64) -> (f64, f64) {
        let mut m = 0.0;
        let mut v = 0.0;
        for (idx, wt) in self.corners(self.ea_bracket(ea), self.om_bracket(om)) {
            m += wt * self.mean[idx][d];
            v += wt * self.var[idx][d];
        }
        (m, v)
    }

    /// Tempered log-likelihood of the clipped features `y` at `(ea, Ω1)`.
    pub fn log_likelihood(&self, y: &[f64], ea: f64, om: f64, opts: &DiagnoseOptions) -> f64 {
        let yw: Vec<f64> = self.wear_features.iter().map(|&d| y[d]).collect();
        let s0 = opts.feature_sigma * opts.feature_sigma;
        let corners = self.corners(self.ea_bracket(ea), self.om_bracket(om));
        self.wear_log_likelihood(&yw, &corners, s0) / opts.temperature.max(1e-9)
    }

    /// Untempered log-likelihood of the wear features `yw` (in `wear_features` order) at the
    /// bilinear `corners`, from the flat per-entry arrays. Same arithmetic, in the same order,
    /// as [`Matcher::stats_at`] per feature (the results are bit-identical).
    #[inline]
    fn wear_log_likelihood(&self, yw: &[f64], corners: &[(usize, f64); 4], s0: f64) -> f64 {
        let nw = yw.len();
        let rows = corners.map(|(idx, _)| idx * nw);
        // −½ Σ_q [(y_q − m_q)²/σ_q² + ln σ_q²], with ln of the product of up to eight σ² at a
        // time instead of one ln per feature (the logarithm was the costliest step of the
        // posterior): σ² ≥ s0 > 0, so a product of eight stays normal unless the variances are
        // extreme, and then that group takes one ln per feature.
        const GROUP: usize = 8;
        let (mut chi2, mut ln_var) = (0.0, 0.0);
        for (g, ys) in yw.chunks(GROUP).enumerate() {
            let mut prod = 1.0;
            let mut vars = [0.0; GROUP];
            for (k, &yq) in ys.iter().enumerate() {
                let q = g * GROUP + k;
                let mut m = 0.0;
                let mut v = 0.0;
                for (r, &(_, wt)) in rows.iter().zip(corners) {
                    m += wt * self.wear_mean[r + q];
                    v += wt * self.wear_var[r + q];
                }
                let var = v + s0;
                chi2 += (yq - m).powi(2) / var;
                prod *= var;
                vars[k] = var;
            }
            ln_var += if prod.is_normal() {
                prod.ln()
            } else {
                vars[..ys.len()].iter().map(|v| v.ln()).sum()
            };
        }
        -0.5 * (chi2 + ln_var)
    }

    /// χ² of the clipped features `y` at `(ea, Ω1)` and the number of features in it.
    pub fn chi2(&self, y: &[f64], ea: f64, om: f64, opts: &DiagnoseOptions) -> (f64, usize) {
        let s0 = opts.feature_sigma * opts.feature_sigma;
        let c = self
            .wear_features
            .iter()
            .map(|&d| {
                let (m, v) = self.stats_at(d, ea, om);
                (y[d] - m).powi(2) / (v + s0)
            })
            .sum();
        (c, self.wear_features.len())
    }

    /// Log-likelihood at a grid entry (no interpolation).
    fn entry_log_likelihood(&self, y: &[f64], k: usize, opts: &DiagnoseOptions) -> f64 {
        let s0 = opts.feature_sigma * opts.feature_sigma;
        let mut ll = 0.0;
        for &d in &self.wear_features {
            let var = self.var[k][d] + s0;
            ll += -0.5 * (y[d] - self.mean[k][d]).powi(2) / var - 0.5 * var.ln();
        }
        ll / opts.temperature.max(1e-9)
    }

    /// The paper's single-ratio estimate: the ea whose table mean of ln(A_f2/A_f1) at Ω1 is
    /// closest to the measured one.
    pub fn baseline(&self, y: &[f64], om: f64, step: f64) -> Option<f64> {
        let f2 = self.f2_feature?;
        let (lo, hi) = (self.ea[0], self.ea[self.n_ea - 1]);
        let n = ((hi - lo) / step).round() as usize;
        let mut best = (f64::INFINITY, lo);
        for k in 0..=n {
            let ea = lo + k as f64 * step;
            let (m, _) = self.stats_at(f2, ea, om);
            let d = (y[f2] - m).abs();
            if d < best.0 {
                best = (d, ea);
            }
        }
        Some(best.1)
    }
}

/// Posterior over ea.
#[derive(Debug, Clone)]
pub struct Posterior {
    pub ea: Vec<f64>,
    /// Normalised to sum 1.
    pub p: Vec<f64>,
    pub omega_mean: f64,
}

impl Posterior {
    /// Quantile `q` (linear within a grid cell).
    pub fn quantile(&self, q: f64) -> f64 {
        let mut c = 0.0;
        for (k, p) in self.p.iter().enumerate() {
            if c + p >= q {
                let frac = if *p > 0.0 { (q - c) / p } else { 0.0 };
                let step = if self.ea.len() > 1 {
                    self.ea[1] - self.ea[0]
                } else {
                    0.0
                };
                return (self.ea[k] - 0.5 * step + frac * step)
                    .clamp(self.ea[0], self.ea[self.ea.len() - 1]);
            }
            c += p;
        }
        self.ea[self.ea.len() - 1]
    }
    /// Mode.
    pub fn mode(&self) -> f64 {
        let k = self
            .p
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(k, _)| k)
            .unwrap_or(0);
        self.ea[k]
    }
}

/// Posterior of ea given clipped features `y` and the measured Ω1.
pub fn posterior(m: &Matcher, y: &[f64], omega1: f64, opts: &DiagnoseOptions) -> Posterior {
    let (lo, hi) = (m.ea[0], m.ea[m.n_ea - 1]);
    let step = opts.ea_step.max(1e-4);
    let n = ((hi - lo) / step).round() as usize + 1;
    let ea: Vec<f64> = (0..n).map(|k| (lo + k as f64 * step).min(hi)).collect();
    let (olo, ohi) = (m.om[0], m.om[m.n_om - 1]);
    let sig = opts.omega1_sigma.max(0.0);
    let oms: Vec<(f64, f64)> = if sig == 0.0 || m.n_om == 1 {
        vec![(omega1.clamp(olo, ohi), 1.0)]
    } else {
        (-4..=4)
            .map(|k| {
                let z = k as f64 * 0.6;
                ((omega1 + z * sig).clamp(olo, ohi), (-0.5 * z * z).exp())
            })
            .collect()
    };
    // Brackets of every Ω1 node and every ea node, found once (not per feature and point).
    let yw: Vec<f64> = m.wear_features.iter().map(|&d| y[d]).collect();
    let s0 = opts.feature_sigma * opts.feature_sigma;
    let temp = opts.temperature.max(1e-9);
    let om_nodes: Vec<((usize, f64), f64)> = oms
        .iter()
        .map(|&(o, w)| (m.om_bracket(o), w.ln()))
        .collect();
    let no = oms.len();
    let mut ll = vec![0.0; n * no];
    let mut max = f64::NEG_INFINITY;
    for (k, &e) in ea.iter().enumerate() {
        let eb = m.ea_bracket(e);
        for (j, &(ob, lnw)) in om_nodes.iter().enumerate() {
            let corners = m.corners(eb, ob);
            let v = m.wear_log_likelihood(&yw, &corners, s0) / temp + lnw;
            ll[k * no + j] = v;
            max = max.max(v);
        }
    }
    let mut p = vec![0.0; n];
    let mut om_acc = 0.0;
    for k in 0..n {
        for (j, &(o, _)) in oms.iter().enumerate() {
            let v = (ll[k * no + j] - max).exp();
            p[k] += v;
            om_acc += v * o;
        }
    }
    let total: f64 = p.iter().sum();
    let (p, omega_mean) = if total > 0.0 && total.is_finite() {
        (p.iter().map(|v| v / total).collect(), om_acc / total)
    } else {
        (vec![1.0 / n as f64; n], omega1)
    };
    Posterior { ea, p, omega_mean }
}

/// Local spectral floor: running median of `amp` over ±`half` bins, evaluated every `stride`
/// bins and interpolated. The medians are computed on first use: the f1 search reads the floor
/// only around the speed band and the partner lines, a fraction of the spectrum.
struct LocalFloor {
    half: usize,
    stride: usize,
    /// Median at centre `i · stride`, once computed.
    medians: Vec<std::cell::OnceCell<f64>>,
}

impl LocalFloor {
    fn new(n: usize, half: usize, stride: usize) -> Self {
        LocalFloor {
            half,
            stride,
            medians: (0..n.div_ceil(stride))
                .map(|_| std::cell::OnceCell::new())
                .collect(),
        }
    }

    fn median(&self, amp: &[f64], i: usize) -> f64 {
        *self.medians[i].get_or_init(|| {
            let c = i * self.stride;
            let lo = c.saturating_sub(self.half);
            let hi = (c + self.half + 1).min(amp.len());
            let mut buf = amp[lo..hi].to_vec();
            let mid = buf.len() / 2;
            buf.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
            buf[mid].max(1e-300)
        })
    }

    /// The floor at bin `k` of `amp` (the spectrum this floor was made for).
    fn at(&self, amp: &[f64], k: usize) -> f64 {
        let last = self.medians.len() - 1;
        let i = (k / self.stride).min(last);
        let i1 = (i + 1).min(last);
        let t = if i1 > i {
            (k - i * self.stride) as f64 / ((i1 - i) * self.stride) as f64
        } else {
            0.0
        };
        self.median(amp, i) * (1.0 - t) + self.median(amp, i1) * t
    }
}

/// [`LocalFloor`] at every bin (reference for the tests).
#[cfg(test)]
fn local_floor(amp: &[f64], half: usize, stride: usize) -> Vec<f64> {
    let f = LocalFloor::new(amp.len(), half, stride);
    (0..amp.len()).map(|k| f.at(amp, k)).collect()
}

/// Hann-windowed DTFT magnitude of the whole record at `f` (Hz): a smooth peak to refine on.
/// `xw` is the record times the window.
fn dtft_mag(xw: &[f64], fs: f64, f: f64) -> f64 {
    let (re, im) = crate::signal::dtft_sums(xw, f / fs);
    re.hypot(im)
}

/// Golden-section maximisation of the DTFT magnitude on `[a, b]`.
fn refine_peak(x: &[f64], fs: f64, a: f64, b: f64, w: &[f64]) -> f64 {
    // The windowed record does not depend on the frequency: form it once.
    let xw: Vec<f64> = x.iter().zip(w).map(|(x, w)| x * w).collect();
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (a, b);
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (dtft_mag(&xw, fs, c), dtft_mag(&xw, fs, d));
    for _ in 0..40 {
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = dtft_mag(&xw, fs, c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = dtft_mag(&xw, fs, d);
        }
        if (b - a) < 1e-7 * b.abs().max(1.0) {
            break;
        }
    }
    0.5 * (a + b)
}

/// Refine a peak near `f0` (Hz) to the maximum of the whole-record Hann DTFT within ±`half`.
fn refine_near(x: &[f64], fs: f64, f0: f64, half: f64) -> f64 {
    let w = crate::signal::shared_window(Window::Hann, x.len());
    refine_peak(x, fs, (f0 - half).max(1e-9), f0 + half, &w)
}

/// Kinematic partners (name, ratio) used to recognise the stage-1 mesh line.
///
/// Every other stage's mesh line `fk` and, for a stage the wear acts on, `2fk` and `f1−fk`;
/// then `f1+fk` of the wear stages; then `2f1` (and `3f1` for a single-stage gearbox, which has
/// no other partner). For the first paper's rig: f2, 2f2, f1−f2, f3, f1+f2, 2f1.
fn partners(gb: &Gearbox) -> Vec<(String, f64)> {
    let wear = gb.wear_stages();
    let others: Vec<(usize, f64, bool)> = gb
        .mesh_ratios
        .iter()
        .enumerate()
        .skip(1)
        .map(|(i, r)| (i + 1, *r, wear.contains(&(i + 1))))
        .collect();
    let mut v = Vec::new();
    for &(k, r, w) in &others {
        v.push((format!("f{k}"), r));
        if w {
            v.push((format!("2f{k}"), 2.0 * r));
            if r < 1.0 {
                v.push((format!("f1-f{k}"), 1.0 - r));
            }
        }
    }
    for &(k, r, w) in &others {
        if w {
            v.push((format!("f1+f{k}"), 1.0 + r));
        }
    }
    v.push(("2f1".into(), 2.0));
    if others.is_empty() {
        v.push(("3f1".into(), 3.0));
    }
    v
}

/// Spectrum used for the f1 search: Hann, whole record up to 2^17 samples, Welch above.
struct SearchSpectrum {
    freq_step: f64,
    amp: Vec<f64>,
    freq: Vec<f64>,
    /// `amp` is the whole record's [`amplitude_spectrum`] (not Welch).
    whole: bool,
    floor: LocalFloor,
}

impl SearchSpectrum {
    fn new(x: &[f64], fs: f64) -> Result<Self> {
        const MAX: usize = 1 << 17;
        let whole = x.len() <= MAX;
        let s = if whole {
            amplitude_spectrum(x, fs, Window::Hann)?
        } else {
            welch(x, fs, MAX, 0.5, Window::Hann)?
        };
        let floor = LocalFloor::new(s.amplitude.len(), 100, 10);
        Ok(SearchSpectrum {
            freq_step: s.resolution(),
            amp: s.amplitude,
            freq: s.freq,
            whole,
            floor,
        })
    }

    /// The whole record's Hann amplitude spectrum, if that is what the search used.
    fn into_whole(self) -> Option<Spectrum> {
        self.whole.then_some(Spectrum {
            freq: self.freq,
            amplitude: self.amp,
        })
    }
    /// Peak prominence (dB over the local floor) of the largest bin within ±tol Hz of f.
    fn prominence(&self, f: f64, tol: f64) -> f64 {
        let lo = ((f - tol) / self.freq_step).floor().max(0.0) as usize;
        let hi = (((f + tol) / self.freq_step).ceil() as usize).min(self.amp.len() - 1);
        if lo > hi {
            return 0.0;
        }
        (lo..=hi)
            .map(|k| 20.0 * (self.amp[k] / self.floor.at(&self.amp, k)).log10())
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// Find f1 (Hz). `band` is the admissible f1 range (Hz).
fn locate_f1(
    x: &[f64],
    fs: f64,
    spec: &SearchSpectrum,
    gb: &Gearbox,
    band: (f64, f64),
    nominal: Option<f64>,
) -> Result<(f64, F1Detection)> {
    let df = spec.freq_step;
    let tol = |f: f64| (2.0 * df).max(0.002 * f);
    let w = crate::signal::shared_window(Window::Hann, x.len());
    let parts = partners(gb);
    let evidence = |f: f64| -> (f64, Vec<String>) {
        let mut score = spec.prominence(f, tol(f)).clamp(0.0, 60.0);
        let mut found = Vec::new();
        for (name, r) in &parts {
            let fp = r * f;
            if fp >= 0.5 * fs {
                continue;
            }
            let p = spec.prominence(fp, tol(fp));
            score += p.clamp(0.0, 30.0);
            if p >= 6.0 {
                found.push(name.to_string());
            }
        }
        (score, found)
    };
    if let Some(f0) = nominal {
        let half = (0.003 * f0).max(2.0 * df);
        let f = refine_peak(x, fs, f0 - half, f0 + half, &w);
        let prom = spec.prominence(f, tol(f));
        let (score, found) = evidence(f);
        return Ok((
            f,
            F1Detection {
                method: "shaft-speed",
                initial_hz: f0,
                prominence_db: prom,
                partners_found: found,
                score,
                runner_up_hz: None,
                runner_up_score: None,
                candidates: Vec::new(),
            },
        ));
    }
    let klo = (band.0 / df).ceil().max(1.0) as usize;
    let khi = ((band.1 / df).floor() as usize).min(spec.amp.len().saturating_sub(3));
    let mut cands: Vec<(usize, f64)> = Vec::new();
    for k in klo.max(2)..=khi {
        let a = spec.amp[k];
        if a >= spec.amp[k - 1]
            && a > spec.amp[k + 1]
            && a >= spec.amp[k - 2]
            && a > spec.amp[k + 2]
        {
            let p = 20.0 * (a / spec.floor.at(&spec.amp, k)).log10();
            if p >= 10.0 {
                cands.push((k, p));
            }
        }
    }
    if cands.is_empty() {
        return Err(Error::NoMeshLine {
            lo_hz: band.0,
            hi_hz: band.1,
            reason: "no spectral peak stands 10 dB above the local floor in the band; give the \
                     shaft rate (--shaft-hz) or check the sample rate"
                .into(),
        });
    }
    cands.sort_by(|a, b| b.1.total_cmp(&a.1));
    cands.truncate(40);
    let mut scored: Vec<(f64, f64, Vec<String>, f64)> = cands
        .iter()
        .map(|&(k, p)| {
            let f = k as f64 * df;
            let (s, found) = evidence(f);
            (f, s, found, p)
        })
        .collect();
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    // Harmonic ambiguity: with a rich nonlinear spectrum, 2·f1 finds "partners" too (the
    // combination tones 2·f2, 2·(f1 − f2), …). Prefer the half-frequency candidate when it is
    // nearly as well supported and carries most of the first-order partners.
    let mut pick = 0;
    for (k, c) in scored.iter().enumerate().skip(1) {
        let best = &scored[0];
        if (c.0 - 0.5 * best.0).abs() <= tol(c.0) && c.1 >= best.1 - 15.0 && c.2.len() >= 4 {
            pick = k;
            break;
        }
    }
    let (f0, score, found, prom) = scored[pick].clone();
    let f = refine_peak(x, fs, f0 - 1.5 * df, f0 + 1.5 * df, &w);
    Ok((
        f,
        F1Detection {
            method: "spectrum",
            initial_hz: f0,
            prominence_db: prom,
            partners_found: found,
            score,
            runner_up_hz: scored.get(1).map(|s| s.0),
            runner_up_score: scored.get(1).map(|s| s.1),
            candidates: scored
                .iter()
                .take(4)
                .map(|s| (s.0, s.1, s.2.clone()))
                .collect(),
        },
    ))
}

/// Diagnose one record against a signature table. See the [module docs](self).
///
/// Errors (each carries the numbers): [`Error::EmptyRecord`], [`Error::FlatRecord`],
/// [`Error::ClippedRecord`] (see [`crate::record::check_signal`]), [`Error::RecordTooShort`]
/// (fewer f1 periods than one estimator segment), [`Error::NonFiniteSample`], [`Error::SampleRateTooLow`],
/// [`Error::NoMeshLine`], [`Error::SpeedOutOfBand`], [`Error::InvalidParameter`] for a bad
/// shaft rate or sample rate.
pub fn diagnose(
    record: &Record,
    table: &SignatureTable,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis> {
    let matcher = Matcher::new(table, opts)?;
    diagnose_with(record, table, &matcher, opts)
}

/// [`diagnose`] with a prepared [`Matcher`] (what a service keeps between requests).
pub fn diagnose_with(
    record: &Record,
    table: &SignatureTable,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis> {
    diagnose_with_spectrum(record, table, matcher, opts).map(|(d, _)| d)
}

/// [`diagnose_with`], also handing back the spectrum its f1 search computed: the record's
/// Hann-windowed [`amplitude_spectrum`] (`None` for a record over 2^17 samples, searched on a
/// Welch average). The service plots that spectrum instead of transforming the record again.
pub fn diagnose_with_spectrum(
    record: &Record,
    table: &SignatureTable,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) -> Result<(Diagnosis, Option<Spectrum>)> {
    diagnose_inner(Inputs::new(record, table)?, matcher, opts)
}

/// [`diagnose`] with known effects the table does not hold **held fixed**: `shift[k]` (the
/// change those effects make to unclipped feature `k` of [`LineMeasurement::features`], same
/// order and length) is subtracted from the record's features before they are clipped and
/// matched, and `shift_var[k]` (that change's own uncertainty, ln-units²) is added to the
/// feature's variance at every table entry ([`Matcher::with_extra_variance`]), so the posterior
/// over `(ea, Ω1)` reads the record as the table's model would make it without the effects,
/// leaning on the features they barely touch. The closed loop computes both from simulations
/// with and without the effects it claimed (`closed_loop::calibrate`'s
/// `table-posterior-effects-held` wear).
///
/// Errors: those of [`diagnose`], and a shift or variance whose length is not the table's
/// feature count or that holds a non-finite value.
pub fn diagnose_shifted(
    record: &Record,
    table: &SignatureTable,
    opts: &DiagnoseOptions,
    shift: &[f64],
    shift_var: &[f64],
) -> Result<Diagnosis> {
    let nf = table.features.lines.len();
    for (what, v) in [("shift", shift), ("shift variance", shift_var)] {
        if v.len() != nf || v.iter().any(|x| !x.is_finite()) {
            return Err(Error::Signal(format!(
                "feature {what}: {} values (need {nf}, all finite)",
                v.len()
            )));
        }
    }
    let matcher = Matcher::new(table, opts)?.with_extra_variance(shift_var);
    let inp = Inputs {
        shift: Some(shift),
        ..Inputs::new(record, table)?
    };
    diagnose_inner(inp, &matcher, opts).map(|(d, _)| d)
}

fn diagnose_inner(
    inp: Inputs<'_>,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) -> Result<(Diagnosis, Option<Spectrum>)> {
    let table = inp.table;
    let nominal = inp.nominal_f1(opts.shaft_hz)?;
    let mut warnings = Vec::new();
    let (mut f1, mut detection, spectrum) = inp.locate(nominal, &mut warnings)?;
    let mut ev = inp.evaluate(matcher, opts, f1)?;
    let nfeat = matcher.wear_features.len();
    if detection.method == "spectrum"
        && nan_or_above(
            ev.chi2 / nfeat.max(1) as f64,
            opts.reselect_chi2_per_feature,
        )
    {
        f1 = inp.reselect_f1(matcher, opts, f1, &mut detection, &mut ev, &mut warnings);
    }
    let omega1 = f1 / inp.f_ref;
    let fit = fit_and_inflate(matcher, opts, &mut ev, omega1, &mut warnings);
    let wear = wear_degree(&ev.post, opts.credible_level);
    let i_om = nearest(&table.grid.omega1, omega1);
    let (motion_state, share) =
        motion_state_at(table, nearest(&table.grid.ea, wear.estimate), i_om);
    let near = nearest_entries(table, matcher, &ev.y, i_om, opts);
    let planetary = planetary_check(matcher, &ev.y, wear.estimate, omega1, opts);
    let out_lines = matched_lines(inp.lines, &ev.meas, matcher, wear.estimate, omega1, f1);
    let shaft = f1 * inp.gb.input_shaft_ratio();
    let ci = inp.condition_indicators(f1, shaft)?;
    let x = inp.x;
    let fs = inp.fs;
    // The f1 found above is precise: the tracker searches its line within ±1 %.
    let spectrum = spectrum.into_whole();
    let (order, order_error) =
        match crate::novelty::order_analysis_with(x, fs, inp.gb, f1, 0.01, spectrum.as_ref()) {
            Ok(a) => (Some(a), None),
            Err(e) => (None, Some(e.to_string())),
        };
    let diagnosis = Diagnosis {
        wear_degree: wear,
        f1_hz: f1,
        shaft_hz: shaft,
        omega1,
        omega1_posterior: ev.post.omega_mean,
        f1_detection: detection,
        motion_state,
        motion_state_share: share,
        planetary_clearance_elevated: planetary.as_ref().is_some_and(|p| p.z > opts.planetary_z),
        planetary,
        lines: out_lines,
        condition_indicators: ci,
        nearest_entries: near,
        posterior: coarse_density(&ev.post),
        fit,
        baseline_single_ratio: matcher
            .baseline(&ev.y, omega1, opts.ea_step)
            .map(|ea| Baseline {
                method: "paper: ea whose table mean ln(A_f2/A_f1) at the measured Ω1 is closest",
                ea,
            }),
        record: RecordInfo {
            samples: x.len(),
            sample_rate_hz: fs,
            duration_s: x.len() as f64 / fs,
            f1_periods: x.len() as f64 * f1 / fs,
            welch_segments: ev.meas.segments,
            segment_len: ev.meas.segment_len,
        },
        table_model_hash: table.model_hash.clone(),
        sensor: table.sensor.label().into(),
        warnings,
        order,
        order_error,
    };
    Ok((diagnosis, spectrum))
}

/// The record and the table's facts that the steps of [`diagnose_with_spectrum`] share.
struct Inputs<'a> {
    table: &'a SignatureTable,
    /// Subtracted from the unclipped features before matching ([`diagnose_shifted`]).
    shift: Option<&'a [f64]>,
    x: &'a [f64],
    fs: f64,
    gb: &'a Gearbox,
    f_ref: f64,
    lines: &'a [LineDef],
    /// The lines' ratios to f1, in their order.
    ratios: Vec<f64>,
    /// Highest line ratio: the sample rate must exceed `2 top f1`.
    top: f64,
    /// The table's Ω1 band, and the same in Hz of f1.
    omega_band: (f64, f64),
    band_hz: (f64, f64),
}

/// The lines measured at one f1 and what the matcher makes of them (steps 3 and 4).
struct Evaluation {
    meas: LineMeasurement,
    /// The clipped features.
    y: Vec<f64>,
    post: Posterior,
    /// χ² of the wear features at the posterior mode.
    chi2: f64,
}

impl<'a> Inputs<'a> {
    /// Step 1: validate the record (sample rate, samples) and gather the table's facts.
    fn new(record: &'a Record, table: &'a SignatureTable) -> Result<Self> {
        let x = &record.samples;
        let fs = record.sample_rate;
        crate::record::check_sample_rate(fs)?;
        crate::record::check_signal(x)?;
        let gb = table.gearbox();
        let f_ref = gb.reference_frequency_hz();
        let lines = &table.features.lines;
        let (olo, ohi) = table.omega_band();
        let ratios = line_ratios(lines);
        Ok(Inputs {
            table,
            shift: None,
            x,
            fs,
            gb,
            f_ref,
            lines,
            top: highest_ratio(&ratios),
            ratios,
            omega_band: (olo, ohi),
            band_hz: (olo * f_ref, ohi * f_ref),
        })
    }

    /// Refuse a record shorter than one estimator segment at `f1`.
    fn check_length(&self, f1: f64) -> Result<()> {
        let needed = segment_len(self.fs, f1).max(16);
        if self.x.len() < needed {
            return Err(Error::RecordTooShort {
                samples: self.x.len(),
                periods: self.x.len() as f64 * f1 / self.fs,
                f1_hz: f1,
                needed_periods: SEGMENT_PERIODS as usize,
                needed_samples: needed,
            });
        }
        Ok(())
    }

    /// True when `2 top f1` reaches the sample rate.
    fn rate_too_low_for(&self, f1: f64) -> bool {
        2.0 * self.top * f1 >= self.fs
    }

    fn rate_too_low(&self, f1: f64) -> Error {
        Error::SampleRateTooLow {
            sample_rate: self.fs,
            highest_line_hz: self.top * f1,
            needed: 2.0 * self.top * f1,
        }
    }

    /// True when `omega1` is more than `tol` outside the table's Ω1 band.
    fn outside_band(&self, omega1: f64, tol: f64) -> bool {
        omega1 < self.omega_band.0 - tol || omega1 > self.omega_band.1 + tol
    }

    fn out_of_band(&self, f1: f64, omega1: f64) -> Error {
        Error::SpeedOutOfBand {
            f1_hz: f1,
            omega1,
            min: self.omega_band.0,
            max: self.omega_band.1,
            min_hz: self.band_hz.0,
            max_hz: self.band_hz.1,
        }
    }

    /// How far a refined f1 may stand outside the band (Ω1 units).
    fn edge(&self) -> f64 {
        BAND_EDGE_TOLERANCE * self.omega_band.0
    }

    /// Step 1, the shaft rate: the f1 it implies, refused outside the table's band, above what
    /// the sample rate carries or with too short a record. Without a shaft rate, the sample rate
    /// must carry the lines at the band's lowest f1.
    fn nominal_f1(&self, shaft_hz: Option<f64>) -> Result<Option<f64>> {
        match shaft_hz {
            Some(s) => {
                if !(s.is_finite() && s > 0.0) {
                    return Err(Error::param(
                        "shaft_hz",
                        s,
                        "the input-shaft rate must be a positive number of Hz",
                    ));
                }
                let f1 = self.gb.f1_hz(s);
                let om = f1 / self.f_ref;
                if self.outside_band(om, 1e-9) {
                    return Err(self.out_of_band(f1, om));
                }
                if self.rate_too_low_for(f1) {
                    return Err(self.rate_too_low(f1));
                }
                self.check_length(f1)?;
                Ok(Some(f1))
            }
            None => {
                if self.rate_too_low_for(self.band_hz.0) {
                    return Err(self.rate_too_low(self.band_hz.0));
                }
                Ok(None)
            }
        }
    }

    /// Step 2: locate f1 in the search band (the table's, limited by what the sample rate can
    /// carry), refuse it outside the band or with too short a record, and warn about a weak f1
    /// line or one without kinematic partners. Also returns the spectrum the search used.
    fn locate(
        &self,
        nominal: Option<f64>,
        warnings: &mut Vec<String>,
    ) -> Result<(f64, F1Detection, SearchSpectrum)> {
        let (x, fs) = (self.x, self.fs);
        let search = (
            self.band_hz.0,
            self.band_hz.1.min(0.999 * fs / (2.0 * self.top)),
        );
        // Length check against the most lenient f1 of the band (the exact check follows).
        self.check_length(search.1)?;
        let spectrum = SearchSpectrum::new(x, fs)?;
        let (f1, detection) = locate_f1(x, fs, &spectrum, self.gb, search, nominal)?;
        let omega1 = f1 / self.f_ref;
        // Refinement may move a peak found at the band edge a hair outside it.
        if self.outside_band(omega1, self.edge()) {
            return Err(self.out_of_band(f1, omega1));
        }
        self.check_length(f1)?;
        if detection.prominence_db < 10.0 {
            warnings.push(format!(
                "the f1 line at {f1:.2} Hz stands only {:.1} dB over the local floor",
                detection.prominence_db
            ));
        }
        if detection.method == "spectrum" && detection.partners_found.len() < 2 {
            warnings.push(format!(
                "tacho-less f1 = {f1:.2} Hz has only {} kinematic partner line(s) of this rig \
                 ({:?}); the record may come from another gearbox or f1 may be wrong",
                detection.partners_found.len(),
                detection.partners_found
            ));
        }
        Ok((f1, detection, spectrum))
    }

    /// Steps 3 and 4 at one f1: measure the lines, clip the features, the posterior over
    /// `(ea, Ω1)` and the χ² at its mode.
    fn evaluate(&self, matcher: &Matcher, opts: &DiagnoseOptions, f1: f64) -> Result<Evaluation> {
        let meas = measure_lines(self.x, self.fs, f1, &self.ratios)?;
        let mut raw = meas.features(self.lines);
        if let Some(shift) = self.shift {
            raw.iter_mut().zip(shift).for_each(|(v, d)| *v -= d);
        }
        let y = matcher.clip(&raw);
        let post = posterior(matcher, &y, f1 / self.f_ref, opts);
        let (chi2, _) = matcher.chi2(&y, post.mode(), post.omega_mean, opts);
        Ok(Evaluation {
            meas,
            y,
            post,
            chi2,
        })
    }

    /// Tacho-less and the model explains the record worse than it explains its own
    /// simulations: maybe the wrong peak won (a harmonic or subharmonic of f1). Try the other
    /// spectral candidates and keep the one the model explains best: `ev`, `detection` and a
    /// warning are updated when one is chosen. Returns the f1 kept.
    fn reselect_f1(
        &self,
        matcher: &Matcher,
        opts: &DiagnoseOptions,
        f1: f64,
        detection: &mut F1Detection,
        ev: &mut Evaluation,
        warnings: &mut Vec<String>,
    ) -> f64 {
        let (x, fs) = (self.x, self.fs);
        let nfeat = matcher.wear_features.len();
        let df = fs / x.len().min(1 << 17) as f64;
        let first = ev.chi2;
        let mut chosen = None;
        for &(cand, _, _) in detection.candidates.iter() {
            if (cand - detection.initial_hz).abs() < 0.5 * df {
                continue;
            }
            let fc = refine_near(x, fs, cand, 1.5 * df);
            if self.outside_band(fc / self.f_ref, self.edge())
                || self.check_length(fc).is_err()
                || self.rate_too_low_for(fc)
            {
                continue;
            }
            // Switch only to a candidate the model actually explains: when every candidate
            // fits badly the record is not this gearbox's, and the spectral choice stands.
            if let Ok(r) = self.evaluate(matcher, opts, fc)
                && r.chi2 < ev.chi2
                && r.chi2 <= opts.max_chi2_per_feature * nfeat as f64
            {
                *ev = r;
                chosen = Some((cand, fc));
            }
        }
        let Some((cand, fc)) = chosen else {
            return f1;
        };
        warnings.push(format!(
            "tacho-less f1 re-selected by model fit: the strongest candidate {f1:.2} Hz gave \
             χ² {first:.1}, the candidate {cand:.2} Hz (refined {fc:.2} Hz) gives {:.1}",
            ev.chi2
        ));
        detection.method = "spectrum, re-selected by model fit";
        detection.initial_hz = cand;
        fc
    }

    /// Step 6: the condition indicators, every model line but f1 and 2f1 counted as "other".
    fn condition_indicators(&self, f1: f64, shaft: f64) -> Result<ConditionIndicators> {
        let other: Vec<f64> = self
            .lines
            .iter()
            .filter(|l| l.name != "f1" && l.name != "2f1")
            .map(|l| l.ratio * f1)
            .collect();
        condition_indicators(self.x, self.fs, f1, shaft, &other)
    }
}

/// The fit at the best table point. A poor one flattens the likelihood (Birge-ratio
/// inflation: every variance scaled by χ²/D so the interval reflects the misfit instead of the
/// then meaningless nominal spread), recomputes `ev.post` and warns.
fn fit_and_inflate(
    matcher: &Matcher,
    opts: &DiagnoseOptions,
    ev: &mut Evaluation,
    omega1: f64,
    warnings: &mut Vec<String>,
) -> Fit {
    let nfeat = matcher.wear_features.len();
    let fit = Fit {
        chi2: ev.chi2,
        features: nfeat,
        chi2_per_feature: ev.chi2 / nfeat.max(1) as f64,
        inflated: fit_is_poor(ev.chi2 / nfeat.max(1) as f64, opts),
    };
    if fit.inflated {
        let inflated = DiagnoseOptions {
            temperature: opts.temperature * fit.chi2_per_feature,
            ..opts.clone()
        };
        ev.post = posterior(matcher, &ev.y, omega1, &inflated);
        warnings.push(format!(
            "poor fit: χ² per feature {:.1} at the best table point (threshold {}); the record \
             does not look like this model's output (another gearbox, sensor or fault?). The \
             likelihood was flattened by that factor; treat the wear degree and the planetary \
             flag as unreliable",
            fit.chi2_per_feature, opts.max_chi2_per_feature
        ));
    }
    fit
}

/// Step 4, the answer: the posterior median, the credible interval at `level` and the mode.
fn wear_degree(post: &Posterior, level: f64) -> WearDegree {
    let c = level.clamp(0.0, 1.0);
    WearDegree {
        estimate: post.quantile(0.5),
        lower: post.quantile(0.5 * (1.0 - c)),
        upper: post.quantile(0.5 * (1.0 + c)),
        level: c,
        mode: post.mode(),
    }
}

/// The majority motion state of the table entry `(i_ea, i_om)` and the share of its seeds in
/// that state.
fn motion_state_at(table: &SignatureTable, i_ea: usize, i_om: usize) -> (String, f64) {
    let entry = table.entry(i_ea, i_om);
    let motion_state = entry.majority_motion();
    let share = entry.motion.iter().filter(|m| **m == motion_state).count() as f64
        / entry.motion.len().max(1) as f64;
    (motion_state, share)
}

/// The five entries of highest likelihood among the Ω1 columns next to `i_om`.
fn nearest_entries(
    table: &SignatureTable,
    matcher: &Matcher,
    y: &[f64],
    i_om: usize,
    opts: &DiagnoseOptions,
) -> Vec<NearEntry> {
    let mut near: Vec<NearEntry> = Vec::new();
    let no = table.grid.omega1.len();
    for j in i_om.saturating_sub(1)..(i_om + 2).min(no) {
        for i in 0..table.grid.ea.len() {
            let k = i * no + j;
            near.push(NearEntry {
                ea: table.grid.ea[i],
                omega1: table.grid.omega1[j],
                log_likelihood: matcher.entry_log_likelihood(y, k, opts),
                motion_state: table.entries[k].majority_motion(),
            });
        }
    }
    near.sort_by(|a, b| b.log_likelihood.total_cmp(&a.log_likelihood));
    near.truncate(5);
    near
}

/// Step 5: the z-score of the measured `ln(A_f3/A_f1)` against what the table expects at
/// `(ea, omega1)`.
fn planetary_check(
    matcher: &Matcher,
    y: &[f64],
    ea: f64,
    omega1: f64,
    opts: &DiagnoseOptions,
) -> Option<PlanetaryCheck> {
    let f3 = matcher.f3_feature?;
    let (m3, v3) = matcher.stats_at(f3, ea, omega1);
    let s3 = (v3 + opts.feature_sigma.powi(2)).sqrt();
    Some(PlanetaryCheck {
        f3_log_ratio: y[f3],
        expected: m3,
        sigma: s3,
        z: (y[f3] - m3) / s3,
        threshold: opts.planetary_z,
    })
}

/// Every measured line with its level re f1 and what the table expects at `(ea, omega1)`.
fn matched_lines(
    lines: &[LineDef],
    meas: &LineMeasurement,
    matcher: &Matcher,
    ea: f64,
    omega1: f64,
    f1: f64,
) -> Vec<MatchedLine> {
    let i1 = LineMeasurement::index(lines, "f1").unwrap_or(0);
    let a1 = meas.amplitudes[i1];
    let to_db = 20.0 / std::f64::consts::LN_10;
    lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let expected = feature_index(lines, &l.name).map(|d| {
                let (m, v) = matcher.stats_at(d, ea, omega1);
                (m * to_db, v.sqrt() * to_db)
            });
            MatchedLine {
                name: l.name.clone(),
                normalised_frequency: l.ratio,
                frequency_hz: l.ratio * f1,
                amplitude: meas.amplitudes[i],
                level_db: 20.0 * (meas.amplitudes[i] / a1).log10(),
                expected_db: if l.name == "f1" {
                    Some(0.0)
                } else {
                    expected.map(|e| e.0)
                },
                expected_std_db: if l.name == "f1" {
                    Some(0.0)
                } else {
                    expected.map(|e| e.1)
                },
            }
        })
        .collect()
}

/// The posterior density over ea on a 0.01 grid (per unit ea), rounded to 4 decimals.
fn coarse_density(post: &Posterior) -> Vec<(f64, f64)> {
    let step = post.ea.get(1).map(|e| e - post.ea[0]).unwrap_or(1.0);
    let per = ((0.01 / step).round() as usize).max(1);
    post.ea
        .chunks(per)
        .zip(post.p.chunks(per))
        .map(|(e, p)| {
            let mass: f64 = p.iter().sum();
            let round = |v: f64| (v * 1e4).round() / 1e4;
            (round(e[0]), round(mass / (step * p.len() as f64)))
        })
        .collect()
}

fn nearest(axis: &[f64], v: f64) -> usize {
    axis.iter()
        .enumerate()
        .min_by(|a, b| (a.1 - v).abs().total_cmp(&(b.1 - v).abs()))
        .map(|(i, _)| i)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The running median equals a fresh median of every window.
    #[test]
    fn local_floor_matches_per_window_median() {
        let mut s = 12345u64;
        let amp: Vec<f64> = (0..3001)
            .map(|i| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                // Repeated values too (ties).
                if i % 7 == 0 {
                    0.5
                } else {
                    (s >> 11) as f64 / (1u64 << 53) as f64
                }
            })
            .collect();
        for (half, stride) in [(100, 10), (3, 10), (50, 1)] {
            let got = local_floor(&amp, half, stride);
            let n = amp.len();
            let mut c = 0;
            while c < n {
                let mut w = amp[c.saturating_sub(half)..(c + half + 1).min(n)].to_vec();
                let mid = w.len() / 2;
                w.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
                assert_eq!(got[c], w[mid], "half {half} stride {stride} centre {c}");
                c += stride;
            }
        }
    }
}

#[cfg(test)]
mod likelihood_tests {
    use super::*;

    /// The grouped logarithm of [`Matcher::wear_log_likelihood`] against one ln per feature
    /// from [`Matcher::stats_at`], on the committed table, and with the table's variances
    /// scaled by 1e-50 (and feature σ 1e-60) so that the products of eight underflow and the
    /// per-feature fallback runs.
    #[test]
    fn grouped_log_likelihood_matches_per_feature_sum() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join("signatures")
            .join("model_a_accel.json");
        let table = SignatureTable::load(&path).expect("committed table");
        for sigma in [DiagnoseOptions::default().feature_sigma, 1e-60] {
            let opts = DiagnoseOptions {
                feature_sigma: sigma,
                ..DiagnoseOptions::default()
            };
            let mut m = Matcher::new(&table, &opts).unwrap();
            if sigma < 1e-30 {
                m.wear_var.iter_mut().for_each(|v| *v *= 1e-50);
                m.var.iter_mut().flatten().for_each(|v| *v *= 1e-50);
            }
            let k = m.mean.len() / 3;
            let y: Vec<f64> = m.mean[k].iter().map(|v| v + 0.05).collect();
            let y = m.clip(&y);
            let s0 = sigma * sigma;
            for (ea, om) in [
                (0.1, m.om[0]),
                (0.47, 0.5 * (m.om[0] + m.om[m.n_om - 1])),
                (1.0, m.om[m.n_om - 1]),
            ] {
                let direct: f64 = m
                    .wear_features
                    .iter()
                    .map(|&d| {
                        let (mu, v) = m.stats_at(d, ea, om);
                        let var = v + s0;
                        -0.5 * (y[d] - mu).powi(2) / var - 0.5 * var.ln()
                    })
                    .sum();
                let got = m.log_likelihood(
                    &y,
                    ea,
                    om,
                    &DiagnoseOptions {
                        temperature: 1.0,
                        ..opts.clone()
                    },
                );
                assert!(
                    (got - direct).abs() <= 1e-9 * direct.abs().max(1.0),
                    "σ {sigma}, ea {ea}: {got} vs {direct}"
                );
            }
        }
    }
}
