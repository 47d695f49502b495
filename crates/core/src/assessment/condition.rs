//! The condition-monitoring part of an assessment ([`crate::condition`]): the record's
//! measured operating state (once per record), each channel's order-domain evidence, its
//! score against the machine's state-aware baseline and the findings.

use serde::Serialize;

use super::{Machine, RecordFacts};
use crate::condition::{
    EVIDENCE_VERSION, Finding, OperatingState, Parts, StateBaseline, StateRecord, StateScore,
    Tacho, evidence, findings, measure,
};
use crate::novelty::{FeatureZ, Novelty, OrderAnalysis, RecordFeatures};
use crate::record::Record;
use crate::signal::order::ShaftAngle;
use crate::signal::tsa::order_analysis_at;
use crate::{Error, Result};

/// A record's tachometer channel: its name among the record's channels and its pulses per
/// input-shaft revolution.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TachoChannel {
    pub name: String,
    pub pulses_per_rev: usize,
}

/// The record's measured state, shared by its channels.
#[derive(Debug, Clone, Default)]
pub struct Measured {
    pub angle: Option<ShaftAngle>,
    pub state: Option<OperatingState>,
    /// Why there is no state (a tacho-less track that failed, no hint).
    pub note: Option<String>,
    /// The described gearbox's parts (a described machine only), for every channel's evidence
    /// and findings.
    pub parts: Option<Parts>,
}

/// How a channel's record compares with the state's baseline.
#[derive(Debug, Clone, Serialize)]
pub struct StateJudgement {
    /// `same-state`, `interpolated` or `nearest`.
    pub reference: &'static str,
    /// Speeds (Hz) of the baseline records the reference comes from.
    pub reference_hz: Vec<f64>,
    pub score: f64,
    pub threshold: f64,
}

