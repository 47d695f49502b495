//! `/v1/machines/{machine_id}/calibration`: close the loop on a record of the machine
//! ([`crate::closed_loop::calibrate`], off the async runtime) and keep the accepted effects, so
//! that later diagnoses of the machine use them (see "Through the service" in
//! `docs/closed-loop.md`).
//!
//! Scopes: POST and DELETE need `admin` — a calibration changes how every later record of the
//! machine is diagnosed, which an `ingest` key (a sensor gateway) should not be able to do;
//! GET needs `read` (like the other reads, open with `--dashboard-without-key`).

use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::Value;

use super::AppState;
use super::auth::Caller;
use super::error::problem_from_error;
use super::error::{ApiError, ApiResult};
use super::http::{body_format, check_machine_id, content_decoded, json_response, read_body};
use super::wire::{Decoded, decode, parse_query};
use crate::keys::Scope;
use crate::store::{CalibrationRow, new_id, now_ms};
use crate::time::rfc3339;

/// The answer body: the report plus the ids the service gave it.
fn body(c: &CalibrationRow) -> Value {
    let mut v: Value = serde_json::from_str(&c.report).unwrap_or(Value::Null);
    if let Value::Object(m) = &mut v {
        m.insert("id".into(), c.id.clone().into());
        m.insert("machine_id".into(), c.machine_id.clone().into());
        m.insert("created_at".into(), rfc3339(c.created_at).into());
    }
    v
}

fn no_calibration(id: &str) -> ApiError {
    ApiError::not_found(
        "no-calibration",
        format!(
            "machine `{id}` has no calibration; POST a record to \
             /v1/machines/{id}/calibration to make one"
        ),
    )
    .with("machine_id", id)
}

/// `POST`: decode the body like the records endpoint, calibrate, store, answer 201.
pub async fn post(
    State(app): State<AppState>,
    caller: Caller,
    Path(machine_id): Path<String>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
    body_in: Body,
) -> Response {
    match calibrate(&app, &caller, &machine_id, query, &headers, body_in).await {
        Ok(r) => r,
        Err(e) => {
            app.metrics.rejected(e.slug);
            e.into_response()
        }
    }
}

async fn calibrate(
    app: &AppState,
    caller: &Caller,
    machine_id: &str,
    query: Option<String>,
    headers: &HeaderMap,
    body_in: Body,
) -> ApiResult<Response> {
    let limits = &app.settings.limits;
    if let Err(e) = caller.require(app, Scope::Admin) {
        let _ = read_body(headers, body_in, limits.max_body_bytes).await;
        return Err(e);
    }
    check_machine_id(machine_id)?;
    if app.settings.require_registered_machines {
        // A strict fleet calibrates only the machines it knows (as it takes only their records).
        let machine = app.store.get_machine(machine_id).await?;
        super::lifecycle::check_registered(app, machine_id, machine.as_ref())?;
    }
    let format = body_format(headers)?;
    let q = parse_query(query.as_deref())?;
    let bytes = read_body(headers, body_in, limits.max_body_bytes).await?;
    let bytes = content_decoded(headers, bytes, limits.max_body_bytes)?;
    let (format, bytes, _) = super::http::sniffed(format, bytes, limits.max_body_bytes)?;
    let dec = decode(format, &q, &bytes, limits, None)?;
    let samples = dec.single(q.channel.as_deref())?.to_vec();
    let Decoded {
        sample_rate_hz,
        shaft_hz,
        ..
    } = dec;
    let record = crate::record::Record {
        samples,
        sample_rate: sample_rate_hz,
    };
    let diag = app.diagnoser.clone();
    let report = tokio::task::spawn_blocking(move || diag.calibrate(&record, shaft_hz))
        .await
        .map_err(|e| ApiError::internal(format!("the calibration task failed: {e}")))?
        .map_err(|e| problem_from_error(&e))?;
    let row = CalibrationRow {
        machine_id: machine_id.to_string(),
        id: new_id(),
        created_at: now_ms(),
        effects: report["effects"].to_string(),
        report: report.to_string(),
    };
    app.store.put_calibration(&row).await?;
    tracing::info!(machine = machine_id, calibration = %row.id, effects = %row.effects, "machine calibrated");
    let mut r = json_response(StatusCode::CREATED, &body(&row));
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/machines/{machine_id}/calibration")) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    Ok(r)
}

/// `GET`: the machine's current calibration.
pub async fn get(
    State(app): State<AppState>,
    caller: Caller,
    Path(machine_id): Path<String>,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    check_machine_id(&machine_id)?;
    let c = app
        .store
        .get_calibration(&machine_id)
        .await?
        .ok_or_else(|| no_calibration(&machine_id))?;
    Ok(json_response(StatusCode::OK, &body(&c)))
}

/// `DELETE`: later diagnoses of the machine use the plain model again.
pub async fn delete(
    State(app): State<AppState>,
    caller: Caller,
    Path(machine_id): Path<String>,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    check_machine_id(&machine_id)?;
    if app.store.delete_calibration(&machine_id).await? {
        Ok(StatusCode::NO_CONTENT.into_response())
    } else {
        Err(no_calibration(&machine_id))
    }
}
