//! Scalar statistics used as gear condition indicators.
//!
//! All use population (1/N) moments. The `f64` versions return `NaN` for input the `try_*`
//! versions would reject (empty, non-finite samples, or a constant record where a ratio to the
//! standard deviation is undefined).

use super::check_samples;
use crate::{Error, Result};

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// The median of `values` (sorted in place; the mean of the two middle values for an even
/// count; NaN for none).
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// Root mean square `sqrt(Σ x² / N)`, in the unit of `x`. Not mean-removed: a constant `c`
/// has RMS `|c|`, a sine of amplitude `A` over whole periods has RMS `A/√2`.
///
/// Errors: empty record or non-finite sample.
pub fn try_rms(x: &[f64]) -> Result<f64> {
    check_samples(x)?;
    // Scale by max|x| to avoid overflow of x² for huge (but finite) samples.
    let m = x.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    if m == 0.0 {
        return Ok(0.0);
    }
    let s = x.iter().map(|v| (v / m) * (v / m)).sum::<f64>() / x.len() as f64;
    Ok(m * s.sqrt())
}

/// [`try_rms`], returning `NaN` for unusable input.
pub fn rms(x: &[f64]) -> f64 {
    try_rms(x).unwrap_or(f64::NAN)
}

/// Population central moments (m2, m4) of `(x − mean) / s`, with `s = max|x − mean|` so that
/// huge samples cannot overflow; (0, 0) for a constant record.
fn central_moments(x: &[f64]) -> (f64, f64) {
    let mu = mean(x);
    let scale = x.iter().fold(0.0_f64, |a, v| a.max((v - mu).abs()));
    if scale == 0.0 || !scale.is_finite() {
        return (0.0, 0.0);
    }
    let n = x.len() as f64;
    let (mut m2, mut m4) = (0.0, 0.0);
    for v in x {
        let d = (v - mu) / scale;
        let d2 = d * d;
        m2 += d2;
        m4 += d2 * d2;
    }
    (m2 / n, m4 / n)
}

/// Kurtosis `m4 / m2²` with population central moments (not excess kurtosis): a Gaussian
/// gives 3, a sine 1.5, a square wave 1; impulsive (e.g. tooth-fault) signals give > 3.
/// Dimensionless.
///
/// Errors: empty record, non-finite sample, or a constant record (zero variance).
pub fn try_kurtosis(x: &[f64]) -> Result<f64> {
    check_samples(x)?;
    let (m2, m4) = central_moments(x);
    if m2 == 0.0 {
        return Err(Error::ConstantSignal {
            analysis: "kurtosis",
            samples: x.len(),
        });
    }
    Ok(m4 / (m2 * m2))
}

/// [`try_kurtosis`], returning `NaN` for unusable input.
pub fn kurtosis(x: &[f64]) -> f64 {
    try_kurtosis(x).unwrap_or(f64::NAN)
}

/// Crest factor `max|x − mean| / rms(x − mean)`, dimensionless: √2 for a sine sampled at its
/// peak, 1 for a square wave, large for impulsive signals.
///
/// Errors: empty record, non-finite sample, or a constant record (zero RMS about the mean).
pub fn try_crest_factor(x: &[f64]) -> Result<f64> {
    check_samples(x)?;
    let (m2, _) = central_moments(x);
    if m2 == 0.0 {
        return Err(Error::ConstantSignal {
            analysis: "crest factor",
            samples: x.len(),
        });
    }
    // Moments are scaled by max|x − mean|, so the scaled peak is exactly 1.
    Ok(1.0 / m2.sqrt())
}

/// [`try_crest_factor`], returning `NaN` for unusable input.
pub fn crest_factor(x: &[f64]) -> f64 {
    try_crest_factor(x).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{PI, SQRT_2};

    #[test]
    fn median_of_odd_even_and_no_values() {
        assert_eq!(median(&mut [3.0, -1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }

    /// `periods` whole periods of `a sin(2πt)` with `per` samples per period, phase 0 so that
    /// a sample lands on each peak when `per` is a multiple of 4.
    fn sine(a: f64, per: usize, periods: usize) -> Vec<f64> {
        (0..per * periods)
            .map(|i| a * (2.0 * PI * i as f64 / per as f64).sin())
            .collect()
    }

    #[test]
    fn sine_statistics() {
        let a = 2.5;
        let x = sine(a, 64, 10);
        assert!((rms(&x) - a / SQRT_2).abs() < 1e-12);
        assert!((kurtosis(&x) - 1.5).abs() < 1e-12);
        assert!((crest_factor(&x) - SQRT_2).abs() < 1e-12);
        // With an offset: rms is not mean-removed, kurtosis and crest factor are.
        let y: Vec<f64> = x.iter().map(|v| v + 3.0).collect();
        assert!((rms(&y) - (9.0 + a * a / 2.0_f64).sqrt()).abs() < 1e-12);
        assert!((kurtosis(&y) - 1.5).abs() < 1e-12);
        assert!((crest_factor(&y) - SQRT_2).abs() < 1e-12);
    }

    #[test]
    fn square_wave_and_impulse() {
        let sq: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        assert!((kurtosis(&sq) - 1.0).abs() < 1e-12);
        assert!((crest_factor(&sq) - 1.0).abs() < 1e-12);
        assert!((rms(&sq) - 1.0).abs() < 1e-12);
        // One impulse of height 1 in N zeros: mean 1/N, variance (N-1)/N²,
        // kurtosis = (1 - 3/N + 3/N² ... ) computed independently below.
        let n = 50usize;
        let mut imp = vec![0.0; n];
        imp[7] = 1.0;
        let nf = n as f64;
        let mu = 1.0 / nf;
        let m2 = ((1.0 - mu).powi(2) + (nf - 1.0) * mu * mu) / nf;
        let m4 = ((1.0 - mu).powi(4) + (nf - 1.0) * mu.powi(4)) / nf;
        assert!((kurtosis(&imp) - m4 / (m2 * m2)).abs() < 1e-9);
        assert!((crest_factor(&imp) - (1.0 - mu) / m2.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn huge_values_do_not_overflow() {
        let x = [1e300, -1e300, 1e300, -1e300];
        assert!((rms(&x) - 1e300).abs() < 1e286);
        assert!((kurtosis(&x) - 1.0).abs() < 1e-12);
        assert!((crest_factor(&x) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn error_paths() {
        for f in [try_rms, try_kurtosis, try_crest_factor] {
            let e = f(&[]).unwrap_err();
            assert!(matches!(e, crate::Error::EmptyRecord), "{e}");
            let e = f(&[1.0, f64::NAN, 2.0]).unwrap_err().to_string();
            assert!(e.contains("sample 1") && e.contains("NaN"), "{e}");
            let e = f(&[1.0, f64::INFINITY]).unwrap_err().to_string();
            assert!(e.contains("inf"), "{e}");
        }
        assert!(rms(&[]).is_nan());
        assert!(kurtosis(&[f64::NAN]).is_nan());
        assert!(crest_factor(&[]).is_nan());
        assert_eq!(rms(&[0.0, 0.0]), 0.0);
        assert!(
            try_kurtosis(&[2.0; 5])
                .unwrap_err()
                .to_string()
                .contains("constant")
        );
        assert!(
            try_crest_factor(&[2.0; 5])
                .unwrap_err()
                .to_string()
                .contains("constant")
        );
    }
}
