//! A machine's declared units and ISO 20816-3 class, checked as every door that writes a
//! machine checks them (`PUT /v1/machines/{id}`'s `channel_units` and `iso_20816`,
//! `gearwear machine set --unit … --iso-group …`, `gearwear diagnose --unit …`).
//!
//! A refusal ([`Refusal`]) carries what was wrong and on which channel; each door words it in
//! its own terms (the API's members, the command line's flags).

use std::collections::BTreeMap;

use thiserror::Error;

use super::{ANY_CHANNEL, ChannelUnits, IsoClass, UnitError, UnitSpec};

/// Most channels a machine may declare units for.
pub const MAX_DECLARED: usize = 64;

/// Longest channel name (bytes of UTF-8).
pub const MAX_CHANNEL_NAME: usize = 64;

/// A declared ISO 20816-3 class before it is checked: `group` is a number so that `2.0`
/// (JSON Schema's integers) is read as 2.
#[derive(Debug, Clone, PartialEq)]
pub struct IsoDeclared {
    pub group: f64,
    pub support: String,
}

/// Why a machine's units or ISO class were refused. The messages name values, not the
/// caller's members or flags.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Refusal {
    /// One channel's unit cannot be converted.
    #[error("{error}")]
    Channel { channel: String, error: UnitError },
    /// A channel name that is empty or too long.
    #[error("a channel name is 1 to {MAX_CHANNEL_NAME} characters")]
    NameLength { channel: String },
    /// Units declared for the tachometer's channel.
    #[error(
        "this is the machine's tachometer channel: it gives the speed, not a vibration; \
         declare units for the vibration channels only"
    )]
    Tachometer { channel: String },
    /// Units declared for a channel the machine does not diagnose.
    #[error(
        "the machine diagnoses only the channels {}: a unit for `{channel}` would never be \
         used; name one of them, or \"{ANY_CHANNEL}\" for all",
        quoted(.diagnosed)
    )]
    NotDiagnosed {
        channel: String,
        diagnosed: Vec<String>,
    },
    /// More declarations than [`MAX_DECLARED`].
    #[error("at most {max} channels, got {count}")]
    TooMany { count: usize, max: usize },
    /// A group that is not a whole number.
    #[error("`group` is the machine's ISO 20816-3 group, 1 or 2, got {0}")]
    IsoGroup(f64),
    /// A group or support the standard does not have.
    #[error("{0}")]
    IsoClass(UnitError),
    /// An ISO class without units: the zone is judged on a velocity in mm/s.
    #[error(
        "the ISO 20816-3 zone is judged on the velocity in mm/s, which needs the channels' \
         units: declare them"
    )]
    IsoWithoutUnits,
}

impl Refusal {
    /// The channel the refusal is about, when it is about one.
    pub fn channel(&self) -> Option<&str> {
        match self {
            Refusal::Channel { channel, .. }
            | Refusal::NameLength { channel }
            | Refusal::Tachometer { channel }
            | Refusal::NotDiagnosed { channel, .. } => Some(channel),
            _ => None,
        }
    }
}

