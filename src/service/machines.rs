//! A machine's configuration and its baseline.
//!
//! * `PUT /v1/machines/{id}` (admin): `{"gearbox": "<id>", "input_shaft_hz"?: number,
//!   "channels"?: [names], "tacho_channel"?: name, "tacho_ppr"?: integer, "channel_units"?:
//!   {name: unit}, "iso_20816"?: {"group", "support"}}` — which gearbox the machine's records
//!   are diagnosed with (default the built-in paper rig), its nominal input-shaft rate (a hint
//!   for finding the mesh line; the rate itself is measured in each record), the channels to
//!   diagnose, the channel of its tachometer with its pulses per input-shaft revolution (the
//!   record's speed is then counted from the pulses), and what its channels measure with its
//!   ISO 20816-3 class ([`super::units`]).
//! * `GET/POST/DELETE /v1/machines/{id}/baseline`: the records marked healthy. A record is
//!   marked when posted (`…/records?baseline=true`) or afterwards (POST `{"record_ids": […]}`,
//!   admin); DELETE clears the baseline, `DELETE …/baseline/{record_id}` unmarks one.
//!
//! What a record's diagnosis needs of its machine, and its baselines fitted from the stored
//! features of its baseline records, are in [`super::context`].

use std::collections::BTreeMap;
use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

use super::AppState;
use super::auth::Caller;
use super::context::{baselines, stored_features};
use super::error::{ApiError, ApiResult, unknown_machine};
use super::gearboxes::BUILTIN_ID;
use super::http::{check_gearbox_id, check_machine_id, json_with_etag, read_body};
use crate::assessment::Baselines;
use crate::keys::Scope;
use crate::novelty::MIN_BASELINE_RECORDS;
use crate::store::{MachineConfig, MachineRow, now_ms};
use crate::time::rfc3339;
use crate::views::{machine_model_json, path_json};

/// Largest configuration or baseline request body.
const SMALL_BODY: usize = 64 * 1024;

/// A JSON object as `T` (serde alone also takes an array for a struct: `[null, null]`).
fn json_object<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    let v: Value = serde_json::from_slice(bytes).map_err(|e| e.to_string())?;
    if !v.is_object() {
        return Err("the body must be a JSON object".into());
    }
    serde_json::from_value(v).map_err(|e| e.to_string())
}

/// `PUT /v1/machines/{id}` body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineBody {
    pub gearbox: Option<String>,
    #[serde(default)]
    pub input_shaft_hz: Option<f64>,
    #[serde(default)]
    pub channels: Option<Vec<String>>,
    #[serde(default)]
    pub tacho_channel: Option<String>,
    /// A number so that `10.0` is read as 10 (JSON Schema's integers); checked to be whole.
    #[serde(default)]
    pub tacho_ppr: Option<f64>,
    /// What each channel measures ([`super::units`]).
    #[serde(default)]
    pub channel_units: Option<BTreeMap<String, crate::units::UnitSpec>>,
    /// The machine's ISO 20816-3 class.
    #[serde(default)]
    pub iso_20816: Option<super::units::IsoBody>,
    /// The range of input-shaft rates `[lo, hi]` Hz the machine runs over: part of what its
    /// gearbox's table must cover ([`super::tables`]).
    #[serde(default)]
    pub speed_range_hz: Option<[f64; 2]>,
}

pub use crate::machine::{DEFAULT_TACHO_CHANNEL, MAX_TACHO_PPR, TachoProblem, check_tacho};

/// A tachometer problem in the API's words (its members `tacho_channel`, `tacho_ppr`,
/// `channels`).
pub fn tacho_detail(p: &TachoProblem) -> String {
    match p {
        TachoProblem::PulsesPerRev(got) => format!(
            "`tacho_ppr` is the tachometer's pulses per input-shaft revolution, a whole number \
             from 1 to {MAX_TACHO_PPR}, got {got}"
        ),
        TachoProblem::ChannelName => {
            "`tacho_channel` is a channel name of 1 to 64 characters".into()
        }
        TachoProblem::ChannelDiagnosed(t) => format!(
            "`tacho_channel` `{t}` is also in `channels`: the tachometer's channel gives the \
             speed and is not diagnosed; list only the vibration channels in `channels`"
        ),
    }
}

