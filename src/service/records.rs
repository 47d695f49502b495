//! `POST /v1/machines/{machine_id}/records`: decode, assess (off the async runtime, with the
//! core's [`crate::assessment::assess`]), store in one transaction, answer 201 with the
//! assessment. `Idempotency-Key` makes retries safe.
//!
//! The record's operating state: its load from `?load=` or the JSON body's `load`; its speed
//! counted from its tachometer channel — the machine's `tacho_channel`, else a channel named
//! `tacho` — which is not diagnosed itself ([`tacho_of`]).

use std::sync::Arc;
use std::sync::atomic::Ordering;

use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult, problem_from_error};
use super::http::{body_format, check_machine_id, content_decoded, read_body, sniffed};
use super::machines::{DEFAULT_TACHO_CHANNEL, MachineContext};
use super::metrics::StageClock;
use super::spectrum::{PlotSpectrum, plot_from_spectrum, plot_spectrum};
use super::wire::{BodyFormat, Decoded, RecordQuery, decode, parse_query};
use crate::assessment::{
    Assessment, Baselines, Level, Machine, MachineCalibration, RecordFacts, TableDiagnoser,
    TachoChannel, Thresholds, assess,
};
use crate::gearbox::Gearbox;
use crate::keys::Scope;
use crate::store::{
    AlertInput, DiagnosisRow, IdemRow, Ingest, MachineRow, NewRecord, StoreError, new_id, now_ms,
};
use crate::time::parse_rfc3339;
use crate::units::MachineUnits;

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

/// A decoded record with its machine and what came with it: what [`prepare`] hands to
/// [`accept`].
pub struct Prepared {
    machine: Option<MachineRow>,
    /// The decoded record.
    pub dec: Decoded,
    request: RecordRequest,
    /// Warnings about how the body was read (a sniffed format), added to the assessment's.
    pub warnings: Vec<String>,
}

/// The steps of every record path (HTTP and MQTT) before the assessment: the machine (and,
/// with `--require-registered-machines`, that it is registered), the record decoded from
/// `format` with the query parameters `q`, its tachometer.
pub async fn prepare(
    app: &AppState,
    machine_id: &str,
    format: BodyFormat,
    q: RecordQuery,
    bytes: &[u8],
    clock: &mut StageClock,
) -> ApiResult<Prepared> {
    let machine = app.store.get_machine(machine_id).await?;
    super::lifecycle::check_registered(app, machine_id, machine.as_ref())?;
    clock.skip();
    let pulses = tacho_name(machine.as_ref());
    let dec = decode(format, &q, bytes, &app.settings.limits, Some(pulses))?;
    let declared_healthy = q.baseline()?;
    let tacho = tacho_of(machine.as_ref(), &dec, q.tacho_ppr()?)?;
    clock.lap("decode");
    Ok(Prepared {
        machine,
        dec,
        request: RecordRequest {
            channel: q.channel,
            declared_healthy,
            tacho,
        },
        warnings: Vec::new(),
    })
}

/// What [`accept`] did with a record.
pub enum Accepted {
    /// Stored: the answer (the assessment with its ids) and the diagnosis's id.
    Created {
        response_text: String,
        diagnosis_id: String,
    },
    /// A concurrent request with the same idempotency key committed first: its stored answer.
    Replayed(IdemRow),
}

