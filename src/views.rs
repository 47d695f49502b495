//! The JSON of stored rows as the API answers them and the CLI prints them, and the webhook
//! payloads rendered from the store's typed events (`docs/service.md`, "Webhooks").

use serde_json::{Map, Value, json};

use crate::condition::StateBaseline;
use crate::gearbox::Gearbox;
use crate::store::events::{DiagnosisEvent, Event, QueuedEvent};
use crate::store::{AlertEventRow, AlertRow, DiagnosisRow, GearboxRow};
use crate::time::rfc3339;

/// A channel's calibrated machine model ([`crate::condition::machine_model`]): its report
/// when it was accepted, the reason when it was refused, `null` when the baseline's records
/// carry no line levels (stored before line levels were kept).
pub fn machine_model_json(b: &StateBaseline) -> Value {
    match b.model() {
        Some(Ok(m)) => json!({"status": "calibrated", "report": m.report}),
        Some(Err(e)) => json!({"status": "refused", "reason": e.to_string()}),
        None => Value::Null,
    }
}

/// A channel's transfer path calibrated on its healthy records' line ratios
/// ([`crate::diagnosis::machine_path`]): `calibrated` with the figures, `refused` with the
/// reason, `null` when its records carry too few line ratios or the table is not ready.
pub fn path_json(b: &crate::assessment::Baselines, channel: &str) -> Value {
    if let Some(p) = b.paths.get(channel) {
        return json!({
            "status": "calibrated",
            "records": p.records,
            "f1_hz": p.f1_hz,
            "lambda": p.lambda,
            "residual_db": p.residual_after_db,
            "plain_residual_db": p.residual_before_db,
            "path": p.path(),
        });
    }
    match b.path_refusals.get(channel) {
        Some(why) => json!({"status": "refused", "reason": why}),
        None => Value::Null,
    }
}

/// An episode (without its audit trail).
pub fn alert_json(a: &AlertRow) -> Value {
    json!({
        "id": a.id,
        "machine_id": a.machine_id,
        "level": a.level,
        "state": a.state,
        "opened_at": rfc3339(a.opened_at),
        "acknowledged_at": a.acknowledged_at.map(rfc3339),
        "acknowledged_by": a.acknowledged_by,
        "note": a.note,
        "closed_at": a.closed_at.map(rfc3339),
        "closed_record_id": a.closed_record_id,
        "peak_severity": a.peak_severity,
        "record_id": a.record_id,
    })
}

/// One line of an episode's audit trail.
pub fn alert_event_json(e: &AlertEventRow) -> Value {
    json!({
        "at": rfc3339(e.at),
        "event": e.event,
        "by": e.by,
        "note": e.note,
        "record_id": e.record_id,
        "level": e.level,
        "severity": e.severity,
    })
}

/// `{estimate, lower, upper}`, or null for a diagnosis without a wear degree.
pub fn wear_json(d: &DiagnosisRow) -> Value {
    if d.has_wear {
        json!({"estimate": d.ea_estimate, "lower": d.ea_lower, "upper": d.ea_upper})
    } else {
        Value::Null
    }
}

/// `{score, threshold, anomalous}`, or null without a baseline.
pub fn novelty_json(d: &DiagnosisRow) -> Value {
    novelty(d.novelty_score, d.novelty_threshold)
}

fn novelty(score: Option<f64>, threshold: Option<f64>) -> Value {
    match (score, threshold) {
        (Some(s), Some(t)) => json!({"score": s, "threshold": t, "anomalous": s > t}),
        _ => Value::Null,
    }
}

/// A gearbox: its row, and with `full` its resolved description, kinematics and warnings.
pub fn gearbox_json(row: &GearboxRow, gb: Option<&Gearbox>, full: bool) -> Value {
    let mut v = json!({
        "id": row.id,
        "name": row.name,
        "builtin": row.builtin,
        "hash": row.hash,
        "status": row.status,
        "progress": row.progress,
        "error": row.error,
        "attempts": row.attempts,
        "created_at": rfc3339(row.created_at),
        "updated_at": rfc3339(row.updated_at),
        "started_at": row.started_at.map(rfc3339),
        "finished_at": row.finished_at.map(rfc3339),
    });
    if let (true, Some(gb)) = (full, gb) {
        let nominal = gb.description.nominal_input_hz;
        v["description"] = serde_json::to_value(&gb.description).unwrap_or(Value::Null);
        v["source_format"] = row.source_format.clone().into();
        v["nominal_input_hz"] = json!(nominal);
        v["kinematics"] = json!({
            "input_hz": nominal.unwrap_or(1.0),
            "per_input_hz": nominal.is_none(),
            "rates": serde_json::to_value(gb.kinematics(nominal.unwrap_or(1.0))).unwrap_or(Value::Null),
        });
        v["reference_frequency_hz"] = json!(gb.reference_frequency_hz());
        v["dynamics_estimated"] = json!(gb.dynamics_estimated());
        v["assumed"] = serde_json::to_value(&gb.assumed).unwrap_or(Value::Null);
        v["warnings"] = json!(gb.warnings);
        // What the table covers (the built-in rig's is the served file: the service fills it
        // in) and an extension pending on it.
        v["covers"] = crate::service::tables::covers_json(
            gb,
            row.table_columns.as_deref().unwrap_or_default(),
        );
        v["extension"] = crate::service::tables::extension_json(row, gb);
    }
    v
}

/// The payload a delivery sends: its queued event rendered, or (queued already rendered by
/// an earlier build) the stored text as it is.
pub fn delivery_payload(stored: &str) -> String {
    match QueuedEvent::parse(stored) {
        Some(q) => render(&q).to_string(),
        None => stored.to_string(),
    }
}

