//! The input shaft's rate from the record itself (no tachometer): the rate at which the
//! record's spectral lines line up with **every** shaft's harmonics.
//!
//! At the true input rate `f`, every line a shaft of the train makes sits at `o · f` for an
//! order `o` on the common period's grid ([`super::lines`]: `j/P`, the orders some shaft owns);
//! a rate off by `δ` moves the line at order `o` by `o δ f`, off the bins the grid predicts.
//! Each line's **prominence** is its log amplitude over the mean log amplitude of the bins
//! around it (a local geometric mean) where its bin is a local maximum, counted from 0 (below
//! the background, or on another line's skirt) to
//! [`MAX_PROMINENCE`] (so that a few strong mesh lines do not outvote the many sidebands and
//! shaft lines); the rate's score is the sum over every grid line up to the search's highest
//! order. Two passes: the whole window `hint · (1 ± search)` at a step that moves the highest
//! line by half a bin, over the orders up to 1.5 × the highest mesh order; then, around the
//! best few, a step a quarter of that over the orders up to 3 × the highest mesh order.
//!
//! Many lines make the score sharp where one or a few mesh lines are ambiguous (a mesh line
//! at `k O_i f` is also near `k' O_i f'` for another rate, and a dense spectrum has a line
//! near almost anywhere).

use super::lines::LineMap;
use crate::error::SpeedProblem;
use crate::signal::{Window, amplitude_spectrum};
use crate::{Error, Result};

/// Largest prominence a line counts for (ln: ≈ 26 dB).
pub const MAX_PROMINENCE: f64 = 3.0;
/// Weight of a mesh harmonic against another line of the grid: the mesh lines are what every
/// gearbox makes, so a sparse spectrum (a few lines) is read at the rate that puts them on a
/// mesh order, not on some other line of the grid.
pub const MESH_WEIGHT: f64 = 5.0;
/// Bins either side of a line in its background.
const BACKGROUND_BINS: usize = 24;
/// Most samples read (the first ones): 2¹⁹, ≈ 8 s at 66.7 kHz.
const MAX_SAMPLES: usize = 1 << 19;

/// Per bin that is a local maximum: `ln A` minus the mean of `ln A` over the
/// [`BACKGROUND_BINS`] either side (`A` floored 180 dB under the largest bin, so that round-off
/// between the lines of a noiseless record is no background); 0 elsewhere.
fn prominence(amplitude: &[f64]) -> Vec<f64> {
    let floor = 1e-9 * amplitude.iter().fold(0.0f64, |a, &b| a.max(b));
    let l: Vec<f64> = amplitude
        .iter()
        .map(|a| a.max(floor).max(1e-300).ln())
        .collect();
    let n = l.len();
    let mut cum = vec![0.0; n + 1];
    for i in 0..n {
        cum[i + 1] = cum[i] + l[i];
    }
    (0..n)
        .map(|i| {
            // Only a local maximum is a line (not the skirt of its window's leakage).
            let peak = (i == 0 || l[i] >= l[i - 1]) && (i + 1 == n || l[i] >= l[i + 1]);
            if !peak {
                return 0.0;
            }
            let lo = i.saturating_sub(BACKGROUND_BINS);
            let hi = (i + BACKGROUND_BINS + 1).min(n);
            let mean = (cum[hi] - cum[lo] - l[i]) / (hi - lo - 1).max(1) as f64;
            (l[i] - mean).clamp(0.0, MAX_PROMINENCE)
        })
        .collect()
}

/// The input-shaft rate (Hz) within `hint_hz · (1 ± search)` at which the grid lines of `map`
/// are most prominent in `x` (sample rate `fs`); see the [module docs](self).
///
/// Errors: the record's spectrum's (bad samples or rate); no grid (rates not commensurate) or
/// no grid line under 0.45 × the sample rate.
pub fn synchronous_rate(
    x: &[f64],
    fs: f64,
    map: &LineMap,
    hint_hz: f64,
    search: f64,
) -> Result<f64> {
    LineProminence::of(x, fs)?.rate(map, hint_hz, search)
}

/// A record's lines: every bin's prominence ([`prominence`]) and the spectrum's resolution.
#[derive(Debug, Clone)]
pub struct LineProminence {
    p: Vec<f64>,
    /// Bin spacing, Hz.
    df: f64,
    /// Sample rate, Hz.
    fs: f64,
}

/// The grid's orders (ascending) up to `o_max` with their weights ([`MESH_WEIGHT`] for a mesh
/// line, else 1); `None` when the shafts' rates are not commensurate or the map has no mesh.
pub fn grid_orders(map: &LineMap, o_max_meshes: f64) -> Option<Vec<(f64, f64)>> {
    let top_mesh = map.meshes.iter().fold(0.0f64, |a, &b| a.max(b));
    let (Some(period), true) = (map.period_revs, top_mesh > 0.0) else {
        return None;
    };
    let layout = super::lines::Layout {
        revolutions: 2 * period as usize,
        periods: Some(2),
    };
    Some(
        map.lines(&layout, true)
            .into_iter()
            .map(|(bin, class)| {
                let w = if class == super::lines::Class::Mesh {
                    MESH_WEIGHT
                } else {
                    1.0
                };
                (bin as f64 / layout.revolutions as f64, w)
            })
            .filter(|(o, _)| *o <= o_max_meshes * top_mesh)
            .collect(),
    )
}

impl LineProminence {
    /// The prominence of `x`'s lines (the first [`MAX_SAMPLES`] samples; rate `fs`, Hz).
    ///
    /// Errors: the spectrum's (bad samples or rate).
    pub fn of(x: &[f64], fs: f64) -> Result<LineProminence> {
        let x = &x[..x.len().min(MAX_SAMPLES)];
        let spec = amplitude_spectrum(x, fs, Window::Hann)?;
        Ok(LineProminence {
            df: spec.resolution(),
            p: prominence(&spec.amplitude),
            fs,
        })
    }

