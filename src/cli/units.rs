//! `--unit`, `--sensitivity`, `--iso-group`, `--iso-support`: what a record's channels
//! measure and the machine's ISO 20816-3 class, for `gearwear diagnose` and `gearwear machine
//! set` (as `channel_units` and `iso_20816` of `PUT /v1/machines/{id}`, checked by the same
//! rules: [`check_declared`]).

use std::collections::BTreeMap;

use anyhow::{Result, bail};
use clap::Args;

use crate::units::{
    ANY_CHANNEL, ChannelUnits, IsoClass, IsoDeclared, MachineUnits, Refusal, UnitError, UnitSpec,
    check_declared, parse_sensitivity,
};

/// The unit flags.
#[derive(Debug, Args, Clone, Default)]
pub struct UnitArgs {
    /// What the channels' numbers are: g or m/s² (an accelerometer), mm/s (a velocity sensor),
    /// or V (with --sensitivity); NAME=UNIT for one channel (repeat the flag for several).
    /// The answer then has `vibration`: acceleration RMS and peak, velocity RMS over
    /// 10–1000 Hz.
    #[arg(long, value_name = "UNIT|NAME=UNIT")]
    pub unit: Vec<String>,
    /// The sensor's sensitivity, for a channel in V: 100mV/g, 10.2mV/(m/s²) or 20mV/(mm/s);
    /// NAME=S for one channel (a bare one applies to every channel without its own).
    #[arg(long, value_name = "S|NAME=S", requires = "unit")]
    pub sensitivity: Vec<String>,
    /// The machine's ISO 20816-3 group: 1 (large: 300 kW to 50 MW) or 2 (medium: 15 kW to
    /// 300 kW). With --iso-support, `vibration` has the velocity's ISO 20816-3 zone.
    #[arg(long, value_name = "1|2", requires_all = ["iso_support", "unit"])]
    pub iso_group: Option<i64>,
    /// The machine's support: rigid (its lowest natural frequency at least 25 % above the
    /// running speed) or flexible.
    #[arg(long, value_name = "rigid|flexible", requires = "iso_group")]
    pub iso_support: Option<String>,
}

/// `NAME=VALUE` → `(NAME, VALUE)`; a bare `VALUE` → `("*", VALUE)`.
fn split(arg: &str) -> (&str, &str) {
    arg.split_once('=').unwrap_or((ANY_CHANNEL, arg))
}

/// "--unit", "--unit a1=…": the flag that declared a channel.
fn flag(base: &str, channel: &str) -> String {
    if channel == ANY_CHANNEL {
        base.to_string()
    } else {
        format!("{base} {channel}=…")
    }
}

impl UnitArgs {
    /// The declarations by channel name (a bare `--unit` is every channel's).
    fn specs(&self) -> Result<BTreeMap<String, UnitSpec>> {
        let mut specs = BTreeMap::new();
        for u in &self.unit {
            let (name, unit) = split(u);
            if specs
                .insert(name.to_string(), UnitSpec::plain(unit))
                .is_some()
            {
                bail!("{}: given twice", flag("--unit", name));
            }
        }
        let mut bare = None;
        let mut own = BTreeMap::new();
        for s in &self.sensitivity {
            let (name, text) = split(s);
            let parsed = parse_sensitivity(text)
                .map_err(|e| anyhow::anyhow!("{}: {e}", flag("--sensitivity", name)))?;
            if name == ANY_CHANNEL {
                bare = Some(parsed);
            } else if !specs.contains_key(name) {
                bail!("--sensitivity {name}=…: no --unit {name}=V declares that channel");
            } else {
                own.insert(name.to_string(), parsed);
            }
        }
        let mut bare_used = false;
        for (name, spec) in specs.iter_mut() {
            let given = match own.get(name) {
                Some(s) => Some(*s),
                None if spec.unit.trim() == "V" => {
                    bare_used |= bare.is_some();
                    bare
                }
                None => None,
            };
            if let Some((mv, per)) = given {
                *spec = UnitSpec {
                    unit: spec.unit.clone(),
                    ..UnitSpec::volts(mv, per)
                };
            }
        }
        if bare.is_some() && !bare_used {
            bail!("--sensitivity: no channel is declared in V (--unit V or --unit NAME=V)");
        }
        Ok(specs)
    }

    fn iso(&self) -> Option<IsoDeclared> {
        Some(IsoDeclared {
            group: self.iso_group? as f64,
            support: self.iso_support.clone()?,
        })
    }

    /// The flags checked by the rules `PUT /v1/machines/{id}` applies to `channel_units` and
    /// `iso_20816` ([`check_declared`]). Errors name the flags.
    fn declared(
        &self,
        channels: Option<&[String]>,
        tacho_channel: Option<&str>,
    ) -> Result<(Option<ChannelUnits>, Option<IsoClass>)> {
        let specs = self.specs()?;
        check_declared(
            Some(specs).filter(|s| !s.is_empty()),
            self.iso().as_ref(),
            channels,
            tacho_channel,
        )
        .map_err(|r| anyhow::anyhow!(cli_message(&r)))
    }