/// The documented payload of an event: `event` (its name), `event_id` and its members.
pub fn render(q: &QueuedEvent) -> Value {
    let mut p = match &q.event {
        Event::DiagnosisCreated { diagnosis } => diagnosis_members(diagnosis),
        Event::AlertOpened { alert, by } | Event::AlertClosed { alert, by } => {
            let mut m = alert_members(alert);
            m.insert("record_id".into(), by.record_id.clone().into());
            m.insert("diagnosis_id".into(), by.diagnosis_id.clone().into());
            m
        }
        Event::AlertAcknowledged { alert } => alert_members(alert),
        Event::WearThresholdCrossed {
            diagnosis,
            previous_alert_level,
            alert_id,
        } => {
            let mut m = diagnosis_members(diagnosis);
            m.insert("previous_alert_level".into(), json!(previous_alert_level));
            m.insert("alert_id".into(), alert_id.clone().into());
            m
        }
        Event::MachineDeleted {
            deletion: d,
            deleted_at,
        } => json!({
            "machine_id": d.machine_id,
            "deleted_at": rfc3339(*deleted_at),
            "records": d.records,
            "diagnoses": d.diagnoses,
            "calibration": d.calibration,
            "alert_level": d.alert_level,
        })
        .as_object()
        .cloned()
        .unwrap_or_default(),
    };
    p.insert("event".into(), q.event.name().into());
    p.insert("event_id".into(), q.event_id.clone().into());
    Value::Object(p)
}

fn alert_members(a: &AlertRow) -> Map<String, Value> {
    let mut m = Map::new();
    m.insert("machine_id".into(), a.machine_id.clone().into());
    m.insert("alert".into(), alert_json(a));
    m
}

/// A diagnosis's members and the service's extras (an extra never replaces a member).
fn diagnosis_members(d: &DiagnosisEvent) -> Map<String, Value> {
    let wear = d.wear.map_or(
        Value::Null,
        |w| json!({"estimate": w.estimate, "lower": w.lower, "upper": w.upper}),
    );
    let novelty = novelty(d.novelty.map(|n| n.score), d.novelty.map(|n| n.threshold));
    let mut m = json!({
        "machine_id": d.machine_id,
        "diagnosis_id": d.diagnosis_id,
        "record_id": d.record_id,
        "created_at": rfc3339(d.created_at),
        "measured_at": rfc3339(d.measured_at),
        "wear_degree": wear,
        "alert_level": d.alert_level,
        "motion_state": d.motion_state,
        "novelty": novelty,
        "channel": d.channel,
    })
    .as_object()
    .cloned()
    .unwrap_or_default();
    for (k, v) in &d.extras {
        m.entry(k.clone()).or_insert_with(|| v.clone());
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assessment::Level;
    use crate::store::events::{Interval, Novelty, RecordRef};

    fn diagnosis() -> DiagnosisEvent {
        let mut extras = Map::new();
        extras.insert("findings".into(), json!([{"kind": "gear"}]));
        extras.insert("machine_id".into(), "not this".into());
        DiagnosisEvent {
            machine_id: "m1".into(),
            diagnosis_id: "d1".into(),
            record_id: "r1".into(),
            created_at: 0,
            measured_at: 1_000,
            wear: Some(Interval {
                estimate: 0.2,
                lower: 0.1,
                upper: 0.3,
            }),
            alert_level: Level::Alarm,
            motion_state: "period-1".into(),
            novelty: Some(Novelty {
                score: 5.0,
                threshold: 3.0,
            }),
            channel: Some("a1".into()),
            extras,
        }
    }

    #[test]
    fn a_crossing_carries_the_diagnosis_its_extras_and_the_episode() {
        let q = QueuedEvent::new(
            "e-crossed".into(),
            Event::WearThresholdCrossed {
                diagnosis: diagnosis(),
                previous_alert_level: Level::Warning,
                alert_id: "a1".into(),
            },
        );
        let p = render(&q);
        assert_eq!(p["event"], "wear.threshold_crossed");
        assert_eq!(p["event_id"], "e-crossed");
        assert_eq!(p["machine_id"], "m1", "an extra never replaces a member");
        assert_eq!(p["findings"][0]["kind"], "gear");
        assert_eq!(p["novelty"]["anomalous"], true);
        assert_eq!(p["wear_degree"]["upper"], 0.3);
        assert_eq!(p["previous_alert_level"], "warning");
        assert_eq!(p["measured_at"], "1970-01-01T00:00:01.000Z");
    }

    #[test]
    fn an_opened_alert_names_its_record_and_an_old_payload_is_sent_as_stored() {
        let alert = AlertRow {
            id: "a1".into(),
            machine_id: "m1".into(),
            level: Level::Alarm,
            state: crate::assessment::episodes::AlertState::Open,
            opened_at: 0,
            record_id: "r1".into(),
            acknowledged_at: None,
            acknowledged_by: None,
            note: None,
            closed_at: None,
            closed_record_id: None,
            peak_severity: 2.0,
            created_at: 0,
        };
        let by = RecordRef {
            record_id: "r1".into(),
            diagnosis_id: "d1".into(),
        };
        let q = QueuedEvent::new("e1".into(), Event::AlertOpened { alert, by });
        let text = serde_json::to_string(&q).unwrap();
        let p: Value = serde_json::from_str(&delivery_payload(&text)).unwrap();
        assert_eq!(p["event"], "alert.opened");
        assert_eq!(p["alert"]["level"], "alarm");
        assert_eq!(p["diagnosis_id"], "d1");
        let old = r#"{"event":"alert.closed","event_id":"x"}"#;
        assert_eq!(delivery_payload(old), old);
    }
}
