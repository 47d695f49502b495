//! The Gottwald–Melbourne 0–1 test for chaos (correlation method).

use std::f64::consts::PI;

use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;

use super::MIN_01_LEN;
use crate::signal::median;
use crate::{Error, Result};

/// Number of random frequencies `c` of the 0–1 test.
const N_C: usize = 100;

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
/// Errors: [`Error::TooFewSamples`] for `N < 50`, [`Error::NonFiniteValue`] for a non-finite sample.
pub fn zero_one_test(series: &[f64]) -> Result<f64> {
    if series.len() < MIN_01_LEN {
        return Err(Error::TooFewSamples {
            analysis: "the 0-1 test",
            needed: MIN_01_LEN,
            samples: series.len(),
        });
    }
    if let Some(i) = series.iter().position(|s| !s.is_finite()) {
        return Err(Error::NonFiniteValue {
            analysis: "the 0-1 test",
            what: format!("sample {i}"),
        });
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

/// Subsampling step of the 0–1 test's oversampling guard: `⌊τ/2⌋` for a first zero crossing
/// of the autocorrelation at lag `τ ≥ 4`, limited so at least 100 samples remain.
pub(super) fn oversampling_step(series: &[f64]) -> usize {
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
