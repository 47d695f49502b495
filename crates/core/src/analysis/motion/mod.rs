//! Motion-state classification of a sampled nonlinear response.
//!
//! A response of the gear model is sampled once per stage-1 mesh period `T₁` (the stroboscopic
//! Poincaré section), giving points `(x, v)` = (displacement, velocity). The motion is then
//! labelled
//!
//! - **period-n** ([`MotionState::Periodic`]): the section consists of `n` clusters visited in
//!   turn, `P_{i+n} ≈ P_i`;
//! - **quasi-periodic** ([`MotionState::QuasiPeriodic`]): the section fills a closed curve (a
//!   torus cut), the motion is regular but never repeats;
//! - **chaotic** ([`MotionState::Chaotic`]): the section is a strange attractor, nearby
//!   trajectories separate exponentially.
//!
//! The excitation also contains mesh frequencies that are *not* harmonics of the stage-1 mesh
//! frequency (ratios 0.36 and 0.0875 in the paper rigs), so even an engineering "period-1"
//! response gives a small cloud or short curve on the section, never one exact point. All
//! tolerances are therefore relative to a caller-supplied `scale` = the size of the whole motion
//! (e.g. the peak-to-peak of the sampled time history), not to the Poincaré set itself.
//!
//! Tools:
//! - [`classify`]: the decision procedure (cluster extent → period detection → 0–1 test);
//! - [`detect_period`]: smallest `n` with `P_{i+n} ≈ P_i` for almost all `i`;
//! - [`zero_one_test`]: the Gottwald–Melbourne 0–1 test for chaos (correlation method);
//! - [`largest_lyapunov`]: Benettin's two-trajectory estimate of the largest Lyapunov exponent.
//!
//! References:
//! - G. A. Gottwald, I. Melbourne, "A new test for chaos in deterministic systems",
//!   Proc. R. Soc. Lond. A 460 (2004) 603–611.
//! - G. A. Gottwald, I. Melbourne, "On the implementation of the 0–1 test for chaos",
//!   SIAM J. Appl. Dyn. Syst. 8 (2009) 129–145.
//! - G. Benettin, L. Galgani, A. Giorgilli, J.-M. Strelcyn, "Lyapunov characteristic exponents
//!   for smooth dynamical systems and for Hamiltonian systems; a method for computing all of
//!   them", Meccanica 15 (1980) 9–20 and 21–30.

mod lyapunov;
mod zero_one;

use std::fmt;

use crate::signal::median;
use crate::{Error, Result};

pub use self::lyapunov::largest_lyapunov;
pub use self::zero_one::zero_one_test;

/// Fraction of points allowed to violate the periodicity criterion (start-up transients,
/// isolated grazing impacts).
const OUTLIER_FRACTION: f64 = 0.05;
/// Upper bound on the reported number of clusters.
pub const CLUSTER_CAP: usize = 100;
/// Minimum series length of the 0–1 test.
pub const MIN_01_LEN: usize = 50;
/// Median nearest-neighbour expansion ratio of the section map above which the geometric
/// criterion calls a section chaotic (a rotation on a curve gives ≈ 1.0–1.15; the logistic map
/// gives 1.3 at r = 3.6, 2.1 at r = 4).
const GEOMETRIC_EXPANSION_THRESHOLD: f64 = 1.25;
/// Below this many points the 0–1 test alone is not trusted to call chaos (see [`classify`]).
pub const RELIABLE_01_LEN: usize = 500;

/// Qualitative state of a (sampled) motion.
///
/// Serialised with an internal tag, e.g. `{"kind":"periodic","period":2}`,
/// `{"kind":"quasi-periodic"}`, `{"kind":"chaotic"}`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum MotionState {
    /// `period` clusters on the Poincaré section, visited in turn (period-`period` motion,
    /// i.e. the response repeats after `period` forcing periods).
    Periodic {
        /// Number of forcing periods after which the motion repeats (≥ 1).
        period: usize,
    },
    /// Regular but non-repeating motion: the section fills a closed curve.
    QuasiPeriodic,
    /// Chaotic motion: the section is a strange attractor.
    Chaotic,
}

impl MotionState {
    /// Short human label: `"period-1"`, `"period-3"`, `"quasi-periodic"`, `"chaotic"`.
    pub fn label(&self) -> String {
        match self {
            MotionState::Periodic { period } => format!("period-{period}"),
            MotionState::QuasiPeriodic => "quasi-periodic".to_string(),
            MotionState::Chaotic => "chaotic".to_string(),
        }
    }
}

