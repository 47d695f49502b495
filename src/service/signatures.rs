//! The service's own signature table, loaded once at start-up and checked against the current
//! model configuration: the built-in gearbox's [`TableDiagnoser`].

use std::path::Path;

use anyhow::Context;

use crate::assessment::TableDiagnoser;
use crate::diagnosis::DiagnoseOptions;
use crate::gearbox::Gearbox;
use crate::signature::SignatureTable;

/// Load the table at `path`; refuse it if it was computed for another model configuration
/// unless `allow_stale` (then log a warning).
pub fn load(path: &Path, allow_stale: bool) -> anyhow::Result<TableDiagnoser> {
    let table = SignatureTable::load(path).with_context(|| {
        format!(
            "regenerate it with `gearwear precompute --output {}`",
            path.display()
        )
    })?;
    // The paper rig's table must match the committed description; any other table must at
    // least match the description it carries.
    let rig = Gearbox::paper_rig();
    let check = if table.gearbox.name == rig.name() {
        table.check_model(&rig)
    } else {
        table.check_model(table.gearbox())
    };
    if let Err(e) = check {
        if allow_stale {
            tracing::warn!(error = %e, "serving with a stale signature table");
        } else {
            return Err(anyhow::Error::from(e).context("pass --allow-stale-table to serve anyway"));
        }
    }
    Ok(TableDiagnoser::new(table, DiagnoseOptions::default())?)
}
