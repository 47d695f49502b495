//! `gearwear diagnose`'s cache: a described gearbox's table over the speeds its records ran at,
//! and a machine's own model (its physics fitted to a baseline, its own table), computed once
//! and reused — the CLI's side of what the service keeps in its database.
//!
//! Where: `$GEARWEAR_CACHE_DIR`, else `$XDG_CACHE_HOME/gearwear`, else `~/.cache/gearwear`;
//! `tables/<name>-<hash>.json` (a description's table, extended in place when a record runs
//! outside it; the committed `signatures/` table is the first one when it matches) and
//! `physics/<key>.json` (the fit of one description, table and baseline). Files are written
//! whole (a temporary file renamed), so an interrupted run leaves the previous one.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::common::{default_table_for, progress_bar};
use crate::assessment::{OwnModel, TableDiagnoser};
use crate::diagnosis::DiagnoseOptions;
use crate::diagnosis::machine_path::LineRatios;
use crate::diagnosis::machine_physics::{MachinePhysics, PhysicsFitOptions};
use crate::gearbox::Gearbox;
use crate::signature::SignatureTable;
use crate::signature::coverage::{self, SpeedSpan};
use crate::signature::precompute::{PrecomputeSpec, default_grid, paper_grid, precompute};
use crate::signature::table::SimulationSettings;

