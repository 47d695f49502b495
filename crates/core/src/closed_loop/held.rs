//! A machine's calibrated effects held fixed in later diagnoses (the service's use of
//! [`super::calibrate`]; see "Through the service" in `docs/closed-loop.md`).
//!
//! * A **path resonance** is a sensor/path stage: [`decolour`] / [`decolour_with`] divide the record's spectrum
//!   by the fitted `|H(f)|` (zero phase, whole-record FFT, correction clamped to
//!   ±[`MAX_CORRECTION_DB`]) so that the ordinary diagnosis reads de-coloured line features.
//!   The mode is kept in **Hz** (`frequency_hz`), as a housing mode does not move with speed.
//! * **Element effects** (shaft modulation, planetary wear, tooth damage) cannot enter the
//!   signature-table likelihood without recomputing the table, so [`super::refit_held`]
//!   re-estimates the wear by the closed loop's wear profile with the stored effects held at
//!   their calibrated values (only `ea`, sensor gain and noise floor are fitted): a continuous
//!   estimate with a profile-likelihood interval, which the service's alert level follows.

use std::collections::BTreeMap;

use serde::Serialize;

use super::effects::{PATH_RESONANCE, PLANETARY_WEAR, Resonance, SHAFT_MODULATION, TOOTH_DAMAGE};
use crate::error::{Error, Result};

/// Largest |correction| (dB) [`decolour`] applies at any frequency: far above a resonance
/// `1/|H|` grows as `(f/f_r)²` and would otherwise amplify the noise without bound.
pub const MAX_CORRECTION_DB: f64 = 30.0;

/// The effects a calibration added, as the later diagnoses hold them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct HeldEffects {
    /// Shaft-modulation sideband amplitude on mesh x1 (units of b); 0: none.
    pub eccentricity_b: f64,
    /// The modulating shaft's rate over f1 (`None`: the input shaft, as stored before the
    /// shaft was a choice).
    pub eccentricity_shaft_ratio: Option<f64>,
    /// Planetary composite-error amplitude (units of b); `None`: the model's baseline.
    pub planetary_error_b: Option<f64>,
    /// Path resonance `(frequency Hz, damping ratio)`.
    pub path_resonance: Option<(f64, f64)>,
    /// The resonance's peak gain over the flat path (peaking form); `None`: the low-pass form.
    pub path_peak_gain: Option<f64>,
    /// A damaged tooth: (stiffness loss, its shaft's rate over f1).
    pub tooth: Option<(f64, f64)>,
}

impl HeldEffects {
    /// From the `effects` of a [`super::CalibrationReport`] (`name` + `parameters`). Unknown
    /// names and missing parameters are errors: a stored calibration must be fully understood.
    pub fn from_effects<'a>(
        effects: impl IntoIterator<Item = (&'a str, &'a BTreeMap<String, f64>)>,
    ) -> Result<HeldEffects> {
        let mut h = HeldEffects::default();
        for (name, p) in effects {
            let get = |k: &str| {
                p.get(k)
                    .copied()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| Error::Stored {
                        what: format!("effect `{name}`"),
                        reason: format!("parameter `{k}` is missing or not finite"),
                    })
            };
            match name {
                SHAFT_MODULATION => {
                    h.eccentricity_b = get("sideband_amplitude_b")?;
                    h.eccentricity_shaft_ratio = get("shaft_ratio").ok();
                }
                PLANETARY_WEAR => h.planetary_error_b = Some(get("planetary_error_b")?),
                PATH_RESONANCE => {
                    h.path_resonance = Some((get("frequency_hz")?, get("damping_ratio")?));
                    h.path_peak_gain = get("peak_gain").ok();
                }
                TOOTH_DAMAGE => h.tooth = Some((get("stiffness_loss")?, get("shaft_ratio")?)),
                other => {
                    return Err(Error::Stored {
                        what: format!("effect `{other}`"),
                        reason: "no effect of this name is known".into(),
                    });
                }
            }
        }
        Ok(h)
    }

    /// No effect at all.
    pub fn is_empty(&self) -> bool {
        *self == HeldEffects::default()
    }

    /// True when an element effect (shaft modulation, planetary wear, tooth damage) is held:
    /// the signature table cannot represent it, so the refit's wear is the machine's wear.
    pub fn has_element_effect(&self) -> bool {
        self.eccentricity_b > 0.0 || self.planetary_error_b.is_some() || self.tooth.is_some()
    }

    /// The path stage at stage-1 mesh frequency `f1` (Hz).
    pub fn resonance_at(&self, f1: f64) -> Option<Resonance> {
        self.path_resonance.map(|(fr, zeta)| Resonance {
            rho: fr / f1,
            zeta,
            peak_gain: self.path_peak_gain,
        })
    }

    /// The record de-coloured by the held path stage ([`decolour_with`]); `None` without one.
    pub fn decolour(&self, x: &[f64], fs: f64) -> Option<Result<Vec<f64>>> {
        self.resonance_at(1.0).map(|h| decolour_with(x, fs, &h))
    }
}

