//! Alerts as events: each machine's alert episodes (opened → acknowledged → closed), their audit
//! trail, and the state machine's counts between records (migration 0008).
//!
//! The state machine is the core's ([`gearwear_core::assessment::episodes`]); it runs inside
//! each record's ingest transaction ([`step_in`], called by the ingest with the machine's row
//! locked), so two replicas or a crash and a retry cannot open an episode twice — and a unique
//! index allows at most one episode per machine that is not closed.

use super::StoreResult;
pub use super::alert_rows::AlertRow;
use crate::events::{DiagnosisEvent, Event, QueuedEvent};
use async_trait::async_trait;
use gearwear_core::assessment::Level;
use gearwear_core::assessment::episodes::{AlertEvent, EpisodePolicy};

/// What the ingest needs to advance a machine's episode with one record.
#[derive(Debug, Clone)]
pub struct AlertInput {
    /// The record's severity (`None`: its level is `unknown`).
    pub severity: Option<f64>,
    /// The record's measurement time, unix ms (`recorded_at` if given, else received).
    pub measured_at: i64,
    pub policy: EpisodePolicy,
}

/// One line of an episode's audit trail.
#[derive(Debug, Clone, PartialEq)]
pub struct AlertEventRow {
    pub alert_id: String,
    pub at: i64,
    pub event: AlertEvent,
    pub by: Option<String>,
    pub note: Option<String>,
    pub record_id: Option<String>,
    pub level: Option<Level>,
    pub severity: Option<f64>,
}

/// Which episodes a listing wants.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlertFilter {
    /// Not closed (`open` and `acknowledged`).
    Open,
    Closed,
    All,
}

/// The outcome of an acknowledgement.
#[derive(Debug, Clone, PartialEq)]
pub enum Acknowledged {
    /// Done: the episode as it is now.
    Done(AlertRow),
    /// No such episode.
    Unknown,
    /// Already acknowledged or closed: the episode as it is.
    Refused(AlertRow),
}

/// A level as stored (a column written from [`Level::as_str`]).
pub fn stored_level(text: String) -> StoreResult<Level> {
    stored_word(text)
}

/// A column written from one of the core's words (`as_str`), read back as its type.
pub fn stored_word<T>(text: String) -> StoreResult<T>
where
    T: std::str::FromStr<Err = gearwear_core::words::UnknownWord>,
{
    text.parse()
        .map_err(|e: gearwear_core::words::UnknownWord| crate::StoreError::Decode(e.to_string()))
}

/// The webhook events of an episode's transition `event`: `alert.opened`, `alert.acknowledged` or `alert.closed` (an
/// escalation has none of its own), and `wear.threshold_crossed` on opening and escalating,
/// with the record's diagnosis `by` and the level before (`ok` when it opened, `warning` when
/// it escalated).
pub fn transition_events(
    a: &AlertRow,
    event: AlertEvent,
    by: Option<&DiagnosisEvent>,
    event_id: &str,
) -> Vec<QueuedEvent> {
    let mut out = Vec::new();
    let record = by.map(DiagnosisEvent::record);
    let alert = a.clone();
    let own = match (event, record) {
        (AlertEvent::Opened, Some(by)) => Some(Event::AlertOpened { alert, by }),
        (AlertEvent::Closed, Some(by)) => Some(Event::AlertClosed { alert, by }),
        (AlertEvent::Acknowledged, _) => Some(Event::AlertAcknowledged { alert }),
        _ => None,
    };
    if let Some(e) = own {
        out.push(QueuedEvent::new(event_id.to_string(), e));
    }
    if let (Some(previous_alert_level), Some(d)) = (
        match event {
            AlertEvent::Opened => Some(Level::Ok),
            AlertEvent::Escalated => Some(Level::Warning),
            _ => None,
        },
        by,
    ) {
        out.push(QueuedEvent::new(
            format!("{event_id}-crossed"),
            Event::WearThresholdCrossed {
                diagnosis: d.clone(),
                previous_alert_level,
                alert_id: a.id.clone(),
            },
        ));
    }
    out
}