/// The configuration part of a machine's JSON.
pub fn config_json(m: &MachineRow) -> Value {
    let (channel_units, iso) = super::units::config_json(m);
    json!({
        "gearbox": m.gearbox_id.clone().unwrap_or_else(|| BUILTIN_ID.to_string()),
        "input_shaft_hz": m.input_shaft_hz,
        "channels": m.channels,
        "tacho_channel": m.tacho_channel,
        "tacho_ppr": m.tacho_ppr,
        "channel_units": channel_units,
        "iso_20816": iso,
        "speed_range_hz": m.speed_range_hz.map(|(lo, hi)| [lo, hi]),
    })
}

/// `PUT /v1/machines/{id}`.
pub async fn put(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: axum::body::Body,
) -> ApiResult<Response> {
    if let Err(e) = caller.require(&app, Scope::Admin) {
        let _ = read_body(&headers, body, SMALL_BODY).await;
        return Err(e);
    }
    check_machine_id(&id)?;
    let body = read_body(&headers, body, SMALL_BODY).await?;
    let b: MachineBody = json_object(&body).map_err(|e| {
        ApiError::bad_request(
            "invalid-machine",
            "Invalid machine configuration",
            format!(
                "{e}; expected {{\"gearbox\": \"<gearbox id>\", \"input_shaft_hz\"?: number, \
                 \"channels\"?: [names], \"tacho_channel\"?: name, \"tacho_ppr\"?: integer, \
                 \"channel_units\"?: {{\"<channel>\": {{\"unit\": \"g\"}}}}, \
                 \"iso_20816\"?: {{\"group\": 1 or 2, \"support\": \"rigid\" or \"flexible\"}}, \
                 \"speed_range_hz\"?: [lo, hi]}}"
            ),
        )
    })?;
    let gearbox = b.gearbox.unwrap_or_else(|| BUILTIN_ID.to_string());
    check_gearbox_id(&gearbox)?;
    let gearbox_row = match app.store.get_gearbox(&gearbox).await? {
        Some(r) => r,
        None if gearbox == BUILTIN_ID => {
            super::gearboxes::ensure_builtin(&app).await?;
            app.store
                .get_gearbox(BUILTIN_ID)
                .await?
                .ok_or_else(|| ApiError::internal("the built-in gearbox is missing"))?
        }
        None => {
            return Err(ApiError::unprocessable(
                "unknown-gearbox",
                "Unknown gearbox",
                format!(
                    "no gearbox `{gearbox}`: PUT its description to /v1/gearboxes/{gearbox} first"
                ),
            )
            .with("gearbox_id", gearbox.as_str()));
        }
    };
    if let Some(hz) = b.input_shaft_hz
        && !(hz.is_finite() && hz > 0.0 && hz <= 1000.0)
    {
        return Err(ApiError::unprocessable(
            "invalid-machine",
            "Invalid machine configuration",
            format!("`input_shaft_hz` must be a rate in Hz above 0 and at most 1000, got {hz}"),
        ));
    }
    let speed_range = check_speed_range(b.speed_range_hz)?;
    let spans = super::tables::machine_spans(b.input_shaft_hz, speed_range);
    let member = if speed_range.is_some() {
        "speed_range_hz"
    } else {
        "input_shaft_hz"
    };
    super::tables::check_machine(&app, &id, &gearbox_row, &spans, member).await?;
    if let Some(ch) = &b.channels {
        let bad = ch.is_empty()
            || ch.len() > 64
            || ch.iter().any(|c| c.is_empty() || c.len() > 64)
            || (1..ch.len()).any(|i| ch[..i].contains(&ch[i]));
        if bad {
            return Err(ApiError::unprocessable(
                "invalid-machine",
                "Invalid machine configuration",
                "`channels` is a list of 1 to 64 distinct names of 1 to 64 characters",
            ));
        }
    }
    let tacho_ppr = match b.tacho_ppr {
        None => 1,
        Some(p) if p.is_finite() && p.fract() == 0.0 && p.abs() <= 1e15 => p as i64,
        Some(p) => {
            return Err(ApiError::unprocessable(
                "invalid-machine",
                "Invalid machine configuration",
                format!("`tacho_ppr` must be a whole number of pulses per revolution, got {p}"),
            ));
        }
    };
    check_tacho(b.tacho_channel.as_deref(), tacho_ppr, b.channels.as_deref()).map_err(|e| {
        ApiError::unprocessable(
            "invalid-machine",
            "Invalid machine configuration",
            tacho_detail(&e),
        )
    })?;
    let (channel_units, iso) = super::units::check(
        b.channel_units,
        b.iso_20816.as_ref(),
        b.channels.as_deref(),
        b.tacho_channel.as_deref(),
    )?;
    let created = app
        .store
        .put_machine(
            &MachineConfig {
                id: id.clone(),
                gearbox_id: (gearbox != BUILTIN_ID).then_some(gearbox),
                input_shaft_hz: b.input_shaft_hz,
                channels: b.channels,
                tacho_channel: b.tacho_channel,
                tacho_ppr,
                channel_units,
                iso_group: iso.map(|c| i64::from(c.group)),
                iso_support: iso.map(|c| c.support.as_str().to_string()),
                speed_range_hz: speed_range,
            },
            now_ms(),
        )
        .await?;
    // Its speeds may lie beyond the gearbox's table: extended in the background.
    if let Err(e) = super::tables::extend_if_needed(&app, &gearbox_row).await {
        tracing::warn!(machine = %id, error = %e.detail, "the table's demand was not checked");
    }
    let m = app
        .store
        .get_machine(&id)
        .await?
        .ok_or_else(|| ApiError::internal("the stored machine vanished"))?;
    let mut body = config_json(&m);
    body["id"] = id.into();
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((status, Json(body)).into_response())
}

