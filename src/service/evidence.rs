//! The record page's evidence: a diagnosis's evidence plot (the core's
//! [`crate::condition::EvidencePlot`]) with, beneath it, the same spectra of the machine's
//! healthy record nearest the record's operating state — the same load when a baseline record
//! has it, then the nearest measured speed. The spectra are in input-shaft orders, so records at
//! different speeds line up line for line.
//!
//! The plot is not drawn on the record path when the record's raw samples are kept: the
//! diagnosis is stored with an [`Undrawn`] note (what the drawing needs besides the samples),
//! and the plot is drawn from the stored samples when the record's page (or a reference to it)
//! first asks for it, then stored in its place. Before the retention drops a record's samples
//! its plot is drawn ([`draw_before_purge`]). Without raw samples (`--raw-retention-days 0`)
//! the plot is drawn on the path and stored with the diagnosis.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::AppState;
use super::error::{ApiError, ApiResult};
use crate::assessment::condition::measure_record;
use crate::assessment::{Assessment, Baselines, Machine, RecordFacts, TachoChannel};
use crate::condition::{EvidencePlot, Load, OperatingState, evidence_plot};
use crate::gearbox::Gearbox;
use crate::store::DiagnosisRow;
use crate::time::rfc3339;

/// The start of a stored `evidence` text that is an [`Undrawn`] note, not a plot.
const UNDRAWN_PREFIX: &str = "{\"undrawn\":";

/// What drawing a record's evidence plot needs besides its stored samples: how its state was
/// measured (the same call as the assessment's, [`measure_record`]) and which channel is drawn.
/// Channels are indices in the record's stored order.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Undrawn {
    /// The channels assessed (a tacho-less track follows the first).
    pub chosen: Vec<usize>,
    /// The deciding channel, drawn, and its name.
    pub deciding: usize,
    pub channel: String,
    /// The record's tachometer: its name and pulses per revolution.
    pub tacho: Option<(String, usize)>,
    /// The speed hints the state was measured with: the record's and the machine's.
    pub shaft_hz: Option<f64>,
    pub input_shaft_hz: Option<f64>,
    pub load: Option<Load>,
    /// The gearbox the record was assessed with and its description's hash.
    pub gearbox_id: String,
    pub gearbox_hash: String,
}

/// The `evidence` text a diagnosis is stored with: the [`Undrawn`] note when the record has a
/// plot to draw and its raw samples are kept (the plot is drawn when first asked for), else the
/// assessment's plot (or `null`).
pub fn stored_evidence(a: &Assessment, undrawn: Option<&Undrawn>, keeps_raw: bool) -> String {
    match undrawn.filter(|_| keeps_raw) {
        Some(u) => json!({ "undrawn": u }).to_string(),
        None => serde_json::to_string(&a.evidence_plot).unwrap_or_else(|_| "null".into()),
    }
}

/// The diagnosis's stored plot as JSON (`null` without one), drawn and stored first when it
/// was not drawn yet.
async fn plot_of(app: &AppState, d: &DiagnosisRow) -> ApiResult<Value> {
    if !d.evidence.starts_with(UNDRAWN_PREFIX) {
        return Ok(serde_json::from_str(&d.evidence).unwrap_or(Value::Null));
    }
    let drawn = draw_stored(app, d).await?;
    let text = serde_json::to_string(&drawn).unwrap_or_else(|_| "null".into());
    // Another request or replica may have stored it meanwhile: the same drawing of the same
    // samples, so either is the plot.
    app.store.set_evidence(&d.id, &d.evidence, &text).await?;
    // Read back from the text, as a stored plot is (its f32 levels written as such).
    Ok(serde_json::from_str(&text).unwrap_or(Value::Null))
}

/// Draw a diagnosis's plot from its record's stored samples and its [`Undrawn`] note; `None`
/// when the samples are gone or the gearbox was described anew since (nothing to draw it from).
async fn draw_stored(app: &AppState, d: &DiagnosisRow) -> ApiResult<Option<EvidencePlot>> {
    let note: Option<Undrawn> = serde_json::from_str::<Value>(&d.evidence)
        .ok()
        .and_then(|v| serde_json::from_value(v["undrawn"].clone()).ok());
    let Some(u) = note else {
        return Ok(None);
    };
    let Some(gearbox) = gearbox_of(app, &u).await? else {
        return Ok(None);
    };
    let rec = app.store.stored_record(&d.record_id).await?;
    let Some((rec, bytes)) = rec.and_then(|mut r| r.samples.take().map(|b| (r, b))) else {
        return Ok(None);
    };
    let channels = super::wire::stored_channels(&rec, &bytes);
    let fs = rec.sample_rate_hz;
    tokio::task::spawn_blocking(move || draw(&u, &channels, fs, &gearbox))
        .await
        .map_err(|e| ApiError::internal(format!("the evidence plot's task failed: {e}")))
}

