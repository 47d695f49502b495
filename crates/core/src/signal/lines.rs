//! The line estimator: amplitudes of chosen spectral lines of a record and the power of a band,
//! at frequencies given as multiples of a reference `f1` (the stage-1 mesh frequency). The
//! offline signature table ([`crate::signature::precompute`]), the diagnosis of a measured record
//! ([`crate::diagnosis`]) and the closed loop ([`crate::closed_loop`]) all measure with
//! [`measure_lines`], so a record and the table are measured alike. Which lines, and the
//! gain-invariant features made of the amplitudes, are the signature's
//! ([`crate::signature::line_set`], [`LineMeasurement::features`]).
//!
//! # The estimator
//!
//! A record `x[n]` sampled at `fs` with a known stage-1 mesh frequency `f1` (same time unit) is
//! cut into segments of `L = round(SEGMENT_PERIODS · fs / f1)` samples (so every segment spans
//! the same number of mesh periods whatever the speed or sample rate: the frequency resolution
//! is `f1 / SEGMENT_PERIODS` for every record and every table entry), hopping by `L/2`. Each
//! segment has its mean removed and is multiplied by a periodic Hann window `w`. For every line
//! `ℓ` at normalised frequency `r_ℓ` (multiple of f1) the segment's Hann DTFT at exactly
//! `r_ℓ f1` gives a peak amplitude `A_{ℓ,s} = 2 |Σ w[n] x[n] e^{−2πi r_ℓ f1 n / fs}| / Σ w`;
//! segments are averaged in power, `A_ℓ = sqrt(mean_s A_{ℓ,s}²)` (unit of `x`).
//!
//! The band power `P_band` is the mean square in `[BAND_LO, BAND_HI] · f1`, from the same
//! segments (Parseval on the Hann-windowed FFT).

use serde::Serialize;

use super::{PlanCache, Window, shared_window, unit_phasors};
use crate::error::{Error, Result};

/// Segment length of the line estimator, in stage-1 mesh periods (resolution `f1 / 64`).
pub const SEGMENT_PERIODS: f64 = 64.0;
/// Lower edge of the band whose power normalises `f1_power_fraction`, in units of f1.
pub const BAND_LO: f64 = 0.05;
/// Upper edge of that band, in units of f1.
pub const BAND_HI: f64 = 2.5;

/// Line amplitudes and band power of a record, as defined in the [module docs](self). The
/// signature adds the feature vector ([`LineMeasurement::features`]).
#[derive(Debug, Clone, Serialize)]
pub struct LineMeasurement {
    /// Peak amplitude of each line (unit of the record), in the order of the ratios measured.
    pub amplitudes: Vec<f64>,
    /// Power (mean square, unit²) in `[BAND_LO, BAND_HI] · f1`.
    pub band_power: f64,
    /// Number of Welch segments averaged.
    pub segments: usize,
    /// Segment length in samples.
    pub segment_len: usize,
}

/// Highest line ratio, at least `BAND_HI` (sets the sample-rate requirement
/// `fs > 2 · max · f1`).
pub fn highest_ratio(ratios: &[f64]) -> f64 {
    ratios.iter().copied().fold(BAND_HI, f64::max)
}

/// Samples per segment for a record at `fs` with mesh frequency `f1` (same time unit).
pub fn segment_len(fs: f64, f1: f64) -> usize {
    (SEGMENT_PERIODS * fs / f1).round().max(0.0) as usize
}