impl fmt::Display for MotionState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.label())
    }
}

/// Tuning of [`classify`].
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ClassifyOptions {
    /// Cluster tolerance relative to the attractor scale (per coordinate): two section points
    /// are "the same" when `|Δx| ≤ rel_tol·scale.0` and `|Δv| ≤ rel_tol·scale.1`. Default 0.02.
    pub rel_tol: f64,
    /// Largest period looked for; longer periodic orbits are reported as quasi-periodic or
    /// chaotic. Default 8.
    pub max_period: usize,
    /// The motion is called chaotic when the 0–1 test statistic `K` exceeds this. Default 0.5.
    pub chaos_threshold: f64,
}

impl Default for ClassifyOptions {
    fn default() -> Self {
        ClassifyOptions {
            rel_tol: 0.02,
            max_period: 8,
            chaos_threshold: 0.5,
        }
    }
}

/// Result of [`classify`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct Classification {
    /// The motion state.
    pub state: MotionState,
    /// 0–1 test statistic `K` when it was computed (non-periodic sections of at least
    /// [`MIN_01_LEN`] points).
    pub k_01: Option<f64>,
    /// Diameter of the Poincaré set relative to the scale: `max(range(x)/scale.0,
    /// range(v)/scale.1)`.
    pub spread: f64,
    /// Number of distinct clusters (greedy leader clustering with radius `rel_tol` in scaled
    /// coordinates, max-norm), capped at [`CLUSTER_CAP`].
    pub clusters: usize,
    /// Largest Lyapunov exponent per forcing period `λ T`, when one was supplied
    /// ([`classify_with_lyapunov`]).
    pub lyapunov_per_period: Option<f64>,
}

/// Classify a motion from its Poincaré points (one per forcing period).
///
/// `scale = (sx, sv)` is the typical size of the full motion in each coordinate (e.g. the
/// peak-to-peak of the sampled time history of `x` and of `v`); all tolerances are relative to
/// it, so a period-1 response whose section is a small cloud (incommensurate excitation
/// components) is still period-1.
///
/// Decision procedure, on the scaled points `(x/sx, v/sv)`:
/// 1. **Periodic**: the smallest `n ≤ max_period` such that (a) the [`detect_period`] pair
///    criterion holds (`P_i`, `P_{i+n}` within `rel_tol` for ≥ 95 % of `i`) and (b) every phase
///    class `{P_{r+kn}}` (`r = 0..n`) has an extent ≤ `rel_tol` per coordinate after trimming
///    2.5 % of its values at each end. Condition (b) rejects slow drifts (e.g. a slowly
///    rotating quasi-periodic section) whose consecutive points are close but which do not
///    return. For `n = 1` this is "the set's diameter is below `rel_tol`".
/// 2. Otherwise, with at least [`MIN_01_LEN`] points: the 0–1 test ([`zero_one_test`]) on the
///    coordinate with the larger relative spread; `K > chaos_threshold` → chaotic, else
///    quasi-periodic.
/// 3. The geometric criterion: the median expansion ratio of nearest neighbours under the
///    section map, `|P_{i+1} − P_{j+1}| / |P_i − P_j|` with `P_j` the nearest neighbour of
///    `P_i`; > 1.25 → chaotic (a quasi-periodic section map on a curve is conjugate to a
///    rotation and does not expand distances on average). It decides alone below
///    [`MIN_01_LEN`] points, and below [`RELIABLE_01_LEN`] points it must agree with the 0–1
///    test to call chaos: with only `N/10 < 50` lags the 0–1 test resolves frequencies to about
///    `±3/(N/10)` rad, so the harmonics of a quasi-periodic curve resonate with most `c` and
///    give `K ≈ 0.9` (observed for a 3-harmonic golden-mean curve up to `N = 200`).
///
/// For a dependable chaotic / quasi-periodic verdict collect at least [`RELIABLE_01_LEN`]
/// section points; two-frequency (torus) sections are only separated from chaos by the 0–1
/// test and need that many.
///
/// Errors ([`Error::TooFewSamples`], [`Error::NonFiniteValue`], [`Error::InvalidParameter`]): fewer than 2 points, a
/// non-finite point, a non-finite or non-positive scale component, invalid options.
pub fn classify(
    points: &[(f64, f64)],
    scale: (f64, f64),
    opts: &ClassifyOptions,
) -> Result<Classification> {
    validate_options(opts)?;
    validate_scale(scale)?;
    if points.len() < 2 {
        return Err(Error::TooFewSamples {
            analysis: "motion classification (Poincaré points)",
            needed: 2,
            samples: points.len(),
        });
    }
    if let Some(i) = points
        .iter()
        .position(|&(x, v)| !x.is_finite() || !v.is_finite())
    {
        return Err(Error::NonFiniteValue {
            analysis: "motion classification",
            what: format!("Poincaré point {i} {:?}", points[i]),
        });
    }
    let scaled: Vec<(f64, f64)> = points
        .iter()
        .map(|&(x, v)| (x / scale.0, v / scale.1))
        .collect();
    let (rx, rv) = ranges(&scaled);
    let spread = rx.max(rv);
    let clusters = count_clusters(&scaled, opts.rel_tol);

    let period = (1..=opts.max_period).find(|&n| {
        pair_criterion(&scaled, n, opts.rel_tol) && class_extent_ok(&scaled, n, opts.rel_tol)
    });
    if let Some(period) = period {
        return Ok(Classification {
            state: MotionState::Periodic { period },
            k_01: None,
            spread,
            clusters,
            lyapunov_per_period: None,
        });
    }

    if scaled.len() >= MIN_01_LEN {
        let series: Vec<f64> = if rx >= rv {
            scaled.iter().map(|p| p.0).collect()
        } else {
            scaled.iter().map(|p| p.1).collect()
        };
        let k = zero_one_test(&series)?;
        let chaotic = k > opts.chaos_threshold
            && (scaled.len() >= RELIABLE_01_LEN
                || neighbour_expansion(&scaled)
                    .is_none_or(|ratio| ratio > GEOMETRIC_EXPANSION_THRESHOLD));
        let state = if chaotic {
            MotionState::Chaotic
        } else {
            MotionState::QuasiPeriodic
        };
        return Ok(Classification {
            state,
            k_01: Some(k),
            spread,
            clusters,
            lyapunov_per_period: None,
        });
    }

    let state = match neighbour_expansion(&scaled) {
        Some(ratio) if ratio > GEOMETRIC_EXPANSION_THRESHOLD => MotionState::Chaotic,
        _ => MotionState::QuasiPeriodic,
    };
    Ok(Classification {
        lyapunov_per_period: None,
        state,
        k_01: None,
        spread,
        clusters,
    })
}

