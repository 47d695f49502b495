//! A machine's physical units: `channel_units` and `iso_20816` of `PUT /v1/machines/{id}` —
//! checked ([`check`], shared with `gearwear machine set`), stored as JSON and two columns,
//! shown in the machine's configuration ([`config_json`]), and handed to the assessment
//! ([`machine_units`]).
//!
//! ```json
//! "channel_units": {"a1": {"unit": "V", "sensitivity_mv_per_g": 100}, "*": {"unit": "g"}},
//! "iso_20816": {"group": 2, "support": "rigid"}
//! ```
//!
//! `channel_units` maps a channel name (`"*"`: every channel not named; a one-channel record's
//! channel is `"0"`) to its unit ([`crate::units::UnitSpec`]). Absent or null: the machine's
//! records stay unitless and their diagnoses have no `vibration`.

use std::collections::BTreeMap;

use serde::Deserialize;
use serde_json::{Value, json};

use super::error::{ApiError, ApiResult};
use crate::store::MachineRow;
use crate::units::{ANY_CHANNEL, ChannelUnits, IsoClass, MachineUnits, UnitError, UnitSpec};

/// Most channels a machine may declare units for (as `channels`).
const MAX_DECLARED: usize = 64;

/// `iso_20816` of a machine's configuration.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsoBody {
    /// A number so that `2.0` is read as 2 (JSON Schema's integers); checked to be 1 or 2.
    pub group: f64,
    pub support: String,
}

/// Why a machine's units were refused, by the part of the configuration at fault.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    /// One channel's declaration.
    Channel { channel: String, error: UnitError },
    /// A declaration for a name that cannot be one of the machine's vibration channels.
    Name { channel: String, reason: String },
    /// `channel_units` as a whole.
    Units(String),
    /// The ISO class.
    Iso(String),
}

impl Refusal {
    /// The 422 of `PUT /v1/machines/{id}`, naming the member to fix.
    pub fn problem(&self) -> ApiError {
        let (member, detail) = match self {
            Refusal::Channel { channel, error } => {
                let hint = match error {
                    UnitError::NoSensitivity => {
                        "; give `sensitivity_mv_per_g`, `sensitivity_mv_per_m_s2` or \
                         `sensitivity_mv_per_mm_s`"
                    }
                    _ => "",
                };
                (format!("channel_units.{channel}"), format!("{error}{hint}"))
            }
            Refusal::Name { channel, reason } => {
                (format!("channel_units.{channel}"), reason.clone())
            }
            Refusal::Units(m) => ("channel_units".to_string(), m.clone()),
            Refusal::Iso(m) => ("iso_20816".to_string(), m.clone()),
        };
        let (slug, title) = match self {
            Refusal::Channel { .. } => ("invalid-unit", "Unit cannot be used"),
            _ => ("invalid-machine", "Invalid machine configuration"),
        };
        ApiError::unprocessable(slug, title, format!("`{member}`: {detail}")).with("member", member)
    }
}

/// Check a machine's units against its `channels` and `tacho_channel`: the `channel_units`
/// JSON to store and the ISO class.
///
/// Refused: a unit that cannot be converted ([`UnitError`]); more than 64 declarations, or a
/// name of more than 64 characters; a name that is not among `channels` (when the machine
/// lists them) or is the tachometer's; an ISO group other than 1 or 2 or a support other than
/// rigid or flexible; an ISO class without units (its zone is judged on a velocity in mm/s).
pub fn check(
    channel_units: Option<BTreeMap<String, UnitSpec>>,
    iso: Option<&IsoBody>,
    channels: Option<&[String]>,
    tacho_channel: Option<&str>,
) -> Result<(Option<String>, Option<IsoClass>), Refusal> {
    let iso = iso
        .map(|b| {
            let group = if b.group.fract() == 0.0 && b.group.abs() <= 1e15 {
                b.group as i64
            } else {
                return Err(Refusal::Iso(format!(
                    "`group` is the machine's ISO 20816-3 group, 1 or 2, got {}",
                    b.group
                )));
            };
            IsoClass::new(group, &b.support).map_err(|e| Refusal::Iso(e.to_string()))
        })
        .transpose()?;
    let Some(specs) = channel_units.filter(|m| !m.is_empty()) else {
        if iso.is_some() {
            return Err(Refusal::Iso(
                "the ISO 20816-3 zone is judged on the velocity in mm/s, which needs the \
                 channels' units: declare them in `channel_units`"
                    .into(),
            ));
        }
        return Ok((None, None));
    };
    if specs.len() > MAX_DECLARED {
        return Err(Refusal::Units(format!(
            "at most {MAX_DECLARED} channels, got {}",
            specs.len()
        )));
    }
    for name in specs.keys() {
        let reason = if name.is_empty() || name.len() > 64 {
            "a channel name is 1 to 64 characters".to_string()
        } else if Some(name.as_str()) == tacho_channel {
            "this is the machine's tachometer channel: it gives the speed, not a vibration; \
             declare units for the vibration channels only"
                .to_string()
        } else if let Some(list) = channels.filter(|_| name != ANY_CHANNEL)
            && !list.contains(name)
        {
            format!(
                "the machine diagnoses only the channels {} (`channels`): a unit for `{name}` \
                 would never be used; name one of them, or \"{ANY_CHANNEL}\" for all",
                list.iter()
                    .map(|c| format!("`{c}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            continue;
        };
        return Err(Refusal::Name {
            channel: name.clone(),
            reason,
        });
    }
    let units =
        ChannelUnits::new(specs).map_err(|(channel, error)| Refusal::Channel { channel, error })?;
    let text = serde_json::to_string(&units.specs())
        .map_err(|e| Refusal::Units(format!("cannot be written: {e}")))?;
    Ok((Some(text), iso))
}

/// `channel_units` and `iso_20816` of a machine's configuration (null when not declared).
pub fn config_json(m: &MachineRow) -> (Value, Value) {
    let units = m
        .channel_units
        .as_deref()
        .and_then(|t| serde_json::from_str(t).ok())
        .unwrap_or(Value::Null);
    let iso = match (m.iso_group, &m.iso_support) {
        (Some(g), Some(s)) => json!({"group": g, "support": s}),
        _ => Value::Null,
    };
    (units, iso)
}

/// What the assessment needs of a machine's units (none for a machine without a row).
pub fn machine_units(m: Option<&MachineRow>) -> ApiResult<MachineUnits> {
    let Some(m) = m else {
        return Ok(MachineUnits::default());
    };
    let bad = |what: String| {
        ApiError::internal(format!(
            "machine `{}`: its stored units are unreadable ({what}); PUT its configuration again",
            m.id
        ))
    };
    let channels = match &m.channel_units {
        None => ChannelUnits::default(),
        Some(t) => {
            let specs: BTreeMap<String, UnitSpec> =
                serde_json::from_str(t).map_err(|e| bad(e.to_string()))?;
            ChannelUnits::new(specs).map_err(|(c, e)| bad(format!("{c}: {e}")))?
        }
    };
    let iso = match (m.iso_group, &m.iso_support) {
        (Some(g), Some(s)) => Some(IsoClass::new(g, s).map_err(|e| bad(e.to_string()))?),
        _ => None,
    };
    Ok(MachineUnits { channels, iso })
}
