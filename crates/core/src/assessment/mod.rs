//! What one record means for its machine — its **assessment**: each chosen channel diagnosed
//! with the machine's gearbox table (when it is ready, with the machine's calibration when it
//! has one), its novelty features scored against the machine's baseline (when it has one), an
//! alert level from both ([`alert`]), and the channel that decides the record's level.
//!
//! One function, [`assess`], builds it for the service (`POST …/records`) and for
//! `gearwear diagnose`, so both give the same answer for the same record, baseline and
//! calibration. The [`Assessment`] serialises to the diagnosis object of the API (the deciding
//! channel's diagnosis fields, then `calibration`, `channel`, `channels`, `gearbox`, `novelty`,
//! `baseline`, `indicators`, `alert`).

pub mod alert;
pub mod diagnoser;

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::Value;

pub use alert::{Alert, Thresholds, alert, deciding, severity};
pub use diagnoser::{
    CalibrationUse, MachineCalibration, PathCorrection, TableDiagnoser, TableReading, WearInterval,
};

use crate::diagnosis::{Diagnosis, Fit, WearDegree};
use crate::gearbox::Gearbox;
use crate::novelty::{
    MIN_BASELINE_RECORDS, MachineBaseline, Novelty, RecordFeatures, record_features_with,
};
use crate::record::Record;

/// What the assessment knows of the machine a record comes from.
pub struct Machine<'a> {
    /// The machine's gearbox.
    pub gearbox: &'a Gearbox,
    /// The `gearbox` object of the answer.
    pub gearbox_ref: GearboxRef,
    /// The machine names its gearbox (not the built-in default): only then do the novelty
    /// features track its shafts.
    pub described: bool,
    /// The gearbox's table, ready to diagnose; `None` while the table is not ready.
    pub diagnoser: Option<&'a TableDiagnoser>,
    /// The note a diagnosis carries while the table is not ready.
    pub table_note: Option<String>,
    /// The machine's nominal input-shaft rate (Hz), a hint for the novelty features.
    pub input_shaft_hz: Option<f64>,
    /// The machine's baseline per channel (fitted ones only).
    pub baselines: &'a BTreeMap<String, MachineBaseline>,
    /// Baseline records per channel (fitted or not).
    pub baseline_counts: &'a BTreeMap<String, usize>,
    /// The machine's calibration.
    pub calibration: Option<&'a MachineCalibration>,
    pub thresholds: Thresholds,
}

/// What came with the record.
#[derive(Debug, Clone, Default)]
pub struct RecordFacts {
    pub sample_rate_hz: f64,
    /// The input-shaft rate (Hz) when the sender knows it.
    pub shaft_hz: Option<f64>,
    pub sensor: Option<String>,
    /// The record was sent as healthy (part of the machine's baseline).
    pub declared_healthy: bool,
}

/// The `gearbox` object of an assessment: which description and table it used.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GearboxRef {
    pub id: String,
    pub name: String,
    /// The description's hash.
    pub hash: String,
    /// `queued`, `running`, `ready` or `failed`.
    pub table_status: String,
    /// 0–1.
    pub table_progress: f64,
}

/// The `baseline` object of an assessment.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct BaselineUse {
    /// Baseline records of the deciding channel.
    pub records: usize,
    pub min_records: usize,
    /// This record was sent as healthy.
    pub this_record: bool,
}

/// The deciding channel's reading: the table's diagnosis, or what stands in for it while the
/// table is not ready.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum Reading {
    Table(Box<Diagnosis>),
    NoTable(NoTable),
}

/// The stand-in for a diagnosis without a table.
#[derive(Debug, Clone, Serialize)]
pub struct NoTable {
    /// Always `None` (`null`).
    pub wear_degree: Option<WearDegree>,
    /// `unknown`.
    pub motion_state: String,
    /// The record's sensor, `""` when none was given.
    pub sensor: String,
    pub warnings: Vec<String>,
}

