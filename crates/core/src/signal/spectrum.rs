//! One-sided peak-amplitude spectra: single FFT, Welch average, and single-line DTFT.
//!
//! Scaling and output order are described in the [module docs](super).

use std::sync::Arc;

use realfft::RealToComplex;
use realfft::num_complex::Complex;
use serde::Serialize;

use super::window::{Window, shared_window};
use super::{PlanCache, check_min_len, check_rate, check_samples};
use crate::{Error, Result};

/// A one-sided amplitude spectrum.
///
/// * `freq[k] = k · fs / N` for `k = 0 ..= N/2` (ascending; `N` = transform length, i.e. the
///   record length for [`amplitude_spectrum`], the segment length for [`welch`]), in cycles per
///   unit time of the sample rate.
/// * `amplitude[k]` is the **peak** amplitude (not RMS, not power, not density) in the unit of
///   the samples: a sine `A sin(2πf t + φ)` on bin `k` reads `A`; the DC bin reads the
///   magnitude of the (window-weighted) mean; an even-`N` Nyquist bin reads the amplitude of
///   the `(−1)^n` component. See the [module docs](super) for the exact formula.
///
/// Both vectors have the same length, `N/2 + 1`.
#[derive(Debug, Clone, Serialize)]
pub struct Spectrum {
    /// Bin frequencies, ascending, `k · fs / N`.
    pub freq: Vec<f64>,
    /// Peak amplitude of each bin, same unit as the samples.
    pub amplitude: Vec<f64>,
}

impl Spectrum {
    /// Bin spacing `fs / N` (frequency units), taken as `freq[1] − freq[0]`.
    /// `NaN` if the spectrum has fewer than two bins.
    pub fn resolution(&self) -> f64 {
        match self.freq.as_slice() {
            [f0, f1, ..] => f1 - f0,
            _ => f64::NAN,
        }
    }

    /// Index of the bin nearest `f`, or `None` if `f` is not finite, the spectrum is empty, or
    /// `f` lies more than half a bin outside `[freq[0], freq[last]]`.
    fn nearest(&self, f: f64) -> Option<usize> {
        let n = self.freq.len().min(self.amplitude.len());
        if n == 0 || !f.is_finite() {
            return None;
        }
        let fr = &self.freq[..n];
        let half = if n >= 2 {
            0.5 * self.resolution().abs()
        } else {
            0.0
        };
        if f < fr[0] - half || f > fr[n - 1] + half {
            return None;
        }
        let i = fr.partition_point(|&v| v < f);
        Some(if i == 0 {
            0
        } else if i == n || (f - fr[i - 1]) <= (fr[i] - f) {
            i - 1
        } else {
            i
        })
    }

    /// Amplitude at the bin nearest frequency `f` (same unit as the samples).
    ///
    /// Returns `NaN` if `f` is not finite, the spectrum is empty, or `f` lies more than half a
    /// bin outside the spectrum's frequency range (e.g. above Nyquist). Note the scalloping
    /// loss for an off-bin sine with Hann/rectangular windows; use [`Window::FlatTop`] or
    /// [`line_amplitude`] when the exact amplitude of an off-bin line matters.
    pub fn at(&self, f: f64) -> f64 {
        self.nearest(f).map_or(f64::NAN, |k| self.amplitude[k])
    }

    /// `(frequency, amplitude)` of the largest bin with frequency in
    /// `[f − half_width, f + half_width]`.
    ///
    /// If that interval holds no bin (`half_width` below half the resolution), the nearest bin
    /// to `f` is used, as in [`Spectrum::at`]. Returns `(NaN, NaN)` if `f` or `half_width` is
    /// not finite, `half_width < 0`, or no bin is within reach.
    pub fn peak_near(&self, f: f64, half_width: f64) -> (f64, f64) {
        const NONE: (f64, f64) = (f64::NAN, f64::NAN);
        if !(half_width.is_finite() && half_width >= 0.0 && f.is_finite()) {
            return NONE;
        }
        let n = self.freq.len().min(self.amplitude.len());
        let fr = &self.freq[..n];
        let lo = fr.partition_point(|&v| v < f - half_width);
        let hi = fr.partition_point(|&v| v <= f + half_width);
        let mut best: Option<usize> = None;
        for k in lo..hi {
            let a = self.amplitude[k];
            if best.is_none_or(|b| a > self.amplitude[b]) {
                best = Some(k);
            }
        }
        match best.or_else(|| self.nearest(f)) {
            Some(k) => (self.freq[k], self.amplitude[k]),
            None => NONE,
        }
    }
}

