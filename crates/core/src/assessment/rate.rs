//! Sample-rate consistency: do the record's gear-mesh lines sit where the gearbox description
//! and a shaft rate the record does not measure itself (the sender's `shaft_hz`, else the
//! machine's nominal input-shaft rate) put them?
//!
//! A record whose sample rate is declared wrong by a factor r (the true rate is r times the
//! declared one) shows every line at f/r: its mesh lines sit at c = 1/r times where they are
//! predicted. A rate counted from the record itself (a tachometer, the tacho-less tracker)
//! scales with it and cannot tell; only an outside rate can, so the check runs only with one.
//!
//! **The rule** (fixed before it was run on any record): the predicted lines are the first
//! three harmonics of every mesh of the description (duplicates within 1 % once) between
//! 5 Hz and 0.45 fs. For each factor c in [`FACTORS`] and 1, each line's prominence is the
//! largest amplitude within ±0.8 % of c·f over the median amplitude within ±5 % (in dB, capped
//! at 40 dB); the factor's score is the mean over its lines (at least two). When the best
//! factor is not 1, scores at least [`MIN_SCORE_DB`] and beats 1 by at least [`MARGIN_DB`],
//! the record's sample rate is probably the declared one divided by c — a warning (the alert
//! is capped at `unknown`), and a refusal naming that rate when the diagnosis then finds no
//! mesh line.

use serde::Serialize;

use crate::gearbox::Gearbox;
use crate::signal::{Window, amplitude_spectrum};

/// Factors checked besides 1: half and double, 0.9 and 1.1, the 44.1 kHz / 48 kHz confusion.
/// (A quarter and four times were tried and dropped: a quarter of a mesh order is often a
/// strong shaft harmonic, and was named wrongly on the PHM 2009 records.)
pub const FACTORS: [f64; 6] = [0.5, 2.0, 0.9, 1.1, 44_100.0 / 48_000.0, 48_000.0 / 44_100.0];
/// Smallest mean prominence (dB) of the lines at a factor for it to count as a fit.
pub const MIN_SCORE_DB: f64 = 10.0;
/// How much (dB) the best factor must beat 1.
pub const MARGIN_DB: f64 = 6.0;
/// Half-width of the window a predicted line is looked for in, relative.
const LINE_TOL: f64 = 0.008;
/// Half-width of the background around a line, relative.
const BACKGROUND: f64 = 0.05;
/// Most samples used (the first ones).
const MAX_SAMPLES: usize = 1 << 19;

/// A sample rate that does not fit the description and the shaft rate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RateMismatch {
    /// Where the lines sit, as a multiple of where they are predicted.
    pub factor: f64,
    pub declared_hz: f64,
    /// The declared rate divided by `factor`.
    pub likely_hz: f64,
    /// The shaft rate the prediction used, Hz.
    pub shaft_hz: f64,
    /// Mean prominence of the predicted lines at `factor` and at 1, dB.
    pub score_db: f64,
    pub score_at_1_db: f64,
}

impl RateMismatch {
    /// The sentence a person reads.
    pub fn message(&self) -> String {
        format!(
            "the mesh lines sit at {:.2} × where {:.2} Hz predicts (the gearbox description's \
             meshes at that shaft rate): is the sample rate {:.0} Hz, not {:.0}? Check the \
             rate the record was sent with (or the shaft rate)",
            self.factor, self.shaft_hz, self.likely_hz, self.declared_hz
        )
    }
}

/// Check `x` (sample rate `fs`, Hz) against the meshes of `gearbox` at the input-shaft rate
/// `shaft_hz` (see the [module docs](self)); `None` when it fits or cannot be told.
pub fn check_rate(x: &[f64], fs: f64, gearbox: &Gearbox, shaft_hz: f64) -> Option<RateMismatch> {
    if !(shaft_hz.is_finite() && shaft_hz > 0.0) || x.len() < 1024 {
        return None;
    }
    let x = &x[..x.len().min(MAX_SAMPLES)];
    let spectrum = amplitude_spectrum(x, fs, Window::Hann).ok()?;
    let mut meshes: Vec<f64> = Vec::new();
    for m in gearbox.shaft_train().meshes {
        for h in 1..=3 {
            let f = m.abs() * h as f64 * shaft_hz;
            if !meshes.iter().any(|g| (g / f - 1.0).abs() < 0.01) {
                meshes.push(f);
            }
        }
    }
    let score = |c: f64| -> Option<f64> {
        let p: Vec<f64> = meshes
            .iter()
            .map(|f| c * f)
            .filter(|&f| f > 5.0 && f < 0.45 * fs)
            .filter_map(|f| prominence_db(&spectrum.freq, &spectrum.amplitude, f))
            .collect();
        (p.len() >= 2).then(|| p.iter().sum::<f64>() / p.len() as f64)
    };
    let at_1 = score(1.0).unwrap_or(0.0);
    let (factor, best) = FACTORS
        .iter()
        .filter_map(|&c| score(c).map(|s| (c, s)))
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    (best >= MIN_SCORE_DB && best - at_1 >= MARGIN_DB).then(|| RateMismatch {
        factor,
        declared_hz: fs,
        likely_hz: fs / factor,
        shaft_hz,
        score_db: best,
        score_at_1_db: at_1,
    })
}

/// The largest amplitude within ±[`LINE_TOL`] of `f` over the median within ±[`BACKGROUND`],
/// dB (at most 40).
fn prominence_db(freq: &[f64], amp: &[f64], f: f64) -> Option<f64> {
    let range = |lo: f64, hi: f64| {
        let a = freq.partition_point(|&v| v < lo);
        let b = freq.partition_point(|&v| v <= hi);
        (a < b).then_some(a..b)
    };
    let peak = amp[range(f * (1.0 - LINE_TOL), f * (1.0 + LINE_TOL))?]
        .iter()
        .fold(0.0_f64, |m, &v| m.max(v));
    let mut bg: Vec<f64> = amp[range(f * (1.0 - BACKGROUND), f * (1.0 + BACKGROUND))?].to_vec();
    if bg.len() < 8 {
        return None;
    }
    let mid = bg.len() / 2;
    let med = *bg.select_nth_unstable_by(mid, f64::total_cmp).1;
    if med <= 0.0 || peak <= 0.0 {
        return None;
    }
    Some((20.0 * (peak / med).log10()).min(40.0))
}