/// The gearbox of `u` as it was when the record was assessed (`None`: described anew since).
async fn gearbox_of(app: &AppState, u: &Undrawn) -> ApiResult<Option<Arc<Gearbox>>> {
    let Some(row) = app.store.get_gearbox(&u.gearbox_id).await? else {
        return Ok(None);
    };
    if row.hash != u.gearbox_hash {
        return Ok(None);
    }
    if row.builtin {
        return Ok(Some(app.builtin_gearbox.clone()));
    }
    match app.tables.gearbox(&row) {
        Ok(g) => Ok(Some(g)),
        Err(e) => {
            tracing::warn!(gearbox = %u.gearbox_id, error = %e, "the evidence plot's gearbox does not read");
            Ok(None)
        }
    }
}

/// The plot the assessment would have drawn: the record's state measured as the assessment
/// measured it, the deciding channel drawn against it.
fn draw(
    u: &Undrawn,
    channels: &[(String, Vec<f64>)],
    fs: f64,
    gearbox: &Gearbox,
) -> Option<EvidencePlot> {
    if u.chosen
        .iter()
        .chain([&u.deciding])
        .any(|&i| i >= channels.len())
    {
        return None;
    }
    let facts = RecordFacts {
        sample_rate_hz: fs,
        shaft_hz: u.shaft_hz,
        sensor: None,
        declared_healthy: false,
        load: u.load.clone(),
        tacho: u.tacho.clone().map(|(name, pulses_per_rev)| TachoChannel {
            name,
            pulses_per_rev,
        }),
    };
    let baselines = Baselines::default();
    let mut machine = Machine::described(&u.gearbox_id, gearbox, None, &baselines);
    machine.input_shaft_hz = u.input_shaft_hz;
    let measured = measure_record(channels, &u.chosen, &facts, &machine).ok()?;
    let (angle, parts) = (measured.angle?, measured.parts?);
    evidence_plot(&u.channel, &channels[u.deciding].1, fs, &angle, &parts).ok()
}

/// Draw the plots not drawn yet of records whose raw samples the retention is about to drop
/// (received before `before`), so that their pages keep their evidence.
pub async fn draw_before_purge(app: &AppState, before: i64) -> ApiResult<usize> {
    let mut drawn = 0;
    loop {
        let rows = app
            .store
            .undrawn_evidence(UNDRAWN_PREFIX, before, 50)
            .await?;
        if rows.is_empty() {
            return Ok(drawn);
        }
        for d in &rows {
            plot_of(app, d).await?;
            drawn += 1;
        }
    }
}

/// The diagnosis's `evidence` member: its evidence plot with `reference` (`null` when the
/// machine has no other baseline record with a measured state on that channel); `null` when
/// the diagnosis has no plot.
pub async fn evidence_of(app: &AppState, d: &DiagnosisRow) -> ApiResult<Value> {
    let mut ev = plot_of(app, d).await?;
    if !ev.is_object() {
        return Ok(Value::Null);
    }
    let body: Value = serde_json::from_str(&d.body).unwrap_or(Value::Null);
    let state: Option<OperatingState> =
        serde_json::from_value(body["operating_state"].clone()).ok();
    let channel = ev["channel"].as_str().unwrap_or_default().to_string();
    ev["reference"] = match state {
        Some(s) => reference(app, d, &channel, &s).await?,
        None => Value::Null,
    };
    Ok(ev)
}

/// The baseline record of the machine nearest `state` on `channel` (never the record
/// itself), with its spectra.
async fn reference(
    app: &AppState,
    d: &DiagnosisRow,
    channel: &str,
    state: &OperatingState,
) -> ApiResult<Value> {
    let mut best: Option<(bool, f64, String, OperatingState)> = None;
    for r in app.store.baseline_records(&d.machine_id).await? {
        if r.id == d.record_id {
            continue;
        }
        let f: Value = serde_json::from_str(&r.features).unwrap_or(Value::Null);
        let st = &f["channels"][channel]["novelty_features"]["state"];
        let Ok(st) = serde_json::from_value::<OperatingState>(st.clone()) else {
            continue;
        };
        let same_load = match (&state.load, &st.load) {
            (Some(a), Some(b)) => Load::same(a, b),
            (None, None) => true,
            _ => false,
        };
        let gap = (st.shaft_hz - state.shaft_hz).abs();
        let better = best
            .as_ref()
            .is_none_or(|(l, g, ..)| (same_load, -gap) > (*l, -*g));
        if better {
            best = Some((same_load, gap, r.id, st));
        }
    }
    let Some((same_load, _, record_id, st)) = best else {
        return Ok(Value::Null);
    };
    let Some(rd) = app.store.diagnosis_of_record(&record_id).await? else {
        return Ok(Value::Null);
    };
    let plot = plot_of(app, &rd).await?;
    if !plot.is_object() {
        return Ok(Value::Null);
    }
    Ok(json!({
        "record_id": record_id,
        "diagnosis_id": rd.id,
        "measured_at": rfc3339(rd.measured_at),
        "shaft_hz": st.shaft_hz,
        "load": st.load,
        "same_load": same_load,
        "orders": plot["orders"],
        "envelope": plot["envelope"]["trace"],
    }))
}
