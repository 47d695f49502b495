//! `gearwear diagnose`'s baseline: healthy records given one by one (`--baseline FILE`) or
//! with their operating states in a manifest (`--baseline-manifest F.csv`), their features
//! computed once, exactly as the service computes them for records posted with
//! `?baseline=true`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::assessment::{Baselines, Machine, RecordFacts, TachoChannel, baseline_features};
use crate::condition::Load;
use crate::diagnosis::machine_path::LineRatios;
use crate::novelty::RecordFeatures;

/// One healthy record and what is known of its state.
#[derive(Debug, Clone, PartialEq)]
pub struct BaselineFile {
    pub path: PathBuf,
    /// The nominal input-shaft rate (a hint; the rate is measured).
    pub shaft_hz: Option<f64>,
    pub load: Option<Load>,
}

/// A manifest: CSV with a header naming `file` and optionally `shaft_hz` and `load`
/// (any order); empty cells mean "measure" / "unknown"; paths are relative to the manifest.
pub fn read_manifest(path: &Path) -> Result<Vec<BaselineFile>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the baseline manifest {}", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<String> = lines
        .next()
        .with_context(|| format!("the baseline manifest {} is empty", path.display()))?
        .split(',')
        .map(|h| h.trim().to_ascii_lowercase())
        .collect();
    let col = |name: &str| header.iter().position(|h| h == name);
    let Some(file_col) = col("file") else {
        bail!(
            "the baseline manifest {} has no `file` column; its header must name `file` and \
             may name `shaft_hz` and `load` (e.g. `file,shaft_hz,load`)",
            path.display()
        );
    };
    let (hz_col, load_col) = (col("shaft_hz"), col("load"));
    let mut out = Vec::new();
    for (i, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let cell = |c: Option<usize>| c.and_then(|c| cells.get(c)).copied().unwrap_or("");
        let file = cell(Some(file_col));
        if file.is_empty() {
            bail!(
                "baseline manifest {} row {}: the `file` cell is empty",
                path.display(),
                i + 2
            );
        }
        let hz = cell(hz_col);
        let shaft_hz = if hz.is_empty() {
            None
        } else {
            Some(
                hz.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .with_context(|| {
                        format!(
                            "baseline manifest {} row {}: shaft_hz `{hz}` is not a positive \
                             number of Hz (leave it empty to measure it)",
                            path.display(),
                            i + 2
                        )
                    })?,
            )
        };
        out.push(BaselineFile {
            path: dir.join(file),
            shaft_hz,
            load: Load::parse(cell(load_col)),
        });
    }
    if out.is_empty() {
        bail!("the baseline manifest {} lists no record", path.display());
    }
    Ok(out)
}

/// A record as read for the assessment.
pub struct Loaded {
    /// Every channel read, `(name, samples)`.
    pub channels: Vec<(String, Vec<f64>)>,
    /// Indices of the channels to assess.
    pub chosen: Vec<usize>,
    pub sample_rate_hz: f64,
    pub tacho: Option<TachoChannel>,
}

/// The machine's baselines from healthy records: `read` loads a file; `facts` gives a file's
/// facts. Fitted by the core's one fitter, as the service fits a machine's; every channel must
/// get its baseline (the records were given to be one). Also each channel's records' line
/// ratios (what the machine's own model is fitted to).
pub fn fit(
    files: &[BaselineFile],
    machine: &Machine,
    read: &dyn Fn(&Path) -> Result<Loaded>,
    facts: &dyn Fn(&BaselineFile, &Loaded) -> RecordFacts,
) -> Result<(Baselines, BTreeMap<String, Vec<LineRatios>>)> {
    let mut by_channel: BTreeMap<String, Vec<RecordFeatures>> = BTreeMap::new();
    for f in files {
        let mut rec =
            read(&f.path).with_context(|| format!("baseline record {}", f.path.display()))?;
        let names: Vec<String> = rec
            .chosen
            .iter()
            .map(|&i| rec.channels[i].0.clone())
            .collect();
        let facts = facts(f, &rec);
        let feats = baseline_features(&mut rec.channels, &rec.chosen, &facts, machine)
            .with_context(|| format!("baseline record {}", f.path.display()))?;
        for (n, ft) in names.into_iter().zip(feats) {
            by_channel.entry(n).or_default().push(ft);
        }
    }
    let fitted = Baselines::fit(&by_channel).require_all().with_context(|| {
        format!(
            "{} baseline record(s) given; give at least {} healthy records of the machine",
            files.len(),
            crate::novelty::MIN_BASELINE_RECORDS
        )
    })?;
    let ratios = by_channel
        .iter()
        .map(|(k, v)| {
            (
                k.clone(),
                v.iter().filter_map(|f| f.ratios.clone()).collect(),
            )
        })
        .collect();
    Ok((fitted.with_paths(&by_channel, machine.diagnoser), ratios))
}
