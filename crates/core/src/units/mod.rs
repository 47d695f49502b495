//! Physical units of a record's channels: what a machine declares its numbers to be, their
//! conversion to SI, and the figures a vibration analyst reads first ([`vibration`]: the
//! acceleration's RMS and peak, the velocity RMS over 10–1000 Hz, the ISO 20816-3 zone of
//! [`iso`]).
//!
//! # Units a channel may declare ([`UnitSpec`])
//!
//! | `unit` | sensor | to SI (one sample `x`) |
//! | --- | --- | --- |
//! | `g` | accelerometer | `a = 9.80665 x` m/s² (standard gravity, ISO 80000-3) |
//! | `m/s²` (also `m/s^2`, `m/s2`) | accelerometer | `a = x` m/s² |
//! | `mm/s` | velocity sensor | `v = x / 1000` m/s |
//! | `V` + `sensitivity_mv_per_g` = S | accelerometer | `a = 1000 x / S × 9.80665` m/s² |
//! | `V` + `sensitivity_mv_per_m_s2` = S | accelerometer | `a = 1000 x / S` m/s² |
//! | `V` + `sensitivity_mv_per_mm_s` = S | velocity sensor | `v = x / S` m/s (`1000 x / S` mm/s) |
//!
//! Refused, with a [`UnitError`] that says what to write instead: any other unit; a
//! displacement (µm, mm, mil, …: a proximity probe's shaft motion is not the housing vibration
//! these figures describe); V without a sensitivity; a sensitivity on a channel that is not in
//! V; two sensitivities; a sensitivity that is not a number above 0 and at most
//! [`MAX_SENSITIVITY`].

pub mod declared;
pub mod iso;
pub mod vibration;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

pub use crate::error::UnitError;
pub use crate::signal::velocity::Kinematic;
pub use declared::{IsoDeclared, Refusal, check_declared, quoted};
pub use iso::{IsoClass, IsoZone, Support, Zone};
pub use vibration::{Vibration, WearUm, vibration};

/// Standard gravity (m/s² per g; ISO 80000-3, CGPM 1901).
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// Largest sensitivity accepted, in mV per unit (a 10 V/g accelerometer is 10 000 mV/g).
pub const MAX_SENSITIVITY: f64 = 1.0e6;

/// The key of [`ChannelUnits`] that declares every channel not named.
pub const ANY_CHANNEL: &str = "*";

/// A channel's unit as declared — the shape of the API's `channel_units` entries and of the
/// store: `{"unit": "V", "sensitivity_mv_per_g": 100}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitSpec {
    /// `g`, `m/s²`, `mm/s` or `V`.
    pub unit: String,
    /// An accelerometer's sensitivity, mV/g (unit V only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity_mv_per_g: Option<f64>,
    /// An accelerometer's sensitivity, mV/(m/s²) (unit V only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity_mv_per_m_s2: Option<f64>,
    /// A velocity sensor's sensitivity, mV/(mm/s) (unit V only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity_mv_per_mm_s: Option<f64>,
}

/// A converted unit: what the samples measure and the factor that takes them to SI (m/s² for
/// an acceleration, m/s for a velocity).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelUnit {
    pub quantity: Kinematic,
    pub to_si: f64,
}

/// What a sensitivity is per.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Per {
    G,
    MetrePerSecondSquared,
    MillimetrePerSecond,
}

impl Per {
    /// As written after `mV/`.
    pub fn label(self) -> &'static str {
        match self {
            Per::G => "g",
            Per::MetrePerSecondSquared => "(m/s²)",
            Per::MillimetrePerSecond => "(mm/s)",
        }
    }

    /// The SI value of one volt from a sensor of sensitivity `mv` mV per this unit.
    fn si_per_volt(self, mv: f64) -> f64 {
        match self {
            Per::G => 1000.0 / mv * STANDARD_GRAVITY,
            Per::MetrePerSecondSquared => 1000.0 / mv,
            Per::MillimetrePerSecond => 1.0 / mv,
        }
    }

    fn quantity(self) -> Kinematic {
        match self {
            Per::G | Per::MetrePerSecondSquared => Kinematic::Acceleration,
            Per::MillimetrePerSecond => Kinematic::Velocity,
        }
    }

    /// `g`, `m/s²` (`m/s^2`, `m/s2`), `mm/s`, with or without parentheses.
    fn parse(text: &str) -> Option<Per> {
        let t = text.trim();
        let t = t
            .strip_prefix('(')
            .and_then(|t| t.strip_suffix(')'))
            .unwrap_or(t);
        match t {
            "g" => Some(Per::G),
            "m/s²" | "m/s^2" | "m/s2" => Some(Per::MetrePerSecondSquared),
            "mm/s" => Some(Per::MillimetrePerSecond),
            _ => None,
        }
    }
}

/// Units that are displacements (refused with [`UnitError::Displacement`]).
const DISPLACEMENTS: [&str; 10] = [
    "µm", "μm", "um", "mm", "m", "nm", "mil", "mils", "in", "inch",
];

impl UnitSpec {
    /// A unit without a sensitivity (`g`, `m/s²`, `mm/s`).
    pub fn plain(unit: &str) -> UnitSpec {
        UnitSpec {
            unit: unit.to_string(),
            sensitivity_mv_per_g: None,
            sensitivity_mv_per_m_s2: None,
            sensitivity_mv_per_mm_s: None,
        }
    }

