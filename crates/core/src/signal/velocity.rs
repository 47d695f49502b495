//! Vibration velocity over a band, by integration in the frequency domain, and the level
//! (RMS and peak) of a record's acceleration — the figures of ISO 20816 and of every
//! vibration analyst's first look. Samples are in SI units here: acceleration in m/s²,
//! velocity in m/s (the conversion from a sensor's unit is [`crate::units`]'s).
//!
//! # Velocity RMS
//!
//! A record `x[n]`, `n = 0 … N−1`, at sample rate `fs` (Hz), of acceleration `a` (m/s²) or of
//! velocity `v` (m/s):
//!
//! 1. **Detrend**: `x̃[n] = x[n] − (α + β n)`, the least-squares line removed. A sensor's offset
//!    (a DC-coupled accelerometer reads gravity) and a linear drift are not vibration, and
//!    integrated (÷ 2πf) they would swamp the lowest bins.
//! 2. **Window**: `y[n] = w[n] x̃[n]`, `w[n] = ½ − ½ cos(2πn/N)` (periodic Hann). The record's
//!    periodic extension is then continuous with a continuous slope, so a line's leakage falls
//!    as 1/f³: content below the band (a slow shaft, what remains of a drift) does not leak
//!    into it, and the ends of the record do not ring.
//! 3. **Transform**: `Y_k = Σ_n y[n] e^{−2πikn/N}` (one real FFT of the whole record),
//!    `f_k = k fs / N`.
//! 4. **Integrate and band-limit, summing power** (Parseval):
//!
//!    `v_rms² = Σ_{k=1}^{⌊N/2⌋} c_k |Y_k|² H(f_k)² G(f_k)² / (N Σ_n w[n]²)`
//!
//!    with `c_k = 2` (1 for the Nyquist bin of an even `N`), `G(f) = 1/(2πf)` for an
//!    acceleration record (`V = A / jω`; the phase does not enter a power sum) and `G = 1` for a
//!    velocity record, and `H` the band's weight ([`Band::weight`]).
//!
//! With `G = H = 1` the sum is `Σ w² x̃² / Σ w²`, the window-weighted mean square: a sine
//! `A sin(2πft)` reads `A²/2` at any frequency, on a bin or between bins (the bins it leaks into
//! sum to its power). With `G = 1/(2πf)` it reads `(A/2πf)²/2`, up to the spread of the
//! window's main lobe (±2 bins, ±2/T Hz for a record of T s) over a `1/f²` that changes
//! across it — a bias of about `+(1/(T f))²` in power, +0.5 % in RMS at 10 Hz for 1 s,
//! +0.005 % at 100 Hz — and, at the band's edges, the weight that lobe's outer bins get (see
//! [`Band::weight`]). The measured errors are in `docs/diagnosis.md` ("Physical units").
//!
//! # Acceleration level
//!
//! [`acceleration_level`]: the RMS and the largest absolute value of the acceleration less its
//! mean (an AC-coupled reading: a sensor's offset is not vibration) over the whole record
//! (0 < f ≤ fs/2). Only the mean: removing a line as well would bend a slow line's crests (by
//! about `6 / (2πf T)` of its amplitude at the record's ends: 2 % at 10 Hz for 1 s). A velocity
//! record is differentiated in the frequency domain (`A = jω V`) after a cosine taper over its
//! first and last [`TAPER`] × N samples, and its level is read over the untapered interior
//! only, where the derivative is the record's own (less its mean there: a drift's constant
//! slope); above the sensor's band the derivative is its noise × 2πf.

use realfft::num_complex::Complex;
use serde::Serialize;

use super::window::{Window, shared_window};
use super::{PlanCache, check_min_len, check_rate, check_samples};
use crate::{Error, Result};

/// What a record's samples measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kinematic {
    /// Acceleration (m/s²): an accelerometer.
    Acceleration,
    /// Velocity (m/s): a velocity sensor.
    Velocity,
}

/// A frequency band with smooth edges (Hz).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    pub lo_hz: f64,
    pub hi_hz: f64,
}

/// ISO 20816-3's band for machines running above 600 r/min (ISO 20816-1 § 5, ISO 2954):
/// 10–1000 Hz.
pub const ISO_BAND: Band = Band {
    lo_hz: 10.0,
    hi_hz: 1000.0,
};

/// The lower transition spans this factor below `lo_hz` (an octave).
const LOWER_SPAN: f64 = 2.0;
/// The upper transition spans this factor above `hi_hz` (a third-octave, 2^(1/3)).
const UPPER_SPAN: f64 = 1.259_921_049_894_873_2;