/// Forward-FFT workspace for one transform length.
struct Fft {
    plan: Arc<dyn RealToComplex<f64>>,
    input: Vec<f64>,
    output: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl Fft {
    fn new(n: usize) -> Self {
        let plan = PlanCache::global().forward(n);
        Fft {
            input: plan.make_input_vec(),
            output: plan.make_output_vec(),
            scratch: plan.make_scratch_vec(),
            plan,
        }
    }

    /// One-sided peak amplitudes of `seg · w` (`seg.len() == w.len() == n`), written to `out`
    /// (`n/2 + 1` values) through `emit(out_k, amplitude_k)`.
    fn amplitudes(
        &mut self,
        seg: &[f64],
        w: &[f64],
        inv_wsum: f64,
        out: &mut [f64],
        emit: impl Fn(&mut f64, f64),
    ) -> Result<()> {
        let n = seg.len();
        for ((d, s), wv) in self.input.iter_mut().zip(seg).zip(w) {
            *d = s * wv;
        }
        self.plan
            .process_with_scratch(&mut self.input, &mut self.output, &mut self.scratch)
            .map_err(|e| Error::fft(n, e))?;
        for (k, (o, c)) in out.iter_mut().zip(&self.output).enumerate() {
            let one_sided = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
            // |c| as √(re² + im²), not `norm()` (libm's `hypot`, which guards against
            // overflow at ~4× the cost; it was 4 % of the service's CPU). Squares overflow only
            // past 1e154, far beyond any record's spectrum.
            emit(o, one_sided * (c.re * c.re + c.im * c.im).sqrt() * inv_wsum);
        }
        Ok(())
    }
}

fn freq_axis(n: usize, sample_rate: f64) -> Vec<f64> {
    (0..=n / 2)
        .map(|k| k as f64 * sample_rate / n as f64)
        .collect()
}

/// One-sided peak-amplitude spectrum of the whole record `x` (one FFT of length `N = x.len()`,
/// any `N ≥ 2`, no zero padding, no detrending).
///
/// Output: bins `k = 0 ..= N/2` at `freq[k] = k · sample_rate / N`, ascending, with
/// `amplitude[k] = c_k |Σ_n w[n] x[n] e^{−2πikn/N}| / Σ_n w[n]`, where `c_k = 1` for DC and the
/// even-`N` Nyquist bin and `2` otherwise. A sine of amplitude `A` on a bin reads `A`; DC reads
/// `|mean|` (rectangular) or the magnitude of the window-weighted mean; with
/// [`Window::FlatTop`] an off-bin sine reads `A` within 0.05 % at its nearest bin.
///
/// FFT plans come from [`PlanCache::global`], so repeated calls with one length plan once.
///
/// Errors: empty record, fewer than 2 samples, non-finite sample
/// ([`Error::EmptyRecord`], [`Error::TooFewSamples`], [`Error::NonFiniteSample`]); non-positive or non-finite `sample_rate`
/// ([`Error::InvalidParameter`]).
pub fn amplitude_spectrum(x: &[f64], sample_rate: f64, window_kind: Window) -> Result<Spectrum> {
    check_rate(sample_rate)?;
    check_samples(x)?;
    check_min_len(x, 2, "an amplitude spectrum")?;
    let n = x.len();
    let w = shared_window(window_kind, n);
    let inv_wsum = 1.0 / w.iter().sum::<f64>();
    let mut amplitude = vec![0.0; n / 2 + 1];
    Fft::new(n).amplitudes(x, &w, inv_wsum, &mut amplitude, |o, a| *o = a)?;
    Ok(Spectrum {
        freq: freq_axis(n, sample_rate),
        amplitude,
    })
}

/// Welch-averaged one-sided peak-amplitude spectrum.
///
/// The record is cut into segments of `segment_len` samples starting every
/// `hop = round(segment_len · (1 − overlap))` samples (at least 1); the tail that does not fill
/// a whole segment is dropped. Each segment is windowed and transformed exactly as in
/// [`amplitude_spectrum`], and the segment amplitudes are averaged **in power**:
/// `amplitude[k] = sqrt(mean_s A_{s,k}²)`. A stationary sine of amplitude `A` therefore still
/// reads `A` (on-bin, or off-bin with [`Window::FlatTop`]), while noise is smoothed.
/// Frequencies are `k · sample_rate / segment_len`, `k = 0 ..= segment_len/2`.
///
/// `overlap` is the overlapping fraction of consecutive segments, `0 ≤ overlap < 1`
/// (0.5 is the usual choice for Hann).
///
/// Errors: empty record or non-finite sample, or a record shorter than one segment
/// ([`Error::TooFewSamples`], …); `segment_len < 2`, `overlap` outside `[0, 1)` or not finite,
/// non-positive or non-finite `sample_rate` ([`Error::InvalidParameter`]).
pub fn welch(
    x: &[f64],
    sample_rate: f64,
    segment_len: usize,
    overlap: f64,
    window_kind: Window,
) -> Result<Spectrum> {
    check_rate(sample_rate)?;
    if segment_len < 2 {
        return Err(Error::param(
            "segment_len",
            segment_len as f64,
            "a Welch segment needs at least 2 samples (typical: a power of two, 256 … 65536)",
        ));
    }
    if !(overlap.is_finite() && (0.0..1.0).contains(&overlap)) {
        return Err(Error::param(
            "overlap",
            overlap,
            "must be a fraction in [0, 1) (0.5 is usual for a Hann window)",
        ));
    }
    check_samples(x)?;
    let l = segment_len;
    if x.len() < l {
        return Err(Error::TooFewSamples {
            analysis: "a Welch segment",
            needed: l,
            samples: x.len(),
        });
    }
    let hop = ((l as f64 * (1.0 - overlap)).round() as usize).clamp(1, l);
    let nseg = 1 + (x.len() - l) / hop;
    let w = shared_window(window_kind, l);
    let inv_wsum = 1.0 / w.iter().sum::<f64>();
    let mut acc = vec![0.0; l / 2 + 1];
    let mut fft = Fft::new(l);
    for s in 0..nseg {
        let seg = &x[s * hop..s * hop + l];
        fft.amplitudes(seg, &w, inv_wsum, &mut acc, |o, a| *o += a * a)?;
    }
    let inv = 1.0 / nseg as f64;
    for a in &mut acc {
        *a = (*a * inv).sqrt();
    }
    Ok(Spectrum {
        freq: freq_axis(l, sample_rate),
        amplitude: acc,
    })
}

/// Peak amplitude (unit of `x`) of the component at exactly `freq` (same time unit as
/// `sample_rate`; need not fall on an FFT bin).
///
/// The mean is removed, the record is multiplied by a periodic Hann window `w`, and the DTFT
/// is evaluated at `freq`: `2 |Σ_n w[n] (x[n] − mean) e^{−2πi·freq·n/sample_rate}| / Σ_n w[n]`.
/// A sine of amplitude `A` at `freq` reads `A`, up to leakage from other components (Hann
/// sidelobes fall as 1/Δ³, so components a few bins `sample_rate/N` away barely matter; the
/// record should span at least ~4 periods of `freq` and of its separation from other lines).
/// Cost O(N).
///
/// Errors: empty record, fewer than 8 samples, non-finite sample ([`Error::TooFewSamples`], [`Error::NonFiniteSample`]);
/// `freq` not in `(0, sample_rate/2)`, non-positive or non-finite `sample_rate`
/// ([`Error::InvalidParameter`]).
pub fn line_amplitude(x: &[f64], sample_rate: f64, freq: f64) -> Result<f64> {
    check_rate(sample_rate)?;
    if !(freq.is_finite() && freq > 0.0 && freq < 0.5 * sample_rate) {
        return Err(Error::param(
            "freq",
            freq,
            format!(
                "must lie strictly between 0 and the Nyquist frequency {} (= sample_rate / 2)",
                0.5 * sample_rate
            ),
        ));
    }
    check_samples(x)?;
    check_min_len(x, 8, "line_amplitude")?;
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n as f64;
    let w = shared_window(Window::Hann, n);
    let wsum: f64 = w.iter().sum();
    let cycles_per_sample = freq / sample_rate;
    let (mut re, mut im) = (0.0, 0.0);
    for (i, (xv, wv)) in x.iter().zip(w.iter()).enumerate() {
        // Reduce the phase to one cycle before scaling by 2π, to keep it accurate for long records.
        let ph = (cycles_per_sample * i as f64).fract() * std::f64::consts::TAU;
        let (s, c) = ph.sin_cos();
        let v = wv * (xv - mean);
        re += v * c;
        im -= v * s;
    }
    Ok(2.0 * re.hypot(im) / wsum)
}

#[cfg(test)]
mod tests {
    use super::super::test_util::lcg;
    use super::super::window::window;
    use super::*;
    use std::f64::consts::PI;