/// Measure the record's state: from its tachometer channel when the machine or the request
/// names one, else tacho-less on the first chosen channel around the speed hint (a described
/// gearbox only: the track follows a mesh line of known order).
///
/// Errors: a named tachometer channel that is absent or gives too few pulses (the sender's
/// data is wrong); a tacho-less track that fails is a note, not an error.
pub fn measure_record(
    channels: &[(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
) -> Result<Measured> {
    let mut m = measure_state(channels, chosen, facts, machine)?;
    m.parts = machine.described.then(|| Parts::of(machine.gearbox));
    Ok(m)
}

/// [`measure_record`] without the parts.
fn measure_state(
    channels: &[(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
) -> Result<Measured> {
    let fs = facts.sample_rate_hz;
    if let Some(t) = &facts.tacho {
        let Some((_, samples)) = channels.iter().find(|(n, _)| *n == t.name) else {
            return Err(Error::UnknownChannel {
                requested: t.name.clone(),
                available: channels.iter().map(|(n, _)| n.clone()).collect(),
            });
        };
        let tacho = Tacho {
            samples,
            pulses_per_rev: t.pulses_per_rev,
        };
        let angle = measure(
            samples,
            fs,
            machine.gearbox,
            Some(tacho),
            None,
            facts.load.clone(),
        )
        .map_err(|e| e.in_channel(t.name.clone()))?;
        let (angle, mut state) = angle;
        state.hint_hz = facts.shaft_hz.or(machine.input_shaft_hz);
        return Ok(Measured {
            angle: Some(angle),
            state: Some(state),
            ..Default::default()
        });
    }
    if !machine.described {
        return Ok(Measured::default());
    }
    let hint = facts
        .shaft_hz
        .or(machine.input_shaft_hz)
        .or(machine.gearbox.description.nominal_input_hz);
    let x = &channels[chosen[0]].1;
    Ok(
        match measure(x, fs, machine.gearbox, None, hint, facts.load.clone()) {
            Ok((angle, state)) => Measured {
                angle: Some(angle),
                state: Some(state),
                ..Default::default()
            },
            Err(e) => Measured {
                note: Some(format!("the shaft rate could not be measured: {e}")),
                ..Default::default()
            },
        },
    )
}

/// The channel's per-shaft TSA from the measured angle (a described gearbox only).
pub fn order_at(rec: &Record, machine: &Machine, m: &Measured) -> Option<OrderAnalysis> {
    let angle = m.angle.as_ref()?;
    if !machine.described {
        return None;
    }
    order_analysis_at(
        &rec.samples,
        rec.sample_rate,
        &machine.gearbox.shaft_train(),
        angle,
    )
    .ok()
}

/// Add the state and the evidence to a channel's features (with a measured angle and a
/// described gearbox).
pub fn add_evidence(
    features: &mut RecordFeatures,
    rec: &Record,
    m: &Measured,
    order: Option<&OrderAnalysis>,
) {
    features.state = m.state.clone();
    let (Some(angle), Some(parts)) = (&m.angle, &m.parts) else {
        return;
    };
    match evidence(&rec.samples, rec.sample_rate, angle, parts, order) {
        Ok(ev) => {
            features.evidence = ev.values;
            features.evidence_spread = ev.spread;
            features.lines = ev.lines;
            features.evidence_version = crate::condition::EVIDENCE_VERSION;
            if let (Some(note), Some(o)) = (ev.note, features.indicators.as_object_mut()) {
                o.insert("evidence_note".into(), note.into());
            }
        }
        Err(e) => {
            if let Some(o) = features.indicators.as_object_mut() {
                o.insert("evidence_error".into(), e.to_string().into());
            }
        }
    }
}

/// A channel judged against its state-aware baseline.
pub struct Judged {
    /// The score as a [`Novelty`]: what the alert policy reads.
    pub novelty: Novelty,
    pub judgement: StateJudgement,
    pub findings: Vec<Finding>,
}

/// A channel judged against its state-aware baseline (`None` without a measured state and
/// evidence); `Err` says which state the baseline lacks.
pub fn judge(
    baseline: &StateBaseline,
    features: &RecordFeatures,
    m: &Measured,
    response: Option<&crate::condition::candidates::Response>,
) -> Option<std::result::Result<Judged, String>> {
    let state = features.state.as_ref()?;
    let parts = m.parts.as_ref()?;
    if features.evidence.is_empty() {
        return None;
    }
    Some(baseline.score(state, &features.evidence).map(|s| Judged {
        findings: findings(&s, parts, response),
        novelty: novelty_of(&s, baseline),
        judgement: judgement_of(&s),
    }))
}

fn novelty_of(s: &StateScore, b: &StateBaseline) -> Novelty {
    Novelty {
        score: s.score,
        threshold: s.threshold,
        anomalous: s.anomalous,
        baseline_records: b.records(),
        top_features: s
            .departures
            .iter()
            .take(5)
            .map(|d| FeatureZ {
                name: d.feature.clone(),
                z: d.z,
            })
            .collect(),
        features_used: s.departures.len(),
    }
}

fn judgement_of(s: &StateScore) -> StateJudgement {
    StateJudgement {
        reference: s.reference,
        reference_hz: s.reference_hz.clone(),
        score: s.score,
        threshold: s.threshold,
    }
}

/// The state-aware baseline of one channel from its baseline records' features: `None`
/// when fewer than [`crate::condition::baseline::MIN_STATE_RECORDS`] carry a state and
/// evidence (the channel then keeps the pooled baseline only).
pub fn state_baseline(features: &[RecordFeatures]) -> Option<Result<StateBaseline>> {
    let recs: Vec<StateRecord> = features
        .iter()
        .filter(|f| !f.evidence.is_empty() && f.evidence_version == EVIDENCE_VERSION)
        .filter_map(|f| {
            Some(StateRecord {
                state: f.state.clone()?,
                values: f.evidence.clone(),
                spread: f.evidence_spread.clone(),
                lines: f.lines.clone(),
            })
        })
        .collect();
    (recs.len() >= crate::condition::baseline::MIN_STATE_RECORDS).then(|| StateBaseline::fit(recs))
}