/// Periods of the band's lower edge a record must hold for a velocity over the band: 5
/// (0.5 s for 10 Hz). The Hann window's main lobe (±2/T Hz) then lies within the lower
/// transition (an octave, 5 Hz wide at 10 Hz), so a line at the lower edge keeps most of its
/// power; the errors at 10 Hz are measured for 0.5, 1 and 2 s.
pub const MIN_PERIODS: f64 = 5.0;

/// Fraction of a velocity record tapered at each end before it is differentiated.
pub const TAPER: f64 = 0.1;

impl Band {
    /// The weight `H(f)` of a line at `f` Hz (its amplitude's; power is weighted by `H²`):
    ///
    /// * `1` on `[lo, hi]`, edges included (a line at 10 Hz or 1000 Hz counts in full, as ISO
    ///   2954 asks of a velocity meter within its tolerance of 0.8–1.1 there);
    /// * `sin²(π/2 · log₂(f/(lo/2)))` over the octave below, `lo/2 ≤ f < lo` (0 at 5 Hz,
    ///   0.5 at 7.07 Hz, 0.94 at 9 Hz for the ISO band);
    /// * `cos²(π/2 · log(f/hi) / log 2^(1/3))` over the third-octave above, `hi < f ≤ 2^(1/3)
    ///   hi` (0.5 at 1122 Hz, 0 at 1260 Hz);
    /// * `0` elsewhere (and for `f ≤ 0`).
    ///
    /// Smooth edges (continuous with a continuous slope) instead of a brick wall: a line that
    /// sits on an edge is not counted or dropped by a fraction of a bin.
    pub fn weight(&self, f: f64) -> f64 {
        let (lo0, hi1) = (self.lo_hz / LOWER_SPAN, self.hi_hz * UPPER_SPAN);
        if !(f > lo0 && f < hi1) {
            0.0
        } else if f < self.lo_hz {
            let u = (f / lo0).ln() / LOWER_SPAN.ln();
            (std::f64::consts::FRAC_PI_2 * u).sin().powi(2)
        } else if f <= self.hi_hz {
            1.0
        } else {
            let u = (f / self.hi_hz).ln() / UPPER_SPAN.ln();
            (std::f64::consts::FRAC_PI_2 * u).cos().powi(2)
        }
    }

    /// The shortest record (s) [`velocity_rms`] takes over this band.
    pub fn min_seconds(&self) -> f64 {
        MIN_PERIODS / self.lo_hz
    }

    /// Refuse a record this band cannot be measured in: shorter than [`Band::min_seconds`], or
    /// sampled at or below twice the band's upper edge.
    pub fn check_record(&self, samples: usize, fs: f64) -> Result<()> {
        let seconds = samples as f64 / fs;
        if seconds < self.min_seconds() {
            return Err(Error::RecordTooShortForBand {
                seconds,
                needed_seconds: self.min_seconds(),
                periods: MIN_PERIODS,
                lo_hz: self.lo_hz,
                hi_hz: self.hi_hz,
            });
        }
        if fs <= 2.0 * self.hi_hz {
            return Err(Error::SampleRateBelowBand {
                sample_rate: fs,
                nyquist_hz: fs / 2.0,
                needed: 2.0 * self.hi_hz,
                lo_hz: self.lo_hz,
                hi_hz: self.hi_hz,
            });
        }
        Ok(())
    }
}

/// `x` less its least-squares line `α + β n` (mean and linear drift removed).
pub fn detrend(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let nf = n as f64;
    let mid = (nf - 1.0) / 2.0;
    let mean = x.iter().sum::<f64>() / nf;
    // Σ (n − mid)² = N (N² − 1) / 12.
    let stt = nf * (nf * nf - 1.0) / 12.0;
    let slope = x
        .iter()
        .enumerate()
        .map(|(i, v)| (i as f64 - mid) * (v - mean))
        .sum::<f64>()
        / stt;
    x.iter()
        .enumerate()
        .map(|(i, v)| v - mean - slope * (i as f64 - mid))
        .collect()
}

/// The one-sided spectrum `Y_k`, `k = 0 ..= N/2`, of `y` (one real FFT).
fn real_fft(mut y: Vec<f64>) -> Result<Vec<Complex<f64>>> {
    let n = y.len();
    let plan = PlanCache::global().forward(n);
    let mut out = plan.make_output_vec();
    plan.process(&mut y, &mut out)
        .map_err(|e| Error::fft(n, e))?;
    Ok(out)
}