    /// The flags as a machine's stored configuration: the `channel_units` JSON and the ISO
    /// class.
    pub fn check(
        &self,
        channels: Option<&[String]>,
        tacho_channel: Option<&str>,
    ) -> Result<(Option<String>, Option<IsoClass>)> {
        let (units, iso) = self.declared(channels, tacho_channel)?;
        let text = units
            .map(|u| serde_json::to_string(&u.specs()))
            .transpose()?;
        Ok((text, iso))
    }

    /// The units of `gearwear diagnose`: every declared name must be one of the record's
    /// `names` (but the tachometer's).
    pub fn machine_units(&self, names: &[String], tacho: Option<&str>) -> Result<MachineUnits> {
        let (units, iso) = self.declared(None, tacho)?;
        let Some(channels) = units else {
            return Ok(MachineUnits::default());
        };
        for (name, _) in channels.specs() {
            if name != ANY_CHANNEL && !names.contains(&name) {
                bail!(
                    "--unit {name}=…: the record has no channel `{name}` (its channels: {})",
                    names.join(", ")
                );
            }
        }
        Ok(MachineUnits { channels, iso })
    }
}

/// A refusal in the words of the command line.
fn cli_message(r: &Refusal) -> String {
    let channel = r.channel().unwrap_or(ANY_CHANNEL);
    match r {
        Refusal::Channel {
            error: UnitError::NoSensitivity,
            ..
        } => format!(
            "{}: {r}; give it with --sensitivity (e.g. --sensitivity 100mV/g)",
            flag("--unit", channel)
        ),
        Refusal::Channel {
            error:
                UnitError::SensitivityWithoutVolts { .. }
                | UnitError::TwoSensitivities { .. }
                | UnitError::BadSensitivity { .. },
            ..
        } => format!("{}: {r}", flag("--sensitivity", channel)),
        Refusal::NotDiagnosed { diagnosed, .. } => format!(
            "{}: the machine diagnoses only the channels {} (--channels): a unit for \
             `{channel}` would never be used; name one of them, or a bare --unit for all",
            flag("--unit", channel),
            diagnosed.join(", ")
        ),
        Refusal::IsoGroup(_) | Refusal::IsoClass(_) => {
            format!("--iso-group/--iso-support: {r}")
        }
        Refusal::IsoWithoutUnits => format!("--iso-group/--iso-support: {r} with --unit"),
        _ => format!("{}: {r}", flag("--unit", channel)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(unit: &[&str], sensitivity: &[&str]) -> UnitArgs {
        UnitArgs {
            unit: unit.iter().map(|s| s.to_string()).collect(),
            sensitivity: sensitivity.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn flags_become_the_api_shape() {
        let (text, iso) = args(&["V", "a2=g"], &["100mV/g"])
            .check(None, None)
            .unwrap();
        let v: serde_json::Value = serde_json::from_str(&text.unwrap()).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"*": {"unit": "V", "sensitivity_mv_per_g": 100.0},
                               "a2": {"unit": "g"}})
        );
        assert_eq!(iso, None);
        let (text, _) = args(&["a1=V", "a2=V"], &["a1=10.2mV/(m/s²)", "20 mV/(mm/s)"])
            .check(None, None)
            .unwrap();
        let v: serde_json::Value = serde_json::from_str(&text.unwrap()).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"a1": {"unit": "V", "sensitivity_mv_per_m_s2": 10.2},
                               "a2": {"unit": "V", "sensitivity_mv_per_mm_s": 20.0}})
        );
    }

    #[test]
    fn refusals_name_the_flags() {
        let e = args(&["V"], &[]).check(None, None).unwrap_err().to_string();
        assert!(
            e.starts_with("--unit: ") && e.contains("--sensitivity 100mV/g"),
            "{e}"
        );
        let e = args(&["g"], &["100mV/g"])
            .check(None, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--sensitivity: ") && e.contains("in V"),
            "{e}"
        );
        let e = args(&["a1=g"], &["a1=100mV/g"])
            .check(None, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--sensitivity a1=…: ") && e.contains("`g`"),
            "{e}"
        );
        let e = args(&["a1=µm"], &[])
            .check(None, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--unit a1=…: ") && e.contains("displacement"),
            "{e}"
        );
        let e = args(&["V"], &["100 mV per g"])
            .check(None, None)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--sensitivity: "), "{e}");
        let e = args(&["a9=g"], &[])
            .check(Some(&["a1".to_string()]), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("(--channels)"), "{e}");
        let iso = UnitArgs {
            iso_group: Some(3),
            iso_support: Some("rigid".into()),
            ..args(&["g"], &[])
        };
        let e = iso.check(None, None).unwrap_err().to_string();
        assert!(
            e.starts_with("--iso-group/--iso-support: ") && e.contains("group 3"),
            "{e}"
        );
    }
}
