//! What one record means for its machine — its **assessment**: each chosen channel diagnosed
//! with the machine's gearbox table (when it is ready, with the machine's calibration when it
//! has one), its novelty features scored against the machine's baseline (when it has one), an
//! alert level from both ([`alert`]), and the channel that decides the record's level.
//!
//! One function, [`assess`], builds it for the service (`POST …/records`) and for
//! `gearwear diagnose`, so both give the same answer for the same record, baseline and
//! calibration. The [`Assessment`] serialises to the diagnosis object of the API (the deciding
//! channel's diagnosis fields, then `wear_degree_um`, `calibration`, `channel`, `channels`,
//! `gearbox`, `operating_state`, `state_note`, `findings`, `novelty`, `state_reference`,
//! `baseline`, `vibration`, `indicators`, `alert`).
//!
//! A channel whose unit the machine declares ([`Machine::units`]) gets its `vibration` in
//! physical units ([`crate::units::vibration`]: acceleration RMS and peak, velocity RMS over
//! 10–1000 Hz, the ISO 20816-3 zone when the machine declares its class); a channel without
//! one has no `vibration` member at all. `wear_degree_um` is the wear degree in µm (times the
//! table's gearbox's reference length), present whenever `wear_degree` is.
//!
//! With a described gearbox the record's operating state is measured once ([`condition`]:
//! tachometer, else tacho-less) and every channel's order-domain evidence computed from it; a
//! channel whose baseline records carry states is judged against them at the record's state
//! ([`crate::condition`]), with findings, instead of against the pooled baseline.

pub mod alert;
pub mod baselines;
pub mod condition;
pub mod diagnoser;
pub mod episodes;
pub mod level;
pub mod own_model;
pub mod quality;
mod reading;
pub mod setup;
pub mod stored;

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::Value;

pub use alert::{Alert, Thresholds, alert, deciding};
pub use baselines::Baselines;
pub use condition::{Measured, StateJudgement, TachoChannel, state_baseline};
pub use diagnoser::{
    CalibrationUse, MachineCalibration, PathCorrection, TableDiagnoser, TableReading, WearInterval,
};
pub use level::{Basis, Level};
pub use own_model::OwnModel;
pub use quality::Quality;
pub use reading::TableMiss;
use reading::{read_table, withhold_for_part};
pub use stored::{STORED_FEATURES_VERSION, StoredChannel, StoredFeatures};

use crate::condition::{EvidencePlot, Finding, Load, OperatingState, StateBaseline, evidence_plot};
use crate::diagnosis::machine_path::PathCalibration;
use crate::diagnosis::{Diagnosis, Fit, WearDegree, WithheldReason};
use crate::gearbox::Gearbox;
use crate::novelty::{
    MIN_BASELINE_RECORDS, MachineBaseline, Novelty, OrderAnalysis, RecordFeatures,
    record_features_with,
};
use crate::record::Record;
use crate::units::{MachineUnits, Vibration, WearUm, vibration};

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
    /// The machine's state-aware baseline per channel (from baseline records with a measured
    /// state and evidence); a channel that has one is judged against it, not `baselines`.
    pub state_baselines: &'a BTreeMap<String, StateBaseline>,
    /// Baseline records per channel (fitted or not).
    pub baseline_counts: &'a BTreeMap<String, usize>,
    /// The machine's calibration.
    pub calibration: Option<&'a MachineCalibration>,
    /// Each channel's transfer path calibrated on its healthy records' line ratios
    /// ([`crate::diagnosis::machine_path`]): the channel's wear is read through it.
    pub paths: &'a BTreeMap<String, PathCalibration>,
    /// The machine's own model (its physics fitted to its healthy records, its own table):
    /// a channel it was fitted on reads its wear against it, not through `paths`.
    pub own_model: Option<&'a OwnModel>,
    /// A record outside the gearbox's table is answered `table-in-progress`: the caller extends
    /// the table to the record's speed and reads the record again when it is ready (the
    /// service). `false`: `outside-table`.
    pub extends_tables: bool,
    pub thresholds: Thresholds,
    /// What its channels' numbers are (and its ISO 20816-3 class); empty: unitless.
    pub units: MachineUnits,
}