/// Assess a prepared record (off the async runtime, with the core's [`assess`]) and store it
/// with its diagnosis, webhook deliveries and `idem`'s answer in one transaction; the record
/// path every source shares.
pub async fn accept(
    app: &AppState,
    machine_id: &str,
    format: BodyFormat,
    prepared: Prepared,
    idem: &Idempotency,
    mut clock: StageClock,
) -> ApiResult<Accepted> {
    let Prepared {
        machine,
        dec,
        request,
        warnings,
    } = prepared;
    let declared_healthy = request.declared_healthy;
    let job = request.load(app, machine_id, machine, dec).await?;
    let (dec, mut assessment, spectrum, job_clock) = tokio::task::spawn_blocking(move || job.run())
        .await
        .map_err(|e| ApiError::internal(format!("the diagnosis task failed: {e}")))?
        .map_err(|e| problem_from_error(&e))?;
    for note in warnings {
        assessment.warn(note);
    }
    clock.absorb(job_clock);
    clock.skip();

    let ids = Ids {
        now: now_ms(),
        record_id: new_id(),
        diagnosis_id: new_id(),
    };
    // Written once, straight from the typed assessment: the stored diagnosis, and the answer
    // with the ids spliced in.
    let body = serde_json::to_string(&assessment)
        .map_err(|e| ApiError::internal(format!("the assessment did not serialise: {e}")))?;
    let response_text = answer(&body, &ids, machine_id, assessment.level());
    let mut ing = Ingest {
        record: record_row(
            app,
            &dec,
            &assessment,
            &ids,
            machine_id,
            format,
            idem,
            declared_healthy,
        ),
        diagnosis: diagnosis_row(
            &assessment,
            body,
            spectrum.as_ref(),
            &ids,
            machine_id,
            measured_at(&dec, &ids),
        ),
        idempotency: idem.row(&response_text),
        event_extras: event_extras(&assessment),
        registered_only: app.settings.require_registered_machines,
        alert: Some(AlertInput {
            severity: assessment.severity(&app.settings.thresholds),
            measured_at: measured_at(&dec, &ids),
            policy: app.settings.alerts,
        }),
    };
    // The webhook payloads carry the machine's wear trend with this record in it: a read of
    // the history and a bootstrapped fit (≈ 10 ms of CPU at 200 points), so only when a
    // webhook will receive a diagnosis payload.
    if super::trend::payloads_wanted(app).await {
        let trend = super::trend::summary_with(app, &ing.diagnosis).await;
        ing.event_extras.insert("trend_summary".into(), trend);
    }
    clock.lap("assemble");
    if let Some(prev) = store(app, ing, idem).await? {
        return Ok(Accepted::Replayed(prev));
    }
    app.metrics.records_accepted.fetch_add(1, Ordering::Relaxed);
    app.metrics.stages(&clock);
    app.webhook_wake.notify_one();
    let ea = assessment.wear().map(|w| w.estimate);
    tracing::info!(machine = machine_id, diagnosis = %ids.diagnosis_id, ea, alert_level = %assessment.level(), "record accepted");
    Ok(Accepted::Created {
        response_text,
        diagnosis_id: ids.diagnosis_id,
    })
}

