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
//! [`context`] gives a record's diagnosis what it needs of its machine; [`baselines`] fits the
//! machine's baseline per channel from the stored features of its baseline records (only those
//! computed with the machine's current gearbox description).

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
use super::error::{ApiError, ApiResult, unknown_machine};
use super::gearboxes::BUILTIN_ID;
use super::http::{check_gearbox_id, check_machine_id, json_with_etag, read_body};
use crate::assessment::state_baseline;
use crate::assessment::{GearboxRef, TableDiagnoser};
use crate::condition::StateBaseline;
use crate::gearbox::Gearbox;
use crate::keys::Scope;
use crate::novelty::{MIN_BASELINE_RECORDS, MachineBaseline, RecordFeatures};
use crate::store::{GearboxRow, MachineConfig, MachineRow, now_ms};
use crate::time::rfc3339;

/// Largest configuration or baseline request body.
const SMALL_BODY: usize = 64 * 1024;

/// What a record's diagnosis needs of its machine.
pub struct MachineContext {
    pub machine: Option<MachineRow>,
    pub gearbox_row: GearboxRow,
    pub gearbox: Arc<Gearbox>,
    /// The diagnoser of the gearbox's table; `None` while the table is not ready.
    pub diagnoser: Option<Arc<TableDiagnoser>>,
}

impl MachineContext {
    /// The note a diagnosis carries while the gearbox's table is not ready.
    pub fn table_note(&self) -> Option<String> {
        if self.diagnoser.is_some() {
            return None;
        }
        let g = &self.gearbox_row;
        Some(match g.status.as_str() {
            "failed" => format!(
                "the signature table of gearbox `{}` failed ({}): no wear degree; this diagnosis \
                 uses the machine's baseline and indicators only — PUT a corrected description",
                g.id,
                g.error.as_deref().unwrap_or("no reason stored")
            ),
            s => format!(
                "the signature table of gearbox `{}` is not ready ({s}, {:.0} %): no wear degree \
                 yet; this diagnosis uses the machine's baseline and indicators only",
                g.id,
                100.0 * g.progress
            ),
        })
    }

    /// The `gearbox` object of a diagnosis.
    pub fn gearbox_ref(&self) -> GearboxRef {
        GearboxRef {
            id: self.gearbox_row.id.clone(),
            name: self.gearbox_row.name.clone(),
            hash: self.gearbox_row.hash.clone(),
            table_status: self.gearbox_row.status.clone(),
            table_progress: self.gearbox_row.progress,
        }
    }

    pub fn input_shaft_hz(&self) -> Option<f64> {
        self.machine.as_ref().and_then(|m| m.input_shaft_hz)
    }
}

/// The machine (if it exists), its gearbox and that gearbox's diagnoser.
pub async fn context(app: &AppState, machine_id: &str) -> ApiResult<MachineContext> {
    let machine = app.store.get_machine(machine_id).await?;
    context_of(app, machine_id, machine).await
}

/// [`context`] of a machine row already read (`None`: a machine without a row yet).
pub async fn context_of(
    app: &AppState,
    machine_id: &str,
    machine: Option<MachineRow>,
) -> ApiResult<MachineContext> {
    let gid = machine
        .as_ref()
        .and_then(|m| m.gearbox_id.clone())
        .unwrap_or_else(|| BUILTIN_ID.to_string());
    let row = match app.store.get_gearbox(&gid).await? {
        Some(r) => r,
        None if gid == BUILTIN_ID => {
            super::gearboxes::ensure_builtin(app).await?;
            app.store
                .get_gearbox(BUILTIN_ID)
                .await?
                .ok_or_else(|| ApiError::internal("the built-in gearbox is missing"))?
        }
        None => {
            return Err(ApiError::internal(format!(
                "machine `{machine_id}` names gearbox `{gid}`, which is not stored"
            )));
        }
    };
    let gearbox = if row.builtin {
        app.builtin_gearbox.clone()
    } else {
        app.tables
            .gearbox(&row)
            .map_err(|e| ApiError::internal(format!("gearbox `{gid}`: {e}")))?
    };
    let diagnoser = app.tables.diagnoser(app, &row).await?;
    Ok(MachineContext {
        machine,
        gearbox_row: row,
        gearbox,
        diagnoser,
    })
}