/// Whether a record of `gearbox` is read as a described machine's (its shafts tracked, its
/// operating state measured and its parts' evidence taken; [`Machine::described`]): always,
/// except for the first paper's rig without a tachometer. Its records carry no line of the
/// input shaft of their own, so the tacho-less tracking and the set-up check, which follow
/// those lines, misread them; with a tachometer the angle is counted. The rule is the same for
/// the rig whether it is the default or named (`--gearbox configs/gearboxes/wang2019.toml`, a
/// machine of gearbox `wang2019`), so both read a record alike.
pub fn reads_as_described(gearbox: &Gearbox, tachometer: bool) -> bool {
    tachometer || gearbox.hash != Gearbox::paper_rig().hash
}

impl<'a> Machine<'a> {
    /// A machine with a described gearbox whose table is ready (`diagnoser`), judged against
    /// `baselines` (pooled, state-aware and paths), with the default thresholds, no closed-loop
    /// calibration and unitless channels: what a study of a gearbox's records sets up.
    pub fn described(
        id: &str,
        gearbox: &'a Gearbox,
        diagnoser: Option<&'a TableDiagnoser>,
        baselines: &'a Baselines,
    ) -> Machine<'a> {
        Machine {
            gearbox,
            gearbox_ref: GearboxRef {
                id: id.into(),
                name: gearbox.name().into(),
                hash: gearbox.hash.clone(),
                table_status: crate::signature::TableStatus::Ready,
                table_progress: 1.0,
            },
            described: true,
            diagnoser,
            table_note: None,
            input_shaft_hz: None,
            baselines: &baselines.pooled,
            state_baselines: &baselines.states,
            baseline_counts: &baselines.counts,
            calibration: None,
            paths: &baselines.paths,
            own_model: None,
            extends_tables: false,
            thresholds: Thresholds::default(),
            units: Default::default(),
        }
    }
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
    /// The load the record was taken at, when the sender says.
    pub load: Option<Load>,
    /// The record's tachometer channel, when it has one.
    pub tacho: Option<TachoChannel>,
}

/// The `gearbox` object of an assessment: which description and table it used.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GearboxRef {
    pub id: String,
    pub name: String,
    /// The description's hash.
    pub hash: String,
    pub table_status: crate::signature::TableStatus,
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
    /// Why there is no wear figure, in words, when the record ran outside the table.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_note: Option<String>,
    /// Why there is no wear figure, as a code (`table-in-progress`, `outside-table`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_withheld: Option<WithheldReason>,
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
    pub alert_level: Level,
    pub alert: Alert,
    pub wear_degree: Option<WearDegree>,
    /// `wear_degree` in µm, when it is shown.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_degree_um: Option<WearUm>,
    pub fit: Option<Fit>,
    /// Why this channel has no wear figure, as a code, when it has none for a known reason.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_withheld: Option<WithheldReason>,
    pub novelty: Option<Novelty>,
    pub findings: Vec<Finding>,
    /// In physical units, when the channel's unit is declared.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vibration: Option<Vibration>,
}

/// One channel of a record, analysed.
#[derive(Debug, Clone)]
pub struct ChannelAssessment {
    pub name: String,
    /// The table's reading, when the gearbox's table is ready.
    pub reading: Option<TableReading>,
    /// The record ran outside the gearbox's table (no reading).
    pub table_miss: Option<TableMiss>,
    pub features: RecordFeatures,
    pub novelty: Option<Novelty>,
    /// The comparison with the state-aware baseline, when the channel has one.
    pub state: Option<StateJudgement>,
    pub findings: Vec<Finding>,
    pub alert: Alert,
    /// The wear degree in µm, when the reading shows one.
    pub wear_um: Option<WearUm>,
    /// In physical units, when the channel's unit is declared.
    pub vibration: Option<Vibration>,
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
            wear_degree_um: self.wear_um,
            fit: self.reading.as_ref().map(|r| r.diagnosis.fit.clone()),
            wear_withheld: match &self.reading {
                Some(r) => r.diagnosis.wear_withheld,
                None => self.table_miss.as_ref().map(|m| m.reason),
            },
            novelty: self.novelty.clone(),
            findings: self.findings.clone(),
            vibration: self.vibration.clone(),
        }
    }
}

