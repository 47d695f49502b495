//! A channel's reading of the tables: the description's table at the measured speed, then
//! the machine's own model or its calibrated path, the wear withheld (with its reason) where
//! the model does not fit, one part explains the change, or the speed lies outside the table.

use super::{Machine, Measured, OwnModel, RecordFacts, TableDiagnoser, TableReading, WearInterval};
use crate::condition::Finding;
use crate::diagnosis::machine_path::PathCalibration;
use crate::diagnosis::{DiagnoseOptions, Diagnosis, WithheldReason};
use crate::record::Record;

/// A channel whose record ran outside the gearbox's table: the input-shaft rate it ran at,
/// the reason its answer gives and the sentence.
#[derive(Debug, Clone, PartialEq)]
pub struct TableMiss {
    /// The record's input-shaft rate (Hz), which a table extension must cover.
    pub input_hz: f64,
    /// [`WithheldReason::TableInProgress`] when the machine's tables are extended
    /// ([`Machine::extends_tables`]), else [`WithheldReason::OutsideTable`].
    pub reason: WithheldReason,
    pub note: String,
}

/// The table's reading of channel `name` at the measured speed — against the machine's own
/// model when it has one for the channel, else through the channel's calibrated path — with
/// the wear withheld when the model does not fit. A speed outside the table is not an error
/// for a channel with a baseline (the baseline still judges it), for a record sent as healthy
/// (it becomes part of that baseline: a machine's healthy records span its speeds) nor for a
/// machine whose tables are extended to its records' speeds: `(None, Some(miss))`.
#[allow(clippy::too_many_arguments)]
pub(super) fn read_table(
    rec: &Record,
    facts: &RecordFacts,
    machine: &Machine,
    measured: &Measured,
    has_baseline: bool,
    track_orders: bool,
    name: &str,
) -> crate::Result<(Option<TableReading>, Option<TableMiss>)> {
    let Some(d) = machine.diagnoser else {
        return Ok((None, None));
    };
    let shaft_hz = measured
        .state
        .as_ref()
        .map(|s| s.shaft_hz)
        .or(facts.shaft_hz);
    let mut r = match d.read_with(rec, shaft_hz, machine.calibration, track_orders) {
        Ok(r) => r,
        Err(crate::Error::SpeedOutOfBand {
            f1_hz,
            min_hz,
            max_hz,
            ..
        }) if has_baseline || facts.declared_healthy || machine.extends_tables => {
            return Ok((
                None,
                Some(speed_outside_table(f1_hz, min_hz, max_hz, machine)),
            ));
        }
        Err(e) => return Err(e),
    };
    let own = machine
        .own_model
        .filter(|m| machine.calibration.is_none() && m.physics.channels.contains_key(name));
    if let Some(m) = own {
        against_own_model(&mut r, m, rec, name, d, shaft_hz);
    } else if let Some(p) = machine
        .paths
        .get(name)
        .filter(|_| machine.calibration.is_none())
    {
        through_path(&mut r, p, rec, d, shaft_hz);
    }
    if r.diagnosis.wear_degree.withheld.is_some() {
        return Ok((Some(r), None));
    }
    let fit = &r.diagnosis.fit;
    if fit.inflated {
        let why = format!(
            "no wear figure: the model does not fit this record (χ² per feature {:.1} over {} \
             features); a wear degree read off it would be the prior's, not the machine's",
            fit.chi2_per_feature, fit.features
        );
        r.diagnosis.withhold(WithheldReason::PoorFit, why);
    }
    Ok((Some(r), None))
}

/// Withhold the wear figure of a reading whose record changed mostly at one part
/// ([`crate::condition::findings::mostly_one_part`]: a gear's local damage or eccentricity,
/// a shaft, a bearing): the line ratios the table reads moved for that part, not for the
/// clearance every tooth shares. `true` when it withheld a figure the reading gave (the alert
/// then follows the baseline alone).
pub(super) fn withhold_for_part(r: &mut TableReading, findings: &[Finding]) -> bool {
    let Some(f) = crate::condition::findings::mostly_one_part(findings) else {
        return false;
    };
    if r.diagnosis.wear_degree.withheld.is_some() {
        return false;
    }
    let why = format!(
        "no wear figure: {:.0} % of this record's change is one part's ({}), not of the wear \
         kind (a stage's mesh lines moving together); a wear degree read off it would be that \
         part's change",
        100.0 * f.share,
        f.summary
    );
    r.diagnosis.withhold(WithheldReason::OnePart, why);
    true
}

