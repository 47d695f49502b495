//! The record page's evidence: a diagnosis's stored evidence plot (the core's
//! [`crate::condition::EvidencePlot`], computed once when the record was assessed) with, beneath
//! it, the same spectra of the machine's healthy record nearest the record's operating state —
//! the same load when a baseline record has it, then the nearest measured speed. The spectra are
//! in input-shaft orders, so records at different speeds line up line for line.

use serde_json::{Value, json};

use super::AppState;
use super::error::ApiResult;
use crate::condition::{Load, OperatingState};
use crate::store::DiagnosisRow;
use crate::time::rfc3339;

/// The diagnosis's `evidence` member: its evidence plot with `reference` (`null` when the
/// machine has no other baseline record with a measured state on that channel); `null` when
/// the diagnosis has no plot.
pub async fn evidence_of(app: &AppState, d: &DiagnosisRow) -> ApiResult<Value> {
    let mut ev: Value = serde_json::from_str(&d.evidence).unwrap_or(Value::Null);
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
    let plot: Value = serde_json::from_str(&rd.evidence).unwrap_or(Value::Null);
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
