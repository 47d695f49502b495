//! Standard gear condition indicators from one record, without a tachometer.
//!
//! Definitions (Zakrajsek 1993; Lebold, McClintic et al. 2000, "A review of vibration-based
//! techniques for helicopter transmission diagnostics"):
//!
//! * `rms`, `crest_factor = max|x − x̄| / rms`, `kurtosis = m4 / m2²` of the mean-removed record;
//! * `FM0 = (max x − min x) / Σ_k A(k f1)`: peak-to-peak over the summed amplitudes of the mesh
//!   harmonics `k f1 < fs/2` (at most [`MAX_HARMONICS`]);
//! * `FM4 = kurtosis` of the **difference signal** `d`: the record with the mesh harmonics, their
//!   first-order shaft sidebands `k f1 ± f_shaft` and the caller's other regular lines removed;
//! * `NA4` of the **residual signal** `r` (mesh harmonics removed, sidebands kept):
//!   `NA4 = mean((r − r̄)⁴) / (mean_m var(r_m))²`, the variance averaged over the `M` consecutive
//!   segments of the record (the literature averages over the records of a run; one record split
//!   in time is the single-record analogue; for a stationary record NA4 ≈ kurtosis of `r`).
//!
//! **Tacho-less approximation (honest note).** The literature computes these on the
//! time-synchronous average (TSA) of the shaft of interest, which needs a once-per-rev pulse.
//! Here there is none: lines are removed by a least-squares sinusoid fit at their exact
//! frequencies over the whole record (projection on `cos`/`sin`; the lines are far apart
//! compared with `1/T`), followed by zeroing `±REMOVE_BINS` FFT bins around each to catch speed
//! wander. Everything not synchronous with the removed lines (noise, bearing tones, other
//! shafts) stays in `d` and `r`, so FM4 and NA4 read ≈ 3 for a Gaussian background and are not
//! comparable with TSA-based alarm thresholds; they are reported beside the model-based answer,
//! not used by it.

use serde::Serialize;

use super::phasor::{fit_sums, subtract_sinusoid};
use super::{PlanCache, check_samples};
use crate::{Error, Result};

/// Largest number of mesh harmonics removed / summed.
pub const MAX_HARMONICS: usize = 10;
/// Half-width (FFT bins of the whole record) zeroed around every removed line.
pub const REMOVE_BINS: usize = 2;

/// The indicators of one record.
#[derive(Debug, Clone, Serialize)]
pub struct ConditionIndicators {
    /// RMS of the mean-removed record (unit of the record).
    pub rms: f64,
    /// Peak |x − x̄| over RMS.
    pub crest_factor: f64,
    /// Kurtosis (3 for Gaussian).
    pub kurtosis: f64,
    pub fm0: f64,
    pub fm4: f64,
    pub na4: f64,
    /// RMS of the residual over the RMS of the record (share not explained by mesh harmonics).
    pub residual_rms_ratio: f64,
    /// Number of mesh harmonics removed.
    pub harmonics: usize,
    /// One-line description of the method (tacho-less approximation).
    pub method: &'static str,
}

/// Fit and subtract `a cos + b sin` at `freq` (cycles/sample) from `x`; return the amplitude.
fn remove_sinusoid(x: &mut [f64], cyc: f64) -> f64 {
    let n = x.len();
    let [c, s, cc, ss, cs] = fit_sums(x, cyc);
    // 2×2 normal equations.
    let det = cc * ss - cs * cs;
    if det.abs() <= 1e-12 * (cc * ss).max(1e-300) || det.is_nan() || n < 4 {
        return 0.0;
    }
    let a = (c * ss - s * cs) / det;
    let b = (s * cc - c * cs) / det;
    subtract_sinusoid(x, cyc, a, b);
    a.hypot(b)
}

/// Zero `±REMOVE_BINS` bins around each frequency (cycles/sample) through a real FFT.
fn notch(x: &mut [f64], cycs: &[f64]) -> Result<()> {
    let n = x.len();
    // Plans from the process-wide cache: planning a record-length FFT pair costs more than the
    // transforms themselves, and this runs twice per diagnosis.
    let fwd = PlanCache::global().forward(n);
    let inv = PlanCache::global().inverse(n);
    let mut spec = fwd.make_output_vec();
    let mut scratch = fwd.make_scratch_vec();
    if inv.get_scratch_len() > scratch.len() {
        scratch.resize(inv.get_scratch_len(), Default::default());
    }
    fwd.process_with_scratch(x, &mut spec, &mut scratch)
        .map_err(|e| Error::fft(n, e))?;
    for &c in cycs {
        let k = (c * n as f64).round() as isize;
        for d in -(REMOVE_BINS as isize)..=REMOVE_BINS as isize {
            let j = k + d;
            if j > 0 && (j as usize) < spec.len() {
                spec[j as usize] = realfft::num_complex::Complex::new(0.0, 0.0);
            }
        }
    }
    // The inverse needs purely real DC (and Nyquist for even n).
    spec[0].im = 0.0;
    if n.is_multiple_of(2)
        && let Some(last) = spec.last_mut()
    {
        last.im = 0.0;
    }
    inv.process_with_scratch(&mut spec, x, &mut scratch)
        .map_err(|e| Error::fft(n, e))?;
    for v in x.iter_mut() {
        *v /= n as f64;
    }
    Ok(())
}

