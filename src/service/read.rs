//! Read endpoints: machines, their diagnoses (cursor pagination, ETag/304), one diagnosis.

use axum::extract::{Path, RawQuery, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use serde_json::{Value, json};

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult, unknown_machine};
use super::gearboxes::BUILTIN_ID;
use super::http::{check_machine_id, json_with_etag};
use crate::store::{DiagnosisRow, MachineRow};
use crate::time::{parse_rfc3339, rfc3339};
use crate::views::{novelty_json, wear_json};

/// How many diagnoses the machine view's wear trend shows (the latest by measurement time,
/// the same as its `trend_summary` fits).
const TREND_POINTS: i64 = super::trend::SERIES_POINTS;

fn machine_summary(m: &MachineRow) -> Value {
    json!({
        "id": m.id,
        "alert_level": m.alert_level,
        "record_count": m.record_count,
        "created_at": rfc3339(m.created_at),
        "updated_at": rfc3339(m.updated_at),
        "last_diagnosis_id": m.last_diagnosis_id,
        "gearbox": m.gearbox_id.clone().unwrap_or_else(|| BUILTIN_ID.to_string()),
        "registered_at": m.registered_at.map(rfc3339),
    })
}

pub fn diagnosis_summary(d: &DiagnosisRow) -> Value {
    json!({
        "id": d.id,
        "machine_id": d.machine_id,
        "record_id": d.record_id,
        "created_at": rfc3339(d.created_at),
        "measured_at": rfc3339(d.measured_at),
        "wear_degree": wear_json(d),
        "alert_level": d.alert_level,
        "motion_state": d.motion_state,
        "novelty": novelty_json(d),
        "channel": d.channel,
        "wear_withheld": d.wear_withheld,
        "reread": d.reread_status,
        "replaces": d.replaces,
    })
}

pub async fn list_machines(
    State(app): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let ms = app.store.list_machines().await?;
    let body = json!({"machines": ms.iter().map(machine_summary).collect::<Vec<_>>()});
    Ok(json_with_etag(&headers, &body))
}

pub async fn get_machine(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    check_machine_id(&id)?;
    let m = app
        .store
        .get_machine(&id)
        .await?
        .ok_or_else(|| unknown_machine(&id))?;
    let trend = app.store.recent_diagnoses(&id, TREND_POINTS).await?;
    let latest = match &m.last_diagnosis_id {
        Some(d) => app.store.get_diagnosis(d).await?,
        None => None,
    };
    let latest = latest.map(|d| {
        let full: Value = serde_json::from_str(&d.body).unwrap_or(Value::Null);
        let mut s = diagnosis_summary(&d);
        s["f1_hz"] = full["f1_hz"].clone();
        s["shaft_hz"] = full["shaft_hz"].clone();
        s["planetary_clearance_elevated"] = full["planetary_clearance_elevated"].clone();
        s["warnings"] = full.get("warnings").cloned().unwrap_or(json!([]));
        s["alert"] = full.get("alert").cloned().unwrap_or(Value::Null);
        s["channels"] = full.get("channels").cloned().unwrap_or(Value::Null);
        if let Some(cs) = s["channels"].as_array_mut() {
            cs.iter_mut().for_each(feature_words);
        }
        s["indicators"] = full.get("indicators").cloned().unwrap_or(Value::Null);
        // The record's measured speed and load, why the wear figure is missing (when it is)
        // and what the departure from the baseline points at, for people.
        s["operating_state"] = full.get("operating_state").cloned().unwrap_or(Value::Null);
        s["state_note"] = full.get("state_note").cloned().unwrap_or(Value::Null);
        s["wear_note"] = full.get("wear_note").cloned().unwrap_or(Value::Null);
        s["findings"] = full.get("findings").cloned().unwrap_or(json!([]));
        // The figures in physical units: the wear in µm and, for a channel whose unit the
        // machine declares, its vibration (absent, not null, when there are none).
        for k in ["wear_degree_um", "vibration"] {
            if let Some(v) = full.get(k) {
                s[k] = v.clone();
            }
        }
        s
    });
    let mut body = machine_summary(&m);
    body["configuration"] = super::machines::config_json(&m);
    let gid = m.gearbox_id.as_deref().unwrap_or(BUILTIN_ID);
    body["gearbox"] = match app.store.get_gearbox(gid).await? {
        Some(g) => crate::views::gearbox_json(&g, None, false),
        None => json!({"id": gid, "status": "unknown"}),
    };
    body["baseline"] = super::machines::baseline_json(&app, &m).await?;
    body["thresholds"] = serde_json::to_value(app.settings.thresholds).unwrap_or(Value::Null);
    body["latest"] = latest.unwrap_or(Value::Null);
    let open = super::alerts::open_alert(&app, &id).await?;
    body["state"] = super::alerts::state_json(m.alert_level, open.as_ref());
    body["open_alert"] = super::alerts::open_alert_json(&app, open.as_ref()).await?;
    body["trend_summary"] = super::trend::summary(&app, &trend, open.as_ref());
    body["trend"] = trend
        .iter()
        .map(|d| {
            json!({
                "diagnosis_id": d.id,
                "created_at": rfc3339(d.created_at),
                "measured_at": rfc3339(d.measured_at),
                "estimate": d.has_wear.then_some(d.ea_estimate),
                "lower": d.has_wear.then_some(d.ea_lower),
                "upper": d.has_wear.then_some(d.ea_upper),
                "alert_level": d.alert_level,
                "novelty": d.novelty_score,
                "novelty_threshold": d.novelty_threshold,
            })
        })
        .collect::<Vec<_>>()
        .into();
    Ok(json_with_etag(&headers, &body))
}