/// Velocity RMS (m/s) of a record of acceleration (m/s²) or velocity (m/s) over `band`
/// (the method and its equations are in the [module docs](self)).
///
/// Errors: empty record, non-finite sample, non-positive sample rate; a record shorter than
/// [`Band::min_seconds`] ([`Error::RecordTooShortForBand`]) or sampled at or below twice the
/// band's upper edge ([`Error::SampleRateBelowBand`]).
pub fn velocity_rms(x: &[f64], fs: f64, input: Kinematic, band: Band) -> Result<f64> {
    check_rate(fs)?;
    check_samples(x)?;
    band.check_record(x.len(), fs)?;
    let n = x.len();
    let w = shared_window(Window::Hann, n);
    let y: Vec<f64> = detrend(x)
        .iter()
        .zip(w.iter())
        .map(|(v, w)| v * w)
        .collect();
    let spectrum = real_fft(y)?;
    let df = fs / n as f64;
    let mut power = 0.0;
    for (k, c) in spectrum.iter().enumerate().skip(1) {
        let f = k as f64 * df;
        let h = band.weight(f);
        if h == 0.0 {
            continue;
        }
        let g = match input {
            Kinematic::Acceleration => 1.0 / (std::f64::consts::TAU * f),
            Kinematic::Velocity => 1.0,
        };
        let one_sided = if 2 * k == n { 1.0 } else { 2.0 };
        power += one_sided * c.norm_sqr() * (h * g).powi(2);
    }
    let w2: f64 = w.iter().map(|v| v * v).sum();
    Ok((power / (n as f64 * w2)).sqrt())
}

/// The RMS and the peak (largest absolute value) of a signal, in its unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Level {
    pub rms: f64,
    pub peak: f64,
}

impl Level {
    fn of(x: &[f64]) -> Level {
        let peak = x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let rms = if peak == 0.0 {
            0.0
        } else {
            peak * (x.iter().map(|v| (v / peak).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
        };
        Level { rms, peak }
    }
}

/// The acceleration level (m/s²) of a record of acceleration (m/s²) or velocity (m/s): RMS and
/// peak of the acceleration less its mean, over the whole band (see the [module docs](self)).
///
/// Errors: empty record, non-finite sample, non-positive sample rate; a velocity record of
/// fewer than 20 samples (too short to taper).
pub fn acceleration_level(x: &[f64], fs: f64, input: Kinematic) -> Result<Level> {
    check_rate(fs)?;
    check_samples(x)?;
    match input {
        Kinematic::Acceleration => Ok(Level::of(&less_mean(x))),
        Kinematic::Velocity => {
            check_min_len(x, 20, "differentiating a velocity record")?;
            let (a, taper) = differentiate(x, fs)?;
            Ok(Level::of(&less_mean(&a[taper..a.len() - taper])))
        }
    }
}

/// `x` less its mean.
fn less_mean(x: &[f64]) -> Vec<f64> {
    let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
    x.iter().map(|v| v - mean).collect()
}

/// `dv/dt` of a velocity record in the frequency domain (`A_k = j 2π f_k V_k`, the Nyquist bin
/// of an even `N` dropped: its derivative is not defined), after removing its mean and a
/// cosine taper over `taper` samples at each end; with `taper`.
fn differentiate(v: &[f64], fs: f64) -> Result<(Vec<f64>, usize)> {
    let n = v.len();
    let taper = ((TAPER * n as f64).ceil() as usize).max(1);
    let mut y = less_mean(v);
    for i in 0..taper {
        let w = 0.5 - 0.5 * (std::f64::consts::PI * i as f64 / taper as f64).cos();
        y[i] *= w;
        y[n - 1 - i] *= w;
    }
    let mut spectrum = real_fft(y)?;
    let df = fs / n as f64;
    for (k, c) in spectrum.iter_mut().enumerate() {
        let omega = std::f64::consts::TAU * k as f64 * df;
        *c = if k == 0 || 2 * k == n {
            Complex::new(0.0, 0.0)
        } else {
            Complex::new(-omega * c.im, omega * c.re) / n as f64
        };
    }
    let plan = PlanCache::global().inverse(n);
    let mut a = plan.make_output_vec();
    plan.process(&mut spectrum, &mut a)
        .map_err(|e| Error::fft(n, e))?;
    Ok((a, taper))
}

#[cfg(test)]
mod tests;