/// Largest Lyapunov exponent per forcing period above which a motion is called chaotic.
///
/// Numerical noise on a stable (forcing-locked) attractor gives clearly negative values
/// (about `−2π ξ ω / Ω` for the weakest-damped mode); a torus born of a Hopf bifurcation gives
/// ≈ 0. A margin of 0.02 per period (2 % growth) keeps both on the regular side.
pub const LYAPUNOV_CHAOS_THRESHOLD: f64 = 0.02;

/// Classify with a measured largest Lyapunov exponent per forcing period `λ T` (see
/// [`crate::analysis::simulate::observe`]). This is the reliable test for gear models whose
/// other mesh frequencies are not harmonics of the sampled one: their Poincaré set of a
/// perfectly regular response is a curve or a band, which short-series geometric tests can
/// mistake for chaos. `λ T > LYAPUNOV_CHAOS_THRESHOLD` → chaotic; otherwise the geometric
/// classification decides between period-n and quasi-periodic (never chaotic).
pub fn classify_with_lyapunov(
    points: &[(f64, f64)],
    scale: (f64, f64),
    lyapunov_per_period: f64,
    opts: &ClassifyOptions,
) -> Result<Classification> {
    if !lyapunov_per_period.is_finite() {
        return Err(Error::NonFiniteValue {
            analysis: "motion classification",
            what: format!("the Lyapunov exponent ({lyapunov_per_period})"),
        });
    }
    let mut c = classify(points, scale, opts)?;
    c.lyapunov_per_period = Some(lyapunov_per_period);
    c.state = if lyapunov_per_period > LYAPUNOV_CHAOS_THRESHOLD {
        MotionState::Chaotic
    } else {
        match c.state {
            MotionState::Chaotic => MotionState::QuasiPeriodic,
            other => other,
        }
    };
    Ok(c)
}

/// Harmonics of each other forcing phase used by [`classify_forced`].
const FORCED_HARMONICS: usize = 3;

