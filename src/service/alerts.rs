//! Alerts as events: `GET /v1/alerts`, `GET /v1/alerts/{alert_id}` (with its audit trail) and
//! `POST /v1/alerts/{alert_id}/acknowledge` (the `acknowledge` scope, which `read` does not
//! give). Episodes open, escalate and close inside each record's ingest transaction (the
//! core's [`crate::assessment::episodes`], the store's `alerts` module); acknowledging is the
//! one transition a person makes.

use std::collections::HashMap;

use axum::Json;
use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::HeaderMap;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::{check_machine_id, read_body};
use crate::assessment::episodes::{AlertEvent, AlertState};
use crate::keys::Scope;
use crate::store::{Acknowledged, AlertFilter, AlertRow, now_ms};
use crate::time::rfc3339;
use crate::views::{alert_event_json, alert_json};

/// Longest acknowledgement note, in characters.
pub const MAX_NOTE_CHARS: usize = 4000;

#[derive(Debug, Default, Deserialize)]
struct ListQuery {
    state: Option<String>,
    machine_id: Option<String>,
    limit: Option<String>,
}

fn bad(p: &'static str, d: String) -> ApiError {
    ApiError::bad_request("invalid-query", "Invalid query parameter", d).with("parameter", p)
}

/// `GET /v1/alerts?state=open|closed|all&machine_id=…&limit=…`: newest opened first.
pub async fn list(
    State(app): State<AppState>,
    caller: Caller,
    RawQuery(query): RawQuery,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let q: ListQuery = serde_urlencoded::from_str(query.as_deref().unwrap_or(""))
        .map_err(|e| bad("query", e.to_string()))?;
    let filter = match q.state.as_deref() {
        None | Some("open") => AlertFilter::Open,
        Some("closed") => AlertFilter::Closed,
        Some("all") => AlertFilter::All,
        Some(s) => {
            return Err(bad(
                "state",
                format!(
                    "`state` must be `open` (open or acknowledged), `closed` or `all`, got `{s}`"
                ),
            ));
        }
    };
    if let Some(m) = &q.machine_id {
        check_machine_id(m).map_err(|e| e.with("parameter", "machine_id"))?;
    }
    let limit = match &q.limit {
        None => 100,
        Some(s) => match s.parse::<i64>() {
            Ok(n) if (1..=1000).contains(&n) => n,
            _ => {
                return Err(bad(
                    "limit",
                    format!("`limit` must be an integer from 1 to 1000, got `{s}`"),
                ));
            }
        },
    };
    let rows = app
        .store
        .list_alerts(filter, q.machine_id.as_deref(), limit)
        .await?;
    let mut labels = Labels::default();
    let mut alerts = Vec::with_capacity(rows.len());
    for a in &rows {
        alerts.push(alert_view(&app, a, &mut labels).await?);
    }
    Ok(Json(json!({"alerts": alerts})).into_response())
}

fn unknown_alert(id: &str) -> ApiError {
    ApiError::not_found(
        "unknown-alert",
        format!("no alert `{id}`; GET /v1/alerts?state=all lists them"),
    )
    .with("alert_id", id)
}

