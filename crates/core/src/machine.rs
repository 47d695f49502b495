//! A machine's configuration as every door that writes one checks it (the service's
//! `PUT /v1/machines/{id}`, `gearwear machine set`): its id, its gearbox's default, its
//! tachometer. The problems carry what was wrong; each door words them in its own terms (the
//! API's members, the command line's flags).

/// The gearbox a machine that names none is diagnosed with: the first paper's rig.
pub const BUILTIN_GEARBOX_ID: &str = "wang2019";
/// The name of a record's tachometer channel, for a machine that names none.
pub const DEFAULT_TACHO_CHANNEL: &str = "tacho";
/// Most tachometer pulses per revolution accepted (a fine shaft encoder).
pub const MAX_TACHO_PPR: i64 = crate::condition::state::MAX_PULSES_PER_REV as i64;
/// Longest machine or gearbox id, and longest channel name.
pub const MAX_NAME_CHARS: usize = 64;

/// Whether `id` is 1–64 characters of `A–Z a–z 0–9 . _ -` (machine and gearbox ids).
pub fn is_valid_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= MAX_NAME_CHARS
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'.' || b == b'_' || b == b'-')
}

/// What is wrong with a machine's tachometer settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TachoProblem {
    /// Pulses per revolution outside `1..=`[`MAX_TACHO_PPR`] (the value given).
    PulsesPerRev(i64),
    /// The tachometer's channel name is empty or longer than [`MAX_NAME_CHARS`].
    ChannelName,
    /// The tachometer's channel is also one of the channels to diagnose (its name).
    ChannelDiagnosed(String),
}

/// Check a machine's tachometer settings: `tacho_channel` a channel name that is not among the
/// `channels` to diagnose, `tacho_ppr` from 1 to [`MAX_TACHO_PPR`].
pub fn check_tacho(
    tacho_channel: Option<&str>,
    tacho_ppr: i64,
    channels: Option<&[String]>,
) -> Result<(), TachoProblem> {
    if !(1..=MAX_TACHO_PPR).contains(&tacho_ppr) {
        return Err(TachoProblem::PulsesPerRev(tacho_ppr));
    }
    let Some(t) = tacho_channel else {
        return Ok(());
    };
    if t.is_empty() || t.len() > MAX_NAME_CHARS {
        return Err(TachoProblem::ChannelName);
    }
    if channels.is_some_and(|c| c.iter().any(|c| c == t)) {
        return Err(TachoProblem::ChannelDiagnosed(t.to_string()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_tachometers_are_checked() {
        assert!(is_valid_id("press-7.a_1"));
        for bad in ["", "a b", "é", &"x".repeat(65)] {
            assert!(!is_valid_id(bad), "{bad}");
        }
        let chans = vec!["a1".to_string(), "a2".to_string()];
        assert_eq!(check_tacho(Some("tacho"), 10, Some(&chans)), Ok(()));
        assert_eq!(check_tacho(None, 1, None), Ok(()));
        assert_eq!(
            check_tacho(Some("t"), 0, None),
            Err(TachoProblem::PulsesPerRev(0))
        );
        assert_eq!(
            check_tacho(Some(""), 1, None),
            Err(TachoProblem::ChannelName)
        );
        assert_eq!(
            check_tacho(Some("a1"), 1, Some(&chans)),
            Err(TachoProblem::ChannelDiagnosed("a1".into()))
        );
    }
}