/// A machine's baselines per channel, fitted from the stored features of its baseline
/// records computed with its gearbox description.
#[derive(Debug, Default)]
pub struct Baselines {
    pub pooled: BTreeMap<String, MachineBaseline>,
    /// State-aware, where enough baseline records carry a measured state.
    pub states: BTreeMap<String, StateBaseline>,
    /// Baseline records per channel.
    pub counts: BTreeMap<String, usize>,
}

/// The stored features of the machine's baseline records computed with gearbox description
/// `hash`, per channel.
pub async fn baseline_features(
    app: &AppState,
    machine_id: &str,
    hash: &str,
) -> ApiResult<BTreeMap<String, Vec<RecordFeatures>>> {
    let rows = app.store.baseline_records(machine_id).await?;
    let mut per: BTreeMap<String, Vec<RecordFeatures>> = BTreeMap::new();
    for r in rows {
        let Ok(f) = serde_json::from_str::<Value>(&r.features) else {
            continue;
        };
        if f["gearbox_hash"].as_str() != Some(hash) {
            continue;
        }
        if let Some(chs) = f["channels"].as_object() {
            for (name, c) in chs {
                if let Ok(rf) =
                    serde_json::from_value::<RecordFeatures>(c["novelty_features"].clone())
                {
                    per.entry(name.clone()).or_default().push(rf);
                }
            }
        }
    }
    Ok(per)
}

/// The machine's baselines per channel, fitted from the stored features of its baseline
/// records computed with gearbox description `hash`.
pub async fn baselines(app: &AppState, machine_id: &str, hash: &str) -> ApiResult<Baselines> {
    let per = baseline_features(app, machine_id, hash).await?;
    let counts = per.iter().map(|(k, v)| (k.clone(), v.len())).collect();
    let (pooled, states) = tokio::task::spawn_blocking(move || {
        let pooled = per
            .iter()
            .filter(|(_, v)| v.len() >= MIN_BASELINE_RECORDS)
            .filter_map(|(k, v)| MachineBaseline::fit(v).ok().map(|b| (k.clone(), b)))
            .collect::<BTreeMap<_, _>>();
        let states = per
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), state_baseline(v)?.ok()?)))
            .collect::<BTreeMap<_, _>>();
        (pooled, states)
    })
    .await
    .map_err(|e| ApiError::internal(format!("fitting the baseline failed: {e}")))?;
    Ok(Baselines {
        pooled,
        states,
        counts,
    })
}

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
}

/// The default name of a record's tachometer channel, for a machine that names none.
pub const DEFAULT_TACHO_CHANNEL: &str = "tacho";
/// Most tachometer pulses per revolution accepted (a fine shaft encoder).
pub const MAX_TACHO_PPR: i64 = crate::condition::state::MAX_PULSES_PER_REV as i64;

