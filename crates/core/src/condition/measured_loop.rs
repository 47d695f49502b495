//! The closed loop on a **measured** record: its residual against the machine's healthy
//! reference (the calibrated model's at a state no healthy record covers, see
//! [`super::machine_model`]) → the effect library of the explainer ([`super::explain`]: each
//! gear's local damage and eccentricity, each shaft, each bearing, the non-synchronous
//! background, a stage's mesh lines, a band of the transfer path) → the error before and after
//! each accepted effect, and what is left unexplained.
//!
//! The error is over the features some effect can explain (line-class energies, shaft lines,
//! envelope lines): before, the RMS of the record's departure from the reference in dB,
//! `E₀ = sqrt(mean_f (20 log10 e · Δ_f)²)`; after each accepted effect, the RMS of what is left
//! in units of each feature's healthy scale (`sqrt(χ²/n)`), and after all of them again in dB.
//! An effect is accepted by the explainer's own rule (a drop of χ² of at least
//! [`super::explain::MIN_GAIN`] and [`super::explain::MIN_SHARE`] of the change) whether the
//! record is anomalous or not: on a healthy record the loop should accept nothing.

use serde::Serialize;

use super::baseline::StateScore;
use super::explain::Cause;
use super::findings::{Finding, FindingKind, explained};
use super::parts::Parts;

/// dB per ln unit of amplitude.
const DB_PER_LN: f64 = 20.0 / std::f64::consts::LN_10;

/// One accepted effect and the error after it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoopStep {
    /// As a finding's `kind`.
    pub kind: FindingKind,
    pub shaft: Option<String>,
    pub bearing: Option<String>,
    /// Share (0–1) of the change it explains.
    pub share: f64,
    /// RMS of what is left after it, in healthy scales.
    pub rms_z_after: f64,
}

/// The loop on one record (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeasuredLoop {
    /// How the reference was made (`same-state`, `interpolated`, `nearest`, `model`).
    pub reference: &'static str,
    /// Features the error is over.
    pub features: usize,
    pub error_before_db: f64,
    pub error_after_db: f64,
    pub rms_z_before: f64,
    /// Accepted effects in the order they were accepted (changes every part shares first).
    pub steps: Vec<LoopStep>,
    /// Share of the change no accepted effect explains.
    pub unexplained_share: f64,
    /// The findings as the record's answer words them.
    pub findings: Vec<Finding>,
}

impl MeasuredLoop {
    /// The first accepted effect that names a part (a gear, a shaft or a bearing).
    pub fn first_part(&self) -> Option<&LoopStep> {
        self.steps.iter().find(|s| s.kind.names_part())
    }
}

/// What a cause is called, and the shaft and bearing it names.
fn named(cause: &Cause, parts: &Parts) -> (FindingKind, Option<String>, Option<String>) {
    match cause {
        Cause::GearLocal { gear } => (
            FindingKind::GearLocalDamage,
            Some(parts.gears[*gear].shaft.clone()),
            None,
        ),
        Cause::GearEccentric { gear } => (
            FindingKind::GearEccentricity,
            Some(parts.gears[*gear].shaft.clone()),
            None,
        ),
        Cause::Shaft { shaft } => (FindingKind::Shaft, Some(shaft.clone()), None),
        Cause::Bearing { bearing, .. } => {
            let shaft = parts
                .bearings
                .iter()
                .find(|b| b.name == *bearing)
                .map(|b| b.shaft.clone());
            (FindingKind::Bearing, shaft, Some(bearing.clone()))
        }
        Cause::NonSynchronous => (FindingKind::NonSynchronous, None, None),
        Cause::MeshLines { .. } => (FindingKind::MeshLines, None, None),
        Cause::Path { .. } => (FindingKind::TransferPath, None, None),
    }
}

/// Close the loop on a record judged against its reference (see the [module docs](self)).
pub fn close_loop(score: &StateScore, parts: &Parts) -> MeasuredLoop {
    let (ex, findings) = explained(score, parts, None);
    let n = ex.residual.len().max(1) as f64;
    let by_name = |f: &str| score.departures.iter().find(|d| d.feature == f);
    let rms_db = |v: &mut dyn Iterator<Item = f64>| (v.map(|x| x * x).sum::<f64>() / n).sqrt();
    let error_before_db = rms_db(
        &mut ex
            .residual
            .iter()
            .filter_map(|(f, _)| by_name(f).map(|d| d.change * DB_PER_LN)),
    );
    let error_after_db = rms_db(
        &mut ex
            .residual
            .iter()
            .filter_map(|(f, z)| by_name(f).map(|d| z * d.scale * DB_PER_LN)),
    );
    let mut left = ex.total;
    let steps = ex
        .picks
        .iter()
        .map(|p| {
            left -= p.gain;
            let (kind, shaft, bearing) = named(&p.cause, parts);
            LoopStep {
                kind,
                shaft,
                bearing,
                share: p.share,
                rms_z_after: (left.max(0.0) / n).sqrt(),
            }
        })
        .collect();
    let explained_share: f64 = ex.picks.iter().map(|p| p.share).sum();
    MeasuredLoop {
        reference: score.reference,
        features: ex.residual.len(),
        error_before_db,
        error_after_db,
        rms_z_before: (ex.total / n).sqrt(),
        steps,
        unexplained_share: (1.0 - explained_share).max(0.0),
        findings,
    }
}