/// The cache directory (see the [module docs](self)).
pub fn dir() -> PathBuf {
    if let Some(d) = std::env::var_os("GEARWEAR_CACHE_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    dirs::cache_dir()
        .unwrap_or_else(std::env::temp_dir)
        .join("gearwear")
}

fn short(hash: &str) -> &str {
    &hash[..16.min(hash.len())]
}

fn table_file(gb: &Gearbox) -> PathBuf {
    dir()
        .join("tables")
        .join(format!("{}-{}.json", gb.name(), short(&gb.hash)))
}

/// Write `text` to `path` whole: a temporary file beside it, renamed.
fn write_whole(path: &Path, text: &str) -> Result<()> {
    let parent = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}

/// A table of `gb` that is usable as it is: the cached one, else the committed default.
fn existing_table(gb: &Gearbox) -> Option<SignatureTable> {
    [table_file(gb), default_table_for(gb)]
        .iter()
        .filter(|p| p.exists())
        .filter_map(|p| SignatureTable::load(p).ok())
        .find(|t| t.check_model(gb).is_ok())
}

/// The span of input-shaft rates a table's columns cover.
fn table_span(gb: &Gearbox, t: &SignatureTable) -> SpeedSpan {
    let (lo, hi) = t.omega_band();
    let per = gb.f1_per_input_hz;
    let f_ref = gb.reference_frequency_hz();
    SpeedSpan::range(lo * f_ref / per, hi * f_ref / per)
}

/// Precompute with a progress bar on a terminal.
fn compute(spec: &PrecomputeSpec, what: &str) -> Result<SignatureTable> {
    let g = &spec.grid;
    let points = g.ea.len() * g.omega1.len();
    eprintln!(
        "{what}: {} wear degrees × {} speeds × {} seeds = {} simulations",
        g.ea.len(),
        g.omega1.len(),
        g.seeds,
        points * g.seeds
    );
    let pb = progress_bar(points as u64, "grid points");
    let t = precompute(spec, None, &|| pb.inc(1))?;
    pb.finish_and_clear();
    Ok(t)
}

/// The cached or committed table of `gb` when it covers `spans`.
pub fn cached_table(gb: &Gearbox, spans: &[SpeedSpan]) -> Option<SignatureTable> {
    existing_table(gb).filter(|t| {
        spans
            .iter()
            .all(|s| coverage::covers(gb, &t.grid.omega1, s))
    })
}

/// The table of `gb` over `spans` (the speeds its records ran at): the cached or committed one
/// when it covers them, else that one extended to them (its columns kept), else a new one —
/// written to the cache. `Err` with the core's [`crate::Error::TableTooLarge`] when the speeds
/// would need more simulations than a table may take.
pub fn table_for(gb: &Gearbox, spans: &[SpeedSpan]) -> Result<SignatureTable> {
    let have = existing_table(gb);
    if let Some(t) = &have
        && spans
            .iter()
            .all(|s| coverage::covers(gb, &t.grid.omega1, s))
    {
        return Ok(t.clone());
    }
    let table = match have {
        Some(t) => {
            let mut all = spans.to_vec();
            all.push(table_span(gb, &t));
            let per = t.grid.ea.len() * t.grid.seeds;
            let cols = coverage::plan_columns(gb, &t.grid.omega1, &all, per)?;
            eprintln!(
                "extending the table of `{}` to the records' speeds: {} new speeds",
                gb.name(),
                cols.iter().filter(|c| !t.grid.omega1.contains(c)).count()
            );
            let pb = progress_bar(
                ((cols.len() - t.grid.omega1.len().min(cols.len())) * t.grid.ea.len()) as u64,
                "grid points",
            );
            let x = coverage::extend(&t, &cols, None, &|| pb.inc(1))?;
            pb.finish_and_clear();
            x
        }
        None => {
            let grid = match coverage::grid_for(gb, spans)? {
                Some(g) => g,
                None if gb.hash == Gearbox::paper_rig().hash => paper_grid(),
                None => default_grid(gb),
            };
            let spec = PrecomputeSpec {
                gearbox: std::sync::Arc::new(gb.clone()),
                sensor: Default::default(),
                grid,
                settings: SimulationSettings::default(),
                created_by: "gearwear diagnose (the table over the records' speeds)".into(),
            };
            compute(&spec, &format!("the table of `{}`", gb.name()))?
        }
    };
    stored(&table_file(gb), &table)
}

/// Write `table` to `path` and read it back: the table a later run reads (its samples are
/// stored rounded), so that this run and the next give the same answer.
fn stored(path: &Path, table: &SignatureTable) -> Result<SignatureTable> {
    let json = table.to_json()?;
    write_whole(path, &json)?;
    Ok(SignatureTable::from_json(
        &json,
        &path.display().to_string(),
    )?)
}

/// A cached fit: the machine's physics, or why it was refused.
#[derive(Debug, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "status")]
pub enum CachedFit {
    Fitted { physics: Box<MachinePhysics> },
    Refused { reason: String },
}

/// The key of one fit: the description, its table, the baseline's line ratios and the fit's
/// options.
fn fit_key(
    gb: &Gearbox,
    table: &SignatureTable,
    ratios: &BTreeMap<String, Vec<LineRatios>>,
    fo: &PhysicsFitOptions,
) -> String {
    let text = serde_json::json!({
        "gearbox": gb.hash,
        "table": table.model_hash,
        "grid": table.grid,
        "ratios": ratios,
        "options": fo,
    })
    .to_string();
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The machine's own model from its baseline's line ratios: the physics fitted (or read from
/// the cache) and its own table (computed or read from the cache); `compute: false` takes only
/// what the cache holds. The model is `None` when the fit is refused (the [`CachedFit`] says
/// why; the record is then read as before) or, without `compute`, not cached.
pub fn own_model(
    gb: &Gearbox,
    table: &SignatureTable,
    opts: &DiagnoseOptions,
    ratios: &BTreeMap<String, Vec<LineRatios>>,
    compute_missing: bool,
) -> Result<(CachedFit, Option<OwnModel>)> {
    let fo = PhysicsFitOptions::default();
    let path = dir()
        .join("physics")
        .join(format!("{}.json", short(&fit_key(gb, table, ratios, &fo))));
    let cached: Option<CachedFit> = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    let fit = match cached {
        Some(f) => f,
        None if !compute_missing => {
            return Ok((
                CachedFit::Refused {
                    reason: "not in the cache (--cached-only)".into(),
                },
                None,
            ));
        }
        None => {
            let n = ratios.values().map(Vec::len).max().unwrap_or(0);
            eprintln!(
                "fitting the machine's physics to its {n} healthy records (simulating `{}`; \
                 about half a minute, once)",
                gb.name()
            );
            let f = match MachinePhysics::fit(gb, table, opts, ratios, &fo) {
                Ok(p) => CachedFit::Fitted {
                    physics: Box::new(p),
                },
                Err(e) => CachedFit::Refused {
                    reason: e.to_string(),
                },
            };
            write_whole(&path, &serde_json::to_string_pretty(&f)?)?;
            f
        }
    };
    let CachedFit::Fitted { physics } = &fit else {
        return Ok((fit, None));
    };
    let spec = physics.table_spec(gb, table)?;
    let own_path = table_file(&spec.gearbox);
    let own = match SignatureTable::load(&own_path) {
        Ok(t) if t.grid == spec.grid && t.check_model(&spec.gearbox).is_ok() => t,
        _ if !compute_missing => return Ok((fit, None)),
        _ => stored(&own_path, &compute(&spec, "the machine's own table")?)?,
    };
    let diagnoser = TableDiagnoser::new(own, opts.clone())?;
    let model = OwnModel::new((**physics).clone(), diagnoser);
    Ok((fit, Some(model)))
}
