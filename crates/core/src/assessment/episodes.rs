//! Alerts as events: a machine's alert *episode* opens when its records' severity rises, can be
//! acknowledged by a person, and closes when the severity has stayed low — the pure state
//! machine (the store keeps its state and runs [`step`] inside each record's transaction).
//!
//! # Severity
//! A record's alert level (`ok` / `warning` / `alarm`, [`super::alert`]) is a step function of
//! continuous evidence; hysteresis needs the evidence itself. The **severity** `s` (unitless)
//! puts both kinds of evidence on one scale whose integer marks are the level thresholds:
//!
//! * wear (when the model fits): `s = ea / w` below the warning degree `w`, then
//!   `s = 1 + (ea − w) / (a − w)`, so `s = 1` at `ea = w` and `s = 2` at the alarm degree `a`;
//! * novelty: `s = score / threshold` (warning above the threshold, alarm from twice it);
//! * both: the larger, exactly as the level takes the more severe.
//!
//! The value is clamped into its level's band (`ok` `[0, 1)`, `warning` `[1, 2)`, `alarm`
//! `[2, ∞)`), so the severity never contradicts the level the record answered (a record the
//! policy capped, or posted as healthy, keeps its level). A record whose level is `unknown` has
//! no severity: it neither opens nor closes an alert, nor breaks a run.
//!
//! # The episode
//! With `N = open_after`, `M = close_after` ([`EpisodePolicy`]):
//! * **opens** when `N` consecutive records (with a severity) reach `s ≥ 1`; its level is
//!   `alarm` if those `N` were all `≥ 2`, else `warning` — one noisy record opens nothing;
//! * **escalates** from `warning` to `alarm` after `N` consecutive records at `s ≥ 2`;
//! * **closes** after `M` consecutive records below `close_below` (default 0.8): the gap
//!   between 1 (open) and 0.8 (close) is the hysteresis, so a machine hovering at the warning
//!   threshold stays in one episode instead of opening and closing on every record;
//! * acknowledging does not change the counts (an acknowledged alert is still open and still
//!   escalates and closes).

use serde::{Deserialize, Serialize};

use super::{Assessment, ChannelAssessment, Thresholds};
use crate::novelty::Novelty;

/// The hysteresis and delays of alert episodes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EpisodePolicy {
    /// `N`: consecutive records at or above warning (severity ≥ 1) that open an alert, and at
    /// alarm (≥ 2) that escalate one (≥ 1).
    pub open_after: u32,
    /// `M`: consecutive records below `close_below` that close an alert (≥ 1).
    pub close_after: u32,
    /// Severity under which a record counts towards closing (in `(0, 1]`; 1 = no hysteresis).
    pub close_below: f64,
}

impl Default for EpisodePolicy {
    /// `gearwear serve --alert-open-after 2 --alert-close-after 3` (and a close threshold of
    /// 0.8 of the warning severity).
    fn default() -> Self {
        EpisodePolicy {
            open_after: 2,
            close_after: 3,
            close_below: 0.8,
        }
    }
}

use super::{Basis, Level};

/// Level of an open episode.
pub const WARNING: Level = Level::Warning;
/// Level of an open episode.
pub const ALARM: Level = Level::Alarm;

/// An open (or acknowledged) episode as the state machine sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenEpisode {
    /// `warning` or `alarm`.
    pub level: Level,
    /// Highest severity of a record since the run that opened it began.
    pub peak_severity: f64,
}

/// A machine's episode state between records.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Tracker {
    /// Consecutive records with severity ≥ 1.
    pub rising: u32,
    /// Consecutive records with severity ≥ 2.
    pub alarm_run: u32,
    /// Consecutive records with severity below `close_below`.
    pub falling: u32,
    /// Highest severity of the current rising run (becomes the episode's peak when it opens).
    pub run_peak: f64,
    /// The open episode, if any.
    pub open: Option<OpenEpisode>,
}

/// Where an episode stands: `open` (opened by its records), `acknowledged` (a person saw it;
/// still open: it escalates and closes as before) or `closed`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AlertState {
    Open,
    Acknowledged,
    Closed,
}

crate::words::words!(AlertState, "an alert state", {
    Open => "open",
    Acknowledged => "acknowledged",
    Closed => "closed",
});

/// One line of an episode's audit trail: what happened to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AlertEvent {
    Opened,
    Escalated,
    Acknowledged,
    Closed,
}

crate::words::words!(AlertEvent, "an alert event", {
    Opened => "opened",
    Escalated => "escalated",
    Acknowledged => "acknowledged",
    Closed => "closed",
});