/// `` `a`, `b` ``: channel names as the refusals list them.
pub fn quoted(names: &[String]) -> String {
    names
        .iter()
        .map(|c| format!("`{c}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Check a machine's declared units against its diagnosed `channels` (when it lists them)
/// and its `tacho_channel`: the units and the ISO class to keep.
///
/// Refused: a unit that cannot be converted; more than [`MAX_DECLARED`] declarations, or a
/// name of more than [`MAX_CHANNEL_NAME`] characters; a name that is not among `channels` or
/// is the tachometer's; an ISO group other than 1 or 2 or a support other than rigid or
/// flexible; an ISO class without units.
pub fn check_declared(
    channel_units: Option<BTreeMap<String, UnitSpec>>,
    iso: Option<&IsoDeclared>,
    channels: Option<&[String]>,
    tacho_channel: Option<&str>,
) -> Result<(Option<ChannelUnits>, Option<IsoClass>), Refusal> {
    let iso = iso.map(check_iso).transpose()?;
    let Some(specs) = channel_units.filter(|m| !m.is_empty()) else {
        return match iso {
            Some(_) => Err(Refusal::IsoWithoutUnits),
            None => Ok((None, None)),
        };
    };
    if specs.len() > MAX_DECLARED {
        return Err(Refusal::TooMany {
            count: specs.len(),
            max: MAX_DECLARED,
        });
    }
    for name in specs.keys() {
        check_name(name, channels, tacho_channel)?;
    }
    let units =
        ChannelUnits::new(specs).map_err(|(channel, error)| Refusal::Channel { channel, error })?;
    Ok((Some(units), iso))
}

fn check_iso(b: &IsoDeclared) -> Result<IsoClass, Refusal> {
    if b.group.fract() != 0.0 || b.group.abs() > 1e15 {
        return Err(Refusal::IsoGroup(b.group));
    }
    IsoClass::new(b.group as i64, &b.support).map_err(Refusal::IsoClass)
}

fn check_name(
    name: &str,
    channels: Option<&[String]>,
    tacho_channel: Option<&str>,
) -> Result<(), Refusal> {
    let channel = name.to_string();
    if name.is_empty() || name.len() > MAX_CHANNEL_NAME {
        return Err(Refusal::NameLength { channel });
    }
    if Some(name) == tacho_channel {
        return Err(Refusal::Tachometer { channel });
    }
    if let Some(list) = channels.filter(|_| name != ANY_CHANNEL)
        && !list.iter().any(|c| c == name)
    {
        return Err(Refusal::NotDiagnosed {
            channel,
            diagnosed: list.to_vec(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn specs(pairs: &[(&str, &str)]) -> BTreeMap<String, UnitSpec> {
        pairs
            .iter()
            .map(|(k, u)| (k.to_string(), UnitSpec::plain(u)))
            .collect()
    }

    #[test]
    fn a_unit_for_the_tachometer_or_an_undiagnosed_channel_is_refused() {
        let chans = vec!["a1".to_string(), "a2".to_string()];
        let r = check_declared(Some(specs(&[("tacho", "g")])), None, None, Some("tacho"));
        assert_eq!(
            r.unwrap_err(),
            Refusal::Tachometer {
                channel: "tacho".into()
            }
        );
        let r = check_declared(Some(specs(&[("a3", "g")])), None, Some(&chans), None);
        let e = r.unwrap_err();
        assert_eq!(e.channel(), Some("a3"));
        assert!(e.to_string().contains("`a1`, `a2`"), "{e}");
        let (units, iso) =
            check_declared(Some(specs(&[("*", "g")])), None, Some(&chans), None).unwrap();
        assert!(units.unwrap().of("a2").is_some());
        assert!(iso.is_none());
    }

    #[test]
    fn an_iso_class_needs_units_and_a_whole_group() {
        let iso = |group: f64| IsoDeclared {
            group,
            support: "rigid".into(),
        };
        assert_eq!(
            check_declared(None, Some(&iso(2.0)), None, None).unwrap_err(),
            Refusal::IsoWithoutUnits
        );
        assert_eq!(
            check_declared(Some(specs(&[("*", "g")])), Some(&iso(1.5)), None, None).unwrap_err(),
            Refusal::IsoGroup(1.5)
        );
        assert!(matches!(
            check_declared(Some(specs(&[("*", "g")])), Some(&iso(3.0)), None, None),
            Err(Refusal::IsoClass(UnitError::IsoGroup { group: 3 }))
        ));
        let (_, class) =
            check_declared(Some(specs(&[("*", "mm/s")])), Some(&iso(2.0)), None, None).unwrap();
        assert!(class.is_some());
    }

    #[test]
    fn too_many_declarations_are_refused() {
        let many: BTreeMap<String, UnitSpec> = (0..=MAX_DECLARED)
            .map(|i| (format!("c{i}"), UnitSpec::plain("g")))
            .collect();
        assert_eq!(
            check_declared(Some(many), None, None, None).unwrap_err(),
            Refusal::TooMany {
                count: MAX_DECLARED + 1,
                max: MAX_DECLARED
            }
        );
    }
}