/// A record's assessment: the API's diagnosis object (see the [module docs](self)).
#[derive(Debug, Clone, Serialize)]
pub struct Assessment {
    /// The deciding channel's diagnosis; its fields are the object's.
    #[serde(flatten)]
    pub reading: Reading,
    /// The deciding channel's wear degree in µm, when it is shown.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_degree_um: Option<WearUm>,
    /// How the machine's calibration entered (a calibrated machine with a table only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationUse>,
    /// The deciding channel.
    pub channel: String,
    /// Every channel's summary, for a record of several channels diagnosed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub channels: Option<Vec<ChannelSummary>>,
    pub gearbox: GearboxRef,
    /// The record's measured operating state (`null` when the speed was not measured:
    /// `state_note` says why).
    pub operating_state: Option<OperatingState>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub state_note: Option<String>,
    /// What the deciding channel's departure from its state's baseline points at, strongest
    /// first (empty when it does not depart, or without a state-aware baseline).
    pub findings: Vec<Finding>,
    pub novelty: Option<Novelty>,
    /// How the deciding channel compares with the state-aware baseline.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub state_reference: Option<StateJudgement>,
    pub baseline: BaselineUse,
    /// The deciding channel's vibration in physical units, when its unit is declared.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vibration: Option<Vibration>,
    /// The deciding channel's condition indicators and order tracking, for people.
    pub indicators: Value,
    pub alert: Alert,
    /// What the record-quality checks found and repaired ([`quality`]).
    pub quality: Quality,
    /// The declared input-shaft rate against the measured one and the lines ([`setup`]).
    pub setup: setup::Setup,
    /// Each chosen channel, analysed (in the order chosen).
    #[serde(skip)]
    pub assessed: Vec<ChannelAssessment>,
    /// Index in `assessed` of the channel that decides.
    #[serde(skip)]
    pub deciding: usize,
    /// The deciding channel's order and envelope spectra with the lines its evidence reads
    /// (a described gearbox with a measured speed only): what the record page draws.
    #[serde(skip)]
    pub evidence_plot: Option<EvidencePlot>,
}

impl Assessment {
    /// The channel that decides.
    pub fn deciding_channel(&self) -> &ChannelAssessment {
        &self.assessed[self.deciding]
    }

    /// The wear the machine's trend and alert follow (see [`TableReading::wear`]); `None`
    /// without a table or when the model does not fit the record (no wear figure).
    pub fn wear(&self) -> Option<WearInterval> {
        self.deciding_channel()
            .reading
            .as_ref()
            .filter(|r| r.diagnosis.wear_degree.withheld.is_none())
            .map(|r| r.wear)
    }

    /// The record's alert level.
    pub fn level(&self) -> Level {
        self.alert.level
    }