/// What a record did to the machine's episode.
#[derive(Debug, Clone, PartialEq)]
pub enum Transition {
    /// A new episode at this level.
    Opened { level: Level },
    /// The open episode went from `warning` to `alarm`.
    Escalated { level: Level },
    /// The open episode ended.
    Closed,
}

impl Transition {
    /// The audit trail's line of it.
    pub fn event(&self) -> AlertEvent {
        match self {
            Transition::Opened { .. } => AlertEvent::Opened,
            Transition::Escalated { .. } => AlertEvent::Escalated,
            Transition::Closed => AlertEvent::Closed,
        }
    }
}

/// The level of an episode that opens: `alarm` when its run was all at alarm, else `warning`.
fn level_of(alarm_run_complete: bool) -> Level {
    if alarm_run_complete { ALARM } else { WARNING }
}

/// Advance a machine's episode by one record of severity `severity` (`None`: the record's
/// level is `unknown`, and nothing changes). Returns the new state and the transition, if any.
pub fn step(
    p: &EpisodePolicy,
    t: &Tracker,
    severity: Option<f64>,
) -> (Tracker, Option<Transition>) {
    let Some(s) = severity.filter(|s| s.is_finite()) else {
        return (t.clone(), None);
    };
    let n = p.open_after.max(1);
    let mut next = t.clone();
    next.rising = if s >= 1.0 { t.rising + 1 } else { 0 };
    next.alarm_run = if s >= 2.0 { t.alarm_run + 1 } else { 0 };
    next.falling = if s < p.close_below { t.falling + 1 } else { 0 };
    next.run_peak = if s >= 1.0 { t.run_peak.max(s) } else { 0.0 };
    match &t.open {
        None => {
            if next.rising >= n {
                let level = level_of(next.alarm_run >= n);
                next.open = Some(OpenEpisode {
                    level,
                    peak_severity: next.run_peak,
                });
                next.falling = 0;
                return (next, Some(Transition::Opened { level }));
            }
            (next, None)
        }
        Some(open) => {
            if next.falling >= p.close_after.max(1) {
                return (Tracker::default(), Some(Transition::Closed));
            }
            let mut o = open.clone();
            o.peak_severity = o.peak_severity.max(s);
            let escalate = o.level == WARNING && next.alarm_run >= n;
            if escalate {
                o.level = ALARM;
            }
            next.open = Some(o);
            (
                next,
                escalate.then_some(Transition::Escalated { level: ALARM }),
            )
        }
    }
}

/// The band of severities a level allows: `ok` `[0, 1)`, `warning` `[1, 2)`, `alarm`
/// `[2, ∞)`; `None` for `unknown`.
fn band(level: Level) -> Option<(f64, f64)> {
    match level {
        Level::Ok => Some((0.0, 1.0 - 1e-9)),
        Level::Warning => Some((1.0, 2.0 - 1e-9)),
        Level::Alarm => Some((2.0, f64::INFINITY)),
        Level::Unknown => None,
    }
}

/// Severity of a wear degree `ea` (units of the backlash) under thresholds `th`: 1 at the
/// warning degree, 2 at the alarm degree, linear in between and below.
pub fn wear_severity(ea: f64, th: &Thresholds) -> f64 {
    let ea = ea.max(0.0);
    if ea < th.warning {
        if th.warning > 0.0 {
            ea / th.warning
        } else {
            0.0
        }
    } else {
        let span = th.alarm - th.warning;
        if span > 0.0 {
            1.0 + (ea - th.warning) / span
        } else {
            2.0
        }
    }
}

/// Severity of a novelty: its score over its threshold.
pub fn novelty_severity(n: &Novelty) -> f64 {
    n.score.max(0.0) / n.threshold.max(f64::MIN_POSITIVE)
}

/// A channel's severity, kept within the band of the level it answered.
pub fn channel_severity(c: &ChannelAssessment, th: &Thresholds) -> Option<f64> {
    let (lo, hi) = band(c.alert.level)?;
    let wear = c
        .reading
        .as_ref()
        .map(|r| r.alert_wear())
        .filter(|w| !w.1)
        .map(|w| wear_severity(w.0, th));
    let novelty = c.novelty.as_ref().map(novelty_severity);
    let raw = match c.alert.basis {
        Basis::Wear => wear.unwrap_or(lo),
        Basis::Novelty => novelty.unwrap_or(lo),
        Basis::Baseline => wear.unwrap_or(0.0),
        Basis::WearAndNovelty | Basis::Quality | Basis::None => {
            wear.into_iter().chain(novelty).fold(lo, f64::max)
        }
    };
    Some(raw.clamp(lo, hi))
}

