//! A machine's physical units: `channel_units` and `iso_20816` of `PUT /v1/machines/{id}` —
//! checked ([`check`]; the rules are the core's, shared with `gearwear machine set`), stored as JSON and two columns,
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
use crate::units::{
    ANY_CHANNEL, ChannelUnits, IsoClass, IsoDeclared, MachineUnits, Refusal, UnitError, UnitSpec,
    check_declared, quoted,
};

/// `iso_20816` of a machine's configuration.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsoBody {
    /// A number so that `2.0` is read as 2 (JSON Schema's integers); checked to be 1 or 2.
    pub group: f64,
    pub support: String,
}

/// The 422 of `PUT /v1/machines/{id}` for a refusal, naming the member to fix.
pub fn problem(r: &Refusal) -> ApiError {
    let member = match (r, r.channel()) {
        (_, Some(c)) => format!("channel_units.{c}"),
        (Refusal::TooMany { .. }, None) => "channel_units".to_string(),
        _ => "iso_20816".to_string(),
    };
    let detail = match r {
        Refusal::Channel {
            error: UnitError::NoSensitivity,
            ..
        } => format!(
            "{r}; give `sensitivity_mv_per_g`, `sensitivity_mv_per_m_s2` or \
             `sensitivity_mv_per_mm_s`"
        ),
        Refusal::NotDiagnosed { channel, diagnosed } => format!(
            "the machine diagnoses only the channels {} (`channels`): a unit for `{channel}` \
             would never be used; name one of them, or \"{ANY_CHANNEL}\" for all",
            quoted(diagnosed)
        ),
        Refusal::IsoWithoutUnits => format!("{r} in `channel_units`"),
        _ => r.to_string(),
    };
    let (slug, title) = match r {
        Refusal::Channel { .. } => ("invalid-unit", "Unit cannot be used"),
        _ => ("invalid-machine", "Invalid machine configuration"),
    };
    ApiError::unprocessable(slug, title, format!("`{member}`: {detail}")).with("member", member)
}

/// Check a machine's units ([`check_declared`]): the `channel_units` JSON to store and the
/// ISO class.
pub fn check(
    channel_units: Option<BTreeMap<String, UnitSpec>>,
    iso: Option<&IsoBody>,
    channels: Option<&[String]>,
    tacho_channel: Option<&str>,
) -> ApiResult<(Option<String>, Option<IsoClass>)> {
    let iso = iso.map(|b| IsoDeclared {
        group: b.group,
        support: b.support.clone(),
    });
    let (units, iso) = check_declared(channel_units, iso.as_ref(), channels, tacho_channel)
        .map_err(|r| problem(&r))?;
    let text = units
        .map(|u| serde_json::to_string(&u.specs()))
        .transpose()
        .map_err(|e| ApiError::internal(format!("channel_units cannot be written: {e}")))?;
    Ok((text, iso))
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
