//! The vocabulary of an alert: its [`Level`] and the [`Basis`] it rests on. Both serialise to
//! the lowercase words of the API (`ok`, `unknown`, `warning`, `alarm`; `wear`, `novelty`,
//! `wear+novelty`, `baseline`, `quality`, `none`) and are compared as values, never as text.

use serde::{Deserialize, Serialize};

/// An alert level, in one order of severity: `ok` < `unknown` < `warning` < `alarm`.
///
/// `unknown` ranks above `ok` because nothing vouches for the machine (no wear figure the model
/// stands behind, no baseline), and below `warning` because nothing says it is worse either.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Level {
    Ok,
    #[default]
    Unknown,
    Warning,
    Alarm,
}

crate::words::words!(Level, "an alert level", {
    Ok => "ok",
    Unknown => "unknown",
    Warning => "warning",
    Alarm => "alarm",
});

/// What an alert level rests on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Basis {
    /// The wear degree of a model that fits the record.
    #[serde(rename = "wear")]
    Wear,
    /// The novelty against the machine's baseline.
    #[serde(rename = "novelty")]
    Novelty,
    /// Both, the level being the higher of the two.
    #[serde(rename = "wear+novelty")]
    WearAndNovelty,
    /// The record was posted as healthy, or its operating state is outside the baseline.
    #[serde(rename = "baseline")]
    Baseline,
    /// The record's quality caps the level at `unknown`.
    #[serde(rename = "quality")]
    Quality,
    /// Nothing: the level is `unknown`.
    #[serde(rename = "none")]
    None,
}

crate::words::words!(Basis, "an alert basis", {
    Wear => "wear",
    Novelty => "novelty",
    WearAndNovelty => "wear+novelty",
    Baseline => "baseline",
    Quality => "quality",
    None => "none",
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_order_by_severity_with_unknown_between_ok_and_warning() {
        let mut v = vec![Level::Alarm, Level::Ok, Level::Warning, Level::Unknown];
        v.sort();
        assert_eq!(v, Level::ALL);
        assert_eq!(Level::ALL.iter().max(), Some(&Level::Alarm));
        assert!(Level::Unknown > Level::Ok && Level::Unknown < Level::Warning);
    }

    #[test]
    fn levels_and_bases_read_and_write_the_api_words() {
        for &l in Level::ALL {
            assert_eq!(l.as_str().parse::<Level>(), Ok(l));
            assert_eq!(serde_json::to_value(l).unwrap(), l.as_str());
        }
        for &b in Basis::ALL {
            assert_eq!(serde_json::to_value(b).unwrap(), b.as_str());
        }
        let e = "OK".parse::<Level>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "`OK` is not an alert level (ok, unknown, warning, alarm)"
        );
        assert_eq!(
            serde_json::to_value(Basis::WearAndNovelty).unwrap(),
            "wear+novelty"
        );
        assert_eq!(
            serde_json::from_str::<Basis>("\"quality\"").unwrap(),
            Basis::Quality
        );
    }
}
