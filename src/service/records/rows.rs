//! What an accepted record writes and answers: its record and diagnosis rows, the members
//! its webhook events carry, and the answer with the ids the service gave it.

use serde_json::{Value, json};

use super::idempotency::Idempotency;
use crate::assessment::{Assessment, Level};
use crate::service::AppState;
use crate::service::spectrum::PlotSpectrum;
use crate::service::wire::{BodyFormat, Decoded};
use crate::store::{DiagnosisRow, NewRecord};
use crate::time::parse_rfc3339;

/// What each webhook payload of the record carries besides the diagnosis row's members: the
/// deciding channel's `findings` (strongest first) and the record's `operating_state`, as
/// answered (and, added by the caller, the machine's `trend_summary`).
pub(crate) fn event_extras(a: &Assessment) -> serde_json::Map<String, Value> {
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
pub(crate) struct Ids {
    pub now: i64,
    pub record_id: String,
    pub diagnosis_id: String,
}

/// The answer: the assessment's members (`body`, a JSON object's text) and the ids and time
/// the service gave it, none of which the assessment has.
pub(super) fn answer(body: &str, ids: &Ids, machine_id: &str, level: Level) -> String {
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

/// `x` as little-endian f32, appended to `v`.
fn put_f32(v: &mut Vec<u8>, x: &[f64]) {
    let start = v.len();
    v.resize(start + 4 * x.len(), 0);
    for (d, s) in v[start..].chunks_exact_mut(4).zip(x) {
        d.copy_from_slice(&(*s as f32).to_le_bytes());
    }
}

/// The record's row: what was received (raw samples kept while the retention allows).
#[allow(clippy::too_many_arguments)]
pub(super) fn record_row(
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
                put_f32(&mut v, x);
            }
            v
        }),
        baseline,
        channels: (channels.len() > 1).then(|| channels.iter().map(|c| c.0.clone()).collect()),
    }
}

/// The diagnosis's row: the assessment as answered (`body`), the wear its trend follows, the
/// spectrum plot, the `evidence` text ([`crate::service::evidence::stored_evidence`]).
pub(crate) fn diagnosis_row(
    a: &Assessment,
    body: String,
    spectrum: Option<&PlotSpectrum>,
    evidence: String,
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
        evidence,
        has_wear: wear.is_some(),
        novelty_score: decide.novelty.as_ref().map(|n| n.score),
        novelty_threshold: decide.novelty.as_ref().map(|n| n.threshold),
        channel: Some(decide.name.clone()),
        measured_at,
        wear_withheld: crate::service::tables::withheld(a).map(|w| w.as_str().to_string()),
        reread_status: None,
        reread_request: None,
        replaces: None,
    }
}

/// When the record was measured, unix ms: its `recorded_at` (checked as RFC 3339 when it was
/// decoded), else the time it was received.
pub(super) fn measured_at(dec: &Decoded, ids: &Ids) -> i64 {
    dec.recorded_at
        .as_deref()
        .and_then(parse_rfc3339)
        .unwrap_or(ids.now)
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