/// Check a machine's tachometer settings: `tacho_channel` a channel name (1 to 64
/// characters) that is not among the `channels` to diagnose, `tacho_ppr` from 1 to
/// [`MAX_TACHO_PPR`]. `Err` is a message for the caller.
pub fn check_tacho(
    tacho_channel: Option<&str>,
    tacho_ppr: i64,
    channels: Option<&[String]>,
) -> Result<(), String> {
    if !(1..=MAX_TACHO_PPR).contains(&tacho_ppr) {
        return Err(format!(
            "`tacho_ppr` is the tachometer's pulses per input-shaft revolution, a whole number \
             from 1 to {MAX_TACHO_PPR}, got {tacho_ppr}"
        ));
    }
    let Some(t) = tacho_channel else {
        return Ok(());
    };
    if t.is_empty() || t.len() > 64 {
        return Err("`tacho_channel` is a channel name of 1 to 64 characters".into());
    }
    if channels.is_some_and(|c| c.iter().any(|c| c == t)) {
        return Err(format!(
            "`tacho_channel` `{t}` is also in `channels`: the tachometer's channel gives the \
             speed and is not diagnosed; list only the vibration channels in `channels`"
        ));
    }
    Ok(())
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
                 \"iso_20816\"?: {{\"group\": 1 or 2, \"support\": \"rigid\" or \"flexible\"}}}}"
            ),
        )
    })?;
    let gearbox = b.gearbox.unwrap_or_else(|| BUILTIN_ID.to_string());
    check_gearbox_id(&gearbox)?;
    if app.store.get_gearbox(&gearbox).await?.is_none() {
        if gearbox == BUILTIN_ID {
            super::gearboxes::ensure_builtin(&app).await?;
        } else {
            return Err(ApiError::unprocessable(
                "unknown-gearbox",
                "Unknown gearbox",
                format!(
                    "no gearbox `{gearbox}`: PUT its description to /v1/gearboxes/{gearbox} first"
                ),
            )
            .with("gearbox_id", gearbox.as_str()));
        }
    }
    if let Some(hz) = b.input_shaft_hz
        && !(hz.is_finite() && hz > 0.0 && hz <= 1000.0)
    {
        return Err(ApiError::unprocessable(
            "invalid-machine",
            "Invalid machine configuration",
            format!("`input_shaft_hz` must be a rate in Hz above 0 and at most 1000, got {hz}"),
        ));
    }
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
        ApiError::unprocessable("invalid-machine", "Invalid machine configuration", e)
    })?;
    let (channel_units, iso) = super::units::check(
        b.channel_units,
        b.iso_20816.as_ref(),
        b.channels.as_deref(),
        b.tacho_channel.as_deref(),
    )
    .map_err(|r| r.problem())?;
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
            },
            now_ms(),
        )
        .await?;
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

/// The `baseline` object of a machine: its records and, per channel, how many and whether a
/// baseline is fitted.
pub async fn baseline_json(app: &AppState, m: &MachineRow) -> ApiResult<Value> {
    let rows = app.store.baseline_records(&m.id).await?;
    let ctx_hash = match &m.gearbox_id {
        Some(g) => app.store.get_gearbox(g).await?.map(|r| r.hash),
        None => app.store.get_gearbox(BUILTIN_ID).await?.map(|r| r.hash),
    };
    let b = match &ctx_hash {
        Some(h) => baselines(app, &m.id, h).await?,
        None => Baselines::default(),
    };
    let (fitted, counts) = (&b.pooled, &b.counts);
    let records: Vec<Value> = rows
        .iter()
        .map(|r| {
            let f: Value = serde_json::from_str(&r.features).unwrap_or(Value::Null);
            json!({
                "record_id": r.id,
                "received_at": rfc3339(r.received_at),
                "baseline_at": r.baseline_at.map(rfc3339),
                "channels": f["channels"].as_object().map(|c| c.keys().cloned().collect::<Vec<_>>()),
                "current_gearbox": ctx_hash.is_some() && f["gearbox_hash"].as_str() == ctx_hash.as_deref(),
            })
        })
        .collect();
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
                }),
            )
        })
        .collect();
    Ok(json!({
        "records": records,
        "count": rows.len(),
        "min_records": MIN_BASELINE_RECORDS,
        "ready": !fitted.is_empty(),
        "first_at": rows.first().map(|r| rfc3339(r.baseline_at.unwrap_or(r.received_at))),
        "last_at": rows.last().map(|r| rfc3339(r.baseline_at.unwrap_or(r.received_at))),
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
