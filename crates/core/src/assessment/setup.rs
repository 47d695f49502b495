//! The set-up step of an assessment: the declared input-shaft rate (the record's `shaft_hz`,
//! else the machine's configured one) against what the record measures and where the
//! gearbox's lines sit ([`crate::condition::setup`]), reported as the answer's `setup` object.
//! A disagreement is also a `warned` quality finding (`sample-rate`, `pulses-per-revolution` or
//! `shaft-rate`) that caps the alert at `unknown`: a record whose rate is in doubt is not
//! judged against the baseline, and gets no advice to add a healthy record at its speed.

use serde::Serialize;

use super::quality::Quality;
use super::{Machine, Measured, RecordFacts};
use crate::condition::lines::LineMap;
use crate::condition::setup::{Cause, SetupCheck, check_tacho_less, check_tachometer};
use crate::condition::{Parts, SpeedSource};
use crate::record::quality::QualityFinding;

/// The `setup` object of an assessment.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Setup {
    /// `agrees`, `disagrees`, or `unchecked` (no declared rate, or a gearbox without a
    /// description to read the lines by).
    pub status: &'static str,
    /// The declared input-shaft rate, Hz, and where it came from (`record` or `machine`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub declared_shaft_hz: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub declared_from: Option<&'static str>,
    /// The measured input-shaft rate, Hz, and how it was measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured_shaft_hz: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<SpeedSource>,
    /// The check's reading (the lines' rate, the ratio, the likely cause).
    #[serde(skip_serializing_if = "Option::is_none", flatten)]
    pub check: Option<SetupCheck>,
    /// The sentence a person reads, when the set-up disagrees.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
}

/// Check the record's set-up (see the [module docs](self)) on the first chosen channel.
pub fn check(
    channels: &[(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
    measured: &Measured,
) -> Setup {
    let (declared, from) = match (facts.shaft_hz, machine.input_shaft_hz) {
        (Some(h), _) => (Some(h), Some("record")),
        (None, Some(h)) => (Some(h), Some("machine")),
        _ => (None, None),
    };
    let mut setup = Setup {
        status: "unchecked",
        declared_shaft_hz: declared,
        declared_from: from,
        measured_shaft_hz: measured.state.as_ref().map(|s| s.shaft_hz),
        source: measured.state.as_ref().map(|s| s.source),
        check: None,
        message: None,
    };
    let Some(declared) = declared.filter(|h| h.is_finite() && *h > 0.0) else {
        return setup;
    };
    if !machine.described || chosen.is_empty() {
        return setup;
    }
    let map = LineMap::of(&Parts::of(machine.gearbox));
    let x = &channels[chosen[0]].1;
    let fs = facts.sample_rate_hz;
    let check = match (&measured.state, &facts.tacho) {
        (Some(s), Some(t)) if s.source == SpeedSource::Tachometer => Some(check_tachometer(
            x,
            fs,
            &map,
            declared,
            s.shaft_hz,
            t.pulses_per_rev,
        )),
        _ => check_tacho_less(x, fs, &map, declared),
    };
    let Some(check) = check else {
        return setup;
    };
    setup.status = if check.cause.is_some() {
        "disagrees"
    } else {
        "agrees"
    };
    setup.message = check.message();
    setup.check = Some(check);
    setup
}

/// A disagreeing set-up as a `warned` quality finding in `q` (the alert capped); returned, to
/// become the refusal when the diagnosis then fails ([`super::quality::rate_refusal`]).
pub fn add_to_quality(
    setup: &Setup,
    channels: &[(String, Vec<f64>)],
    chosen: &[usize],
    fs: f64,
    q: &mut Quality,
) -> Option<QualityFinding> {
    let cause = setup.check.as_ref()?.cause.as_ref()?;
    let message = setup.message.clone()?;
    let (name, x) = &channels[*chosen.first()?];
    let f = QualityFinding {
        defect: match cause {
            Cause::SampleRate { .. } => "sample-rate",
            Cause::PulsesPerRevolution { .. } => "pulses-per-revolution",
            Cause::Speed => "shaft-rate",
        },
        channel: (channels.len() > 1).then(|| name.clone()),
        first_sample: 0,
        last_sample: x.len().saturating_sub(1),
        start_s: 0.0,
        end_s: x.len() as f64 / fs,
        action: "warned",
        message: message.clone(),
    };
    if q.status == "clean" {
        q.status = "warned";
    }
    q.alert_capped = true;
    q.setup_doubt = true;
    q.cap_reason = Some(message);
    q.findings.push(f.clone());
    Some(f)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The check's reading is flattened into the object: every key once.
    #[test]
    fn the_setup_object_has_each_key_once() {
        let setup = Setup {
            status: "disagrees",
            declared_shaft_hz: Some(45.0),
            declared_from: Some("record"),
            measured_shaft_hz: Some(33.68),
            source: Some(SpeedSource::Tachometer),
            check: Some(SetupCheck {
                declared_shaft_hz: 45.0,
                lines_shaft_hz: Some(33.68),
                ratio: 0.748,
                cause: Some(Cause::SampleRate {
                    declared_hz: 50_000.0,
                    likely_hz: 66_807.0,
                }),
            }),
            message: Some("m".into()),
        };
        let text = serde_json::to_string(&setup).unwrap();
        for key in [
            "status",
            "declared_shaft_hz",
            "declared_from",
            "measured_shaft_hz",
            "source",
            "lines_shaft_hz",
            "ratio",
            "cause",
            "declared_hz",
            "likely_hz",
            "message",
        ] {
            assert_eq!(
                text.matches(&format!("\"{key}\":")).count(),
                1,
                "{key}: {text}"
            );
        }
        assert!(text.contains("\"cause\":\"sample-rate\""), "{text}");
    }
}
