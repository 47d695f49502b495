//! A machine's baselines, fitted once from its baseline records' features: one fitter, one rule,
//! for every door a record comes in by (the service's HTTP and MQTT ingest, `gearwear
//! diagnose`), so that the same record against the same baseline is judged the same.
//!
//! The rule, per channel:
//! * fewer than [`MIN_BASELINE_RECORDS`] records: no pooled baseline yet (the count is kept: the
//!   assessment says how many there are of how many needed);
//! * otherwise the pooled baseline ([`MachineBaseline::fit`]);
//! * where at least [`crate::condition::baseline::MIN_STATE_RECORDS`] records carry a measured
//!   state, also the state-aware one ([`state_baseline`]);
//! * a fit that fails leaves the channel without that baseline, and the error is kept in
//!   [`Baselines::unfitted`] for the caller to report;
//! * with the gearbox's table ([`Baselines::with_paths`]), where at least
//!   [`crate::diagnosis::machine_path::MIN_RECORDS`] records carry the table's line ratios, the
//!   channel's transfer path ([`PathCalibration`]), or why it was refused.

use std::collections::BTreeMap;

use super::condition::state_baseline;
use super::diagnoser::TableDiagnoser;
use crate::condition::StateBaseline;
use crate::diagnosis::machine_path::{self, LineRatios, PathCalibration};
use crate::error::{Error, Result};
use crate::novelty::{MIN_BASELINE_RECORDS, MachineBaseline, RecordFeatures};

/// A machine's fitted baselines by channel.
#[derive(Debug, Default)]
pub struct Baselines {
    /// The pooled baseline of each channel with enough records.
    pub pooled: BTreeMap<String, MachineBaseline>,
    /// The state-aware baseline of each channel whose records carry enough states.
    pub states: BTreeMap<String, StateBaseline>,
    /// Baseline records per channel.
    pub counts: BTreeMap<String, usize>,
    /// Channels whose pooled or state-aware fit failed, with the error.
    pub unfitted: BTreeMap<String, Error>,
    /// Each channel's transfer path calibrated on its records' line ratios.
    pub paths: BTreeMap<String, PathCalibration>,
    /// Channels whose records carry enough line ratios but whose path was refused, and why.
    pub path_refusals: BTreeMap<String, String>,
}

impl Baselines {
    /// Fit every channel's baselines from its records' features (see the module docs).
    pub fn fit(by_channel: &BTreeMap<String, Vec<RecordFeatures>>) -> Baselines {
        let mut b = Baselines::default();
        for (name, feats) in by_channel {
            b.counts.insert(name.clone(), feats.len());
            if feats.len() >= MIN_BASELINE_RECORDS {
                match MachineBaseline::fit(feats) {
                    Ok(p) => {
                        b.pooled.insert(name.clone(), p);
                    }
                    Err(e) => {
                        b.unfitted.insert(name.clone(), e);
                        continue;
                    }
                }
            }
            match state_baseline(feats) {
                Some(Ok(s)) => {
                    b.states.insert(name.clone(), s);
                }
                Some(Err(e)) => {
                    b.unfitted.insert(name.clone(), e);
                }
                None => {}
            }
        }
        b
    }

    /// These baselines with each channel's transfer path calibrated through the table of
    /// `diagnoser` (none without one: the table is not ready).
    pub fn with_paths(
        mut self,
        by_channel: &BTreeMap<String, Vec<RecordFeatures>>,
        diagnoser: Option<&TableDiagnoser>,
    ) -> Baselines {
        let Some(d) = diagnoser else {
            return self;
        };
        for (name, feats) in by_channel {
            let ratios: Vec<LineRatios> = feats.iter().filter_map(|f| f.ratios.clone()).collect();
            if ratios.len() < machine_path::MIN_RECORDS {
                continue;
            }
            match PathCalibration::fit(d.table(), &d.options(None), &ratios) {
                Ok(p) => {
                    self.paths.insert(name.clone(), p);
                }
                Err(e) => {
                    self.path_refusals.insert(name.clone(), e.to_string());
                }
            }
        }
        self
    }

    /// For a caller that was given baseline records and needs every channel's pooled
    /// baseline: these baselines, or the first channel's (in name order) failed fit or too
    /// few records as the error.
    pub fn require_all(mut self) -> Result<Baselines> {
        if let Some(name) = self.unfitted.keys().next().cloned() {
            return Err(self.unfitted.remove(&name).expect("the key was just read"));
        }
        if let Some(n) = self.counts.values().find(|n| **n < MIN_BASELINE_RECORDS) {
            return Err(Error::BaselineTooSmall {
                records: *n,
                needed: MIN_BASELINE_RECORDS,
            });
        }
        Ok(self)
    }
}
