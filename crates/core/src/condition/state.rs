//! A record's operating state: the input shaft's **measured** rate and the load.
//!
//! The rate is never taken on trust. With a tachometer it is counted from the pulses
//! ([`track_tachometer`]). Without one it is found in two steps: first the rate within
//! [`TACHO_LESS_SEARCH`] of the nominal hint at which the lines of every shaft line up
//! ([`super::synchronous::synchronous_rate`]; induction motors slip a few per cent below their
//! setting, so the hint only says where to look, and one line alone is easily confused with a
//! sideband in a dense spectrum; [`comb_rate`], the mesh lines alone, when the shafts' rates
//! are not commensurate); then the input shaft's angle is
//! tracked from the phase of the strongest stage-1 mesh harmonic within
//! [`TRACK_SEARCH`] of that rate ([`track_mesh_phase`]), or, when no line can be followed,
//! held at that rate ([`constant_rate_angle`]).

use serde::{Deserialize, Serialize};

use crate::error::SpeedProblem;
use crate::gearbox::Gearbox;
use crate::signal::order::{
    MeshTrackOptions, ShaftAngle, constant_rate_angle, track_mesh_phase, track_tachometer,
};
use crate::signal::{Window, amplitude_spectrum};
use crate::{Error, Result};

/// Relative half-width of the tacho-less search around the hint: motor slip (2–3 % at full
/// load) and a setting that is a little off.
pub const TACHO_LESS_SEARCH: f64 = 0.06;
/// Most tachometer pulses per input-shaft revolution accepted (an encoder's line count).
pub const MAX_PULSES_PER_REV: usize = 10_000;

/// Relative half-width of the phase tracker's search around the lines' rate.
pub const TRACK_SEARCH: f64 = 0.0005;
/// Largest relative difference between the phase tracker's mean rate and the rate every
/// shaft's lines agree on for the track to be used.
pub const TRACK_AGREEMENT: f64 = 2e-4;

/// The input-shaft rate (Hz) within `hint · (1 ± TACHO_LESS_SEARCH)` that maximises the sum of
/// the log amplitudes of the gearbox's mesh lines (orders `k · O_i`, k = 1..3, every stage
/// `i`, under 0.45 × the sample rate), each read as the largest bin within one bin of where it
/// should be. The step keeps the highest line within half a bin between candidates.
///
/// Errors: the record's spectrum's (bad samples or rate); no mesh line under 0.45 × the
/// sample rate.
pub fn comb_rate(x: &[f64], fs: f64, gearbox: &Gearbox, hint_hz: f64) -> Result<f64> {
    let spec = amplitude_spectrum(x, fs, Window::Hann)?;
    let df = spec.resolution();
    let mut orders: Vec<f64> = gearbox
        .shaft_train()
        .meshes
        .iter()
        .flat_map(|o| (1..=3).map(move |k| k as f64 * o))
        .collect();
    orders.sort_by(f64::total_cmp);
    orders.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let (lo, hi) = (
        hint_hz * (1.0 - TACHO_LESS_SEARCH),
        hint_hz * (1.0 + TACHO_LESS_SEARCH),
    );
    orders.retain(|o| o * hi < 0.45 * fs);
    let Some(&top) = orders.last() else {
        return Err(Error::SpeedNotMeasured(SpeedProblem::NoLineInBand {
            lines: "mesh line",
            top_hz: 0.45 * fs,
            hint_hz,
        }));
    };
    let step = 0.5 * df / top;
    let score = |f: f64| -> f64 {
        orders
            .iter()
            .map(|o| {
                let (_, a) = spec.peak_near(o * f, df);
                (a.max(1e-300)).ln()
            })
            .sum()
    };
    let n = ((hi - lo) / step).ceil() as usize;
    let best = (0..=n)
        .map(|i| lo + i as f64 * step)
        .map(|f| (f, score(f)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(hint_hz, |b| b.0);
    Ok(best)
}

/// A load as its user names it: a label (`"High"`) or a number (N·m, %, any unit the user
/// keeps to).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Load {
    Value(f64),
    Label(String),
}

impl Load {
    /// A number when the text reads as one, else a label (trimmed). Empty text: no load.
    pub fn parse(text: &str) -> Option<Load> {
        let t = text.trim();
        if t.is_empty() {
            return None;
        }
        Some(match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Load::Value(v),
            _ => Load::Label(t.to_string()),
        })
    }

    /// The same load: labels equal up to case, numbers within 5 % (or 1e-9 absolute).
    pub fn same(&self, other: &Load) -> bool {
        match (self, other) {
            (Load::Label(a), Load::Label(b)) => a.eq_ignore_ascii_case(b),
            (Load::Value(a), Load::Value(b)) => {
                (a - b).abs() <= 1e-9 || (a - b).abs() <= 0.05 * a.abs().max(b.abs())
            }
            _ => false,
        }
    }
}

impl std::fmt::Display for Load {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Load::Value(v) => write!(f, "{v}"),
            Load::Label(s) => f.write_str(s),
        }
    }
}

/// How the shaft rate was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpeedSource {
    /// Counted from a tachometer channel's pulses.
    Tachometer,
    /// Tracked from a mesh line's phase near the nominal hint.
    TachoLess,
}

/// A record's operating state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperatingState {
    /// Measured mean input-shaft rate (Hz).
    pub shaft_hz: f64,
    pub source: SpeedSource,
    /// The nominal rate the search started from (Hz), when there was one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hint_hz: Option<f64>,
    /// (max − min) / mean of the per-revolution rate over the record.
    pub speed_variation: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<Load>,
}

