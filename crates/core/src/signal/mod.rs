//! Windows, amplitude spectra, simple signal statistics, and the line estimator ([`lines`]:
//! Hann DTFT amplitudes of lines at multiples of a mesh frequency, shared by the signature
//! table, the diagnosis and the closed loop), the search for a gearbox's stage-1 mesh line
//! ([`mesh_search`]), order tracking and angular resampling ([`order`]) and the
//! time-synchronous average with its gear condition metrics and the order analysis of every
//! shaft of a gear train ([`tsa`]), and the velocity RMS over a band and the acceleration level
//! of a record in SI units ([`velocity`]).
//!
//! # Conventions (read this first)
//!
//! * **Units.** Samples are in whatever unit the caller uses (m/s², rad, …); amplitudes come
//!   out in the same unit. Sample rates are in samples per unit of time and frequencies in
//!   cycles per the same unit of time (Hz for seconds; "per period" for dimensionless time).
//! * **Spectra are one-sided with *peak amplitude* scaling.** For a record `x[0..N]`, window
//!   `w[0..N]` and `X_k = Σ_n w[n] x[n] e^{−2πikn/N}` (unnormalised DFT, as computed by
//!   RustFFT/realfft), the spectrum holds bins `k = 0 ..= N/2` (integer division) in
//!   **ascending frequency** `f_k = k · fs / N`, with
//!     - `A_0 = |X_0| / Σw` (DC: the absolute value of the window-weighted mean, i.e. the
//!       plain mean's magnitude for a rectangular window),
//!     - `A_k = 2 |X_k| / Σw` for `0 < k < N/2`, and for `k = (N−1)/2` when `N` is odd,
//!     - `A_{N/2} = |X_{N/2}| / Σw` for the Nyquist bin when `N` is even.
//!
//!   So a sine `A sin(2πft + φ)` whose frequency falls on a bin reads `A` at that bin (any
//!   window); between bins the rectangular and Hann windows read low (scalloping) while the
//!   flat-top window reads `A` within 0.05 %.
//! * **No detrending**: the mean is kept (it is the DC bin), except in [`line_amplitude`],
//!   which removes it.
//! * **Validation**: every function refuses empty records, NaN/±∞ samples, and non-positive or
//!   non-finite sample rates with a typed [`Error`] ([`Error::TooFewSamples`], [`Error::InvalidParameter`], …)
//!   that says what to change. Nothing here panics on any input. The plain statistics
//!   [`rms`], [`kurtosis`], [`crest_factor`] return `f64` for convenience and give `NaN` for
//!   unusable input; their `try_*` twins return the explanatory error instead.

pub mod features;
pub mod lines;
pub mod mesh_search;
pub mod order;
mod phasor;
mod plan;
mod spectrum;
mod stats;
pub mod tsa;
pub mod velocity;
mod window;

pub(crate) use phasor::{dtft_sums, unit_phasors};
pub use plan::PlanCache;
pub use spectrum::{Spectrum, amplitude_spectrum, line_amplitude, welch};
pub use stats::{crest_factor, kurtosis, median, rms, try_crest_factor, try_kurtosis, try_rms};
pub use window::{Window, shared_window, window};

use crate::{Error, Result};

/// Refuse an empty record or one with a non-finite sample.
fn check_samples(x: &[f64]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::EmptyRecord);
    }
    if let Some((i, v)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(Error::NonFiniteSample {
            index: i,
            value: *v,
        });
    }
    Ok(())
}

/// Refuse a record shorter than `min` samples (after [`check_samples`]).
fn check_min_len(x: &[f64], min: usize, what: &'static str) -> Result<()> {
    if x.len() < min {
        return Err(Error::TooFewSamples {
            analysis: what,
            needed: min,
            samples: x.len(),
        });
    }
    Ok(())
}

/// Refuse a non-positive or non-finite sample rate.
fn check_rate(sample_rate: f64) -> Result<()> {
    if !(sample_rate.is_finite() && sample_rate > 0.0) {
        return Err(Error::param(
            "sample_rate",
            sample_rate,
            "must be a finite number > 0 (samples per unit time)",
        ));
    }
    Ok(())
}

/// Helpers the signal modules' (and the condition modules') unit tests share.
#[cfg(test)]
pub(crate) mod test_util {
    /// Deterministic pseudo-random samples in [-1, 1) from a 64-bit LCG (Knuth's MMIX
    /// constants).
    pub fn lcg(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            })
            .collect()
    }
}
