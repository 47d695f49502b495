//! The real [`Diagnoser`]: the signature table loaded once at start-up (and checked against
//! the current model configuration) with its prepared [`Matcher`]; each request runs
//! [`diagnose_with`] — the same code and the same JSON as `gearwear diagnose`.

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use super::diagnoser::{Diagnoser, Input, Output};
use crate::diagnosis::{DiagnoseOptions, Matcher, diagnose_with};
use crate::model::ModelAConfig;
use crate::record::Record;
use crate::signature::SignatureTable;

/// Table + matcher + the default options.
pub struct TableDiagnoser {
    table: SignatureTable,
    matcher: Matcher,
    opts: DiagnoseOptions,
}

impl TableDiagnoser {
    pub fn new(table: SignatureTable, opts: DiagnoseOptions) -> crate::Result<Self> {
        let matcher = Matcher::new(&table, &opts)?;
        Ok(TableDiagnoser {
            table,
            matcher,
            opts,
        })
    }
}

/// Load the table at `path`; refuse it if it was computed for another model configuration
/// unless `allow_stale` (then log a warning).
pub fn load(path: &Path, allow_stale: bool) -> anyhow::Result<TableDiagnoser> {
    let table = SignatureTable::load(path).with_context(|| {
        format!(
            "regenerate it with `gearwear precompute --output {}`",
            path.display()
        )
    })?;
    if let Err(e) = table.check_model(&ModelAConfig::default_rig()) {
        if allow_stale {
            tracing::warn!(error = %e, "serving with a stale signature table");
        } else {
            return Err(anyhow::Error::from(e).context("pass --allow-stale-table to serve anyway"));
        }
    }
    Ok(TableDiagnoser::new(table, DiagnoseOptions::default())?)
}

impl Diagnoser for TableDiagnoser {
    fn diagnose(&self, input: &Input) -> crate::Result<Output> {
        let rec = Record {
            samples: input.samples.clone(),
            sample_rate: input.sample_rate_hz,
        };
        let mut opts = self.opts.clone();
        opts.shaft_hz = input.shaft_hz;
        let d = diagnose_with(&rec, &self.table, &self.matcher, &opts)?;
        let diagnosis =
            serde_json::to_value(&d).map_err(|e| crate::Error::Signal(e.to_string()))?;
        Ok(Output {
            ea_estimate: d.wear_degree.estimate,
            ea_lower: d.wear_degree.lower,
            ea_upper: d.wear_degree.upper,
            motion_state: d.motion_state.clone(),
            f1_hz: d.f1_hz,
            marks: d
                .lines
                .iter()
                .map(|l| (l.name.clone(), l.normalised_frequency))
                .collect(),
            features: json!({
                "lines": diagnosis["lines"],
                "condition_indicators": diagnosis["condition_indicators"],
                "f1_hz": d.f1_hz,
                "omega1": d.omega1,
            }),
            diagnosis,
        })
    }

    fn table_id(&self) -> String {
        self.table.model_hash.clone()
    }
}