    /// Add a warning to the answer's `warnings`.
    pub fn warn(&mut self, note: impl Into<String>) {
        match &mut self.reading {
            Reading::Table(d) => d.warnings.push(note.into()),
            Reading::NoTable(n) => n.warnings.push(note.into()),
        }
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
    assess_drawing(channels, chosen, facts, machine, stage, true)
}

/// [`assess`] without the evidence plot (`evidence_plot` is `None`): for a caller that keeps
/// the record's samples and draws the plot from them when someone asks for it.
pub fn assess_undrawn(
    channels: &mut [(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
    stage: &mut dyn FnMut(&'static str),
) -> crate::Result<Assessment> {
    assess_drawing(channels, chosen, facts, machine, stage, false)
}

/// [`assess`], with the evidence plot drawn only when `draw` (a baseline's features need
/// none).
fn assess_drawing(
    channels: &mut [(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
    stage: &mut dyn FnMut(&'static str),
    draw: bool,
) -> crate::Result<Assessment> {
    let mut quality = quality::inspect_channels(channels, chosen, facts.sample_rate_hz, machine)?;
    let measured = condition::measure_record(channels, chosen, facts, machine)?;
    let setup = setup::check(channels, chosen, facts, machine, &measured);
    let doubt = setup::add_to_quality(&setup, channels, chosen, facts.sample_rate_hz, &mut quality);
    let inspected = Inspected {
        quality,
        measured,
        setup,
    };
    let a = assess_inspected(channels, chosen, facts, machine, inspected, stage, draw);
    a.map_err(|e| match doubt {
        Some(f) if quality::rate_explains(&e) => quality::rate_refusal(f, &e),
        _ => e,
    })
}

/// What the steps before the channels' assessment found: the record's quality, its measured
/// state and its set-up.
struct Inspected {
    quality: Quality,
    measured: Measured,
    setup: setup::Setup,
}

/// [`assess`] after the quality step.
fn assess_inspected(
    channels: &mut [(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
    inspected: Inspected,
    stage: &mut dyn FnMut(&'static str),
    draw: bool,
) -> crate::Result<Assessment> {
    let Inspected {
        quality,
        measured,
        setup,
    } = inspected;
    let mut assessed = Vec::with_capacity(chosen.len());
    for &i in chosen {
        let name = channels[i].0.clone();
        // The channel's samples move into the record and back (no copy).
        let rec = Record {
            samples: std::mem::take(&mut channels[i].1),
            sample_rate: facts.sample_rate_hz,
        };
        let result = assess_channel(name, &rec, facts, machine, &measured, stage);
        channels[i].1 = rec.samples;
        let mut a = result?;
        if let Some(why) = quality
            .cap_reason
            .as_deref()
            .filter(|_| !facts.declared_healthy)
        {
            a.alert = quality::capped(&a.alert, why, quality.setup_doubt);
        }
        assessed.push(a);
    }
    let mut a = assemble(assessed, facts, machine, &measured, quality, setup);
    a.evidence_plot = match (&measured.angle, &measured.parts) {
        (Some(angle), Some(parts)) if draw => {
            let (name, x) = &channels[chosen[a.deciding]];
            evidence_plot(name, x, facts.sample_rate_hz, angle, parts).ok()
        }
        _ => None,
    };
    Ok(a)
}

/// The features of a record's chosen channels exactly as its assessment computes them — what
/// a machine's baseline is fitted from (the service stores them with each record;
/// `gearwear diagnose` computes them for its baseline files).
pub fn baseline_features(
    channels: &mut [(String, Vec<f64>)],
    chosen: &[usize],
    facts: &RecordFacts,
    machine: &Machine,
) -> crate::Result<Vec<RecordFeatures>> {
    let a = assess_drawing(channels, chosen, facts, machine, &mut |_| {}, false)?;
    Ok(a.assessed.into_iter().map(|c| c.features).collect())
}

/// One channel: its reading, features, novelty (against the state-aware baseline when the
/// channel has one), findings and alert.
fn assess_channel(
    name: String,
    rec: &Record,
    facts: &RecordFacts,
    machine: &Machine,
    measured: &Measured,
    stage: &mut dyn FnMut(&'static str),
) -> crate::Result<ChannelAssessment> {
    let has_baseline =
        machine.baselines.contains_key(&name) || machine.state_baselines.contains_key(&name);
    // With the shaft's measured angle, every shaft's TSA comes from it, and the table's
    // reading carries that instead of tracking the record a second time.
    let at_angle = condition::order_at(rec, machine, measured);
    let (mut reading, table_miss) = read_table(
        rec,
        facts,
        machine,
        measured,
        has_baseline,
        at_angle.is_none(),
        &name,
    )?;
    if let (Some(r), Some(a)) = (reading.as_mut(), &at_angle) {
        r.diagnosis.order = Some(a.clone());
        r.diagnosis.order_error = None;
        r.order = Some(a.clone());
    }
    stage("diagnosis");
    let mut features = channel_features(rec, facts, machine, measured, reading.as_ref(), at_angle)?;
    features.ratios = reading.as_ref().and_then(|r| r.ratios.clone());
    let judged = machine.state_baselines.get(&name).and_then(|b| {
        let response = machine.own_model.and_then(|m| m.response.as_ref());
        condition::judge(b, &features, measured, response)
    });
    let (novelty, state, findings, uncovered) = match judged {
        Some(Ok(j)) => (Some(j.novelty), Some(j.judgement), j.findings, None),
        Some(Err(missing)) => (None, None, Vec::new(), Some(missing)),
        None => (
            machine.baselines.get(&name).map(|b| b.score(&features)),
            None,
            Vec::new(),
            None,
        ),
    };
    let part_change = reading
        .as_mut()
        .is_some_and(|r| withhold_for_part(r, &findings));
    let note = table_miss
        .as_ref()
        .map(|m| m.note.as_str())
        .or(machine.table_note.as_deref());
    let mut alert = alert(
        reading
            .as_ref()
            .filter(|_| !part_change)
            .map(TableReading::alert_wear),
        novelty.as_ref(),
        &machine.thresholds,
        note,
        facts.declared_healthy,
    );
    if let Some(missing) = uncovered.filter(|_| !facts.declared_healthy) {
        alert = Alert {
            level: Level::Unknown,
            basis: Basis::Baseline,
            reason: format!("this record's operating state is not covered: {missing}"),
        };
    }
    let vibration = machine
        .units
        .channels
        .of(&name)
        .map(|(spec, unit)| vibration(&rec.samples, rec.sample_rate, spec, unit, machine.units.iso))
        .transpose()?;
    let wear_um = reading.as_ref().and_then(|r| {
        // The wear degree is in units of the reference length of the gearbox its table was
        // computed for.
        let gearbox = machine
            .diagnoser
            .map_or(machine.gearbox, |d| d.table().gearbox());
        WearUm::of(&r.diagnosis.wear_degree, gearbox)
    });
    stage("features");
    Ok(ChannelAssessment {
        name,
        reading,
        table_miss,
        features,
        novelty,
        state,
        findings,
        alert,
        wear_um,
        vibration,
    })
}

/// The channel's features: description-free ones, the per-shaft TSA (from the measured angle
/// when there is one, else reused from the reading or tracked from the speed hint) and, with
/// a measured state, the order-domain evidence.
fn channel_features(
    rec: &Record,
    facts: &RecordFacts,
    machine: &Machine,
    measured: &Measured,
    reading: Option<&TableReading>,
    at_angle: Option<OrderAnalysis>,
) -> crate::Result<RecordFeatures> {
    let gearbox = machine.gearbox;
    let hint = measured
        .state
        .as_ref()
        .map(|s| s.shaft_hz)
        .or(facts.shaft_hz)
        .or(machine.input_shaft_hz)
        .or(reading.map(|o| o.diagnosis.f1_hz / gearbox.f1_per_input_hz));
    // Order features only for a gearbox the machine was given: the built-in rig a machine
    // defaults to would track 29 teeth in another gearbox's records (noise features that make
    // a baseline unstable); without one the features are description-free.
    let gb = machine.described.then_some(gearbox);
    // Without a measured angle, a described machine's diagnosis ran on its own gearbox's
    // table and tracked the record already: its order analysis is reused — when the f1 it
    // tracked from agrees (±1 %, its tracker's search) with the speed the features would
    // start from.
    let order = at_angle.as_ref().or_else(|| {
        reading
            .filter(|o| {
                hint.is_none_or(|h| (o.diagnosis.f1_hz / gearbox.f1_hz(h) - 1.0).abs() < 0.01)
            })
            .and_then(|o| o.order.as_ref())
    });
    let mut features = record_features_with(rec, gb, hint, order)?;
    condition::add_evidence(&mut features, rec, measured, order);
    Ok(features)
}

/// The record's answer from its channels: the deciding channel's reading, novelty and alert,
/// with every channel's summary when there are several.
fn assemble(
    assessed: Vec<ChannelAssessment>,
    facts: &RecordFacts,
    machine: &Machine,
    measured: &Measured,
    quality: Quality,
    setup: setup::Setup,
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
                wear_note: decide.table_miss.as_ref().map(|m| m.note.clone()),
                wear_withheld: decide.table_miss.as_ref().map(|m| m.reason).or_else(|| {
                    machine
                        .table_note
                        .as_ref()
                        .map(|_| match machine.gearbox_ref.table_status {
                            crate::signature::TableStatus::Queued
                            | crate::signature::TableStatus::Running => {
                                WithheldReason::TableInProgress
                            }
                            _ => WithheldReason::OutsideTable,
                        })
                }),
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
        wear_degree_um: decide.wear_um,
        calibration,
        channel: decide.name.clone(),
        channels: (assessed.len() > 1)
            .then(|| assessed.iter().map(ChannelAssessment::summary).collect()),
        gearbox: machine.gearbox_ref.clone(),
        operating_state: measured.state.clone(),
        state_note: measured.note.clone(),
        findings: decide.findings.clone(),
        novelty: decide.novelty.clone(),
        state_reference: decide.state.clone(),
        baseline: BaselineUse {
            records: machine
                .baseline_counts
                .get(&decide.name)
                .copied()
                .unwrap_or(0),
            min_records: MIN_BASELINE_RECORDS,
            this_record: facts.declared_healthy,
        },
        vibration: decide.vibration.clone(),
        indicators: decide.features.indicators.clone(),
        alert: decide.alert.clone(),
        quality,
        setup,
        deciding: di,
        assessed,
        evidence_plot: None,
    }
}