/// `GET /v1/alerts/{alert_id}`: the alert and its audit trail, oldest first.
pub async fn get(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let Some((a, events)) = app.store.get_alert(&id).await? else {
        return Err(unknown_alert(&id));
    };
    let mut labels = Labels::default();
    let mut body = alert_view(&app, &a, &mut labels).await?;
    let mut audit = Vec::with_capacity(events.len());
    for e in &events {
        let mut line = alert_event_json(e);
        line["by_label"] = labels.of(&app, e.by.as_deref()).await?.into();
        audit.push(line);
    }
    body["audit"] = audit.into();
    Ok(Json(body).into_response())
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Ack {
    note: String,
}

/// `POST /v1/alerts/{alert_id}/acknowledge` with `{"note": "what was done"}`: 200 with the
/// alert; 409 when it is already acknowledged or closed.
pub async fn acknowledge(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Body,
) -> ApiResult<Response> {
    if let Err(e) = caller.require(&app, Scope::Acknowledge) {
        let _ = read_body(&headers, body, 64 * 1024).await;
        return Err(e);
    }
    let bytes = read_body(&headers, body, 64 * 1024).await?;
    let ack: Ack = serde_json::from_slice(&bytes).map_err(|e| {
        ApiError::bad_request(
            "invalid-json",
            "Malformed acknowledgement",
            format!(
                "{e}; expected {{\"note\": \"what was done, e.g. oil changed, bearing ordered\"}}"
            ),
        )
    })?;
    let note = ack.note.trim();
    if note.is_empty() || note.chars().count() > MAX_NOTE_CHARS {
        return Err(ApiError::unprocessable(
            "invalid-note",
            "Invalid note",
            format!(
                "`note` must say what was done (1 to {MAX_NOTE_CHARS} characters), got {} characters",
                note.chars().count()
            ),
        ));
    }
    let by = caller.key_id.clone().unwrap_or_default();
    match app
        .store
        .acknowledge_alert(&id, &by, note, now_ms())
        .await?
    {
        Acknowledged::Done(a) => {
            app.webhook_wake.notify_one();
            let view = alert_view(&app, &a, &mut Labels::default()).await?;
            Ok(Json(view).into_response())
        }
        Acknowledged::Unknown => Err(unknown_alert(&id)),
        Acknowledged::Refused(a) => Err(ApiError::new(
            axum::http::StatusCode::CONFLICT,
            "alert-not-open",
            "Alert not open",
            match a.state {
                AlertState::Closed => format!(
                    "alert `{id}` is closed (its machine's level stayed low); nothing to acknowledge"
                ),
                _ => format!(
                    "alert `{id}` was already acknowledged by key `{}`: “{}”",
                    a.acknowledged_by.as_deref().unwrap_or("?"),
                    a.note.as_deref().unwrap_or("")
                ),
            },
        )
        .with("alert_id", id.as_str())
        .with("state", a.state.as_str())),
    }
}

/// The labels of API keys by id, read once per answer: people read "planner's tablet", not a
/// key id. A key deleted since has none (its id stays in `acknowledged_by` / `by`).
#[derive(Default)]
pub struct Labels(HashMap<String, Option<String>>);

impl Labels {
    pub async fn of(&mut self, app: &AppState, id: Option<&str>) -> ApiResult<Option<String>> {
        let Some(id) = id.filter(|i| !i.is_empty()) else {
            return Ok(None);
        };
        if let Some(l) = self.0.get(id) {
            return Ok(l.clone());
        }
        let label = app.store.get_key(id).await?.map(|k| k.label);
        self.0.insert(id.to_string(), label.clone());
        Ok(label)
    }
}

/// The machine's open (or acknowledged) episode, if any.
pub async fn open_alert(app: &AppState, machine_id: &str) -> ApiResult<Option<AlertRow>> {
    let open = app
        .store
        .list_alerts(AlertFilter::Open, Some(machine_id), 1)
        .await?;
    Ok(open.into_iter().next())
}

/// A machine view's `state`: the worse of its latest record's level and its open alert's,
/// and which of the two it is (`alert` when the alert's is worse: an alarm stays open over
/// quiet records until enough of them close it).
pub fn state_json(record_level: crate::assessment::Level, open: Option<&AlertRow>) -> Value {
    let alert_level = open.map(|a| a.level);
    let from_alert = alert_level.is_some_and(|a| a > record_level);
    json!({
        "level": if from_alert { alert_level.unwrap_or(record_level) } else { record_level },
        "source": if from_alert { "alert" } else { "record" },
        "record_level": record_level,
        "alert_level": alert_level,
        "alert_since": open.map(|a| rfc3339(a.opened_at)),
        "acknowledged": open.map(|a| a.state == AlertState::Acknowledged),
    })
}

/// An episode as the API shows it: the store's JSON with the acknowledging key's label.
pub async fn alert_view(app: &AppState, a: &AlertRow, labels: &mut Labels) -> ApiResult<Value> {
    let mut v = alert_json(a);
    v["acknowledged_by_label"] = labels.of(app, a.acknowledged_by.as_deref()).await?.into();
    Ok(v)
}

/// A machine view's `open_alert`: its open (or acknowledged) episode, with `evidence` — the
/// record that opened it or last escalated it (its time, level, reason and findings), which
/// is what the alert is about even when later records are quiet. Null without one.
pub async fn open_alert_json(app: &AppState, open: Option<&AlertRow>) -> ApiResult<Value> {
    let Some(a) = open else {
        return Ok(Value::Null);
    };
    let mut v = alert_view(app, a, &mut Labels::default()).await?;
    let events = app
        .store
        .get_alert(&a.id)
        .await?
        .map(|(_, e)| e)
        .unwrap_or_default();
    let decided = events.iter().rev().find(|e| {
        matches!(e.event, AlertEvent::Opened | AlertEvent::Escalated) && e.record_id.is_some()
    });
    let (event, record_id) = match decided {
        Some(e) => (e.event, e.record_id.clone().unwrap_or_default()),
        None => (AlertEvent::Opened, a.record_id.clone()),
    };
    v["evidence"] = match app.store.diagnosis_of_record(&record_id).await? {
        None => Value::Null,
        Some(d) => {
            let body: Value = serde_json::from_str(&d.body).unwrap_or(Value::Null);
            json!({
                "event": event,
                "record_id": record_id,
                "diagnosis_id": d.id,
                "measured_at": rfc3339(d.measured_at),
                "alert_level": d.alert_level,
                "reason": body["alert"]["reason"],
                "findings": body.get("findings").cloned().unwrap_or(json!([])),
            })
        }
    };
    Ok(v)
}