/// Classify a response of a system forced at several frequencies, sampled once per period of
/// the first one (for Model A: once per stage-1 mesh period, with stage 2 and the planetary
/// stage at `other_ratios = [0.36, 0.0875]` of it).
///
/// A response locked to the forcing is a function of the forcing phases, so its Poincaré
/// points are not one point but `x_k = g(φ_2(k), φ_3(k), …)` with `φ_i(k) = frac(r_i k)`: a
/// curve or a band. This classifier therefore:
/// 1. calls the motion chaotic when the largest Lyapunov exponent per period exceeds
///    [`LYAPUNOV_CHAOS_THRESHOLD`];
/// 2. otherwise looks for the smallest `n ≤ max_period` such that, within each residue class
///    `k mod n`, the points are explained by a smooth periodic function of the other phases
///    (a least-squares Fourier series with [`FORCED_HARMONICS`] harmonics of each phase) to
///    within `rel_tol` of the motion's scale (RMS residual, both coordinates): that is
///    **period-n** — `n` stage-1 periods, modulated by the other meshes;
/// 3. otherwise **quasi-periodic** (a frequency of its own, e.g. a torus after a Hopf
///    bifurcation).
///
/// Each class needs at least twice as many points as regressors; larger `n` are skipped when
/// the series is too short.
pub fn classify_forced(
    points: &[(f64, f64)],
    scale: (f64, f64),
    lyapunov_per_period: f64,
    other_ratios: &[f64],
    opts: &ClassifyOptions,
) -> Result<Classification> {
    let mut c = classify_with_lyapunov(points, scale, lyapunov_per_period, opts)?;
    if c.state == MotionState::Chaotic {
        return Ok(c);
    }
    let n_reg = 1 + 2 * FORCED_HARMONICS * other_ratios.len();
    for n in 1..=opts.max_period {
        let mut ok = true;
        let mut enough = true;
        for class in 0..n {
            let idx: Vec<usize> = (class..points.len()).step_by(n).collect();
            if idx.len() < 2 * n_reg {
                enough = false;
                break;
            }
            let design = nalgebra::DMatrix::from_fn(idx.len(), n_reg, |row, col| {
                if col == 0 {
                    return 1.0;
                }
                let c0 = col - 1;
                let (which, rest) = (c0 / (2 * FORCED_HARMONICS), c0 % (2 * FORCED_HARMONICS));
                let (h, is_sin) = (rest / 2 + 1, rest % 2 == 0);
                let phase = std::f64::consts::TAU
                    * h as f64
                    * (other_ratios[which] * idx[row] as f64).fract();
                if is_sin { phase.sin() } else { phase.cos() }
            });
            let svd = design.clone().svd(true, true);
            for (coord, sc) in [(0usize, scale.0), (1usize, scale.1)] {
                let y = nalgebra::DVector::from_iterator(
                    idx.len(),
                    idx.iter()
                        .map(|&k| if coord == 0 { points[k].0 } else { points[k].1 }),
                );
                let Ok(beta) = svd.solve(&y, 1e-10) else {
                    ok = false;
                    break;
                };
                let resid = &y - &design * beta;
                let rms = (resid.norm_squared() / idx.len() as f64).sqrt();
                if rms > opts.rel_tol * sc {
                    ok = false;
                    break;
                }
            }
            if !ok {
                break;
            }
        }
        if !enough {
            break;
        }
        if ok {
            c.state = MotionState::Periodic { period: n };
            return Ok(c);
        }
    }
    if let MotionState::Periodic { .. } = c.state {
        // The plain geometric test found a period the forced fit could not confirm only when
        // the series was too short for the fit: keep it.
        return Ok(c);
    }
    c.state = MotionState::QuasiPeriodic;
    Ok(c)
}

/// Period detection on a Poincaré sequence.
///
/// Returns the smallest `n ≤ max_period` such that `|x_i − x_{i+n}| ≤ rel_tol·scale.0` and
/// `|v_i − v_{i+n}| ≤ rel_tol·scale.1` for at least 95 % of the pairs `i` (5 % outliers
/// allowed). A candidate `n` needs at least `2n` points (every phase compared at least once).
/// `None` if there is no such `n`, or if the input is unusable (non-positive or non-finite
/// scale or tolerance; non-finite points never match).
///
/// This pair criterion alone accepts a slow drift whose consecutive points are close;
/// [`classify`] adds a cluster-extent check.
pub fn detect_period(
    points: &[(f64, f64)],
    scale: (f64, f64),
    rel_tol: f64,
    max_period: usize,
) -> Option<usize> {
    if validate_scale(scale).is_err() || !(rel_tol.is_finite() && rel_tol > 0.0) {
        return None;
    }
    let scaled: Vec<(f64, f64)> = points
        .iter()
        .map(|&(x, v)| (x / scale.0, v / scale.1))
        .collect();
    (1..=max_period).find(|&n| pair_criterion(&scaled, n, rel_tol))
}

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