/// A tachometer channel: its samples and pulses per input-shaft revolution.
#[derive(Debug, Clone, Copy)]
pub struct Tacho<'a> {
    pub samples: &'a [f64],
    pub pulses_per_rev: usize,
}

/// The input shaft's angle without a tachometer: the rate within [`TACHO_LESS_SEARCH`] of
/// `hint` at which every shaft's lines line up, then the phase of a stage-1 mesh line followed
/// within [`TRACK_SEARCH`] of it (low-passed below the slowest shaft's sideband spacing); a line
/// too weak to follow, or a track whose mean rate leaves that rate by more than
/// [`TRACK_AGREEMENT`], gives that rate held constant.
fn tacho_less(x: &[f64], fs: f64, gearbox: &Gearbox, hint: f64) -> Result<ShaftAngle> {
    let z = gearbox.f1_per_input_hz;
    let parts = super::parts::Parts::of(gearbox);
    let map = super::lines::LineMap::of(&parts);
    let rate = match super::synchronous::synchronous_rate(x, fs, &map, hint, TACHO_LESS_SEARCH) {
        Ok(r) => r,
        Err(_) => comb_rate(x, fs, gearbox, hint)?,
    };
    let slowest = parts
        .shafts
        .values()
        .filter(|r| **r > 0.0)
        .fold(1.0f64, |a, &b| a.min(b));
    let opts = MeshTrackOptions {
        search: TRACK_SEARCH,
        lowpass_orders: 0.4 * slowest,
        ..Default::default()
    };
    Ok(track_mesh_phase(x, fs, z * rate, z, &opts)
        .ok()
        .filter(|a| (a.summary.mean_hz / rate - 1.0).abs() <= TRACK_AGREEMENT)
        .unwrap_or_else(|| constant_rate_angle(x.len(), fs, rate)))
}

/// Measure the input shaft's angle and the record's state: from `tacho` when given, else
/// tacho-less on `x` around `hint_hz` (the stage-1 mesh order of `gearbox`).
///
/// Errors: a tachometer with too few pulses or a wrong rate; no tachometer and no hint; a
/// mesh line too weak to track.
pub fn measure(
    x: &[f64],
    fs: f64,
    gearbox: &Gearbox,
    tacho: Option<Tacho>,
    hint_hz: Option<f64>,
    load: Option<Load>,
) -> Result<(ShaftAngle, OperatingState)> {
    let hint_hz = hint_hz.filter(|h| h.is_finite() && *h > 0.0);
    let (angle, source) = match tacho {
        Some(t) => (
            track_tachometer(t.samples, fs, t.pulses_per_rev)?,
            SpeedSource::Tachometer,
        ),
        None => {
            let h = hint_hz.ok_or(Error::SpeedNotMeasured(SpeedProblem::NoHint))?;
            (tacho_less(x, fs, gearbox, h)?, SpeedSource::TachoLess)
        }
    };
    let state = OperatingState {
        shaft_hz: angle.summary.mean_hz,
        source,
        hint_hz,
        speed_variation: angle.summary.speed_variation,
        load,
    };
    Ok((angle, state))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_parse_and_compare() {
        assert_eq!(Load::parse(" High "), Some(Load::Label("High".into())));
        assert_eq!(Load::parse("40"), Some(Load::Value(40.0)));
        assert_eq!(Load::parse(""), None);
        assert!(
            Load::parse("high")
                .unwrap()
                .same(&Load::parse("HIGH").unwrap())
        );
        assert!(Load::Value(100.0).same(&Load::Value(104.0)));
        assert!(!Load::Value(100.0).same(&Load::Value(120.0)));
        assert!(!Load::Value(1.0).same(&Load::Label("1".into())));
    }

    /// A 10-pulse tachometer at 37.3 Hz and a record of its 16th order: the tachometer gives
    /// the rate to 0.1 %, and tacho-less tracking from a hint 4 % high finds the same rate.
    #[test]
    fn tachometer_and_tacho_less_agree() {
        let gb = Gearbox::parse(
            "format = \"gearwear-gearbox\"\nversion = 1\nname = \"t\"\ninput_shaft = \"in\"\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"in\", teeth = 16 }\n\
             gear = { shaft = \"out\", teeth = 48 }\n",
            "test",
        )
        .unwrap();
        let fs = 20_000.0;
        let f = 37.3;
        let n = 40_000;
        let t = |i: usize| i as f64 / fs;
        let tach: Vec<f64> = (0..n)
            .map(|i| {
                if (t(i) * f * 10.0).fract() < 0.2 {
                    5.0
                } else {
                    0.0
                }
            })
            .collect();
        // The 16th order and a little noise (a record without any is no real record: the
        // tacho-less search reads lines against the background around them).
        let mut s = 11u64;
        let x: Vec<f64> = (0..n)
            .map(|i| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let noise = ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
                (std::f64::consts::TAU * 16.0 * f * t(i)).sin() + 0.01 * noise
            })
            .collect();
        let tacho = Tacho {
            samples: &tach,
            pulses_per_rev: 10,
        };
        let (_, s) = measure(&x, fs, &gb, Some(tacho), None, None).unwrap();
        assert_eq!(s.source, SpeedSource::Tachometer);
        assert!((s.shaft_hz / f - 1.0).abs() < 1e-3, "{s:?}");
        let (_, s) = measure(&x, fs, &gb, None, Some(f * 1.04), None).unwrap();
        assert_eq!(s.source, SpeedSource::TachoLess);
        assert!((s.shaft_hz / f - 1.0).abs() < 1e-3, "{s:?}");
        assert!(measure(&x, fs, &gb, None, None, None).is_err());
    }
}
