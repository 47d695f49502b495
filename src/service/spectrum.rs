//! The spectrum stored with each diagnosis for plotting: the Hann-windowed one-sided peak
//! amplitude spectrum of the record ([`crate::signal::amplitude_spectrum`]) from 0 to 2.5 f1,
//! frequency normalised by f1, level in dB relative to the f1 line, reduced to at most
//! [`MAX_POINTS`] points by keeping the maximum of each group of bins (peaks survive).

use serde::Serialize;

use crate::signal::{Spectrum, Window, amplitude_spectrum};

pub const MAX_POINTS: usize = 1200;
const UPPER: f64 = 2.5;

#[derive(Debug, Clone, Serialize)]
pub struct Mark {
    pub name: String,
    pub f_over_f1: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct PlotSpectrum {
    pub f1_hz: f64,
    /// Frequency / f1.
    pub f_over_f1: Vec<f64>,
    /// 20 log10(A / A(f1)), floored at −120 dB.
    pub level_db: Vec<f64>,
    pub marks: Vec<Mark>,
}

/// Compute the plot spectrum; `None` if the record cannot give one.
pub fn plot_spectrum(x: &[f64], fs: f64, f1: f64, marks: &[(String, f64)]) -> Option<PlotSpectrum> {
    if !(f1 > 0.0) || x.len() < 16 {
        return None;
    }
    let s = amplitude_spectrum(x, fs, Window::Hann).ok()?;
    plot_from_spectrum(&s, f1, marks)
}

/// [`plot_spectrum`] from the record's Hann [`amplitude_spectrum`] already computed (the one
/// [`crate::diagnosis::diagnose_with_spectrum`] hands back).
pub fn plot_from_spectrum(s: &Spectrum, f1: f64, marks: &[(String, f64)]) -> Option<PlotSpectrum> {
    if !(f1 > 0.0) || s.freq.len() < 9 {
        return None;
    }
    let df = s.resolution();
    let hi = ((UPPER * f1 / df).ceil() as usize).min(s.freq.len() - 1);
    let (_, a1) = s.peak_near(f1, (0.01 * f1).max(2.0 * df));
    let a1 = if a1 > 0.0 { a1 } else { 1.0 };
    let group = hi.div_ceil(MAX_POINTS).max(1);
    let mut f = Vec::with_capacity(hi / group + 1);
    let mut l = Vec::with_capacity(hi / group + 1);
    let mut k = 0;
    while k <= hi {
        let end = (k + group).min(hi + 1);
        let (mut best, mut bi) = (-1.0, k);
        for j in k..end {
            if s.amplitude[j] > best {
                best = s.amplitude[j];
                bi = j;
            }
        }
        f.push(round4(s.freq[bi] / f1));
        l.push(round4((20.0 * (best / a1).log10()).max(-120.0)));
        k = end;
    }
    Some(PlotSpectrum {
        f1_hz: f1,
        f_over_f1: f,
        level_db: l,
        marks: marks
            .iter()
            .map(|(n, r)| Mark {
                name: n.clone(),
                f_over_f1: *r,
            })
            .collect(),
    })
}

fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}
