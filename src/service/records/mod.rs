//! `POST /v1/machines/{machine_id}/records`: decode, assess (off the async runtime, with the
//! core's [`crate::assessment::assess`]), store in one transaction, answer 201 with the
//! assessment. `Idempotency-Key` makes retries safe.
//!
//! The handler is here; [`accept`] holds the steps every record source shares (the machine,
//! the decoded record, the assessment, the store), `rows` the rows and answer it writes,
//! [`idempotency`] the key and the replay, [`reread`] a stored record read again once its
//! gearbox's table covers it.
//!
//! The record's operating state: its load from `?load=` or the JSON body's `load`; its speed
//! counted from its tachometer channel — the machine's `tacho_channel`, else a channel named
//! `tacho` — which is not diagnosed itself ([`accept::tacho_of`]).

mod accept;
mod idempotency;
pub mod reread;
mod rows;

use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

pub use accept::{Accepted, Prepared, accept, calibration_of, prepare};
pub use idempotency::Idempotency;

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::{body_format, check_machine_id, content_decoded, read_body, sniffed};
use super::metrics::StageClock;
use super::wire::parse_query;
use crate::keys::Scope;
use idempotency::replay;

/// The handler.
pub async fn post_record(
    State(app): State<AppState>,
    caller: Caller,
    Path(machine_id): Path<String>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
    body: Body,
) -> Response {
    match ingest(&app, &caller, &machine_id, query, &headers, body).await {
        Ok(r) => r,
        Err(e) => {
            app.metrics.rejected(e.slug);
            e.into_response()
        }
    }
}

/// Authorise, read, replay an earlier identical request, decode, assess, store, answer.
async fn ingest(
    app: &AppState,
    caller: &Caller,
    machine_id: &str,
    query: Option<String>,
    headers: &HeaderMap,
    body: Body,
) -> ApiResult<Response> {
    let limits = &app.settings.limits;
    if let Err(e) = caller.require(app, Scope::Ingest) {
        // Read (and drop) the upload so the client sees the 401/403/429, not a reset.
        let _ = read_body(headers, body, limits.max_body_bytes).await;
        return Err(e);
    }
    check_machine_id(machine_id)?;
    let format = body_format(headers)?;
    let q = parse_query(query.as_deref())?;
    let bytes = read_body(headers, body, limits.max_body_bytes).await?;
    // CPU time by stage (`/metrics`), booked only for synchronous sections: a task may move to
    // another thread at an await.
    let mut clock = StageClock::new();
    let bytes = content_decoded(headers, bytes, limits.max_body_bytes)?;
    let (format, bytes, sniff_notes) = sniffed(format, bytes, limits.max_body_bytes)?;
    clock.lap("decode");
    let idem = Idempotency::of(
        headers,
        caller,
        machine_id,
        format,
        query.as_deref(),
        &bytes,
    )?;
    clock.lap("hash");
    if let Some(r) = idem.replay_stored(app).await? {
        return Ok(r);
    }
    let mut prepared = prepare(app, machine_id, format, q, &bytes, &mut clock).await?;
    prepared.warnings = sniff_notes;
    if prepared.dec.record_id.is_some() {
        return Err(ApiError::bad_request(
            "invalid-json",
            "Malformed JSON record",
            "`record_id` is the id an MQTT payload is de-duplicated by; over HTTP, send an \
             `Idempotency-Key` header instead",
        ));
    }
    match accept(app, machine_id, format, prepared, &idem, clock).await? {
        Accepted::Created {
            response_text,
            diagnosis_id,
        } => Ok(created(response_text, &diagnosis_id)),
        Accepted::Replayed(prev) => replay(app, &prev, &idem.request_hash),
    }
}

/// The 201 answer, with the new diagnosis's location.
fn created(response_text: String, diagnosis_id: &str) -> Response {
    let mut r = (StatusCode::CREATED, response_text).into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/diagnoses/{diagnosis_id}")) {
        h.insert(header::LOCATION, v);
    }
    r
}
