//! The normalised log-spectrum the closed loop compares, and its error figure.
//!
//! A record `x[n]` (sample rate `fs`, stage-1 mesh frequency `f1`) is cut into Hann-windowed
//! segments of `L = round(GRID_PERIODS · fs / f1)` samples with 50 % overlap (Welch, peak
//! amplitude scaling: a sine of amplitude `A` on a bin reads `A`). The amplitude spectrum is
//! read on the fixed grid of normalised frequencies
//!
//! `r_j = BAND_LO + j / GRID_PERIODS`, `j = 0, 1, …` while `r_j ≤ BAND_HI`
//!
//! (`r = f / f1`), by linear interpolation of the amplitude `A` between the two neighbouring
//! bins, then `20 log10`. (Interpolating `20 log10 A` instead would be wrong: a grid point
//! 0.4 bin past a bin-centred line's last non-zero bin then took 40 % of the nearly empty next
//! bin's dB value (the grid point read −184 dB in the test below), so a simulated line — exactly on a bin, nothing in the bins beyond ±1 — ended
//! one grid point early while a measured one, never exactly on a bin and with noise around it,
//! did not. Every line's skirt then read as an "extra" line 1.4–1.6 grid steps either side on
//! clean records, at f1 ± the 100-tooth gear's shaft rate, and a damaged tooth on that gear —
//! sidebands at ±1.28 grid steps — fitted the artefact.)
//! The grid step equals the bin spacing, `f1 / GRID_PERIODS`: with 128 periods the input-shaft
//! sidebands `f1 ± f1/29` sit 4.4 bins from the mesh line and are resolved.
//!
//! **Error figure** (used for `error_before` / `error_after`): the RMS log-spectral distance in
//! dB over the grid,
//!
//! `E = sqrt( (1/J) Σ_j (M_j − F_j)² )`, `M_j = 20 log10 A_meas(r_j)`, `F_j` the fitted model,
//!
//! both in dB of the same unit (the model's gain is a fitted parameter).

use crate::error::{Error, Result};
use crate::signal::{Window, welch};

/// Segment length of the closed-loop spectrum, in stage-1 mesh periods (grid step f1/128).
pub const GRID_PERIODS: f64 = 128.0;
/// Lower band edge (units of f1).
pub const BAND_LO: f64 = 0.05;
/// Upper band edge (units of f1).
pub const BAND_HI: f64 = 2.5;

/// The fixed normalised-frequency grid `r_j` (units of f1).
pub fn grid() -> Vec<f64> {
    let n = ((BAND_HI - BAND_LO) * GRID_PERIODS).floor() as usize + 1;
    (0..n).map(|j| BAND_LO + j as f64 / GRID_PERIODS).collect()
}

/// Amplitude spectrum of `x` in dB (20 log10 of the peak amplitude, unit of `x`) on [`grid`].
pub fn log_spectrum(x: &[f64], fs: f64, f1: f64) -> Result<Vec<f64>> {
    if !(f1 > 0.0 && fs > 2.0 * BAND_HI * f1) {
        return Err(Error::param(
            "f1",
            f1,
            format!("need 0 < f1 and fs = {fs} Hz > 2 × {BAND_HI} f1"),
        ));
    }
    let len = (GRID_PERIODS * fs / f1).round() as usize;
    if x.len() < len {
        return Err(Error::RecordTooShort {
            samples: x.len(),
            periods: x.len() as f64 * f1 / fs,
            f1_hz: f1,
            needed_periods: GRID_PERIODS as usize,
            needed_samples: len,
        });
    }
    let s = welch(x, fs, len, 0.5, Window::Hann)?;
    let res = s.resolution();
    let a = &s.amplitude;
    Ok(grid()
        .iter()
        .map(|r| {
            let pos = r * f1 / res;
            let i = (pos.floor() as usize).min(a.len() - 2);
            let u = (pos - i as f64).clamp(0.0, 1.0);
            20.0 * (a[i] * (1.0 - u) + a[i + 1] * u).max(1e-300).log10()
        })
        .collect())
}

/// RMS distance `sqrt(mean((a − b)²))` in dB.
pub fn rms_distance(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1) as f64;
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n).sqrt()
}

/// Index of the grid point nearest `r` (units of f1), if inside the band.
pub fn grid_index(r: f64) -> Option<usize> {
    if !(BAND_LO - 0.5 / GRID_PERIODS..=BAND_HI + 0.5 / GRID_PERIODS).contains(&r) {
        return None;
    }
    let j = ((r - BAND_LO) * GRID_PERIODS).round();
    let n = grid().len();
    Some((j.max(0.0) as usize).min(n - 1))
}

/// Running median of `v` over `±half` points (the smooth trend of a residual).
pub fn running_median(v: &[f64], half: usize) -> Vec<f64> {
    (0..v.len())
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(v.len());
            let mut w: Vec<f64> = v[lo..hi].to_vec();
            w.sort_by(f64::total_cmp);
            w[w.len() / 2]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid value 1.4 bins beside a line (the grid sits 0.4 bin past the bins, `BAND_LO`)
    /// must not depend on whether the line is exactly on a bin: a simulated line is, a measured
    /// one never is. Interpolating in dB, the bin-centred line read −184 dB against −28 dB at
    /// r = 0.9875.
    #[test]
    fn a_lines_skirt_reads_the_same_on_and_off_a_bin() {
        let f1 = 1.0;
        let fs = 32.0;
        let n = 4096 * 3;
        let tone = |f: f64| -> Vec<f64> {
            (0..n)
                .map(|k| (std::f64::consts::TAU * f * k as f64 / fs).sin())
                .collect()
        };
        let on = log_spectrum(&tone(1.0), fs, f1).unwrap();
        // 0.05 bin off, with a −80 dB floor of tiny tones elsewhere (a measured record's noise).
        let mut off = tone(1.0 + 0.05 / GRID_PERIODS);
        for (k, v) in off.iter_mut().enumerate() {
            *v += 1e-4 * (std::f64::consts::TAU * 0.31 * k as f64 / fs).sin();
        }
        let off = log_spectrum(&off, fs, f1).unwrap();
        let j = grid_index(1.0).unwrap();
        // The four grid points a bin-centred Hann line reaches (bins 127–129 of 128 periods).
        for k in [j - 2, j - 1, j, j + 1] {
            assert!(
                (on[k] - off[k]).abs() < 3.0,
                "grid point {k} (r = {:.4}): {:.1} dB on a bin, {:.1} dB off it",
                grid()[k],
                on[k],
                off[k]
            );
        }
        // The line itself reads within the Hann scalloping of its amplitude (1, i.e. 0 dB).
        assert!(on[j].max(on[j + 1]) > -3.5 && on[j].max(on[j + 1]) < 0.1);
    }
}
