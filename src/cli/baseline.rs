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
/// (any order, any case); empty cells mean "measure" / "unknown"; paths are relative to the
/// manifest. Read by the `csv` crate: cells are trimmed, a cell may be quoted (a path with a
/// comma), blank lines are skipped and a short row leaves its missing cells empty. Every error
/// names the manifest, the line and what is wrong with it.
pub fn read_manifest(path: &Path) -> Result<Vec<BaselineFile>> {
    let text = std::fs::read(path)
        .with_context(|| format!("reading the baseline manifest {}", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let at = |pos: Option<&csv::Position>| match pos {
        Some(p) => format!(
            "baseline manifest {} line {}",
            path.display(),
            line_of(&text, p)
        ),
        None => format!("baseline manifest {}", path.display()),
    };
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(text.as_slice());
    let header: Vec<String> = rdr
        .headers()
        .map_err(|e| anyhow::anyhow!("{}: {e}", at(e.position())))?
        .iter()
        .map(str::to_ascii_lowercase)
        .collect();
    if header.iter().all(|h| h.is_empty()) {
        bail!("the baseline manifest {} is empty", path.display());
    }
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
    for row in rdr.records() {
        let row = row.map_err(|e| anyhow::anyhow!("{}: {e}", at(e.position())))?;
        if row.iter().all(str::is_empty) {
            continue; // a line of blanks
        }
        let at = at(row.position());
        let cell = |c: Option<usize>| c.and_then(|c| row.get(c)).unwrap_or("");
        let file = cell(Some(file_col));
        if file.is_empty() {
            bail!("{at}: the `file` cell is empty");
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
                            "{at}: shaft_hz `{hz}` is not a positive number of Hz (leave it \
                             empty to measure it)"
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

/// The line a row of `text` starts on. Hand-written because the `csv` crate places a row that
/// follows blank lines at the first of them (its position is where the reading of the row began):
/// the blank lines between are counted in here.
fn line_of(text: &[u8], pos: &csv::Position) -> u64 {
    let rest = text.get(pos.byte() as usize..).unwrap_or_default();
    let blank = rest.iter().take_while(|b| b.is_ascii_whitespace());
    pos.line() + blank.filter(|&&b| b == b'\n').count() as u64
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
    let ratios = crate::novelty::line_ratios(&by_channel);
    Ok((fitted.with_paths(&by_channel, machine.diagnoser), ratios))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `text` written as a manifest in a fresh folder; the manifest's path.
    fn manifest(name: &str, text: impl AsRef<[u8]>) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("gearwear-manifest-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("m.csv");
        std::fs::write(&p, text).unwrap();
        p
    }

    fn error(name: &str, text: impl AsRef<[u8]>) -> String {
        format!("{:#}", read_manifest(&manifest(name, text)).unwrap_err())
    }

    #[test]
    fn reads_columns_in_any_order_with_blank_lines_quotes_and_short_rows() {
        let p = manifest(
            "ok",
            "Load, FILE ,shaft_hz\n\n high , a.csv , 30\n,\"b, 2.csv\"\n\n7.5,c.csv,\n",
        );
        let dir = p.parent().unwrap();
        let got = read_manifest(&p).unwrap();
        assert_eq!(
            got,
            vec![
                BaselineFile {
                    path: dir.join("a.csv"),
                    shaft_hz: Some(30.0),
                    load: Some(Load::Label("high".into())),
                },
                BaselineFile {
                    path: dir.join("b, 2.csv"),
                    shaft_hz: None,
                    load: None,
                },
                BaselineFile {
                    path: dir.join("c.csv"),
                    shaft_hz: None,
                    load: Some(Load::Value(7.5)),
                },
            ]
        );
    }

    #[test]
    fn errors_name_the_manifest_the_line_and_the_fault() {
        let e = error("hz", "file,shaft_hz\na.csv,30\n\n \r\n\nb.csv,-2\n");
        assert!(
            e.contains("m.csv line 6: shaft_hz `-2` is not a positive number"),
            "{e}"
        );
        let e = error("nofile", "file,load\na.csv,high\n  \n,low\n");
        assert!(e.contains("m.csv line 4: the `file` cell is empty"), "{e}");
        let e = error("nocol", "path,load\na.csv,high\n");
        assert!(e.contains("m.csv has no `file` column"), "{e}");
        assert!(error("empty", "").contains("m.csv is empty"));
        assert!(error("norow", "file,shaft_hz\n\n").contains("m.csv lists no record"));
        let e = error("utf8", b"file\na.csv\n\xff.csv\n");
        assert!(e.contains("m.csv line 3: "), "{e}");
    }
}