/// One channel in a several-channel record's answer.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelSummary {
    pub name: String,
    pub alert_level: &'static str,
    pub alert: Alert,
    pub wear_degree: Option<WearDegree>,
    pub fit: Option<Fit>,
    pub novelty: Option<Novelty>,
}

/// One channel of a record, analysed.
#[derive(Debug, Clone)]
pub struct ChannelAssessment {
    pub name: String,
    /// The table's reading, when the gearbox's table is ready.
    pub reading: Option<TableReading>,
    pub features: RecordFeatures,
    pub novelty: Option<Novelty>,
    pub alert: Alert,
}

impl ChannelAssessment {
    /// The summary of this channel in a record's answer.
    pub fn summary(&self) -> ChannelSummary {
        ChannelSummary {
            name: self.name.clone(),
            alert_level: self.alert.level,
            alert: self.alert.clone(),
            wear_degree: self
                .reading
                .as_ref()
                .map(|r| r.diagnosis.wear_degree.clone()),
            fit: self.reading.as_ref().map(|r| r.diagnosis.fit.clone()),
            novelty: self.novelty.clone(),
        }
    }
}

/// A record's assessment: the API's diagnosis object (see the [module docs](self)).
#[derive(Debug, Clone, Serialize)]
pub struct Assessment {
    /// The deciding channel's diagnosis; its fields are the object's.
    #[serde(flatten)]
    pub reading: Reading,
    /// How the machine's calibration entered (a calibrated machine with a table only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationUse>,
    /// The deciding channel.
    pub channel: String,
    /// Every channel's summary, for a record of several channels diagnosed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub channels: Option<Vec<ChannelSummary>>,
    pub gearbox: GearboxRef,
    pub novelty: Option<Novelty>,
    pub baseline: BaselineUse,
    /// The deciding channel's condition indicators and order tracking, for people.
    pub indicators: Value,
    pub alert: Alert,
    /// Each chosen channel, analysed (in the order chosen).
    #[serde(skip)]
    pub assessed: Vec<ChannelAssessment>,
    /// Index in `assessed` of the channel that decides.
    #[serde(skip)]
    pub deciding: usize,
}

impl Assessment {
    /// The channel that decides.
    pub fn deciding_channel(&self) -> &ChannelAssessment {
        &self.assessed[self.deciding]
    }

    /// The wear the machine's trend and alert follow (see [`TableReading::wear`]); `None`
    /// without a table.
    pub fn wear(&self) -> Option<WearInterval> {
        self.deciding_channel().reading.as_ref().map(|r| r.wear)
    }

    /// The record's alert level.
    pub fn level(&self) -> &'static str {
        self.alert.level
    }
}