/// Whether a wear refit with element effects held moves the machine's wear: only when its
/// `ea` lies outside the table's credible interval `(lower, upper)`; inside it the table's
/// reading stands. One rule for the calibration's `wear_after`
/// (`table-posterior-confirmed`) and the service's alert level (`alert_follows`).
pub fn refit_moves_wear((lower, upper): (f64, f64), ea: f64) -> bool {
    !(lower..=upper).contains(&ea)
}

/// Divide the spectrum of `x` (sample rate `fs`) by `|H(f)|` of a resonance at `fr_hz` with
/// damping `zeta` (zero phase; the correction at each frequency clamped to
/// ±[`MAX_CORRECTION_DB`]).
pub fn decolour(x: &[f64], fs: f64, fr_hz: f64, zeta: f64) -> Result<Vec<f64>> {
    decolour_with(x, fs, &Resonance::low_pass(fr_hz, zeta))
}

/// [`decolour`] for a resonance of either form, `h.rho` in **Hz** (not a ratio to f1).
pub fn decolour_with(x: &[f64], fs: f64, h: &Resonance) -> Result<Vec<f64>> {
    let (fr_hz, zeta) = (h.rho, h.zeta);
    if !(fr_hz > 0.0 && zeta > 0.0 && fs > 0.0) {
        return Err(Error::param(
            "path resonance",
            fr_hz,
            "frequency, damping and sample rate must be positive",
        ));
    }
    let n = x.len();
    if n < 2 {
        return Ok(x.to_vec());
    }
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(n);
    let inv = planner.plan_fft_inverse(n);
    let mut input = x.to_vec();
    let mut spec = fwd.make_output_vec();
    fwd.process(&mut input, &mut spec)
        .map_err(|e| Error::fft(n, e))?;
    for (k, c) in spec.iter_mut().enumerate() {
        let f = k as f64 * fs / n as f64;
        let corr = (-h.gain_db(f)).clamp(-MAX_CORRECTION_DB, MAX_CORRECTION_DB);
        *c *= 10f64.powf(corr / 20.0);
    }
    spec[0].im = 0.0;
    if n.is_multiple_of(2)
        && let Some(last) = spec.last_mut()
    {
        last.im = 0.0;
    }
    let mut out = inv.make_output_vec();
    inv.process(&mut spec, &mut out)
        .map_err(|e| Error::fft(n, e))?;
    let scale = 1.0 / n as f64;
    Ok(out.into_iter().map(|v| v * scale).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn decolour_undoes_the_resonance_gain_of_a_tone() {
        let fs = 8000.0;
        let (fr, zeta) = (1000.0, 0.05);
        let f = 1000.0; // on the resonance: |H| = 1/(2ζ) = 10 (20 dB)
        let x: Vec<f64> = (0..8000)
            .map(|i| 10.0 * (TAU * f * i as f64 / fs).sin())
            .collect();
        let y = decolour(&x, fs, fr, zeta).unwrap();
        let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
        assert!((rms - 1.0 / 2f64.sqrt()).abs() < 1e-6, "rms {rms}");
    }

    #[test]
    fn held_effects_parse_and_refuse_unknown() {
        let mut p = BTreeMap::new();
        p.insert("sideband_amplitude_b".to_string(), 0.08);
        p.insert("shaft_ratio".to_string(), 1.0 / 29.0);
        let h = HeldEffects::from_effects([(SHAFT_MODULATION, &p)]).unwrap();
        assert_eq!(h.eccentricity_b, 0.08);
        assert!(!h.is_empty());
        assert!(HeldEffects::from_effects([("tone", &p)]).is_err());
        assert!(HeldEffects::from_effects([(PLANETARY_WEAR, &p)]).is_err());
    }
}