/// Each of a channel's `novelty.top_features` with `says`: the feature's departure in words
/// ("first sidebands at shaft `idler`'s rate around mesh harmonic 2 …: up by 4.9× the healthy
/// spread"), for the people reading the machine page.
fn feature_words(channel: &mut Value) {
    let Some(top) = channel["novelty"]["top_features"].as_array_mut() else {
        return;
    };
    for f in top {
        if let (Some(name), Some(z)) = (f["name"].as_str(), f["z"].as_f64()) {
            f["says"] = crate::condition::findings::departure_words(name, z).into();
        }
    }
}

#[derive(Debug, Default, Deserialize)]
struct ListQuery {
    since: Option<String>,
    cursor: Option<String>,
    limit: Option<String>,
}

/// A cursor is the `seq` of the last diagnosis on the previous page, in decimal: any digit
/// string is a valid cursor ("after that point"), and the empty string is the first page.
fn encode_cursor(seq: i64) -> String {
    seq.to_string()
}

fn decode_cursor(c: &str) -> Option<i64> {
    if c.is_empty() {
        return Some(0);
    }
    if c.len() > 18 || !c.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    c.parse().ok()
}

pub async fn list_diagnoses(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    check_machine_id(&id)?;
    let bad = |p: &'static str, d: String| {
        ApiError::bad_request("invalid-query", "Invalid query parameter", d).with("parameter", p)
    };
    let q: ListQuery = serde_urlencoded::from_str(query.as_deref().unwrap_or(""))
        .map_err(|e| bad("query", e.to_string()))?;
    let limit = match &q.limit {
        None => 50,
        Some(s) => match s.parse::<i64>() {
            Ok(n) if (1..=500).contains(&n) => n,
            _ => {
                return Err(bad(
                    "limit",
                    format!("`limit` must be an integer from 1 to 500, got `{s}`"),
                ));
            }
        },
    };
    let since = match &q.since {
        None => i64::MIN,
        Some(s) => parse_rfc3339(s).ok_or_else(|| {
            bad(
                "since",
                format!(
                    "`since` must be an RFC 3339 timestamp such as 2026-11-22T08:30:00Z, got `{s}`"
                ),
            )
        })?,
    };
    let after = match &q.cursor {
        None => 0,
        Some(c) => decode_cursor(c).ok_or_else(|| {
            bad(
                "cursor",
                "`cursor` must be the `next_cursor` of an earlier page (digits only)".into(),
            )
        })?,
    };
    if app.store.get_machine(&id).await?.is_none() {
        return Err(unknown_machine(&id));
    }
    let rows = app.store.list_diagnoses(&id, after, since, limit).await?;
    let next = if rows.len() as i64 == limit {
        rows.last().map(|d| encode_cursor(d.seq))
    } else {
        None
    };
    let body = json!({
        "items": rows.iter().map(diagnosis_summary).collect::<Vec<_>>(),
        "next_cursor": next,
    });
    Ok(json_with_etag(&headers, &body))
}

pub async fn get_diagnosis(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let d = app.store.get_diagnosis(&id).await?.ok_or_else(|| {
        ApiError::not_found(
            "unknown-diagnosis",
            format!(
                "no diagnosis `{id}`; diagnosis ids are the `id` of a POST …/records answer or \
                 of an item of GET /v1/machines/{{machine_id}}/diagnoses"
            ),
        )
        .with("diagnosis_id", id.as_str())
    })?;
    diagnosis_view(&app, &headers, &d).await
}

/// One record's diagnosis, by the record's id (a deep link from an alert or a trend point,
/// which name records): the same answer as `GET /v1/diagnoses/{id}`.
pub async fn get_record(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let d = app.store.diagnosis_of_record(&id).await?.ok_or_else(|| {
        ApiError::not_found(
            "unknown-record",
            format!(
                "no record `{id}`; record ids are the `record_id` of a POST …/records answer, \
                 of a diagnosis, a trend point or an alert (a deleted machine's records are gone)"
            ),
        )
        .with("record_id", id.as_str())
    })?;
    diagnosis_view(&app, &headers, &d).await
}

/// A stored diagnosis with its full body, spectrum and evidence (with its healthy
/// reference), ETagged.
async fn diagnosis_view(
    app: &AppState,
    headers: &HeaderMap,
    d: &DiagnosisRow,
) -> ApiResult<Response> {
    let mut body = diagnosis_summary(d);
    body["diagnosis"] = serde_json::from_str(&d.body).unwrap_or(Value::Null);
    body["spectrum"] = serde_json::from_str(&d.spectrum).unwrap_or(Value::Null);
    body["evidence"] = super::evidence::evidence_of(app, d).await?;
    Ok(json_with_etag(headers, &body))
}
