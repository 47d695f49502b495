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

use std::f64::consts::PI;
use std::fmt;

use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;

use crate::signal::median;
use crate::{Error, Result};

/// Fraction of points allowed to violate the periodicity criterion (start-up transients,
/// isolated grazing impacts).
const OUTLIER_FRACTION: f64 = 0.05;
/// Upper bound on the reported number of clusters.
pub const CLUSTER_CAP: usize = 100;
/// Minimum series length of the 0–1 test.
pub const MIN_01_LEN: usize = 50;
/// Number of random frequencies `c` of the 0–1 test.
const N_C: usize = 100;
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
/// Errors ([`Error::Signal`] / [`Error::InvalidParameter`]): fewer than 2 points, a
/// non-finite point, a non-finite or non-positive scale component, invalid options.
pub fn classify(
    points: &[(f64, f64)],
    scale: (f64, f64),
    opts: &ClassifyOptions,
) -> Result<Classification> {
    validate_options(opts)?;
    validate_scale(scale)?;
    if points.len() < 2 {
        return Err(Error::Signal(format!(
            "motion classification needs at least 2 Poincaré points, got {}",
            points.len()
        )));
    }
    if let Some(i) = points
        .iter()
        .position(|&(x, v)| !x.is_finite() || !v.is_finite())
    {
        return Err(Error::Signal(format!(
            "non-finite Poincaré point at index {i}: {:?}",
            points[i]
        )));
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
        return Err(Error::Signal(format!(
            "Lyapunov exponent must be finite, got {lyapunov_per_period}"
        )));
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

/// Gottwald–Melbourne 0–1 test for chaos, correlation method (Gottwald & Melbourne 2009).
///
/// For samples `φ(j)`, `j = 1..N`, and a frequency `c ∈ (π/5, 4π/5)`, the translation
/// variables are `p_c(n) = Σ_{j≤n} φ(j) cos(jc)`, `q_c(n) = Σ_{j≤n} φ(j) sin(jc)`. Their
/// mean-square displacement, with the oscillatory term subtracted, is
///
/// `D_c(n) = 1/(N−n) Σ_{j=1}^{N−n} [(p_c(j+n) − p_c(j))² + (q_c(j+n) − q_c(j))²]
///           − (Eφ)² (1 − cos nc)/(1 − cos c)`,  `n = 1..N/10`,
///
/// which is bounded for regular (periodic or quasi-periodic) dynamics and grows linearly in `n`
/// for chaotic dynamics. `K_c = corr(n, D_c(n))` and `K = median_c K_c` over 100 values of
/// `c` drawn from a fixed-seed linear congruential generator (the median suppresses the rare
/// resonant `c`). `K ≈ 0`: regular; `K ≈ 1`: chaotic; the range is about `[−0.1, 1]`.
///
/// Oversampling guard (as the 2009 paper warns, oversampled data of a flow make a chaotic
/// signal look regular on the time scale `N/10`): if the autocorrelation of `φ` first crosses
/// zero at lag `τ ≥ 4`, the series is subsampled with step `⌊τ/2⌋` (keeping at least 100
/// samples, or all if fewer). Poincaré data (one sample per forcing period) is normally left
/// untouched.
///
/// A constant series (no fluctuation above round-off) gives `K = 0`.
/// The mean-square displacement is evaluated for all `n` at once with an FFT autocorrelation
/// of `z = p + iq`, so the cost is `O(N log N)` per `c`.
///
/// Errors: [`Error::Signal`] for `N < 50` or a non-finite sample.
pub fn zero_one_test(series: &[f64]) -> Result<f64> {
    if series.len() < MIN_01_LEN {
        return Err(Error::Signal(format!(
            "0-1 test needs at least {MIN_01_LEN} samples, got {}",
            series.len()
        )));
    }
    if let Some(i) = series.iter().position(|s| !s.is_finite()) {
        return Err(Error::Signal(format!(
            "0-1 test: non-finite sample at index {i}"
        )));
    }
    let (lo, hi) = series
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &s| {
            (lo.min(s), hi.max(s))
        });
    let magnitude = lo.abs().max(hi.abs());
    if hi - lo <= 1e-12 * magnitude || hi == lo {
        return Ok(0.0);
    }

    let step = oversampling_step(series);
    let phi: Vec<f64> = series.iter().step_by(step).copied().collect();
    let n = phi.len();
    let ncut = n / 10;
    let mean = phi.iter().sum::<f64>() / n as f64;

    let len = (n + ncut).next_power_of_two();
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(len);
    let inv = planner.plan_fft_inverse(len);
    let mut buf = vec![Complex64::new(0.0, 0.0); len];
    let mut scratch = vec![
        Complex64::new(0.0, 0.0);
        fwd.get_inplace_scratch_len()
            .max(inv.get_inplace_scratch_len())
    ];
    let mut z = vec![Complex64::new(0.0, 0.0); n];
    let mut prefix = vec![0.0; n + 1];
    let mut d = vec![0.0; ncut];

    // Regressor ξ = 1..ncut: mean and centred sum of squares.
    let xi_mean = (ncut as f64 + 1.0) / 2.0;
    let xi_ss: f64 = (1..=ncut).map(|k| (k as f64 - xi_mean).powi(2)).sum();

    let mut rng = Lcg::new(0x0017_E57C_4A05);
    let mut kc = Vec::with_capacity(N_C);
    for _ in 0..N_C {
        let c = PI / 5.0 + rng.next_f64() * (3.0 * PI / 5.0);
        // z(j) = Σ_{i≤j} φ(i) e^{ic}, j = 1..N (stored at index j−1).
        let mut acc = Complex64::new(0.0, 0.0);
        for (j, (&f, zj)) in phi.iter().zip(z.iter_mut()).enumerate() {
            let ang = (j + 1) as f64 * c;
            acc += Complex64::new(f * ang.cos(), f * ang.sin());
            *zj = acc;
        }
        for (j, zj) in z.iter().enumerate() {
            prefix[j + 1] = prefix[j] + zj.norm_sqr();
        }
        // Autocorrelation R(m) = Σ_k z[k+m] conj(z[k]) via zero-padded FFT.
        buf[..n].copy_from_slice(&z);
        buf[n..]
            .iter_mut()
            .for_each(|b| *b = Complex64::new(0.0, 0.0));
        fwd.process_with_scratch(&mut buf, &mut scratch);
        buf.iter_mut()
            .for_each(|b| *b = Complex64::new(b.norm_sqr(), 0.0));
        inv.process_with_scratch(&mut buf, &mut scratch);
        let osc_den = 1.0 - c.cos();
        for (m, dm) in (1..=ncut).zip(d.iter_mut()) {
            let tail = prefix[n] - prefix[m]; // Σ_{k=m}^{N−1} |z_k|²
            let head = prefix[n - m]; // Σ_{k=0}^{N−1−m} |z_k|²
            let cross = buf[m].re / len as f64;
            let msd = (tail + head - 2.0 * cross) / (n - m) as f64;
            let v_osc = mean * mean * (1.0 - (m as f64 * c).cos()) / osc_den;
            *dm = msd - v_osc;
        }
        kc.push(correlation_with_index(&d, xi_mean, xi_ss));
    }
    Ok(median(&mut kc))
}

/// Largest Lyapunov exponent by Benettin's two-trajectory renormalisation method.
///
/// A reference trajectory starting at `x0` is first advanced by `transient_intervals`
/// intervals (to settle on the attractor). A companion trajectory is then started at distance
/// `d0` (Euclidean, along `(1, …, 1)/√dim`). Both are advanced by `interval`; the separation
/// `d_k` is measured, `ln(d_k/d0)` accumulated, and the companion is pulled back to distance
/// `d0` along the current separation. After `n_intervals` intervals
///
/// `λ ≈ Σ_k ln(d_k/d0) / (n_intervals · interval)`,
///
/// in units of 1/(independent variable). `d0` must be small enough for the linearisation
/// (e.g. `1e-8` relative to the state size) and `interval` short enough that `d0·e^{λ·interval}`
/// stays small.
///
/// `advance(state, duration)` integrates `state` in place by `duration`; its errors are
/// propagated.
///
/// Errors: empty or non-finite `x0`, non-positive or non-finite `d0`/`interval`,
/// `n_intervals == 0`, or a separation that becomes zero or non-finite ([`Error::Signal`]).
pub fn largest_lyapunov<F>(
    x0: &[f64],
    d0: f64,
    interval: f64,
    n_intervals: usize,
    transient_intervals: usize,
    mut advance: F,
) -> Result<f64>
where
    F: FnMut(&mut [f64], f64) -> Result<()>,
{
    if x0.is_empty() {
        return Err(Error::Signal("Lyapunov exponent: empty state".into()));
    }
    if x0.iter().any(|v| !v.is_finite()) {
        return Err(Error::Signal(
            "Lyapunov exponent: non-finite initial state".into(),
        ));
    }
    if !(d0.is_finite() && d0 > 0.0) {
        return Err(Error::param("d0", d0, "must be finite and > 0"));
    }
    if !(interval.is_finite() && interval > 0.0) {
        return Err(Error::param("interval", interval, "must be finite and > 0"));
    }
    if n_intervals == 0 {
        return Err(Error::param("n_intervals", 0.0, "must be at least 1"));
    }
    let dim = x0.len();
    let mut x = x0.to_vec();
    for _ in 0..transient_intervals {
        advance(&mut x, interval)?;
    }
    let offset = d0 / (dim as f64).sqrt();
    let mut y: Vec<f64> = x.iter().map(|v| v + offset).collect();
    let mut sum_log = 0.0;
    for k in 0..n_intervals {
        advance(&mut x, interval)?;
        advance(&mut y, interval)?;
        let dist = x
            .iter()
            .zip(&y)
            .map(|(a, b)| (b - a).powi(2))
            .sum::<f64>()
            .sqrt();
        if !dist.is_finite() || dist == 0.0 {
            return Err(Error::Signal(format!(
                "Lyapunov exponent: separation became {dist} in interval {k}"
            )));
        }
        sum_log += (dist / d0).ln();
        let s = d0 / dist;
        for (yi, xi) in y.iter_mut().zip(&x) {
            *yi = xi + (*yi - xi) * s;
        }
    }
    Ok(sum_log / (n_intervals as f64 * interval))
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

/// Subsampling step of the 0–1 test's oversampling guard: `⌊τ/2⌋` for a first zero crossing
/// of the autocorrelation at lag `τ ≥ 4`, limited so at least 100 samples remain.
fn oversampling_step(series: &[f64]) -> usize {
    let n = series.len();
    let mean = series.iter().sum::<f64>() / n as f64;
    let var: f64 = series.iter().map(|s| (s - mean).powi(2)).sum();
    if var == 0.0 {
        return 1;
    }
    let max_lag = n / 4;
    let mut tau = max_lag;
    for lag in 1..=max_lag {
        let r: f64 = series
            .iter()
            .zip(&series[lag..])
            .map(|(a, b)| (a - mean) * (b - mean))
            .sum();
        if r <= 0.0 {
            tau = lag;
            break;
        }
    }
    let step = (tau / 2).max(1);
    if tau < 4 {
        return 1;
    }
    let max_step = (n / 100).max(1);
    step.min(max_step)
}

/// Pearson correlation of `d[k]` with `ξ = k + 1`; 0 if `d` has no variance.
fn correlation_with_index(d: &[f64], xi_mean: f64, xi_ss: f64) -> f64 {
    let n = d.len() as f64;
    let d_mean = d.iter().sum::<f64>() / n;
    let mut cov = 0.0;
    let mut d_ss = 0.0;
    for (k, &v) in d.iter().enumerate() {
        let dx = (k + 1) as f64 - xi_mean;
        let dd = v - d_mean;
        cov += dx * dd;
        d_ss += dd * dd;
    }
    if d_ss <= 0.0 || xi_ss <= 0.0 || !d_ss.is_finite() {
        return 0.0;
    }
    cov / (xi_ss * d_ss).sqrt()
}

/// 64-bit linear congruential generator (Knuth's MMIX constants); deterministic, good enough
/// for drawing the test frequencies `c`.
struct Lcg(u64);

impl Lcg {
    fn new(seed: u64) -> Self {
        Lcg(seed)
    }

    /// Uniform in `[0, 1)` from the top 53 bits.
    fn next_f64(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOLDEN: f64 = 0.618_033_988_749_894_8; // (√5 − 1)/2

    fn logistic_points(r: f64, n: usize) -> Vec<(f64, f64)> {
        let mut x = 0.123_456_7;
        for _ in 0..1000 {
            x = r * x * (1.0 - x);
        }
        let mut pts = Vec::with_capacity(n);
        for _ in 0..n {
            let next = r * x * (1.0 - x);
            pts.push((x, next));
            x = next;
        }
        pts
    }

    fn circle_points(alpha: f64, n: usize) -> Vec<(f64, f64)> {
        (0..n)
            .map(|k| {
                let a = 2.0 * PI * k as f64 * alpha;
                (a.cos(), a.sin())
            })
            .collect()
    }

    /// Fixed-step RK4 for the tests' `advance` closures.
    fn rk4<const D: usize>(
        f: impl Fn(&[f64; D]) -> [f64; D],
        state: &mut [f64],
        duration: f64,
        h_max: f64,
    ) {
        let steps = (duration / h_max).ceil().max(1.0) as usize;
        let h = duration / steps as f64;
        let mut y = [0.0; D];
        y.copy_from_slice(state);
        let add = |a: &[f64; D], b: &[f64; D], s: f64| {
            let mut r = *a;
            r.iter_mut().zip(b).for_each(|(ri, bi)| *ri += s * bi);
            r
        };
        for _ in 0..steps {
            let k1 = f(&y);
            let k2 = f(&add(&y, &k1, 0.5 * h));
            let k3 = f(&add(&y, &k2, 0.5 * h));
            let k4 = f(&add(&y, &k3, h));
            for i in 0..D {
                y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        state.copy_from_slice(&y);
    }

    #[test]
    fn motion_labels_and_serde() {
        assert_eq!(MotionState::Periodic { period: 1 }.label(), "period-1");
        assert_eq!(MotionState::Periodic { period: 3 }.to_string(), "period-3");
        assert_eq!(MotionState::QuasiPeriodic.label(), "quasi-periodic");
        assert_eq!(MotionState::Chaotic.to_string(), "chaotic");
        let json = serde_json::to_string(&MotionState::Periodic { period: 2 }).unwrap();
        assert_eq!(json, r#"{"kind":"periodic","period":2}"#);
        let back: MotionState = serde_json::from_str(r#"{"kind":"quasi-periodic"}"#).unwrap();
        assert_eq!(back, MotionState::QuasiPeriodic);
        let o: ClassifyOptions = serde_json::from_str(r#"{"max_period": 4}"#).unwrap();
        assert_eq!((o.rel_tol, o.max_period, o.chaos_threshold), (0.02, 4, 0.5));
    }

    #[test]
    fn motion_linear_oscillator_steady_state_is_period1() {
        // x'' + 2ζx' + x = F cos(ωt), steady state sampled once per forcing period, with a
        // little round-off-sized jitter.
        let (zeta, w, f) = (0.05, 1.3_f64, 1.0);
        let (a, b) = (1.0 - w * w, 2.0 * zeta * w);
        let amp = f / a.hypot(b);
        let phase = b.atan2(a);
        let period = 2.0 * PI / w;
        let t0 = 0.37;
        let pts: Vec<(f64, f64)> = (0..200)
            .map(|k| {
                let t = t0 + k as f64 * period;
                (
                    amp * (w * t - phase).cos(),
                    -amp * w * (w * t - phase).sin(),
                )
            })
            .collect();
        let scale = (2.0 * amp, 2.0 * amp * w);
        let c = classify(&pts, scale, &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::Periodic { period: 1 });
        assert_eq!(c.clusters, 1);
        assert!(c.spread < 1e-9, "spread {}", c.spread);
    }

    #[test]
    fn motion_period1_with_small_drift_stays_period1() {
        let n = 300;
        let pts: Vec<(f64, f64)> = (0..n)
            .map(|k| {
                let s = 0.005 * k as f64 / (n - 1) as f64;
                (0.3 + s, -0.2 + 0.5 * s)
            })
            .collect();
        let c = classify(&pts, (1.0, 1.0), &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::Periodic { period: 1 });
        // …but a drift of 10 % of the scale is not a fixed point.
        let big: Vec<(f64, f64)> = pts.iter().map(|p| (p.0 * 20.0, p.1)).collect();
        let c = classify(&big, (1.0, 1.0), &ClassifyOptions::default()).unwrap();
        assert_ne!(c.state, MotionState::Periodic { period: 1 });
    }

    #[test]
    fn motion_logistic_period_doubling_cascade() {
        let opts = ClassifyOptions::default();
        let scale = (1.0, 1.0);
        let c2 = classify(&logistic_points(3.2, 400), scale, &opts).unwrap();
        assert_eq!(c2.state, MotionState::Periodic { period: 2 });
        assert_eq!(c2.clusters, 2);
        let c4 = classify(&logistic_points(3.5, 400), scale, &opts).unwrap();
        assert_eq!(c4.state, MotionState::Periodic { period: 4 });
        assert_eq!(c4.clusters, 4);
        let cc = classify(&logistic_points(4.0, 1000), scale, &opts).unwrap();
        assert_eq!(cc.state, MotionState::Chaotic);
        assert!(cc.k_01.unwrap() > 0.8);
        assert_eq!(
            detect_period(&logistic_points(3.5, 400), scale, 0.02, 8),
            Some(4)
        );
        assert_eq!(
            detect_period(&logistic_points(3.5, 400), scale, 0.02, 3),
            None
        );
        assert_eq!(
            detect_period(&logistic_points(4.0, 400), scale, 0.02, 8),
            None
        );
    }

    #[test]
    fn motion_circle_rotation_is_quasi_periodic() {
        let pts = circle_points(GOLDEN, 1000);
        let c = classify(&pts, (2.0, 2.0), &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::QuasiPeriodic);
        assert!(c.k_01.unwrap().abs() < 0.2);
        assert!(c.clusters > 8);
        // A slow rotation: consecutive points are close (the pair criterion alone says
        // period-1), but the set does not return: not periodic.
        let slow = circle_points(0.002 * GOLDEN, 1000);
        assert_eq!(detect_period(&slow, (2.0, 2.0), 0.02, 8), Some(1));
        let c = classify(&slow, (2.0, 2.0), &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::QuasiPeriodic);
    }

    #[test]
    fn motion_geometric_fallback_for_short_sections() {
        let opts = ClassifyOptions::default();
        let c = classify(&logistic_points(4.0, 40), (1.0, 1.0), &opts).unwrap();
        assert_eq!(c.state, MotionState::Chaotic);
        assert!(c.k_01.is_none());
        let c = classify(&circle_points(GOLDEN, 40), (2.0, 2.0), &opts).unwrap();
        assert_eq!(c.state, MotionState::QuasiPeriodic);
        let c = classify(&logistic_points(4.0, 100), (1.0, 1.0), &opts).unwrap();
        assert_eq!(c.state, MotionState::Chaotic);
        // A quasi-periodic closed curve with harmonics, 150 points (delay-embedded): the 0–1
        // test alone says chaotic (resonances at ω, 2ω, 3ω), the geometric criterion vetoes.
        let f = |k: usize| {
            let t = 2.0 * PI * GOLDEN * k as f64;
            t.cos() + 0.4 * (2.0 * t).cos() + 0.2 * (3.0 * t).sin()
        };
        let curve: Vec<(f64, f64)> = (0..150).map(|k| (f(k), f(k + 1))).collect();
        let c = classify(&curve, (3.0, 3.0), &opts).unwrap();
        assert!(c.k_01.unwrap() > 0.5, "K = {:?}", c.k_01);
        assert_eq!(c.state, MotionState::QuasiPeriodic);
    }

    #[test]
    fn motion_zero_one_test_reference_signals() {
        let chaotic: Vec<f64> = logistic_points(4.0, 2000).iter().map(|p| p.0).collect();
        let k = zero_one_test(&chaotic).unwrap();
        assert!(k > 0.8, "logistic r=4: K = {k}");

        let quasi: Vec<f64> = (0..2000)
            .map(|n| {
                let n = n as f64;
                (2.0 * PI * GOLDEN * n).cos() + 0.5 * (2.0_f64.sqrt() * n).sin()
            })
            .collect();
        let k = zero_one_test(&quasi).unwrap();
        assert!(k.abs() < 0.2, "quasi-periodic: K = {k}");

        let periodic: Vec<f64> = logistic_points(3.5, 2000).iter().map(|p| p.0).collect();
        let k = zero_one_test(&periodic).unwrap();
        assert!(k.abs() < 0.2, "period-4: K = {k}");

        assert_eq!(zero_one_test(&[1.5; 100]).unwrap(), 0.0);
        assert!(zero_one_test(&chaotic[..49]).is_err());
        let mut bad = chaotic.clone();
        bad[7] = f64::NAN;
        assert!(zero_one_test(&bad).is_err());
    }

    #[test]
    fn motion_zero_one_test_oversampled_flow() {
        // Lorenz x(t) sampled every 0.01 (≈ 60 samples per oscillation): without the guard the
        // 0–1 test sees smooth, regular-looking data on the scale N/10.
        let lorenz = |s: &[f64; 3]| {
            [
                10.0 * (s[1] - s[0]),
                s[0] * (28.0 - s[2]) - s[1],
                s[0] * s[1] - 8.0 / 3.0 * s[2],
            ]
        };
        let mut s = [1.0, 1.0, 20.0];
        rk4(lorenz, &mut s, 20.0, 0.01);
        let xs: Vec<f64> = (0..40_000)
            .map(|_| {
                rk4(lorenz, &mut s, 0.01, 0.01);
                s[0]
            })
            .collect();
        assert!(oversampling_step(&xs) > 1);
        let k = zero_one_test(&xs).unwrap();
        assert!(k > 0.8, "oversampled Lorenz: K = {k}");
    }

    #[test]
    fn motion_lyapunov_damped_oscillator() {
        // x'' + 2ζx' + x = 0: eigenvalues −ζ ± i√(1−ζ²), so λ = −ζ.
        let zeta = 0.1;
        let f = move |s: &[f64; 2]| [s[1], -2.0 * zeta * s[1] - s[0]];
        let lam = largest_lyapunov(&[1.0, 0.0], 1e-6, 1.0, 2000, 0, |s, dt| {
            rk4(f, s, dt, 0.01);
            Ok(())
        })
        .unwrap();
        assert!((lam + zeta).abs() < 0.005, "λ = {lam}");
    }

    #[test]
    fn motion_lyapunov_lorenz() {
        let f = |s: &[f64; 3]| {
            [
                10.0 * (s[1] - s[0]),
                s[0] * (28.0 - s[2]) - s[1],
                s[0] * s[1] - 8.0 / 3.0 * s[2],
            ]
        };
        let lam = largest_lyapunov(&[1.0, 1.0, 20.0], 1e-8, 0.5, 2000, 40, |s, dt| {
            rk4(f, s, dt, 0.005);
            Ok(())
        })
        .unwrap();
        assert!((lam - 0.906).abs() < 0.15 * 0.906, "λ = {lam}");
    }

    #[test]
    fn motion_degenerate_input_is_an_error() {
        let opts = ClassifyOptions::default();
        let pts = logistic_points(3.2, 100);
        assert!(classify(&[], (1.0, 1.0), &opts).is_err());
        assert!(classify(&pts[..1], (1.0, 1.0), &opts).is_err());
        assert!(classify(&pts, (0.0, 1.0), &opts).is_err());
        assert!(classify(&pts, (1.0, f64::NAN), &opts).is_err());
        let mut nan = pts.clone();
        nan[3].1 = f64::NAN;
        assert!(classify(&nan, (1.0, 1.0), &opts).is_err());
        let bad_opts = ClassifyOptions {
            rel_tol: -1.0,
            ..opts
        };
        assert!(classify(&pts, (1.0, 1.0), &bad_opts).is_err());
        assert_eq!(detect_period(&pts, (0.0, 1.0), 0.02, 8), None);
        assert_eq!(detect_period(&[], (1.0, 1.0), 0.02, 8), None);
        let ok = |_: &mut [f64], _: f64| Ok(());
        assert!(largest_lyapunov(&[], 1e-8, 1.0, 10, 0, ok).is_err());
        assert!(largest_lyapunov(&[1.0], 0.0, 1.0, 10, 0, ok).is_err());
        assert!(largest_lyapunov(&[1.0], 1e-8, 1.0, 0, 0, ok).is_err());
        // A map that collapses everything onto one point: separation becomes zero.
        let collapse = |s: &mut [f64], _: f64| {
            s.iter_mut().for_each(|v| *v = 0.0);
            Ok(())
        };
        assert!(largest_lyapunov(&[1.0, 2.0], 1e-8, 1.0, 10, 0, collapse).is_err());
        // Errors of the integrator propagate.
        let fail = |_: &mut [f64], t: f64| Err(Error::NonFinite { t });
        assert!(largest_lyapunov(&[1.0], 1e-8, 1.0, 10, 0, fail).is_err());
    }

    #[test]
    fn forced_classifier_sees_modulated_period_1_and_period_2() {
        use std::f64::consts::TAU;
        let r = [0.36, 0.0875];
        let scale = (1.0, 1.0);
        // Period-1 locked to three forcings: a smooth function of the other phases.
        let p1: Vec<(f64, f64)> = (0..80)
            .map(|k| {
                let (a, b) = ((0.36 * k as f64).fract(), (0.0875 * k as f64).fract());
                let x = 1.0 + 0.1 * (TAU * a).sin() + 0.03 * (TAU * b).cos();
                (x, 0.2 * (TAU * a).cos())
            })
            .collect();
        let c = classify_forced(&p1, scale, -0.1, &r, &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::Periodic { period: 1 });
        // The plain geometric test calls the same set non-periodic.
        assert_ne!(
            classify(&p1, scale, &ClassifyOptions::default())
                .unwrap()
                .state,
            MotionState::Periodic { period: 1 }
        );
        // Period-2: alternate branches.
        let p2: Vec<(f64, f64)> = p1
            .iter()
            .enumerate()
            .map(|(k, &(x, v))| {
                if k % 2 == 0 {
                    (x + 0.5, v)
                } else {
                    (x - 0.5, v)
                }
            })
            .collect();
        let c = classify_forced(&p2, scale, -0.1, &r, &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::Periodic { period: 2 });
        // A frequency of its own (a torus): quasi-periodic.
        let alpha = (5f64.sqrt() - 1.0) / 2.0;
        let q: Vec<(f64, f64)> = (0..80)
            .map(|k| {
                (
                    (TAU * alpha * k as f64).cos(),
                    (TAU * alpha * k as f64).sin(),
                )
            })
            .collect();
        let c = classify_forced(&q, scale, -0.001, &r, &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::QuasiPeriodic);
        // A positive exponent is chaos whatever the geometry.
        let c = classify_forced(&p1, scale, 0.5, &r, &ClassifyOptions::default()).unwrap();
        assert_eq!(c.state, MotionState::Chaotic);
    }
}