    /// Volts with a sensitivity of `mv` mV per `per`.
    pub fn volts(mv: f64, per: Per) -> UnitSpec {
        let mut s = UnitSpec::plain("V");
        match per {
            Per::G => s.sensitivity_mv_per_g = Some(mv),
            Per::MetrePerSecondSquared => s.sensitivity_mv_per_m_s2 = Some(mv),
            Per::MillimetrePerSecond => s.sensitivity_mv_per_mm_s = Some(mv),
        }
        s
    }

    /// The one sensitivity given, if any.
    fn sensitivity(&self) -> Result<Option<(f64, Per)>, UnitError> {
        let given: Vec<(f64, Per)> = [
            (self.sensitivity_mv_per_g, Per::G),
            (self.sensitivity_mv_per_m_s2, Per::MetrePerSecondSquared),
            (self.sensitivity_mv_per_mm_s, Per::MillimetrePerSecond),
        ]
        .into_iter()
        .filter_map(|(v, p)| v.map(|v| (v, p)))
        .collect();
        match given.as_slice() {
            [] => Ok(None),
            [one] => Ok(Some(*one)),
            [a, b, ..] => Err(UnitError::TwoSensitivities {
                first: a.1.label(),
                second: b.1.label(),
            }),
        }
    }

    /// Check the declaration and give its conversion.
    pub fn resolve(&self) -> Result<ChannelUnit, UnitError> {
        let sensitivity = self.sensitivity()?;
        let u = self.unit.trim();
        if u == "V" {
            let (mv, per) = sensitivity.ok_or(UnitError::NoSensitivity)?;
            if !(mv.is_finite() && mv > 0.0 && mv <= MAX_SENSITIVITY) {
                return Err(UnitError::BadSensitivity {
                    value: mv,
                    per: per.label(),
                    max: MAX_SENSITIVITY,
                });
            }
            return Ok(ChannelUnit {
                quantity: per.quantity(),
                to_si: per.si_per_volt(mv),
            });
        }
        let plain = match (u, Per::parse(u)) {
            (_, Some(Per::G)) => (Kinematic::Acceleration, STANDARD_GRAVITY),
            (_, Some(Per::MetrePerSecondSquared)) => (Kinematic::Acceleration, 1.0),
            (_, Some(Per::MillimetrePerSecond)) => (Kinematic::Velocity, 1e-3),
            (d, None) if DISPLACEMENTS.contains(&d) => {
                return Err(UnitError::Displacement { unit: d.into() });
            }
            (other, None) => return Err(UnitError::Unknown { unit: other.into() }),
        };
        if let Some((value, per)) = sensitivity {
            return Err(UnitError::SensitivityWithoutVolts {
                unit: u.into(),
                value,
                per: per.label(),
            });
        }
        Ok(ChannelUnit {
            quantity: plain.0,
            to_si: plain.1,
        })
    }
}

/// A sensitivity as written on a command line: a number, then `mV/g`, `mV/(m/s²)` (or
/// `m/s^2`, `m/s2`) or `mV/(mm/s)`, spaces allowed: `100mV/g`, `10.2 mV/(m/s²)`.
pub fn parse_sensitivity(text: &str) -> Result<(f64, Per), UnitError> {
    let bad = || UnitError::SensitivitySyntax { text: text.into() };
    let (number, per) = text.split_once("mV/").ok_or_else(bad)?;
    let value: f64 = number.trim().parse().map_err(|_| bad())?;
    let per = Per::parse(per).ok_or_else(bad)?;
    Ok((value, per))
}

/// A machine's declared units by channel name; [`ANY_CHANNEL`] (`"*"`) declares every channel
/// not named.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChannelUnits {
    by_name: BTreeMap<String, (UnitSpec, ChannelUnit)>,
}

impl ChannelUnits {
    /// Check every declaration. Errors: the first channel (in name order) whose unit is
    /// refused, with the reason.
    pub fn new(specs: BTreeMap<String, UnitSpec>) -> Result<Self, (String, UnitError)> {
        let mut by_name = BTreeMap::new();
        for (name, spec) in specs {
            let unit = spec.resolve().map_err(|e| (name.clone(), e))?;
            by_name.insert(name, (spec, unit));
        }
        Ok(ChannelUnits { by_name })
    }

    /// The declaration that applies to channel `name`: its own, else [`ANY_CHANNEL`]'s.
    pub fn of(&self, name: &str) -> Option<&(UnitSpec, ChannelUnit)> {
        self.by_name
            .get(name)
            .or_else(|| self.by_name.get(ANY_CHANNEL))
    }

    pub fn is_empty(&self) -> bool {
        self.by_name.is_empty()
    }

    /// The declarations as given (what the store keeps and the API shows).
    pub fn specs(&self) -> BTreeMap<String, UnitSpec> {
        self.by_name
            .iter()
            .map(|(k, (s, _))| (k.clone(), s.clone()))
            .collect()
    }
}

/// What an assessment needs of a machine's units: its channels' and its ISO 20816-3 class.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MachineUnits {
    pub channels: ChannelUnits,
    /// The machine's class, when it declares one: the velocity's zone is then given.
    pub iso: Option<IsoClass>,
}

#[cfg(test)]
mod tests;
