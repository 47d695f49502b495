//! The alert policy: a channel's alert level from its wear degree (when the model fits) and
//! its novelty against the machine's baseline (when it has one), and the channel that decides
//! a record's level.
//!
//! # Alert levels
//! * The **wear** level (`ok` / `warning` / `alarm` by the configured ea thresholds) counts only
//!   when the model fits the record (no "poor fit": χ² per feature within the diagnosis's
//!   limit) — a wear degree read off a model that does not explain the record is not evidence.
//! * The **novelty** level: `ok` when the record is within the baseline's calibrated threshold,
//!   `warning` above it, `alarm` above twice it. The condition indicators (kurtosis, crest
//!   factor, the TSA metrics) enter through the novelty features, scaled by the machine's own
//!   healthy records: fixed textbook limits (FM4 > 3 …) are not used, because healthy real
//!   gearboxes exceed them (the SpectraQuest healthy records have FM4 ≈ 5.5).
//! * The level is the higher of the two that count. When neither counts — the model does not
//!   fit (or the table is not ready) and the machine has no baseline — the level is `unknown`:
//!   not `ok`, because nothing vouches for the machine.
//! * A record posted as healthy (`?baseline=true`) is vouched for by the caller: its level is
//!   `ok` (basis `baseline`), or the wear level if the model fits and it is higher; its novelty
//!   against the earlier baseline is still reported (a baseline record unlike the others is
//!   worth seeing) but raises no alert.
//! * Several channels: each gets its level; the record's is the most severe (alarm > warning >
//!   unknown > ok), ties broken by the larger novelty score over its threshold; that channel
//!   is named as the one that decides.

use serde::Serialize;

use super::ChannelAssessment;
pub use super::level::{Basis, Level};
use crate::novelty::Novelty;

/// Wear-degree thresholds (ea, units of the backlash b) that set a machine's alert level:
/// `ok` below `warning`, `warning` below `alarm`, then `alarm`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Thresholds {
    pub warning: f64,
    pub alarm: f64,
}

impl Default for Thresholds {
    /// The service's default levels (`gearwear serve --warning-ea 0.5 --alarm-ea 0.8`).
    fn default() -> Self {
        Thresholds {
            warning: 0.5,
            alarm: 0.8,
        }
    }
}

impl Thresholds {
    pub fn level(&self, ea: f64) -> Level {
        if ea >= self.alarm {
            Level::Alarm
        } else if ea >= self.warning {
            Level::Warning
        } else {
            Level::Ok
        }
    }
}

/// A channel's (or a record's) alert.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Alert {
    pub level: Level,
    /// What the level rests on.
    pub basis: Basis,
    /// One sentence a person can act on.
    pub reason: String,
}

/// Why a channel that neither a wear degree nor a baseline vouches for is `unknown`, and what
/// to do: a baseline always helps; while the gearbox's table is being computed (`table_note`)
/// the gearbox is described already and a wear degree follows when the table is ready.
fn unknown_reason(fit_note: &str, table_pending: bool) -> String {
    let why = if fit_note.is_empty() {
        "no wear degree is available"
    } else {
        fit_note
    };
    let then = if table_pending {
        "; the wear degree follows when the table is ready"
    } else {
        ""
    };
    format!(
        "{why}, and the machine has no baseline yet: post at least 3 healthy records with \
         ?baseline=true so that later records are judged against them{then}"
    )
}

/// The alert of one channel.
///
/// `wear`: `(estimate, poor_fit, chi2_per_feature)` when the gearbox's table gave a wear
/// degree; `novelty` when the machine has a baseline for this channel.
pub fn alert(
    wear: Option<(f64, bool, f64)>,
    novelty: Option<&Novelty>,
    th: &Thresholds,
    table_note: Option<&str>,
    declared_healthy: bool,
) -> Alert {
    let wear_level = wear.filter(|w| !w.1).map(|w| th.level(w.0));
    if declared_healthy && wear_level.is_none_or(|w| w == Level::Ok) {
        return Alert {
            level: Level::Ok,
            basis: Basis::Baseline,
            reason: match novelty {
                Some(n) => format!(
                    "posted as healthy (baseline record); its novelty against the earlier \
                     baseline is {:.2} (threshold {:.2}){}",
                    n.score,
                    n.threshold,
                    if n.anomalous {
                        ": unlike the other baseline records — check it belongs"
                    } else {
                        ""
                    }
                ),
                None => "posted as healthy (baseline record)".into(),
            },
        };
    }
    let nov_level = novelty.map(|n| {
        if !n.anomalous {
            Level::Ok
        } else if n.score >= 2.0 * n.threshold {
            Level::Alarm
        } else {
            Level::Warning
        }
    });
    let fit_note = match (wear, table_note) {
        (Some((_, true, chi2)), _) => format!(
            "the model does not fit this record (χ² per feature {chi2:.1}), so its wear degree is not used"
        ),
        (None, Some(note)) => note.to_string(),
        _ => String::new(),
    };
    match (wear_level, nov_level) {
        (None, None) => Alert {
            level: Level::Unknown,
            basis: Basis::None,
            reason: unknown_reason(&fit_note, table_note.is_some()),
        },
        (Some(w), None) => Alert {
            level: w,
            basis: Basis::Wear,
            reason: format!(
                "wear degree {:.2} ({w}); no baseline yet for novelty",
                wear.map(|w| w.0).unwrap_or(f64::NAN)
            ),
        },
        (None, Some(n)) => {
            let nv = novelty.expect("novelty level implies novelty");
            Alert {
                level: n,
                basis: Basis::Novelty,
                reason: format!(
                    "novelty {:.2} against the machine's baseline (threshold {:.2}){}{}",
                    nv.score,
                    nv.threshold,
                    if fit_note.is_empty() { "" } else { "; " },
                    fit_note
                ),
            }
        }
        (Some(w), Some(n)) => {
            let nv = novelty.expect("novelty level implies novelty");
            Alert {
                level: n.max(w),
                basis: Basis::WearAndNovelty,
                reason: format!(
                    "wear degree {:.2} ({w}); novelty {:.2} against the machine's baseline \
                     (threshold {:.2}, {n})",
                    wear.map(|w| w.0).unwrap_or(f64::NAN),
                    nv.score,
                    nv.threshold
                ),
            }
        }
    }
}