    /// The prominence at the bin of `f` (Hz; 0 outside the spectrum).
    pub fn at(&self, f: f64) -> f64 {
        let k = (f / self.df).round();
        if k < 0.0 {
            return 0.0;
        }
        self.p.get(k as usize).copied().unwrap_or(0.0)
    }

    /// Bin spacing, Hz.
    pub fn resolution(&self) -> f64 {
        self.df
    }

    /// Highest frequency read (0.45 × the sample rate), Hz.
    pub fn top_hz(&self) -> f64 {
        0.45 * self.fs
    }

    /// Weighted mean prominence of the grid lines `orders` (from [`grid_orders`]) at the
    /// input-shaft rate `rate_hz`, over those under [`Self::top_hz`]; `None` when none is.
    pub fn grid_mean(&self, orders: &[(f64, f64)], rate_hz: f64) -> Option<f64> {
        let (mut s, mut w) = (0.0, 0.0);
        for (o, wt) in orders.iter().filter(|(o, _)| o * rate_hz < self.top_hz()) {
            s += wt * self.at(o * rate_hz);
            w += wt;
        }
        (w > 0.0).then(|| s / w)
    }

    /// [`synchronous_rate`] on these lines.
    ///
    /// Errors: no grid (rates not commensurate) or no grid line under 0.45 × the sample rate.
    pub fn rate(&self, map: &LineMap, hint_hz: f64, search: f64) -> Result<f64> {
        let df = self.df;
        let (lo, hi) = (hint_hz * (1.0 - search), hint_hz * (1.0 + search));
        let grid = |o_max: f64| -> Result<Vec<(f64, f64)>> {
            let g = grid_orders(map, o_max)
                .ok_or(Error::SpeedNotMeasured(SpeedProblem::Incommensurate))?;
            Ok(g.into_iter()
                .filter(|(o, _)| o * hi < self.top_hz())
                .collect())
        };
        let score = |orders: &[(f64, f64)], f: f64| -> f64 {
            orders.iter().map(|(o, w)| w * self.at(o * f)).sum()
        };
        let coarse = grid(1.5)?;
        if coarse.is_empty() {
            return Err(Error::SpeedNotMeasured(SpeedProblem::NoLineInBand {
                lines: "line",
                top_hz: self.top_hz(),
                hint_hz,
            }));
        }
        let top = coarse.iter().fold(0.0f64, |a, b| a.max(b.0));
        let step = 0.5 * df / top;
        let n = ((hi - lo) / step).ceil() as usize;
        let mut scored: Vec<(f64, f64)> = (0..=n)
            .map(|i| lo + i as f64 * step)
            .map(|f| (f, score(&coarse, f)))
            .collect();
        scored.sort_by(|a, b| b.1.total_cmp(&a.1));
        let fine = grid(3.0)?;
        let top = fine.iter().fold(0.0f64, |a, b| a.max(b.0));
        let fine_step = 0.25 * df / top;
        let mut candidates: Vec<f64> = scored
            .iter()
            .take(5)
            .flat_map(|&(f0, _)| {
                let k = (step / fine_step).ceil() as i64;
                (-k..=k).map(move |i| f0 + i as f64 * fine_step)
            })
            .filter(|f| (lo..=hi).contains(f))
            .collect();
        candidates.sort_by(f64::total_cmp);
        candidates.dedup_by(|a, b| (*a - *b).abs() < 0.5 * fine_step);
        let fine_scored: Vec<(f64, f64)> =
            candidates.iter().map(|&f| (f, score(&fine, f))).collect();
        let best = fine_scored.iter().fold(f64::MIN, |a, b| a.max(b.1));
        // The score is flat while every line stays on its bin: the middle of the best plateau.
        let plateau: Vec<f64> = fine_scored
            .iter()
            .filter(|(_, s)| *s >= best - 1e-9)
            .map(|(f, _)| *f)
            .collect();
        Ok(if plateau.is_empty() {
            hint_hz
        } else {
            plateau.iter().sum::<f64>() / plateau.len() as f64
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::test_util::spur;
    use crate::signal::test_util::lcg;
    use std::f64::consts::TAU;

    /// A spur train record at 29.91 Hz: mesh lines, sidebands at the idler's and the output's
    /// rate, shaft lines and noise — and a stronger stray tone near where a 0.8 %-slow comb of
    /// mesh lines would sit. From a hint of 30 Hz the rate is found to 0.02 % (a quarter bin
    /// at the highest order read; the phase of a mesh line refines it).
    #[test]
    fn the_rate_where_every_shafts_lines_line_up() {
        let map = LineMap::of(&spur());
        let (fs, f) = (20_000.0, 29.91);
        let n = 80_000;
        let noise = lcg(n, 7);
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                let th = TAU * f * t;
                let mut v = (32.0 * th).sin() + 0.7 * (16.0 * th).sin() + 0.3 * (48.0 * th).sin();
                for j in 1..6 {
                    let j = j as f64;
                    v += 0.05 / j * ((16.0 + j / 3.0) * th).sin();
                    v += 0.04 / j * ((32.0 - j / 5.0) * th).sin();
                    v += 0.03 / j * ((j / 3.0) * th).sin();
                }
                v + 1.5 * (TAU * 32.0 * 29.67 * t).sin() + 0.25 * noise[i]
            })
            .collect();
        let r = synchronous_rate(&x, fs, &map, 30.0, 0.06).unwrap();
        assert!((r / f - 1.0).abs() < 2e-4, "{r}");
    }
}