    /// Windows written out independently of `window()` for rectangular and Hann.
    fn reference_window(kind: Window, n: usize) -> Vec<f64> {
        match kind {
            Window::Rectangular => vec![1.0; n],
            Window::Hann => (0..n)
                .map(|i| (PI * i as f64 / n as f64).sin().powi(2)) // = 0.5 − 0.5 cos(2πi/N)
                .collect(),
            Window::FlatTop => window(Window::FlatTop, n),
        }
    }

    /// O(N²) one-sided peak-amplitude spectrum straight from the definition.
    fn naive_spectrum(x: &[f64], w: &[f64]) -> Vec<f64> {
        let n = x.len();
        let wsum: f64 = w.iter().sum();
        (0..=n / 2)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for j in 0..n {
                    // (k·j mod N) keeps the twiddle angle small and exact.
                    let ang = -2.0 * PI * ((k * j) % n) as f64 / n as f64;
                    re += w[j] * x[j] * ang.cos();
                    im += w[j] * x[j] * ang.sin();
                }
                let mag = (re * re + im * im).sqrt() / wsum;
                if k == 0 || 2 * k == n { mag } else { 2.0 * mag }
            })
            .collect()
    }

    fn sine(n: usize, fs: f64, a: f64, f: f64, phase: f64) -> Vec<f64> {
        (0..n)
            .map(|i| a * (2.0 * PI * f * i as f64 / fs + phase).sin())
            .collect()
    }

    #[test]
    fn matches_naive_dft_odd_and_even_lengths() {
        for (idx, &n) in [2usize, 3, 5, 16, 17, 100, 255, 256, 1001]
            .iter()
            .enumerate()
        {
            let x: Vec<f64> = lcg(n, 12345 + idx as u64)
                .into_iter()
                .map(|v| v + 0.3)
                .collect();
            for kind in [Window::Rectangular, Window::Hann, Window::FlatTop] {
                let s = amplitude_spectrum(&x, 7.5, kind).unwrap();
                let r = naive_spectrum(&x, &reference_window(kind, n));
                assert_eq!(s.amplitude.len(), n / 2 + 1);
                assert_eq!(s.freq.len(), n / 2 + 1);
                let big = r.iter().fold(0.0_f64, |a, &v| a.max(v));
                for (k, (a, b)) in s.amplitude.iter().zip(&r).enumerate() {
                    let tol = 1e-9 * b.max(1e-2 * big);
                    assert!(
                        (a - b).abs() <= tol,
                        "n={n} {kind:?} bin {k}: fft {a} vs naive {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn frequency_axis_is_k_fs_over_n() {
        for n in [10usize, 11] {
            let fs = 1234.5;
            let s = amplitude_spectrum(&lcg(n, 1), fs, Window::Hann).unwrap();
            assert_eq!(s.freq.len(), n / 2 + 1);
            for (k, f) in s.freq.iter().enumerate() {
                assert!((f - k as f64 * fs / n as f64).abs() < 1e-12 * fs);
            }
            assert!((s.resolution() - fs / n as f64).abs() < 1e-12);
        }
    }

    #[test]
    fn on_bin_sine_reads_its_amplitude() {
        let (n, fs, a) = (1000, 500.0, 2.5);
        let f = 37.0 * fs / n as f64;
        let x = sine(n, fs, a, f, 0.7);
        for kind in [Window::Rectangular, Window::Hann, Window::FlatTop] {
            let s = amplitude_spectrum(&x, fs, kind).unwrap();
            assert!(
                (s.amplitude[37] - a).abs() < 1e-12,
                "{kind:?}: {}",
                s.amplitude[37]
            );
            assert!((s.at(f) - a).abs() < 1e-12);
            let (pf, pa) = s.peak_near(f + 3.0, 5.0);
            assert!((pf - f).abs() < 1e-12 && (pa - a).abs() < 1e-12);
        }
        // Rectangular: all other bins are (numerically) zero.
        let s = amplitude_spectrum(&x, fs, Window::Rectangular).unwrap();
        for (k, v) in s.amplitude.iter().enumerate() {
            if k != 37 {
                assert!(*v < 1e-12, "bin {k}: {v}");
            }
        }
    }

    #[test]
    fn off_bin_sine_with_flat_top_within_0p1_percent() {
        let (n, fs, a) = (2048, 1000.0, 2.5);
        let df = fs / n as f64;
        for i in 0..=10 {
            let f = (200.0 + i as f64 * 0.05) * df; // up to half a bin off
            let x = sine(n, fs, a, f, 0.3 + i as f64);
            let flat = amplitude_spectrum(&x, fs, Window::FlatTop).unwrap().at(f);
            assert!(
                (flat / a - 1.0).abs() < 1e-3,
                "offset {}: {flat}",
                i as f64 * 0.05
            );
            // Hann at half a bin shows its known ~15 % scalloping loss (sanity: the test
            // really is off-bin).
            if i == 10 {
                let hann = amplitude_spectrum(&x, fs, Window::Hann).unwrap();
                let (_, pk) = hann.peak_near(f, df);
                assert!(pk / a < 0.9 && pk / a > 0.8, "hann half-bin {pk}");
            }
        }
    }

    #[test]
    fn dc_reads_the_mean_and_nyquist_is_not_doubled() {
        let n = 512;
        let x: Vec<f64> = lcg(n, 99).iter().map(|v| v - 1.25).collect();
        let mean = x.iter().sum::<f64>() / n as f64;
        let s = amplitude_spectrum(&x, 1.0, Window::Rectangular).unwrap();
        assert!((s.amplitude[0] - mean.abs()).abs() < 1e-12);
        // Constant plus on-bin sine: every window reads the constant at DC.
        let y: Vec<f64> = sine(n, 1.0, 1.0, 20.0 / n as f64, 0.0)
            .iter()
            .map(|v| v + 0.8)
            .collect();
        for kind in [Window::Rectangular, Window::Hann, Window::FlatTop] {
            let s = amplitude_spectrum(&y, 1.0, kind).unwrap();
            assert!((s.amplitude[0] - 0.8).abs() < 1e-12, "{kind:?}");
        }
        // (−1)^n of amplitude 0.6 sits on the Nyquist bin and reads 0.6.
        let z: Vec<f64> = (0..n)
            .map(|i| if i % 2 == 0 { 0.6 } else { -0.6 })
            .collect();
        let s = amplitude_spectrum(&z, 1.0, Window::Rectangular).unwrap();
        assert!((s.amplitude[n / 2] - 0.6).abs() < 1e-12);
        assert!((s.freq[n / 2] - 0.5).abs() < 1e-15);
    }

    #[test]
    fn parseval_rectangular() {
        // Mean square of the record = A0² + Σ A_k²/2 (interior bins) + A_{N/2}² (even N).
        for n in [1000usize, 1001] {
            let x: Vec<f64> = lcg(n, 7).iter().map(|v| 2.0 * v + 0.4).collect();
            let ms = x.iter().map(|v| v * v).sum::<f64>() / n as f64;
            let a = amplitude_spectrum(&x, 3.0, Window::Rectangular)
                .unwrap()
                .amplitude;
            let mut p = a[0] * a[0];
            for (k, v) in a.iter().enumerate().skip(1) {
                p += if 2 * k == n { v * v } else { v * v / 2.0 };
            }
            assert!((p / ms - 1.0).abs() < 1e-12, "n={n}: {p} vs {ms}");
        }
    }

    #[test]
    fn line_amplitude_recovers_off_bin_lines() {
        // Base frequency 1, 80 base periods, components at 0.36 and 0.0875 of it,
        // sample rate not a multiple of anything involved.
        let fs = 64.7;
        let n = (80.0 * fs) as usize;
        let comps = [(0.36, 1.3, 0.4), (0.0875, 0.7, -1.1), (1.0, 2.0, 0.0)];
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                0.5 + comps
                    .iter()
                    .map(|(f, a, p)| a * (2.0 * PI * f * t + p).sin())
                    .sum::<f64>()
            })
            .collect();
        for (f, a, _) in comps {
            let got = line_amplitude(&x, fs, f).unwrap();
            assert!((got / a - 1.0).abs() < 0.01, "f={f}: {got} vs {a}");
        }
        // A frequency with no component reads (nearly) nothing.
        assert!(line_amplitude(&x, fs, 0.6).unwrap() < 0.01);
    }

    #[test]
    fn line_amplitude_removes_a_large_mean() {
        // A line only 2.5 bins above DC on top of an offset 500× its amplitude: without the
        // mean removal, the Hann leakage of the DC term would swamp it.
        let (n, fs) = (400usize, 100.0);
        let f = 2.5 * fs / n as f64;
        let x: Vec<f64> = sine(n, fs, 0.3, f, 0.9).iter().map(|v| v + 150.0).collect();
        let got = line_amplitude(&x, fs, f).unwrap();
        assert!((got / 0.3 - 1.0).abs() < 0.01, "{got}");
    }

    #[test]
    fn welch_reads_stationary_sine_amplitude() {
        let (fs, a) = (1000.0, 1.8);
        let f = 123.4; // off the 1000/1024 bin grid
        let x: Vec<f64> = sine(50_000, fs, a, f, 0.2)
            .iter()
            .zip(lcg(50_000, 3))
            .map(|(s, r)| s + 0.2 * r)
            .collect();
        let s = welch(&x, fs, 1024, 0.5, Window::FlatTop).unwrap();
        assert_eq!(s.freq.len(), 513);
        assert!((s.resolution() - fs / 1024.0).abs() < 1e-12);
        assert!((s.at(f) / a - 1.0).abs() < 0.01, "{}", s.at(f));
        // On-bin with Hann.
        let f2 = 100.0 * fs / 1024.0;
        let y = sine(20_000, fs, a, f2, 1.0);
        let s = welch(&y, fs, 1024, 0.5, Window::Hann).unwrap();
        assert!((s.amplitude[100] / a - 1.0).abs() < 0.01);
    }

    #[test]
    fn welch_is_power_average_of_naive_segment_spectra() {
        let (l, ov) = (64usize, 0.5);
        let x = lcg(300, 11);
        let s = welch(&x, 2.0, l, ov, Window::Hann).unwrap();
        // hop 32 → segments at 0, 32, …, 224 (8 segments); tail dropped.
        let w = reference_window(Window::Hann, l);
        let segs: Vec<Vec<f64>> = (0..8)
            .map(|i| naive_spectrum(&x[32 * i..32 * i + l], &w))
            .collect();
        for k in 0..=l / 2 {
            let r = (segs.iter().map(|a| a[k] * a[k]).sum::<f64>() / 8.0).sqrt();
            assert!((s.amplitude[k] - r).abs() <= 1e-9 * r.max(1e-3), "bin {k}");
            assert!((s.freq[k] - k as f64 * 2.0 / l as f64).abs() < 1e-15);
        }
    }

    #[test]
    fn spectra_use_the_plan_cache() {
        let n = 4111; // unusual length, not used elsewhere in the tests
        let _ = amplitude_spectrum(&lcg(n, 5), 1.0, Window::Hann).unwrap();
        assert!(PlanCache::global().contains(n));
        let _ = welch(&lcg(n, 5), 1.0, 1037, 0.25, Window::Hann).unwrap();
        assert!(PlanCache::global().contains(1037));
    }

    #[test]
    fn spectrum_lookups() {
        let s = Spectrum {
            freq: vec![0.0, 1.0, 2.0, 3.0, 4.0],
            amplitude: vec![0.1, 0.5, 0.2, 0.9, 0.3],
        };
        assert_eq!(s.resolution(), 1.0);
        assert_eq!(s.at(1.4), 0.5);
        assert_eq!(s.at(1.6), 0.2);
        assert_eq!(s.at(-0.4), 0.1);
        assert_eq!(s.at(4.4), 0.3);
        assert!(s.at(4.6).is_nan() && s.at(-0.6).is_nan() && s.at(f64::NAN).is_nan());
        assert_eq!(s.peak_near(1.0, 1.0), (1.0, 0.5));
        assert_eq!(s.peak_near(2.0, 1.0), (3.0, 0.9));
        assert_eq!(s.peak_near(2.2, 0.1), (2.0, 0.2)); // no bin inside: nearest
        assert!(s.peak_near(2.0, -1.0).0.is_nan());
        assert!(s.peak_near(10.0, 0.1).1.is_nan());
        let empty = Spectrum {
            freq: vec![],
            amplitude: vec![],
        };
        assert!(empty.resolution().is_nan() && empty.at(0.0).is_nan());
        assert!(empty.peak_near(0.0, 1.0).0.is_nan());
    }

    fn is_signal(e: &Error) -> bool {
        matches!(
            e,
            Error::TooFewSamples { .. } | Error::EmptyRecord | Error::NonFiniteSample { .. }
        )
    }
    fn is_param(e: &Error, name: &str) -> bool {
        matches!(e, Error::InvalidParameter { name: n, .. } if n == name)
    }

    #[test]
    fn error_paths() {
        let ok = lcg(64, 1);
        let mut bad = ok.clone();
        bad[10] = f64::NAN;
        let w = Window::Hann;

        // Empty and NaN samples.
        for e in [
            amplitude_spectrum(&[], 1.0, w).unwrap_err(),
            welch(&[], 1.0, 16, 0.5, w).unwrap_err(),
            line_amplitude(&[], 1.0, 0.1).unwrap_err(),
        ] {
            assert!(matches!(e, Error::EmptyRecord), "{e}");
        }
        for e in [
            amplitude_spectrum(&bad, 1.0, w).unwrap_err(),
            welch(&bad, 1.0, 16, 0.5, w).unwrap_err(),
            line_amplitude(&bad, 1.0, 0.1).unwrap_err(),
        ] {
            assert!(is_signal(&e) && e.to_string().contains("sample 10"), "{e}");
        }
        // Sample rate 0, negative, NaN, infinite.
        for fs in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            for e in [
                amplitude_spectrum(&ok, fs, w).unwrap_err(),
                welch(&ok, fs, 16, 0.5, w).unwrap_err(),
                line_amplitude(&ok, fs, 0.1).unwrap_err(),
            ] {
                assert!(is_param(&e, "sample_rate"), "{e}");
            }
        }
        // Too short.
        assert!(is_signal(&amplitude_spectrum(&[1.0], 1.0, w).unwrap_err()));
        assert!(is_signal(&line_amplitude(&[1.0; 7], 1.0, 0.1).unwrap_err()));
        let e = welch(&ok, 1.0, 65, 0.5, w).unwrap_err();
        assert!(
            matches!(
                e,
                Error::TooFewSamples {
                    needed: 65,
                    samples: 64,
                    ..
                }
            ),
            "{e}"
        );
        // Bad Welch parameters.
        for l in [0, 1] {
            assert!(is_param(
                &welch(&ok, 1.0, l, 0.5, w).unwrap_err(),
                "segment_len"
            ));
        }
        for ov in [-0.1, 1.0, f64::NAN] {
            assert!(is_param(
                &welch(&ok, 1.0, 16, ov, w).unwrap_err(),
                "overlap"
            ));
        }
        // Line frequency outside (0, Nyquist).
        for f in [0.0, -0.1, 0.5, 0.7, f64::NAN] {
            assert!(is_param(&line_amplitude(&ok, 1.0, f).unwrap_err(), "freq"));
        }
        // Extreme but finite samples do not panic.
        let huge = vec![1e300; 16];
        assert!(amplitude_spectrum(&huge, 1.0, w).is_ok());
        // Exactly one segment: same as a plain spectrum; overlap close to 1 still terminates.
        let a = welch(&ok, 1.0, 64, 0.999, w).unwrap();
        let b = amplitude_spectrum(&ok, 1.0, w).unwrap();
        assert_eq!(a.amplitude.len(), b.amplitude.len());
        for (p, q) in a.amplitude.iter().zip(&b.amplitude) {
            assert!((p - q).abs() < 1e-15);
        }
    }
}