/// Measure the lines at `ratios × f1` of `x` (sample rate `fs`, stage-1 mesh frequency `f1`,
/// same time unit), as defined in the [module docs](self); amplitudes in the order of `ratios`.
///
/// Errors: a non-finite sample, a record shorter than one segment, `f1` or `fs` not positive,
/// a line at or above Nyquist.
pub fn measure_lines(x: &[f64], fs: f64, f1: f64, ratios: &[f64]) -> Result<LineMeasurement> {
    if !(fs.is_finite() && fs > 0.0 && f1.is_finite() && f1 > 0.0) {
        return Err(Error::param(
            "f1 / sample rate",
            f1 / fs,
            "both must be finite and positive",
        ));
    }
    if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(Error::NonFiniteSample { index, value });
    }
    let highest = highest_ratio(ratios) * f1;
    if 2.0 * highest >= fs {
        return Err(Error::SampleRateTooLow {
            sample_rate: fs,
            highest_line_hz: highest,
            needed: 2.0 * highest,
        });
    }
    let l = segment_len(fs, f1);
    if l < 16 || x.len() < l {
        return Err(Error::RecordTooShort {
            samples: x.len(),
            periods: x.len() as f64 * f1 / fs,
            f1_hz: f1,
            needed_periods: SEGMENT_PERIODS as usize,
            needed_samples: l.max(16),
        });
    }
    let hop = (l / 2).max(1);
    let nseg = 1 + (x.len() - l) / hop;
    let w = shared_window(Window::Hann, l);
    let wsum: f64 = w.iter().sum();
    let w2sum: f64 = w.iter().map(|v| v * v).sum();
    // Window × complex exponential, per line, and its sum (for the mean removal). Stored
    // sample-major (`[n][line]`) so that one pass over a segment updates every line's sums:
    // the lines' accumulations are independent chains the CPU overlaps (and vectorises), each
    // still summed in sample order, so the values are those of one line at a time.
    let nl = ratios.len();
    let mut kre = vec![0.0; l * nl];
    let mut kim = vec![0.0; l * nl];
    let mut ksum: Vec<(f64, f64)> = Vec::with_capacity(nl);
    let (mut pc, mut ps) = (vec![0.0; l], vec![0.0; l]);
    for (q, &ratio) in ratios.iter().enumerate() {
        let c = ratio * f1 / fs;
        unit_phasors(c, &mut pc, &mut ps);
        let (mut sr, mut si) = (0.0, 0.0);
        for (n, wv) in w.iter().enumerate() {
            let (s, co) = (ps[n], pc[n]);
            let (re, im) = (wv * co, -wv * s);
            kre[n * nl + q] = re;
            kim[n * nl + q] = im;
            sr += re;
            si += im;
        }
        ksum.push((sr, si));
    }
    let mut sum_re = vec![0.0; nl];
    let mut sum_im = vec![0.0; nl];
    let mut power = vec![0.0; nl];
    let plan = PlanCache::global().forward(l);
    let mut input = plan.make_input_vec();
    let mut spectrum = plan.make_output_vec();
    let mut scratch = plan.make_scratch_vec();
    let (k_lo, k_hi) = (
        (BAND_LO * f1 * l as f64 / fs).ceil() as usize,
        ((BAND_HI * f1 * l as f64 / fs).floor() as usize).min(l / 2),
    );
    let mut band = 0.0;
    for s in 0..nseg {
        let seg = &x[s * hop..s * hop + l];
        let mean = seg.iter().sum::<f64>() / l as f64;
        line_sums(seg, &kre, &kim, &mut sum_re, &mut sum_im);
        for (((p, &(sr, si)), &a), &b) in power.iter_mut().zip(&ksum).zip(&sum_re).zip(&sum_im) {
            let (mut a, mut b) = (a, b);
            a -= mean * sr;
            b -= mean * si;
            let amp = 2.0 * a.hypot(b) / wsum;
            *p += amp * amp;
        }
        for ((o, xv), wv) in input.iter_mut().zip(seg).zip(w.iter()) {
            *o = (xv - mean) * wv;
        }
        plan.process_with_scratch(&mut input, &mut spectrum, &mut scratch)
            .map_err(|e| Error::fft(input.len(), e))?;
        let e: f64 = spectrum[k_lo..=k_hi.max(k_lo)]
            .iter()
            .map(|c| c.norm_sqr())
            .sum();
        band += 2.0 * e / (l as f64 * w2sum);
    }
    let inv = 1.0 / nseg as f64;
    Ok(LineMeasurement {
        amplitudes: power.iter().map(|p| (p * inv).sqrt()).collect(),
        band_power: band * inv,
        segments: nseg,
        segment_len: l,
    })
}

/// `sum_re[q] = Σ_n seg[n] kre[n][q]` and likewise `sum_im`, kernels sample-major with
/// `sum_re.len()` lines; each line summed in sample order.
#[inline(always)]
fn line_sums_impl(seg: &[f64], kre: &[f64], kim: &[f64], sum_re: &mut [f64], sum_im: &mut [f64]) {
    let nl = sum_re.len();
    sum_re.fill(0.0);
    sum_im.fill(0.0);
    for ((xv, kr), ki) in seg
        .iter()
        .zip(kre.chunks_exact(nl))
        .zip(kim.chunks_exact(nl))
    {
        for (a, k) in sum_re.iter_mut().zip(kr) {
            *a += xv * k;
        }
        for (b, k) in sum_im.iter_mut().zip(ki) {
            *b += xv * k;
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn line_sums_avx2(
    seg: &[f64],
    kre: &[f64],
    kim: &[f64],
    sum_re: &mut [f64],
    sum_im: &mut [f64],
) {
    line_sums_impl(seg, kre, kim, sum_re, sum_im)
}

/// [`line_sums_impl`] with 256-bit vectors when the CPU has AVX2 (same operations per line,
/// no FMA contraction: identical results).
fn line_sums(seg: &[f64], kre: &[f64], kim: &[f64], sum_re: &mut [f64], sum_im: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { line_sums_avx2(seg, kre, kim, sum_re, sum_im) };
    }
    line_sums_impl(seg, kre, kim, sum_re, sum_im)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_short_records_and_low_rates() {
        let ratios = [0.0875, 0.36, 0.5, 1.0, 2.0];
        let x = vec![0.0; 100];
        assert!(matches!(
            measure_lines(&x, 25_600.0, 870.0, &ratios),
            Err(Error::RecordTooShort { .. })
        ));
        assert!(matches!(
            measure_lines(&x, 3000.0, 870.0, &ratios),
            Err(Error::SampleRateTooLow { .. })
        ));
    }
}
