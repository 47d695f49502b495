//! The record-quality step of an assessment: each chosen channel inspected
//! ([`crate::record::quality`]) before anything is diagnosed — an untrustworthy channel
//! refuses the record, a repairable one is repaired in place — and the `quality` object of
//! the answer, with the alert capped at `unknown` when the repair was too large for the
//! evidence to survive it.
//!
//! **When the alert stands after a repair.** Replacing k of a channel's n samples by the
//! straight line between their neighbours changes its energy, and so every spectral line and
//! statistic the alert rests on, by at most about k/n of the local level. Up to
//! [`REPAIR_KEEPS_ALERT_FRACTION`] of the samples (one spike in a 10 000-sample record) that
//! is far below the differences the thresholds separate, so the level computed on the
//! repaired record stands; above it the level is capped at `unknown` (`basis: quality`),
//! whatever it would have been: more repaired samples may be a sensor fault that also shows
//! below the spike threshold.

use serde::Serialize;

use super::{Alert, Machine};
use crate::record::quality::{
    QualityFinding, REPAIR_KEEPS_ALERT_FRACTION, inspect, plausible_limit,
};

/// The `quality` object of an assessment.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Quality {
    /// `clean` (nothing found), `repaired` (isolated spikes replaced) or `warned` (a finding
    /// that was neither repaired nor refused, e.g. the sample rate).
    pub status: &'static str,
    /// Samples replaced by the repair, over the chosen channels.
    pub repaired_samples: usize,
    /// The alert was capped at `unknown` because of a finding.
    pub alert_capped: bool,
    pub findings: Vec<QualityFinding>,
    /// Why the alert is capped (when it is).
    #[serde(skip)]
    pub cap_reason: Option<String>,
    /// The cap is a set-up in doubt ([`super::setup`]): it replaces even an `unknown` alert's
    /// reason (an uncovered state's advice to add a healthy record does not apply).
    #[serde(skip)]
    pub setup_doubt: bool,
}

/// Inspect the chosen channels (`(name, samples)`; sample rate `fs`, Hz), repairing the
/// repairable in place. Errors: [`crate::Error::RecordQuality`] (in a record of several
/// channels wrapped in [`crate::Error::InChannel`]).
pub fn inspect_channels(
    channels: &mut [(String, Vec<f64>)],
    chosen: &[usize],
    fs: f64,
    machine: &Machine,
) -> crate::Result<Quality> {
    let several = channels.len() > 1;
    let mut q = Quality {
        status: "clean",
        ..Quality::default()
    };
    let mut worst_fraction = 0.0_f64;
    for &i in chosen {
        let (name, x) = &mut channels[i];
        let limit = machine
            .units
            .channels
            .of(name)
            .map(|(_, unit)| plausible_limit(unit.quantity, unit.to_si));
        let ins = match inspect(x, fs, limit) {
            Ok(ins) => ins,
            Err(e) if several => {
                if let crate::Error::RecordQuality(mut f) = e {
                    f.channel = Some(name.clone());
                    return Err(crate::Error::RecordQuality(f).in_channel(name.clone()));
                }
                return Err(e.in_channel(name.clone()));
            }
            Err(e) => return Err(e),
        };
        if ins.spans.is_empty() {
            // Findings kept as signal (impulses): reported, nothing repaired.
            if !ins.findings.is_empty() && q.status == "clean" {
                q.status = "warned";
            }
            q.findings.extend(ins.findings.into_iter().map(|mut f| {
                if several {
                    f.channel = Some(name.clone());
                }
                f
            }));
            continue;
        }
        ins.repair(x);
        let k = ins.repaired_samples();
        worst_fraction = worst_fraction.max(k as f64 / x.len() as f64);
        q.repaired_samples += k;
        q.status = "repaired";
        q.findings.extend(ins.findings.into_iter().map(|mut f| {
            if several {
                f.channel = Some(name.clone());
            }
            f
        }));
    }
    if worst_fraction > REPAIR_KEEPS_ALERT_FRACTION {
        q.alert_capped = true;
        q.cap_reason = Some(format!(
            "{} samples were repaired (isolated spikes), more than the {} % of a channel up \
             to which the evidence survives the repair",
            q.repaired_samples,
            100.0 * REPAIR_KEEPS_ALERT_FRACTION
        ));
    }
    Ok(q)
}

/// Whether a mis-declared sample rate explains the diagnosis's failure `e` (no mesh line, a
/// speed outside the table, a rate too low for the lines, a record too short in periods).
pub fn rate_explains(e: &crate::Error) -> bool {
    use crate::Error as E;
    matches!(
        e.split_channel().1,
        E::NoMeshLine { .. }
            | E::SpeedOutOfBand { .. }
            | E::SampleRateTooLow { .. }
            | E::RecordTooShort { .. }
    )
}

/// The refusal of a record whose diagnosis failed (`e`) where the set-up check found it in
/// doubt (`f`).
pub fn rate_refusal(mut f: QualityFinding, e: &crate::Error) -> crate::Error {
    f.action = "refused";
    f.message = format!("{} (the diagnosis failed: {e})", f.message);
    crate::Error::RecordQuality(Box::new(f))
}

/// The alert a capped record gets instead of `alert` (unchanged when it is `unknown`
/// already, unless the set-up is in doubt: `setup_doubt`).
pub fn capped(alert: &Alert, why: &str, setup_doubt: bool) -> Alert {
    if setup_doubt {
        return Alert {
            level: super::Level::Unknown,
            basis: super::Basis::Quality,
            reason: format!(
                "{why}; the record is not judged until its set-up is corrected (it would have \
                 been `{}`: {})",
                alert.level, alert.reason
            ),
        };
    }
    if alert.level == super::Level::Unknown {
        return alert.clone();
    }
    Alert {
        level: super::Level::Unknown,
        basis: super::Basis::Quality,
        reason: format!(
            "{why}; the record would have been `{}` ({}), but that cannot be trusted — check \
             the sensor and send a clean record",
            alert.level, alert.reason
        ),
    }
}