/// A `speed_range_hz` as stored: positive rates, the lower first, at most 1000 Hz.
fn check_speed_range(r: Option<[f64; 2]>) -> ApiResult<Option<(f64, f64)>> {
    let Some([lo, hi]) = r else {
        return Ok(None);
    };
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi && hi <= 1000.0) {
        return Err(ApiError::unprocessable(
            "invalid-machine",
            "Invalid machine configuration",
            format!(
                "`speed_range_hz` is `[lo, hi]`, the input shaft's lowest and highest rate in Hz: \
                 above 0, lo below hi, at most 1000; got [{lo}, {hi}]"
            ),
        )
        .with("member", "speed_range_hz"));
    }
    Ok(Some((lo, hi)))
}

/// The `baseline` object of a machine: its records and, per channel, how many and whether a
/// baseline is fitted.
pub async fn baseline_json(app: &AppState, m: &MachineRow) -> ApiResult<Value> {
    let rows = app.store.baseline_records(&m.id).await?;
    let row = match &m.gearbox_id {
        Some(g) => app.store.get_gearbox(g).await?,
        None => app.store.get_gearbox(BUILTIN_ID).await?,
    };
    let ctx_hash = row.as_ref().map(|r| r.hash.clone());
    let b = match &row {
        Some(r) => {
            let diagnoser = app.tables.diagnoser(app, r).await?;
            baselines(app, Some(m), &r.hash, diagnoser).await?
        }
        None => Arc::new(Baselines::default()),
    };
    let (fitted, counts) = (&b.pooled, &b.counts);
    let records = rows
        .iter()
        .map(|r| {
            let f = stored_features(r)?;
            Ok(json!({
                "record_id": r.id,
                "received_at": rfc3339(r.received_at),
                "measured_at": rfc3339(r.measured_at),
                "baseline_at": r.baseline_at.map(rfc3339),
                "channels": f.channels.keys().collect::<Vec<_>>(),
                "current_gearbox": ctx_hash.as_deref() == Some(f.gearbox_hash.as_str()),
            }))
        })
        .collect::<ApiResult<Vec<Value>>>()?;
    let channels: BTreeMap<String, Value> = counts
        .iter()
        .map(|(k, n)| {
            let p = fitted.get(k);
            let st = b.states.get(k);
            (
                k.clone(),
                json!({
                    "records": n,
                    "ready": p.is_some(),
                    "threshold": st.map(|s| s.threshold()).or(p.map(|p| p.threshold)),
                    "state_aware": st.is_some(),
                    "coverage": st.map(|s| s.coverage()),
                    "model": st.map(machine_model_json),
                    "path": path_json(&b, k),
                }),
            )
        })
        .collect();
    let physics = match &row {
        Some(r) => {
            let stored = app.store.get_machine_physics(&m.id).await?;
            super::physics::physics_json(stored.as_ref(), &super::physics_queue::key_of(m, &r.hash))
        }
        None => Value::Null,
    };
    Ok(json!({
        "physics": physics,
        "records": records,
        "count": rows.len(),
        "min_records": MIN_BASELINE_RECORDS,
        "ready": !fitted.is_empty(),
        // The span the baseline's records were measured over (they are in measurement order).
        "first_at": rows.first().map(|r| rfc3339(r.measured_at)),
        "last_at": rows.last().map(|r| rfc3339(r.measured_at)),
        "channels": channels,
    }))
}