/// Alerts and their audit trail.
#[async_trait]
pub trait AlertStore: Send + Sync {
    /// Episodes, newest opened first, at most `limit`.
    async fn list_alerts(
        &self,
        filter: AlertFilter,
        machine_id: Option<&str>,
        limit: i64,
    ) -> StoreResult<Vec<AlertRow>>;
    /// One episode with its audit trail (oldest first).
    async fn get_alert(&self, id: &str) -> StoreResult<Option<(AlertRow, Vec<AlertEventRow>)>>;
    /// Acknowledge an open episode: by the key `by`, at `now`, with `note`; the audit line and
    /// the `alert.acknowledged` webhook deliveries in the same transaction.
    async fn acknowledge_alert(
        &self,
        id: &str,
        by: &str,
        note: &str,
        now: i64,
    ) -> StoreResult<Acknowledged>;
}

/// The SQL of [`AlertStore`] and of the ingest's step for one backend (see `ingest_sql!`).
macro_rules! alerts_sql {
    ($store:ident, $db:ty) => {
        use gearwear_core::assessment::Level;
        use gearwear_core::assessment::episodes::{
            AlertEvent, AlertState, OpenEpisode, Tracker, Transition, step,
        };
        use sqlx::Row;
        use $crate::alerts::*;
        use $crate::*;

        use super::$store;

        fn alert_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<AlertRow> {
            Ok(AlertRow {
                id: r.try_get("id")?,
                machine_id: r.try_get("machine_id")?,
                level: stored_level(r.try_get("level")?)?,
                state: stored_word(r.try_get("state")?)?,
                opened_at: r.try_get("opened_at")?,
                record_id: r.try_get("record_id")?,
                acknowledged_at: r.try_get("acknowledged_at")?,
                acknowledged_by: r.try_get("acknowledged_by")?,
                note: r.try_get("note")?,
                closed_at: r.try_get("closed_at")?,
                closed_record_id: r.try_get("closed_record_id")?,
                peak_severity: r.try_get("peak_severity")?,
                created_at: r.try_get("created_at")?,
            })
        }

        async fn insert_event(
            tx: &mut sqlx::Transaction<'_, $db>,
            e: &AlertEventRow,
        ) -> StoreResult<()> {
            sqlx::query(
                "INSERT INTO alert_events (alert_id, at, event, by_key, note, record_id, level, \
                 severity) VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            )
            .bind(&e.alert_id)
            .bind(e.at)
            .bind(e.event.as_str())
            .bind(&e.by)
            .bind(&e.note)
            .bind(&e.record_id)
            .bind(e.level.map(Level::as_str))
            .bind(e.severity)
            .execute(&mut **tx)
            .await?;
            Ok(())
        }

        async fn open_alert(
            tx: &mut sqlx::Transaction<'_, $db>,
            machine_id: &str,
        ) -> StoreResult<Option<AlertRow>> {
            sqlx::query("SELECT * FROM alerts WHERE machine_id = $1 AND state <> 'closed'")
                .bind(machine_id)
                .fetch_optional(&mut **tx)
                .await?
                .map(|r| alert_row(&r))
                .transpose()
        }

        /// Advance the machine's episode by one record, inside the record's transaction (the
        /// machine's row is locked by the caller): the counts, the episode row, its audit line.
        /// Returns the webhook events of the transition (`by`: the record's diagnosis).
        pub(crate) async fn step_in(
            tx: &mut sqlx::Transaction<'_, $db>,
            machine_id: &str,
            record_id: &str,
            input: &AlertInput,
            by: &DiagnosisEvent,
            now: i64,
        ) -> StoreResult<Vec<QueuedEvent>> {
            let counts = sqlx::query(
                "SELECT rising, alarm_run, falling, run_peak FROM alert_trackers \
                 WHERE machine_id = $1",
            )
            .bind(machine_id)
            .fetch_optional(&mut **tx)
            .await?;
            let open = open_alert(tx, machine_id).await?;
            let count = |name: &str| -> StoreResult<u32> {
                Ok(match &counts {
                    Some(r) => r.try_get::<i64, _>(name)?.clamp(0, u32::MAX as i64) as u32,
                    None => 0,
                })
            };
            let before = Tracker {
                rising: count("rising")?,
                alarm_run: count("alarm_run")?,
                falling: count("falling")?,
                run_peak: match &counts {
                    Some(r) => r.try_get("run_peak")?,
                    None => 0.0,
                },
                open: open.as_ref().map(|a| OpenEpisode {
                    level: a.level,
                    peak_severity: a.peak_severity,
                }),
            };
            let (after, transition) = step(&input.policy, &before, input.severity);
            if after == before {
                return Ok(Vec::new());
            }
            sqlx::query(
                "INSERT INTO alert_trackers (machine_id, rising, alarm_run, falling, run_peak) \
                 VALUES ($1, $2, $3, $4, $5) ON CONFLICT (machine_id) DO UPDATE SET \
                 rising = excluded.rising, alarm_run = excluded.alarm_run, \
                 falling = excluded.falling, run_peak = excluded.run_peak",
            )
            .bind(machine_id)
            .bind(after.rising as i64)
            .bind(after.alarm_run as i64)
            .bind(after.falling as i64)
            .bind(after.run_peak)
            .execute(&mut **tx)
            .await?;
            let audit = |alert_id: &str, event: AlertEvent, level: Option<Level>| AlertEventRow {
                alert_id: alert_id.to_string(),
                at: input.measured_at,
                event,
                by: None,
                note: None,
                record_id: Some(record_id.to_string()),
                level,
                severity: input.severity,
            };
            let row = match (&transition, open, &after.open) {
                (Some(Transition::Opened { level }), _, Some(o)) => {
                    let a = AlertRow {
                        id: new_id(),
                        machine_id: machine_id.to_string(),
                        level: *level,
                        state: AlertState::Open,
                        opened_at: input.measured_at,
                        record_id: record_id.to_string(),
                        acknowledged_at: None,
                        acknowledged_by: None,
                        note: None,
                        closed_at: None,
                        closed_record_id: None,
                        peak_severity: o.peak_severity,
                        created_at: now,
                    };
                    sqlx::query(
                        "INSERT INTO alerts (id, machine_id, level, state, opened_at, record_id, \
                         peak_severity, created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
                    )
                    .bind(&a.id)
                    .bind(&a.machine_id)
                    .bind(a.level.as_str())
                    .bind(a.state.as_str())
                    .bind(a.opened_at)
                    .bind(&a.record_id)
                    .bind(a.peak_severity)
                    .bind(a.created_at)
                    .execute(&mut **tx)
                    .await
                    .map_err(|e| {
                        if is_unique_violation(&e) {
                            StoreError::Conflict(format!("an open alert of `{machine_id}`"))
                        } else {
                            e.into()
                        }
                    })?;
                    insert_event(tx, &audit(&a.id, AlertEvent::Opened, Some(*level))).await?;
                    Some((a, AlertEvent::Opened))
                }
                (Some(Transition::Closed), Some(mut a), _) => {
                    sqlx::query(
                        "UPDATE alerts SET state = 'closed', closed_at = $2, \
                         closed_record_id = $3 WHERE id = $1",
                    )
                    .bind(&a.id)
                    .bind(input.measured_at)
                    .bind(record_id)
                    .execute(&mut **tx)
                    .await?;
                    a.state = AlertState::Closed;
                    a.closed_at = Some(input.measured_at);
                    a.closed_record_id = Some(record_id.to_string());
                    insert_event(tx, &audit(&a.id, AlertEvent::Closed, None)).await?;
                    Some((a, AlertEvent::Closed))
                }
                (t, Some(mut a), Some(o)) => {
                    // Still open: the peak (and, escalating, the level) follow.
                    sqlx::query(
                        "UPDATE alerts SET level = $2, peak_severity = $3 WHERE id = $1",
                    )
                    .bind(&a.id)
                    .bind(o.level.as_str())
                    .bind(o.peak_severity)
                    .execute(&mut **tx)
                    .await?;
                    a.level = o.level;
                    a.peak_severity = o.peak_severity;
                    if matches!(t, Some(Transition::Escalated { .. })) {
                        insert_event(tx, &audit(&a.id, AlertEvent::Escalated, Some(o.level)))
                            .await?;
                        Some((a, AlertEvent::Escalated))
                    } else {
                        None
                    }
                }
                _ => None,
            };
            Ok(match row {
                Some((a, event)) => transition_events(&a, event, Some(by), &new_id()),
                None => Vec::new(),
            })
        }

        #[async_trait::async_trait]
        impl $crate::AlertStore for $store {
            async fn list_alerts(
                &self,
                filter: AlertFilter,
                machine_id: Option<&str>,
                limit: i64,
            ) -> StoreResult<Vec<AlertRow>> {
                let state = match filter {
                    AlertFilter::Open => "state <> 'closed'",
                    AlertFilter::Closed => "state = 'closed'",
                    AlertFilter::All => "1 = 1",
                };
                let q = sqlx::AssertSqlSafe(format!(
                    "SELECT * FROM alerts WHERE {state} AND ($1 IS NULL OR machine_id = $1) \
                     ORDER BY opened_at DESC, id DESC LIMIT $2"
                ));
                sqlx::query(q)
                    .bind(machine_id.map(str::to_string))
                    .bind(limit)
                    .fetch_all(&self.pool)
                    .await?
                    .iter()
                    .map(alert_row)
                    .collect()
            }

            async fn get_alert(
                &self,
                id: &str,
            ) -> StoreResult<Option<(AlertRow, Vec<AlertEventRow>)>> {
                let Some(r) = sqlx::query("SELECT * FROM alerts WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?
                else {
                    return Ok(None);
                };
                let a = alert_row(&r)?;
                let events = sqlx::query(
                    "SELECT * FROM alert_events WHERE alert_id = $1 ORDER BY seq",
                )
                .bind(id)
                .fetch_all(&self.pool)
                .await?
                .iter()
                .map(|r| -> StoreResult<AlertEventRow> {
                    Ok(AlertEventRow {
                        alert_id: r.try_get("alert_id")?,
                        at: r.try_get("at")?,
                        event: stored_word(r.try_get("event")?)?,
                        by: r.try_get("by_key")?,
                        note: r.try_get("note")?,
                        record_id: r.try_get("record_id")?,
                        level: r
                            .try_get::<Option<String>, _>("level")?
                            .map(stored_level)
                            .transpose()?,
                        severity: r.try_get("severity")?,
                    })
                })
                .collect::<StoreResult<Vec<_>>>()?;
                Ok(Some((a, events)))
            }

            async fn acknowledge_alert(
                &self,
                id: &str,
                by: &str,
                note: &str,
                now: i64,
            ) -> StoreResult<Acknowledged> {
                let mut tx = self.pool.begin().await?;
                let done = sqlx::query(
                    "UPDATE alerts SET state = 'acknowledged', acknowledged_at = $2, \
                     acknowledged_by = $3, note = $4 WHERE id = $1 AND state = 'open' \
                     RETURNING *",
                )
                .bind(id)
                .bind(now)
                .bind(by)
                .bind(note)
                .fetch_optional(&mut *tx)
                .await?;
                let Some(r) = done else {
                    tx.rollback().await?;
                    return Ok(match self.get_alert(id).await? {
                        Some((a, _)) => Acknowledged::Refused(a),
                        None => Acknowledged::Unknown,
                    });
                };
                let a = alert_row(&r)?;
                insert_event(
                    &mut tx,
                    &AlertEventRow {
                        alert_id: a.id.clone(),
                        at: now,
                        event: AlertEvent::Acknowledged,
                        by: Some(by.to_string()),
                        note: Some(note.to_string()),
                        record_id: None,
                        level: Some(a.level),
                        severity: None,
                    },
                )
                .await?;
                let events = transition_events(&a, AlertEvent::Acknowledged, None, &new_id());
                super::webhooks::queue_events(&mut tx, &events, now).await?;
                tx.commit().await?;
                Ok(Acknowledged::Done(a))
            }
        }
    };
}
pub(crate) use alerts_sql;