fn moments(x: &[f64]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let (mut m2, mut m4) = (0.0, 0.0);
    for v in x {
        let d = v - m;
        m2 += d * d;
        m4 += d * d * d * d;
    }
    (m, m2 / n, m4 / n)
}

/// Condition indicators of `x` (sample rate `fs`) with stage-1 mesh frequency `f1` and input
/// shaft rate `shaft` (same time unit), removing also `other_lines` (frequencies) from the
/// difference signal. See the [module docs](self).
///
/// Errors: fewer than 64 samples, a non-finite sample, a constant record, or `f1`/`fs`
/// not positive with `f1 < fs/2`.
pub fn condition_indicators(
    x: &[f64],
    fs: f64,
    f1: f64,
    shaft: f64,
    other_lines: &[f64],
) -> Result<ConditionIndicators> {
    check_samples(x)?;
    if x.len() < 64 {
        return Err(Error::TooFewSamples {
            analysis: "condition indicators",
            needed: 64,
            samples: x.len(),
        });
    }
    if !(fs.is_finite() && fs > 0.0 && f1.is_finite() && f1 > 0.0 && f1 < 0.5 * fs) {
        return Err(Error::param(
            "f1",
            f1,
            "must be positive and below the Nyquist frequency",
        ));
    }
    let (mean, var, m4) = moments(x);
    if var <= 0.0 {
        return Err(Error::ConstantSignal {
            analysis: "condition indicators",
            samples: x.len(),
        });
    }
    let rms = var.sqrt();
    let peak = x.iter().fold(0.0_f64, |a, v| a.max((v - mean).abs()));
    let (xmin, xmax) = x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, &v| {
        (a.0.min(v), a.1.max(v))
    });
    let mut r: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let harmonics: Vec<f64> = (1..=MAX_HARMONICS)
        .map(|k| k as f64 * f1)
        .filter(|f| *f < 0.5 * fs)
        .collect();
    let mut sum_amp = 0.0;
    let cyc = |f: f64| f / fs;
    for &h in &harmonics {
        sum_amp += remove_sinusoid(&mut r, cyc(h));
    }
    let hc: Vec<f64> = harmonics.iter().map(|&h| cyc(h)).collect();
    notch(&mut r, &hc)?;
    // Difference signal: also sidebands and the other regular lines.
    let mut d = r.clone();
    let mut extra: Vec<f64> = Vec::new();
    if shaft > 0.0 {
        for &h in &harmonics {
            for f in [h - shaft, h + shaft] {
                if f > 0.0 && f < 0.5 * fs {
                    extra.push(f);
                }
            }
        }
    }
    extra.extend(other_lines.iter().filter(|&&f| f > 0.0 && f < 0.5 * fs));
    for &f in &extra {
        remove_sinusoid(&mut d, cyc(f));
    }
    let ec: Vec<f64> = extra.iter().map(|&f| cyc(f)).collect();
    notch(&mut d, &ec)?;
    let (_, dv, d4) = moments(&d);
    let (rm, rv, r4) = moments(&r);
    let segs = (r.len() / 1024).clamp(1, 10);
    let seg_len = r.len() / segs;
    let mean_var = (0..segs)
        .map(|s| {
            let (_, v, _) = moments(&r[s * seg_len..(s + 1) * seg_len]);
            v
        })
        .sum::<f64>()
        / segs as f64;
    let _ = rm;
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    Ok(ConditionIndicators {
        rms,
        crest_factor: peak / rms,
        kurtosis: m4 / (var * var),
        fm0: ratio(xmax - xmin, sum_amp),
        fm4: ratio(d4, dv * dv),
        na4: ratio(r4, mean_var * mean_var),
        residual_rms_ratio: (rv / var).sqrt(),
        harmonics: harmonics.len(),
        method: "tacho-less: mesh harmonics (and for FM4 shaft sidebands and the model's \
                 other lines) removed by least-squares sinusoid fit plus ±2-bin spectral notch; \
                 no time-synchronous average",
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn removes_mesh_harmonics_and_sees_impulses() {
        let (fs, f1) = (10_000.0, 437.3);
        let n = 20_000;
        let mut x: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                (TAU * f1 * t).sin() + 0.3 * (TAU * 2.0 * f1 * t + 1.0).sin()
            })
            .collect();
        let clean = condition_indicators(&x, fs, f1, f1 / 29.0, &[]).unwrap();
        assert!(clean.residual_rms_ratio < 1e-3, "{clean:?}");
        assert!(clean.fm0 > 1.0 && clean.fm0 < 2.5, "{clean:?}");
        // Add a sparse impulse train: the residual becomes impulsive.
        for i in (0..n).step_by(997) {
            x[i] += 3.0;
        }
        let hit = condition_indicators(&x, fs, f1, f1 / 29.0, &[]).unwrap();
        assert!(hit.na4 > 10.0 && hit.fm4 > 10.0, "{hit:?}");
    }
}
