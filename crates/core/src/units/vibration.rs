//! The `vibration` object of a channel with a declared unit, and the wear degree in µm.

use serde::Serialize;

use super::{ChannelUnit, IsoClass, IsoZone, STANDARD_GRAVITY, UnitSpec};
use crate::Result;
use crate::diagnosis::WearDegree;
use crate::gearbox::Gearbox;
use crate::signal::velocity::{ISO_BAND, acceleration_level, velocity_rms};

/// A channel's vibration in physical units (its unit as declared, flattened in: `unit` and
/// the sensitivity).
///
/// * `acceleration_*`: RMS and peak of the detrended acceleration over the whole record
///   (m/s², and in g of 9.806 65 m/s²); a velocity sensor's is its derivative
///   ([`crate::signal::velocity::acceleration_level`]).
/// * `velocity_rms_mm_s`: the r.m.s. velocity over `velocity_band_hz` (10–1000 Hz), integrated
///   in the frequency domain ([`crate::signal::velocity`]); `null` when the record cannot hold
///   the band (too short, or sampled too slowly), with `velocity_note` saying why.
/// * `iso_20816_3`: the velocity's zone when the machine declares its class
///   ([`super::iso`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Vibration {
    #[serde(flatten)]
    pub declared: UnitSpec,
    pub acceleration_rms_m_s2: f64,
    pub acceleration_rms_g: f64,
    pub acceleration_peak_m_s2: f64,
    pub acceleration_peak_g: f64,
    pub velocity_rms_mm_s: Option<f64>,
    pub velocity_band_hz: [f64; 2],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub velocity_note: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iso_20816_3: Option<IsoZone>,
}

/// The vibration of one channel's samples (in the declared unit) at `fs` Hz.
///
/// Errors: the signal checks' (empty record, non-finite sample, non-positive rate). A record
/// that cannot hold the velocity band is not an error: its velocity is `None`, with a note.
pub fn vibration(
    samples: &[f64],
    fs: f64,
    declared: &UnitSpec,
    unit: &ChannelUnit,
    iso: Option<IsoClass>,
) -> Result<Vibration> {
    let si: Vec<f64> = samples.iter().map(|x| x * unit.to_si).collect();
    let accel = acceleration_level(&si, fs, unit.quantity)?;
    let (velocity, note) = match velocity_rms(&si, fs, unit.quantity, ISO_BAND) {
        Ok(v) => (Some(v * 1000.0), None),
        Err(
            e @ (crate::Error::RecordTooShortForBand { .. }
            | crate::Error::SampleRateBelowBand { .. }),
        ) => (None, Some(format!("no velocity: {e}"))),
        Err(e) => return Err(e),
    };
    Ok(Vibration {
        declared: declared.clone(),
        acceleration_rms_m_s2: accel.rms,
        acceleration_rms_g: accel.rms / STANDARD_GRAVITY,
        acceleration_peak_m_s2: accel.peak,
        acceleration_peak_g: accel.peak / STANDARD_GRAVITY,
        velocity_rms_mm_s: velocity,
        velocity_band_hz: [ISO_BAND.lo_hz, ISO_BAND.hi_hz],
        velocity_note: note,
        iso_20816_3: iso.zip(velocity).map(|(c, v)| c.zone(v)),
    })
}

/// A wear degree in µm: the dimensionless one times the gearbox's reference length (its
/// `reference_length_um`, 5 µm unless the description gives another).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WearUm {
    pub estimate: f64,
    pub lower: f64,
    pub upper: f64,
    /// The unit of the dimensionless wear degree, µm.
    pub reference_length_um: f64,
}

impl WearUm {
    /// `wear` (in units of `gearbox`'s reference length) in µm; `None` when the figure is
    /// withheld (the model does not fit the record).
    pub fn of(wear: &WearDegree, gearbox: &Gearbox) -> Option<WearUm> {
        if wear.withheld.is_some() {
            return None;
        }
        let b = gearbox.reference_length_um();
        Some(WearUm {
            estimate: wear.estimate * b,
            lower: wear.lower * b,
            upper: wear.upper * b,
            reference_length_um: b,
        })
    }
}