impl Assessment {
    /// The record's severity (module doc): the largest of its channels', `None` when the
    /// record's level is `unknown`.
    pub fn severity(&self, th: &Thresholds) -> Option<f64> {
        band(self.level())?;
        self.assessed
            .iter()
            .filter_map(|c| channel_severity(c, th))
            .reduce(f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: EpisodePolicy = EpisodePolicy {
        open_after: 3,
        close_after: 4,
        close_below: 0.8,
    };

    /// Run a severity series; the transitions with the index of the record that made them.
    fn run(p: &EpisodePolicy, series: &[Option<f64>]) -> Vec<(usize, Transition)> {
        let mut t = Tracker::default();
        let mut out = Vec::new();
        for (i, s) in series.iter().enumerate() {
            let (n, tr) = step(p, &t, *s);
            t = n;
            if let Some(tr) = tr {
                out.push((i, tr));
            }
        }
        out
    }

    #[test]
    fn opens_after_n_records_not_after_n_minus_one() {
        let s = |v: &[f64]| v.iter().map(|x| Some(*x)).collect::<Vec<_>>();
        assert!(run(&P, &s(&[1.2, 1.3, 0.5, 1.2, 1.1])).is_empty());
        assert_eq!(
            run(&P, &s(&[1.2, 1.3, 1.5])),
            vec![(2, Transition::Opened { level: WARNING })]
        );
        assert_eq!(
            run(&P, &s(&[2.2, 2.3, 2.5])),
            vec![(2, Transition::Opened { level: ALARM })]
        );
        // An unknown record neither counts nor breaks the run.
        assert_eq!(
            run(&P, &[Some(1.2), None, Some(1.3), Some(1.1)]),
            vec![(3, Transition::Opened { level: WARNING })]
        );
    }

    #[test]
    fn escalates_then_closes_after_m_low_records() {
        let mut series = vec![1.2, 1.2, 1.2, 2.1, 2.1, 2.4];
        series.extend([0.5, 0.5, 0.9, 0.5, 0.5, 0.5, 0.5]);
        let got = run(&P, &series.iter().map(|x| Some(*x)).collect::<Vec<_>>());
        assert_eq!(
            got,
            vec![
                (2, Transition::Opened { level: WARNING }),
                (5, Transition::Escalated { level: ALARM }),
                // 0.9 is below warning but above the close threshold: it restarts the count.
                (12, Transition::Closed),
            ]
        );
    }

    #[test]
    fn the_peak_is_the_highest_severity_of_the_episode() {
        let mut t = Tracker::default();
        for s in [1.4, 1.1, 1.2, 1.9, 1.0] {
            t = step(&P, &t, Some(s)).0;
        }
        assert_eq!(t.open.unwrap().peak_severity, 1.9);
    }

    /// The target: a machine alternating around a threshold for 200 records opens at
    /// most one alert, whatever the amplitude of the alternation and the delays.
    #[test]
    fn alternating_around_a_threshold_opens_at_most_one_alert() {
        for p in [
            P,
            EpisodePolicy::default(),
            EpisodePolicy {
                open_after: 1,
                close_after: 2,
                close_below: 0.8,
            },
        ] {
            for (lo, hi) in [
                (0.95, 1.05),
                (0.5, 1.5),
                (0.79, 1.01),
                (1.9, 2.1),
                (0.1, 2.5),
            ] {
                let series: Vec<Option<f64>> = (0..200)
                    .map(|i| Some(if i % 2 == 0 { hi } else { lo }))
                    .collect();
                let opened = run(&p, &series)
                    .iter()
                    .filter(|(_, t)| matches!(t, Transition::Opened { .. }))
                    .count();
                assert!(opened <= 1, "{p:?} {lo}/{hi}: {opened} alerts");
            }
        }
    }

    #[test]
    fn wear_severity_marks_the_thresholds() {
        let th = Thresholds {
            warning: 0.5,
            alarm: 0.8,
        };
        assert_eq!(wear_severity(0.25, &th), 0.5);
        assert_eq!(wear_severity(0.5, &th), 1.0);
        assert!((wear_severity(0.8, &th) - 2.0).abs() < 1e-12);
        assert!((wear_severity(0.65, &th) - 1.5).abs() < 1e-12);
        let zero = Thresholds {
            warning: 0.0,
            alarm: 0.0,
        };
        assert_eq!(wear_severity(0.3, &zero), 2.0);
    }
}