/// Read the wear of `r` again through the channel's calibrated transfer path `p`: the
/// diagnosis's wear, fit and posterior become the path's (its order analysis and spectrum stay
/// the record's); outside the calibrated speeds, or when the re-read fails, the plain reading
/// stands with a warning saying why.
fn through_path(
    r: &mut TableReading,
    p: &PathCalibration,
    rec: &Record,
    d: &TableDiagnoser,
    shaft_hz: Option<f64>,
) {
    // The plain reading's order analysis stands: the re-read need not track the record again.
    let opts = DiagnoseOptions {
        track_orders: false,
        ..d.options(shaft_hz)
    };
    match p.reread(rec, d.table(), &opts, &r.diagnosis) {
        Ok(Some(c)) => adopt(r, c),
        Ok(None) => r.diagnosis.warnings.push(p.outside(r.diagnosis.f1_hz)),
        Err(e) => r.diagnosis.warnings.push(format!(
            "the machine's calibrated transfer path could not be applied ({e}): read against \
             the plain model"
        )),
    }
}

/// Why a record run at a speed the gearbox's signature table does not cover has no wear
/// figure, in input-shaft speeds (mesh frequencies `f1_hz`, `lo_hz`–`hi_hz` converted).
fn speed_outside_table(f1_hz: f64, lo_hz: f64, hi_hz: f64, machine: &Machine) -> TableMiss {
    let per = machine.gearbox.f1_per_input_hz;
    let (input_hz, lo, hi) = (f1_hz / per, lo_hz / per, hi_hz / per);
    if machine.extends_tables {
        return TableMiss {
            input_hz,
            reason: WithheldReason::TableInProgress,
            note: format!(
                "no wear figure yet: the input shaft ran at {input_hz:.2} Hz, outside the \
                 speeds the gearbox's signature table covers ({lo:.2}–{hi:.2} Hz); the table is \
                 being extended to this speed and the record will be read again when it is \
                 ready — meanwhile the machine's baseline judges it"
            ),
        };
    }
    TableMiss {
        input_hz,
        reason: WithheldReason::OutsideTable,
        note: format!(
            "no wear figure: the input shaft ran at {input_hz:.2} Hz, outside the speeds the \
             gearbox's signature table covers ({lo:.2}–{hi:.2} Hz); the machine's baseline \
             judges this record — a wear figure at this speed needs the table computed over the \
             machine's speeds"
        ),
    }
}

/// Read the wear of `r` again against the machine's own model `m` (its table, the channel's
/// path, the fit's uncertainty): the diagnosis's wear, fit and posterior become the model's
/// (its order analysis and spectrum stay the record's; withheld outside the model's speeds
/// or where it does not fit); when the re-read fails, the plain reading stands with a
/// warning.
fn against_own_model(
    r: &mut TableReading,
    m: &OwnModel,
    rec: &Record,
    name: &str,
    d: &TableDiagnoser,
    shaft_hz: Option<f64>,
) {
    let opts = d.options(shaft_hz);
    match m
        .physics
        .reread(rec, name, m.diagnoser.table(), &opts, &r.diagnosis)
    {
        Ok(Some(c)) => adopt(r, c),
        Ok(None) => {}
        Err(e) => r.diagnosis.warnings.push(format!(
            "the machine's own model could not read this record ({e}): read against the \
             description's table"
        )),
    }
}

/// Make the re-read `c` the reading's diagnosis: its wear, fit and posterior; the plain
/// reading's order analysis (the re-read need not track the record again); the record's own
/// warnings first (the same reading of the same record gives most of them again), then what
/// the re-read adds.
fn adopt(r: &mut TableReading, mut c: Diagnosis) {
    c.order = r.diagnosis.order.take();
    c.order_error = r.diagnosis.order_error.take();
    let mut warnings = std::mem::take(&mut r.diagnosis.warnings);
    for w in c.warnings.drain(..) {
        if !warnings.contains(&w) {
            warnings.push(w);
        }
    }
    c.warnings = warnings;
    r.wear = WearInterval {
        estimate: c.wear_degree.estimate,
        lower: c.wear_degree.lower,
        upper: c.wear_degree.upper,
    };
    r.diagnosis = c;
}