/// The store calls of one accepted record: its rows in one transaction (the group-commit
/// queue); `Some(answer)` when a concurrent request with the same idempotency key committed
/// first (its stored answer).
async fn store(app: &AppState, ing: Ingest, idem: &Idempotency) -> ApiResult<Option<IdemRow>> {
    match app.ingest_queue.ingest(ing).await {
        Ok(()) => Ok(None),
        Err(StoreError::Conflict(_)) if idem.key.is_some() => match idem.stored(app).await? {
            Some(prev) => Ok(Some(prev)),
            None => Err(ApiError::internal(
                "idempotency conflict without a stored answer",
            )),
        },
        Err(e) => Err(e.into()),
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

/// The name of the channel that is the machine's tachometer when a record has it: the
/// machine's `tacho_channel`, else [`DEFAULT_TACHO_CHANNEL`].
fn tacho_name(machine: Option<&MachineRow>) -> &str {
    machine
        .and_then(|m| m.tacho_channel.as_deref())
        .unwrap_or(DEFAULT_TACHO_CHANNEL)
}

/// The record's tachometer: the machine's `tacho_channel` (the record must have it), else a
/// channel named [`DEFAULT_TACHO_CHANNEL`] if the record has one; pulses per revolution from
/// `?tacho_ppr=`, else the machine's `tacho_ppr`.
fn tacho_of(
    machine: Option<&MachineRow>,
    dec: &Decoded,
    ppr: Option<usize>,
) -> ApiResult<Option<TachoChannel>> {
    let name = tacho_name(machine);
    let configured = machine.is_some_and(|m| m.tacho_channel.is_some());
    let has = dec.channels.iter().any(|(n, _)| n == name);
    if configured && !has {
        let names: Vec<String> = dec.channels.iter().map(|(n, _)| format!("`{n}`")).collect();
        return Err(ApiError::unprocessable(
            "missing-tacho-channel",
            "Tachometer channel missing",
            format!(
                "the machine's tachometer channel `{name}` is not in the record (its channels: \
                 {}); send the tachometer's samples as channel `{name}`, or change the \
                 machine's `tacho_channel` (PUT /v1/machines/{{machine_id}})",
                names.join(", ")
            ),
        )
        .with("tacho_channel", name));
    }
    if !has {
        if ppr.is_some() {
            return Err(ApiError::unprocessable(
                "missing-tacho-channel",
                "Tachometer channel missing",
                format!(
                    "`tacho_ppr` was given but the record has no tachometer channel (a channel \
                     named `{name}`, or the machine's `tacho_channel`)"
                ),
            )
            .with("tacho_channel", name));
        }
        return Ok(None);
    }
    let machine_ppr = machine.map_or(1, |m| m.tacho_ppr.max(1) as usize);
    Ok(Some(TachoChannel {
        name: name.to_string(),
        pulses_per_rev: ppr.unwrap_or(machine_ppr),
    }))
}

/// What each webhook payload of the record carries besides the diagnosis row's members: the
/// deciding channel's `findings` (strongest first) and the record's `operating_state`, as
/// answered (and, added by the caller, the machine's `trend_summary`).
fn event_extras(a: &Assessment) -> serde_json::Map<String, Value> {
    let mut m = serde_json::Map::new();
    m.insert(
        "findings".into(),
        serde_json::to_value(&a.findings).unwrap_or(Value::Null),
    );
    m.insert(
        "operating_state".into(),
        serde_json::to_value(&a.operating_state).unwrap_or(Value::Null),
    );
    m
}

/// The ids and time the service gives an accepted record.
struct Ids {
    now: i64,
    record_id: String,
    diagnosis_id: String,
}

/// The answer: the assessment's members (`body`, a JSON object's text) and the ids and time
/// the service gave it, none of which the assessment has.
fn answer(body: &str, ids: &Ids, machine_id: &str, level: Level) -> String {
    let given = json!({
        "id": ids.diagnosis_id,
        "machine_id": machine_id,
        "record_id": ids.record_id,
        "created_at": crate::time::rfc3339(ids.now),
        "alert_level": level,
    })
    .to_string();
    match body.strip_suffix('}') {
        Some(open) if open.len() > 1 => format!("{open},{}", &given[1..]),
        _ => given,
    }
}

fn f32_bytes(x: &[f64]) -> Vec<u8> {
    let mut v = Vec::with_capacity(x.len() * 4);
    for s in x {
        v.extend_from_slice(&(*s as f32).to_le_bytes());
    }
    v
}

/// The record's row: what was received (raw samples kept while the retention allows).
#[allow(clippy::too_many_arguments)]
fn record_row(
    app: &AppState,
    dec: &Decoded,
    a: &Assessment,
    ids: &Ids,
    machine_id: &str,
    format: BodyFormat,
    idem: &Idempotency,
    baseline: bool,
) -> NewRecord {
    let channels = &dec.channels;
    let sample_count = channels.first().map(|c| c.1.len()).unwrap_or(0);
    let keep_raw = !app.settings.raw_retention.is_zero();
    NewRecord {
        id: ids.record_id.clone(),
        machine_id: machine_id.to_string(),
        received_at: ids.now,
        recorded_at: dec.recorded_at.clone(),
        measured_at: measured_at(dec, ids),
        sensor: dec.sensor.clone(),
        content_type: format.mime().into(),
        sample_rate_hz: dec.sample_rate_hz,
        shaft_hz: dec.shaft_hz,
        sample_count: sample_count as i64,
        sha256: idem.body_sha256.clone(),
        features: serde_json::to_string(&a.stored_features()).unwrap_or_default(),
        samples: keep_raw.then(|| {
            let mut v = Vec::with_capacity(4 * sample_count * channels.len());
            for (_, x) in channels {
                v.extend_from_slice(&f32_bytes(x));
            }
            v
        }),
        baseline,
        channels: (channels.len() > 1).then(|| channels.iter().map(|c| c.0.clone()).collect()),
    }
}

/// The diagnosis's row: the assessment as answered (`body`), the wear its trend follows, the
/// spectrum plot.
fn diagnosis_row(
    a: &Assessment,
    body: String,
    spectrum: Option<&PlotSpectrum>,
    ids: &Ids,
    machine_id: &str,
    measured_at: i64,
) -> DiagnosisRow {
    let decide = a.deciding_channel();
    // No wear figure (no table, or the model does not fit the record): `has_wear` is false
    // and the zeros below are never shown (the API answers null, trends leave a gap).
    let wear = a.wear();
    let (ea, lower, upper) = wear.map_or((0.0, 0.0, 0.0), |w| (w.estimate, w.lower, w.upper));
    let motion = match &decide.reading {
        Some(r) => r.diagnosis.motion_state.clone(),
        None => "unknown".to_string(),
    };
    DiagnosisRow {
        seq: 0,
        id: ids.diagnosis_id.clone(),
        record_id: ids.record_id.clone(),
        machine_id: machine_id.to_string(),
        created_at: ids.now,
        ea_estimate: ea,
        ea_lower: lower,
        ea_upper: upper,
        alert_level: a.level(),
        motion_state: motion,
        body,
        spectrum: serde_json::to_string(&spectrum).unwrap_or_else(|_| "null".into()),
        evidence: serde_json::to_string(&a.evidence_plot).unwrap_or_else(|_| "null".into()),
        has_wear: wear.is_some(),
        novelty_score: decide.novelty.as_ref().map(|n| n.score),
        novelty_threshold: decide.novelty.as_ref().map(|n| n.threshold),
        channel: Some(decide.name.clone()),
        measured_at,
    }
}

/// When the record was measured, unix ms: its `recorded_at` (checked as RFC 3339 when it was
/// decoded), else the time it was received.
fn measured_at(dec: &Decoded, ids: &Ids) -> i64 {
    dec.recorded_at
        .as_deref()
        .and_then(parse_rfc3339)
        .unwrap_or(ids.now)
}

/// A record's idempotency key (HTTP: the `Idempotency-Key` header, scoped to the API key;
/// MQTT: the record id, scoped to the machine) and the hashes that identify the request.
pub struct Idempotency {
    key: Option<String>,
    key_id: String,
    /// The body's SHA-256 (stored as the record's `sha256`).
    body_sha256: String,
    /// Over machine, content type, query and the body hash.
    request_hash: String,
}

impl Idempotency {
    fn of(
        headers: &HeaderMap,
        caller: &Caller,
        machine_id: &str,
        format: BodyFormat,
        query: Option<&str>,
        bytes: &[u8],
    ) -> ApiResult<Idempotency> {
        let key = match headers.get("idempotency-key") {
            None => None,
            Some(v) => {
                let s = v.to_str().ok().filter(|s| !s.is_empty() && s.len() <= 255);
                Some(
                    s.ok_or_else(|| {
                        ApiError::bad_request(
                            "invalid-idempotency-key",
                            "Invalid Idempotency-Key",
                            "an Idempotency-Key is 1 to 255 visible ASCII characters (a UUID is a good choice)",
                        )
                    })?
                    .to_string(),
                )
            }
        };
        Ok(Idempotency::new(
            caller.key_id.clone().unwrap_or_default(),
            key,
            machine_id,
            format,
            query,
            bytes,
        ))
    }

    /// The key `key` in the scope `key_id` for a record of `machine_id` sent as `bytes` in
    /// `format` with the query (or MQTT header) `query`.
    pub fn new(
        key_id: String,
        key: Option<String>,
        machine_id: &str,
        format: BodyFormat,
        query: Option<&str>,
        bytes: &[u8],
    ) -> Idempotency {
        // The body is hashed once (it is stored as the record's `sha256`); the request hash
        // covers machine, content type, query and that body hash.
        let body_sha256 = hex::encode(Sha256::digest(bytes));
        let mut h = Sha256::new();
        for part in [
            machine_id.as_bytes(),
            format.mime().as_bytes(),
            query.unwrap_or("").as_bytes(),
            body_sha256.as_bytes(),
        ] {
            h.update(part);
            h.update([0u8]);
        }
        Idempotency {
            key,
            key_id,
            body_sha256,
            request_hash: hex::encode(h.finalize()),
        }
    }

    /// Whether `prev`, a stored answer to this key, answered this same request.
    pub fn same_request(&self, prev: &IdemRow) -> bool {
        prev.request_hash == self.request_hash
    }

    /// The stored answer to this key, if any.
    pub async fn stored(&self, app: &AppState) -> ApiResult<Option<IdemRow>> {
        match &self.key {
            Some(k) => Ok(app.store.get_idempotent(&self.key_id, k).await?),
            None => Ok(None),
        }
    }

    /// The answer of an earlier identical request, replayed.
    async fn replay_stored(&self, app: &AppState) -> ApiResult<Option<Response>> {
        match self.stored(app).await? {
            Some(prev) => replay(app, &prev, &self.request_hash).map(Some),
            None => Ok(None),
        }
    }

    /// The row that keeps this request's answer.
    fn row(&self, response_text: &str) -> Option<IdemRow> {
        self.key.as_ref().map(|k| IdemRow {
            key_id: self.key_id.clone(),
            idem_key: k.clone(),
            request_hash: self.request_hash.clone(),
            status: 201,
            response: response_text.to_string(),
        })
    }
}

fn replay(app: &AppState, prev: &IdemRow, request_hash: &str) -> ApiResult<Response> {
    if prev.request_hash != request_hash {
        return Err(ApiError::unprocessable(
            "idempotency-key-reused",
            "Idempotency-Key reused with a different request",
            "this Idempotency-Key was already used for a different record; use a new key for a new record",
        ));
    }
    app.metrics.records_replayed.fetch_add(1, Ordering::Relaxed);
    let status = StatusCode::from_u16(prev.status as u16).unwrap_or(StatusCode::CREATED);
    let mut r = (status, prev.response.clone()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r.headers_mut()
        .insert("idempotent-replayed", HeaderValue::from_static("true"));
    Ok(r)
}

/// What the request says about the record besides its samples.
struct RecordRequest {
    /// `?channel=`.
    channel: Option<String>,
    /// Posted with `?baseline=true`.
    declared_healthy: bool,
    tacho: Option<TachoChannel>,
}

/// Everything the blocking part of an ingest needs: the decoded record, the chosen channels
/// and the machine's context (gearbox, table, baseline, calibration).
struct AssessJob {
    dec: Decoded,
    chosen: Vec<usize>,
    ctx: MachineContext,
    calibration: Option<MachineCalibration>,
    baselines: Arc<Baselines>,
    thresholds: Thresholds,
    /// Posted with `?baseline=true`.
    declared_healthy: bool,
    tacho: Option<TachoChannel>,
    /// The machine's declared units and ISO class.
    units: MachineUnits,
}

type JobResult = (Decoded, Assessment, Option<PlotSpectrum>, StageClock);

impl RecordRequest {
    /// The machine's gearbox (and its table, when ready), baseline and calibration, and the
    /// channels to assess (never the tachometer's).
    async fn load(
        self,
        app: &AppState,
        machine_id: &str,
        machine: Option<MachineRow>,
        dec: Decoded,
    ) -> ApiResult<AssessJob> {
        let ctx = super::machines::context_of(app, machine_id, machine).await?;
        let tacho_index = self
            .tacho
            .as_ref()
            .and_then(|t| dec.channels.iter().position(|(n, _)| *n == t.name));
        let chosen = dec.select(
            self.channel.as_deref(),
            ctx.machine.as_ref().and_then(|m| m.channels.as_deref()),
            tacho_index,
        )?;
        let units = super::units::machine_units(ctx.machine.as_ref())?;
        let baselines =
            super::machines::baselines(app, ctx.machine.as_ref(), &ctx.gearbox_row.hash).await?;
        let calibration = app
            .store
            .get_calibration(machine_id)
            .await?
            .map(|c| calibration_of(&c));
        Ok(AssessJob {
            dec,
            chosen,
            ctx,
            calibration,
            baselines,
            thresholds: app.settings.thresholds,
            declared_healthy: self.declared_healthy,
            tacho: self.tacho,
            units,
        })
    }
}

impl AssessJob {
    /// The assessment (timed by stage) and the spectrum plot of the deciding channel.
    fn run(mut self) -> crate::Result<JobResult> {
        let mut clock = StageClock::new();
        let facts = RecordFacts {
            sample_rate_hz: self.dec.sample_rate_hz,
            shaft_hz: self.dec.shaft_hz,
            sensor: self.dec.sensor.clone(),
            declared_healthy: self.declared_healthy,
            load: self.dec.load.clone(),
            tacho: self.tacho.clone(),
        };
        let ctx = &self.ctx;
        let diagnoser: Option<&TableDiagnoser> = ctx.diagnoser.as_deref();
        let machine = Machine {
            gearbox: &ctx.gearbox,
            gearbox_ref: ctx.gearbox_ref(),
            described: ctx.machine.as_ref().is_some_and(|m| m.gearbox_id.is_some()),
            diagnoser,
            table_note: ctx.table_note(),
            input_shaft_hz: ctx.input_shaft_hz(),
            baselines: &self.baselines.pooled,
            state_baselines: &self.baselines.states,
            baseline_counts: &self.baselines.counts,
            calibration: self.calibration.as_ref(),
            thresholds: self.thresholds,
            units: std::mem::take(&mut self.units),
        };
        let a = assess(
            &mut self.dec.channels,
            &self.chosen,
            &facts,
            &machine,
            &mut |stage| clock.lap(stage),
        )?;
        let samples = &self.dec.channels[self.chosen[a.deciding]].1;
        let spectrum = plot(&a, samples, &facts, &ctx.gearbox, ctx.input_shaft_hz());
        clock.lap("plot");
        Ok((self.dec, a, spectrum, clock))
    }
}

/// A stored calibration as the assessment holds it.
pub fn calibration_of(c: &crate::store::CalibrationRow) -> MachineCalibration {
    MachineCalibration {
        id: c.id.clone(),
        calibrated_at: crate::time::rfc3339(c.created_at),
        effects: serde_json::from_str(&c.effects).unwrap_or(Value::Array(vec![])),
    }
}

/// The spectrum plot of the deciding channel: from the spectrum its diagnosis computed when it
/// has one, else from its samples.
fn plot(
    a: &Assessment,
    samples: &[f64],
    facts: &RecordFacts,
    gearbox: &Arc<Gearbox>,
    input_shaft_hz: Option<f64>,
) -> Option<PlotSpectrum> {
    let fs = facts.sample_rate_hz;
    match &a.deciding_channel().reading {
        Some(r) => {
            let f1 = r.diagnosis.f1_hz;
            match &r.spectrum {
                Some(s) => plot_from_spectrum(s, f1, &r.marks()),
                None => plot_spectrum(samples, fs, f1, &r.marks()),
            }
        }
        None => {
            let f1 = input_shaft_hz.map(|h| gearbox.f1_hz(h)).unwrap_or(f64::NAN);
            plot_spectrum(samples, fs, f1, &[])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_answer_is_the_assessment_with_the_ids_and_time() {
        let ids = Ids {
            now: 0,
            record_id: "r".into(),
            diagnosis_id: "d".into(),
        };
        let got = answer(r#"{"alert":{"level":"ok"},"x":[1]}"#, &ids, "m", Level::Ok);
        let want = json!({"alert": {"level": "ok"}, "x": [1], "id": "d", "machine_id": "m",
            "record_id": "r", "created_at": crate::time::rfc3339(0), "alert_level": "ok"});
        assert_eq!(serde_json::from_str::<Value>(&got).unwrap(), want);
        let bare: Value = serde_json::from_str(&answer("{}", &ids, "m", Level::Ok)).unwrap();
        assert_eq!(bare["id"], "d");
    }
}