async fn machine_or_404(app: &AppState, id: &str) -> ApiResult<MachineRow> {
    check_machine_id(id)?;
    app.store
        .get_machine(id)
        .await?
        .ok_or_else(|| unknown_machine(id))
}

/// `GET /v1/machines/{id}/baseline`.
pub async fn get_baseline(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let m = machine_or_404(&app, &id).await?;
    let mut body = baseline_json(&app, &m).await?;
    body["machine_id"] = id.into();
    Ok(json_with_etag(&headers, &body))
}

/// `POST /v1/machines/{id}/baseline` body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkBody {
    pub record_ids: Vec<String>,
}

/// `POST /v1/machines/{id}/baseline`: mark stored records as healthy.
pub async fn post_baseline(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: axum::body::Body,
) -> ApiResult<Response> {
    if let Err(e) = caller.require(&app, Scope::Admin) {
        let _ = read_body(&headers, body, SMALL_BODY).await;
        return Err(e);
    }
    let m = machine_or_404(&app, &id).await?;
    let body = read_body(&headers, body, SMALL_BODY).await?;
    let b: MarkBody = json_object(&body).map_err(|e| {
        ApiError::bad_request(
            "invalid-baseline",
            "Invalid baseline request",
            format!("{e}; expected {{\"record_ids\": [\"<record id>\", …]}}"),
        )
    })?;
    if b.record_ids.is_empty() || b.record_ids.len() > 1000 {
        return Err(ApiError::unprocessable(
            "invalid-baseline",
            "Invalid baseline request",
            "`record_ids` holds 1 to 1000 record ids",
        ));
    }
    let known = app.store.machine_record_ids(&id, &b.record_ids).await?;
    let missing: Vec<&String> = b.record_ids.iter().filter(|r| !known.contains(r)).collect();
    if !missing.is_empty() {
        return Err(ApiError::unprocessable(
            "unknown-record",
            "Unknown record",
            format!(
                "machine `{id}` has no record {}; record ids are the `record_id` of a POST …/records answer",
                missing.iter().map(|s| format!("`{s}`")).collect::<Vec<_>>().join(", ")
            ),
        )
        .with("record_ids", json!(missing)));
    }
    app.store
        .set_baseline(&id, &b.record_ids, true, now_ms())
        .await?;
    let mut body = baseline_json(&app, &m).await?;
    body["machine_id"] = id.into();
    Ok((StatusCode::OK, Json(body)).into_response())
}

/// `DELETE /v1/machines/{id}/baseline`: forget the baseline (the records stay).
pub async fn delete_baseline(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    machine_or_404(&app, &id).await?;
    app.store.clear_baseline(&id).await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// `DELETE /v1/machines/{id}/baseline/{record_id}`: unmark one record.
pub async fn delete_baseline_record(
    State(app): State<AppState>,
    caller: Caller,
    Path((id, record_id)): Path<(String, String)>,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    machine_or_404(&app, &id).await?;
    let n = app
        .store
        .set_baseline(&id, std::slice::from_ref(&record_id), false, now_ms())
        .await?;
    if n == 0 {
        return Err(ApiError::not_found(
            "unknown-record",
            format!("machine `{id}` has no baseline record `{record_id}`"),
        ));
    }
    Ok(StatusCode::NO_CONTENT.into_response())
}