fn validate_scale(scale: (f64, f64)) -> Result<()> {
    for (name, v) in [("scale.x", scale.0), ("scale.v", scale.1)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::param(
                name,
                v,
                "motion scale must be finite and > 0 (a motion of zero size cannot be classified)",
            ));
        }
    }
    Ok(())
}

fn validate_options(opts: &ClassifyOptions) -> Result<()> {
    if !(opts.rel_tol.is_finite() && opts.rel_tol > 0.0) {
        return Err(Error::param(
            "rel_tol",
            opts.rel_tol,
            "must be finite and > 0",
        ));
    }
    if opts.max_period == 0 {
        return Err(Error::param("max_period", 0.0, "must be at least 1"));
    }
    if !opts.chaos_threshold.is_finite() {
        return Err(Error::param(
            "chaos_threshold",
            opts.chaos_threshold,
            "must be finite",
        ));
    }
    Ok(())
}

/// Ranges of the two coordinates.
fn ranges(points: &[(f64, f64)]) -> (f64, f64) {
    let mut b = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for &(x, v) in points {
        b[0] = b[0].min(x);
        b[1] = b[1].max(x);
        b[2] = b[2].min(v);
        b[3] = b[3].max(v);
    }
    if points.is_empty() {
        (0.0, 0.0)
    } else {
        (b[1] - b[0], b[3] - b[2])
    }
}

/// `P_i` and `P_{i+n}` within `tol` (max-norm, scaled points) for ≥ 95 % of the pairs; needs
/// `len ≥ 2n`.
fn pair_criterion(scaled: &[(f64, f64)], n: usize, tol: f64) -> bool {
    if n == 0 || scaled.len() < 2 * n {
        return false;
    }
    let pairs = scaled.len() - n;
    let bad = scaled
        .iter()
        .zip(&scaled[n..])
        .filter(|(a, b)| !((a.0 - b.0).abs() <= tol && (a.1 - b.1).abs() <= tol))
        .count();
    (bad as f64) <= OUTLIER_FRACTION * pairs as f64
}

/// Every phase class `{P_{r+kn}}` has a trimmed extent (2.5 % of the values cut at each end,
/// per coordinate) of at most `tol`.
fn class_extent_ok(scaled: &[(f64, f64)], n: usize, tol: f64) -> bool {
    let mut xs = Vec::with_capacity(scaled.len() / n + 1);
    let mut vs = Vec::with_capacity(scaled.len() / n + 1);
    (0..n).all(|r| {
        xs.clear();
        vs.clear();
        for p in scaled.iter().skip(r).step_by(n) {
            xs.push(p.0);
            vs.push(p.1);
        }
        trimmed_extent(&mut xs) <= tol && trimmed_extent(&mut vs) <= tol
    })
}

fn trimmed_extent(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let cut = (0.5 * OUTLIER_FRACTION * values.len() as f64).floor() as usize;
    values[values.len() - 1 - cut] - values[cut]
}

/// Greedy leader clustering in the max-norm with radius `tol`, capped at [`CLUSTER_CAP`].
fn count_clusters(scaled: &[(f64, f64)], tol: f64) -> usize {
    let mut leaders: Vec<(f64, f64)> = Vec::new();
    for &p in scaled {
        let known = leaders
            .iter()
            .any(|l| (l.0 - p.0).abs() <= tol && (l.1 - p.1).abs() <= tol);
        if !known {
            leaders.push(p);
            if leaders.len() >= CLUSTER_CAP {
                break;
            }
        }
    }
    leaders.len()
}

/// Median over `i` of `|P_{i+1} − P_{j+1}| / |P_i − P_j|`, `P_j` the nearest neighbour of `P_i`
/// (among points with a successor, distinct position). `None` with too few usable pairs.
fn neighbour_expansion(scaled: &[(f64, f64)]) -> Option<f64> {
    let dist = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
    let m = scaled.len().checked_sub(1)?;
    let mut ratios = Vec::with_capacity(m);
    for i in 0..m {
        let mut best: Option<(usize, f64)> = None;
        for j in 0..m {
            if j == i {
                continue;
            }
            let d = dist(scaled[i], scaled[j]);
            if d > 0.0 && best.is_none_or(|(_, bd)| d < bd) {
                best = Some((j, d));
            }
        }
        if let Some((j, d)) = best {
            ratios.push(dist(scaled[i + 1], scaled[j + 1]) / d);
        }
    }
    if ratios.len() < 3 {
        return None;
    }
    Some(median(&mut ratios))
}

#[cfg(test)]
mod tests;