/// Index of the channel that decides the record's alert.
pub fn deciding(results: &[ChannelAssessment]) -> usize {
    let ratio = |r: &ChannelAssessment| {
        r.novelty
            .as_ref()
            .map(|n| n.score / n.threshold.max(f64::MIN_POSITIVE))
            .unwrap_or(0.0)
    };
    let mut best = 0;
    for (i, r) in results.iter().enumerate().skip(1) {
        let b = &results[best];
        let (s, sb) = (r.alert.level, b.alert.level);
        if s > sb || (s == sb && ratio(r) > ratio(b)) {
            best = i;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::novelty::{FeatureZ, RecordFeatures};

    const TH: Thresholds = Thresholds {
        warning: 0.5,
        alarm: 0.8,
    };

    fn nov(score: f64) -> Novelty {
        Novelty {
            score,
            threshold: 3.0,
            anomalous: score > 3.0,
            baseline_records: 5,
            features_used: 10,
            top_features: vec![FeatureZ {
                name: "x".into(),
                z: score,
            }],
        }
    }

    #[test]
    fn a_record_nothing_vouches_for_is_unknown_not_ok() {
        let a = alert(Some((0.2, true, 40.0)), None, &TH, None, false);
        assert_eq!(a.level, Level::Unknown);
        assert!(a.reason.contains("baseline"), "{}", a.reason);
        let a = alert(None, None, &TH, Some("the table is not ready"), false);
        assert_eq!(a.level, Level::Unknown);
        assert!(
            a.reason.starts_with("the table is not ready"),
            "{}",
            a.reason
        );
    }

    #[test]
    fn a_record_posted_as_healthy_raises_no_alert_of_its_own() {
        let a = alert(Some((0.2, true, 40.0)), Some(&nov(9.0)), &TH, None, true);
        assert_eq!((a.level, a.basis), (Level::Ok, Basis::Baseline));
        assert!(a.reason.contains("unlike"), "{}", a.reason);
        // A wear degree the model vouches for still counts.
        assert_eq!(
            alert(Some((0.9, false, 1.0)), None, &TH, None, true).level,
            Level::Alarm
        );
    }

    #[test]
    fn a_poor_fit_defers_to_the_baseline() {
        assert_eq!(
            alert(Some((0.9, true, 40.0)), Some(&nov(1.0)), &TH, None, false).level,
            Level::Ok
        );
        let a = alert(Some((0.1, true, 40.0)), Some(&nov(4.0)), &TH, None, false);
        assert_eq!((a.level, a.basis), (Level::Warning, Basis::Novelty));
        assert_eq!(
            alert(None, Some(&nov(6.5)), &TH, None, false).level,
            Level::Alarm
        );
    }

    #[test]
    fn a_good_fit_and_a_baseline_take_the_more_severe() {
        assert_eq!(
            alert(Some((0.9, false, 1.0)), Some(&nov(1.0)), &TH, None, false).level,
            Level::Alarm
        );
        assert_eq!(
            alert(Some((0.1, false, 1.0)), Some(&nov(4.0)), &TH, None, false).level,
            Level::Warning
        );
        assert_eq!(
            alert(Some((0.6, false, 1.0)), None, &TH, None, false).level,
            Level::Warning
        );
        assert_eq!(
            alert(Some((0.1, false, 1.0)), None, &TH, None, false).level,
            Level::Ok
        );
    }

    #[test]
    fn the_most_severe_channel_decides() {
        let ch = |name: &str, level: Level, score: f64| ChannelAssessment {
            name: name.into(),
            reading: None,
            table_miss: None,
            features: RecordFeatures {
                values: Default::default(),
                indicators: serde_json::Value::Null,
                ..Default::default()
            },
            novelty: Some(nov(score)),
            state: None,
            findings: Vec::new(),
            alert: Alert {
                level,
                basis: Basis::Novelty,
                reason: String::new(),
            },
            wear_um: None,
            vibration: None,
        };
        let v = vec![
            ch("a1", Level::Ok, 1.0),
            ch("a2", Level::Warning, 3.5),
            ch("a3", Level::Warning, 5.0),
        ];
        assert_eq!(deciding(&v), 2);
        let v = vec![ch("a1", Level::Unknown, 0.0), ch("a2", Level::Ok, 2.0)];
        assert_eq!(deciding(&v), 0);
    }
}
