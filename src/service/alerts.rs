//! Alerts as events: `GET /v1/alerts`, `GET /v1/alerts/{alert_id}` (with its audit trail) and
//! `POST /v1/alerts/{alert_id}/acknowledge` (the `acknowledge` scope, which `read` does not
//! give). Episodes open, escalate and close inside each record's ingest transaction (the
//! core's [`crate::assessment::episodes`], the store's `alerts` module); acknowledging is the
//! one transition a person makes.

use axum::Json;
use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::HeaderMap;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::json;

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::{check_machine_id, read_body};
use crate::keys::Scope;
use crate::store::{Acknowledged, AlertFilter, now_ms};
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
    Ok(Json(json!({"alerts": rows.iter().map(alert_json).collect::<Vec<_>>()})).into_response())
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
    let mut body = alert_json(&a);
    body["audit"] = events
        .iter()
        .map(alert_event_json)
        .collect::<Vec<_>>()
        .into();
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
            Ok(Json(alert_json(&a)).into_response())
        }
        Acknowledged::Unknown => Err(unknown_alert(&id)),
        Acknowledged::Refused(a) => Err(ApiError::new(
            axum::http::StatusCode::CONFLICT,
            "alert-not-open",
            "Alert not open",
            match a.state.as_str() {
                "closed" => format!(
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