/// Assess a record: `channels` are all of the record's channels `(name, samples)` (each
/// chosen one's samples are read in place and left as they were), `chosen` the indices of
/// those to assess (at least one). `stage` is called with `"diagnosis"` after each channel's
/// diagnosis and `"features"` after its features (the service times the stages).
///
/// Errors are the library's (a record the diagnosis or the features refuse).
pub fn assess(
    channels: &mut [(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
    stage: &mut dyn FnMut(&'static str),
) -> crate::Result<Assessment> {
    let mut assessed = Vec::with_capacity(chosen.len());
    for &i in chosen {
        let name = channels[i].0.clone();
        // The channel's samples move into the record and back (no copy).
        let rec = Record {
            samples: std::mem::take(&mut channels[i].1),
            sample_rate: facts.sample_rate_hz,
        };
        let result = assess_channel(name, &rec, facts, machine, stage);
        channels[i].1 = rec.samples;
        assessed.push(result?);
    }
    Ok(assemble(assessed, facts, machine))
}

/// A record's novelty features exactly as its assessment computes them — what a machine's
/// baseline is fitted from (the service stores them with each record; `gearwear diagnose`
/// computes them for its `--baseline` files). With a described gearbox they track its shafts
/// from the diagnosis's f1, so the record is diagnosed first; otherwise they are
/// description-free and no diagnosis enters them.
pub fn baseline_features(
    rec: &Record,
    facts: &RecordFacts,
    machine: &Machine,
) -> crate::Result<RecordFeatures> {
    if !machine.described {
        return record_features_with(rec, None, None, None);
    }
    assess_channel(String::new(), rec, facts, machine, &mut |_| {}).map(|c| c.features)
}

/// One channel: its reading, features, novelty and alert.
fn assess_channel(
    name: String,
    rec: &Record,
    facts: &RecordFacts,
    machine: &Machine,
    stage: &mut dyn FnMut(&'static str),
) -> crate::Result<ChannelAssessment> {
    let gearbox = machine.gearbox;
    let reading = match machine.diagnoser {
        Some(d) => Some(d.read(rec, facts.shaft_hz, machine.calibration)?),
        None => None,
    };
    stage("diagnosis");
    let hint = facts.shaft_hz.or(machine.input_shaft_hz).or(reading
        .as_ref()
        .map(|o| o.diagnosis.f1_hz / gearbox.f1_per_input_hz));
    // Order features only for a gearbox the machine was given: the built-in rig a machine
    // defaults to would track 29 teeth in another gearbox's records (noise features that make
    // a baseline unstable); without one the features are description-free.
    let gb = machine.described.then_some(gearbox);
    // A described machine's diagnosis ran on its own gearbox's table and tracked the record
    // already: its order analysis is reused, not computed twice — when the f1 it tracked from
    // agrees (±1 %, its tracker's search) with the speed the features would start from (a
    // given or configured shaft rate may disagree with a tacho-less diagnosis; then the record
    // is tracked again from that rate).
    let order = reading
        .as_ref()
        .filter(|o| hint.is_none_or(|h| (o.diagnosis.f1_hz / gearbox.f1_hz(h) - 1.0).abs() < 0.01))
        .and_then(|o| o.order.as_ref());
    let features = record_features_with(rec, gb, hint, order)?;
    let novelty = machine.baselines.get(&name).map(|b| b.score(&features));
    let alert = alert(
        reading.as_ref().map(TableReading::alert_wear),
        novelty.as_ref(),
        &machine.thresholds,
        machine.table_note.as_deref(),
        facts.declared_healthy,
    );
    stage("features");
    Ok(ChannelAssessment {
        name,
        reading,
        features,
        novelty,
        alert,
    })
}

/// The record's answer from its channels: the deciding channel's reading, novelty and alert,
/// with every channel's summary when there are several.
fn assemble(
    assessed: Vec<ChannelAssessment>,
    facts: &RecordFacts,
    machine: &Machine,
) -> Assessment {
    let di = deciding(&assessed);
    let decide = &assessed[di];
    let (mut reading, calibration) = match &decide.reading {
        Some(r) => (
            Reading::Table(Box::new(r.diagnosis.clone())),
            r.calibration.clone(),
        ),
        None => (
            Reading::NoTable(NoTable {
                wear_degree: None,
                motion_state: "unknown".into(),
                sensor: facts.sensor.clone().unwrap_or_default(),
                warnings: Vec::new(),
            }),
            None,
        ),
    };
    if let Some(note) = &machine.table_note {
        match &mut reading {
            Reading::Table(d) => d.warnings.push(note.clone()),
            Reading::NoTable(n) => n.warnings.push(note.clone()),
        }
    }
    Assessment {
        reading,
        calibration,
        channel: decide.name.clone(),
        channels: (assessed.len() > 1)
            .then(|| assessed.iter().map(ChannelAssessment::summary).collect()),
        gearbox: machine.gearbox_ref.clone(),
        novelty: decide.novelty.clone(),
        baseline: BaselineUse {
            records: machine
                .baseline_counts
                .get(&decide.name)
                .copied()
                .unwrap_or(0),
            min_records: MIN_BASELINE_RECORDS,
            this_record: facts.declared_healthy,
        },
        indicators: decide.features.indicators.clone(),
        alert: decide.alert.clone(),
        deciding: di,
        assessed,
    }
}
