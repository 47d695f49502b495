//! The `precompute` and `diagnose` commands (argument structs and bodies; [`crate::cli`]
//! dispatches to them).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};

use super::baseline::{self, BaselineFile, Loaded};
use super::cache;
use super::common::{
    RigArgs, default_table_for, load_gearbox, load_table, parse_range, progress_bar,
};
use super::units::UnitArgs;
use crate::analysis::bifurcation::grid;
use crate::assessment::condition::measure_record;
use crate::assessment::{
    Baselines, GearboxRef, Machine, MachineCalibration, OwnModel, RecordFacts, TableDiagnoser,
    TachoChannel, Thresholds, assess, reads_as_described,
};
use crate::condition::Load;
use crate::diagnosis::DiagnoseOptions;
use crate::diagnosis::machine_path::LineRatios;
use crate::diagnosis::machine_physics::MIN_RECORDS as MIN_PHYSICS_RECORDS;
use crate::gearbox::Gearbox;
use crate::record::{Column, Format, ReadOptions, read_record, read_record_channels_with_pulses};
use crate::signal::lines::SEGMENT_PERIODS;
use crate::signature::coverage::SpeedSpan;
use crate::signature::precompute::{
    PrecomputeSpec, default_grid, paper_grid, partial_path, precompute,
};
use crate::signature::table::SimulationSettings;
use crate::signature::{SensorQuantity, TableStatus};

/// Sensor quantity on the command line.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum SensorArg {
    /// Stage-1 relative displacement x̄1.
    X1,
    /// Stage-1 relative acceleration x̄1'' (default).
    Accel,
    /// Stage-1 dynamic mesh force.
    MeshForce,
}

impl From<SensorArg> for SensorQuantity {
    fn from(s: SensorArg) -> Self {
        match s {
            SensorArg::X1 => SensorQuantity::X1,
            SensorArg::Accel => SensorQuantity::Accel,
            SensorArg::MeshForce => SensorQuantity::MeshForce,
        }
    }
}

#[derive(Debug, Args)]
pub struct PrecomputeArgs {
    /// Output table (JSON; default: `signatures/model_a_accel.json` for the paper's rig,
    /// `signatures/<name>.json` for a described gearbox).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Wear-degree grid START:END:STEP (units of the reference length; default: the paper
    /// rig's 0.1:1:0.025, a described gearbox's 0.1:1:0.05).
    #[arg(long)]
    pub ea: Option<String>,
    /// Ω1 grid START:END:STEP (default: the paper rig's 0.5:1.6:0.05; a described gearbox's
    /// five points over ±15 % of its nominal_input_hz, else 0.5:1.6:0.1).
    #[arg(long, conflicts_with = "input_hz")]
    pub omega1: Option<String>,
    /// Input-shaft rate grid START:END:STEP in Hz, instead of --omega1.
    #[arg(long)]
    pub input_hz: Option<String>,
    /// Random initial states (and transient lengths) per grid point (default: 6 for the
    /// paper's rig, 3 for a described gearbox).
    #[arg(long)]
    pub seeds: Option<usize>,
    /// Retained stage-1 mesh periods per seed.
    #[arg(long, default_value_t = SimulationSettings::default().periods)]
    pub periods: usize,
    /// Simulated sensor quantity.
    #[arg(long, value_enum, default_value_t = SensorArg::Accel)]
    pub sensor: SensorArg,
    /// Ignore (and overwrite) a partial file from an interrupted run.
    #[arg(long)]
    pub fresh: bool,
    #[command(flatten)]
    pub rig: RigArgs,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum FormatArg {
    Csv,
    F32,
    Wav,
}

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Record file: CSV (one column, time,value, or pick --column; `.gz` ok), raw
    /// little-endian f32, or WAV.
    #[arg(long)]
    pub input: PathBuf,
    /// Sample rate in Hz (required for f32 and for CSV without a time column; overrides WAV).
    #[arg(long)]
    pub sample_rate: Option<f64>,
    /// Input (motor) shaft rate in Hz; f1 = 29 × this on the paper's rig. Without it f1 is
    /// found in the spectrum. With a described gearbox it is the nominal rate the real one is
    /// measured around (tacho-less, ±6 %: motor slip), unless --tacho-column counts it.
    #[arg(long)]
    pub shaft_hz: Option<f64>,
    /// CSV column (0-based index or header name) or WAV channel; repeat it to assess several
    /// channels of one record (the most severe decides).
    #[arg(long)]
    pub column: Vec<String>,
    /// The record's tachometer column (name or index): the input-shaft rate and angle are then
    /// counted from its pulses instead of tracked tacho-less around --shaft-hz.
    #[arg(long, value_name = "NAME")]
    pub tacho_column: Option<String>,
    /// Tachometer pulses per input-shaft revolution.
    #[arg(long, value_name = "N", default_value_t = 1, requires = "tacho_column")]
    pub tacho_ppr: usize,
    /// The load the record was taken at: a label (`High`) or a number; a state-aware baseline
    /// compares the record with healthy records of the same load.
    #[arg(long, value_name = "VALUE")]
    pub load: Option<String>,
    /// Healthy records with their operating states: a CSV with columns `file,shaft_hz,load`
    /// (empty cells: measure the speed / load unknown; paths relative to the manifest). The
    /// record is then judged against what these records expect at its measured speed and
    /// load, and its `findings` name the part it points at.
    #[arg(long, value_name = "F.csv")]
    pub baseline_manifest: Option<PathBuf>,
    /// Write the machine's model calibrated on the baseline's records here (JSON, one member
    /// per channel: its report — each state's fit, the leave-one-speed-out error against a
    /// smooth curve's, the uncertainty, the transfer path — or why it was refused), as
    /// `GET /v1/machines/{id}/baseline` shows it under `channels.*.model`.
    #[arg(long, value_name = "FILE")]
    pub model_report: Option<PathBuf>,
    /// Write the machine's own model fitted to the baseline (its physics factors with their
    /// intervals, the fit per speed and line family, the left-out error against the empirical
    /// calibration's) here, or why it was refused (JSON).
    #[arg(long, value_name = "FILE")]
    pub physics_report: Option<PathBuf>,
    /// Compute nothing: use a cached or committed table and own model only (without one that
    /// covers the record, it is judged against its baseline alone).
    #[arg(long)]
    pub cached_only: bool,
    /// Read the wear through the machine's calibrated transfer path alone, without fitting its
    /// physics to the baseline.
    #[arg(long)]
    pub no_own_model: bool,
    /// File format (default: from the extension).
    #[arg(long, value_enum)]
    pub format: Option<FormatArg>,
    /// Signature table (default: the gearbox's table over the speeds the records ran at, from
    /// the cache — computed or extended when none covers them — starting from the committed
    /// `signatures/` table when there is one).
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// Credible level of the wear interval.
    #[arg(long, default_value_t = DiagnoseOptions::default().credible_level)]
    pub level: f64,
    /// Use a table computed for another gearbox description anyway.
    #[arg(long)]
    pub allow_stale: bool,
    /// Gearbox description the table must match (default: the table's own when --table is
    /// given, else the paper's rig).
    #[arg(long, value_name = "FILE")]
    pub gearbox: Option<PathBuf>,
    /// A healthy record of the same machine (same column and sample-rate options); give at
    /// least three (`--baseline a.csv --baseline b.csv …`). The assessment's `novelty` is then
    /// the record's score against these records' features, the threshold calibrated on them by
    /// leave-one-out, and the features that deviate most (null without `--baseline`).
    #[arg(long, value_name = "FILE")]
    pub baseline: Vec<PathBuf>,
    /// The machine's calibration: the JSON of `GET /v1/machines/{id}/calibration` (or of the
    /// `POST` that made it). The record is then diagnosed with the calibrated effects, as the
    /// service diagnoses that machine's records (`calibration` in the answer).
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Wear degree (ea) at which the alert level turns `warning` (as `serve --warning-ea`).
    #[arg(long, default_value_t = Thresholds::default().warning)]
    pub warning_ea: f64,
    /// Wear degree (ea) at which the alert level turns `alarm` (as `serve --alarm-ea`).
    #[arg(long, default_value_t = Thresholds::default().alarm)]
    pub alarm_ea: f64,
    /// The channels' physical units and the machine's ISO 20816-3 class (as a machine's
    /// `channel_units` and `iso_20816`).
    #[command(flatten)]
    pub units: UnitArgs,
}

/// `gearwear precompute`.
pub fn precompute_cmd(a: PrecomputeArgs) -> Result<()> {
    let gb = a.rig.load()?;
    if a.rig.planetary_error.is_some() {
        bail!(
            "--planetary-error is not supported by precompute: the table uses the description's \
             value (write it as the planetary stage's error_um)"
        );
    }
    let described = a.rig.gearbox.is_some();
    let mut g = if described {
        default_grid(&gb)
    } else {
        paper_grid()
    };
    let round = |v: f64| (v * 1e6).round() / 1e6;
    if let Some(ea) = &a.ea {
        let (e0, e1, es) = parse_range(ea)?;
        g.ea = grid(e0, e1, es).into_iter().map(round).collect();
    }
    if let Some(om) = &a.omega1 {
        let (o0, o1, os) = parse_range(om)?;
        g.omega1 = grid(o0, o1, os).into_iter().map(round).collect();
    }
    if let Some(hz) = &a.input_hz {
        let (h0, h1, hs) = parse_range(hz)?;
        let f_ref = gb.reference_frequency_hz();
        g.omega1 = grid(h0, h1, hs)
            .into_iter()
            .map(|h| round(gb.f1_hz(h) / f_ref))
            .collect();
    }
    if let Some(s) = a.seeds {
        g.seeds = s;
    }
    if g.ea.len() < 2 {
        bail!("the ea grid needs at least 2 values, got {:?}", g.ea);
    }
    if g.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    let output = a.output.clone().unwrap_or_else(|| default_table_for(&gb));
    let settings = SimulationSettings {
        periods: a.periods,
        ..Default::default()
    };
    if (settings.periods as f64) < SEGMENT_PERIODS {
        bail!(
            "--periods must be at least {} (one estimator segment)",
            SEGMENT_PERIODS
        );
    }
    let created_by = std::iter::once("gearwear".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ");
    let spec = PrecomputeSpec {
        gearbox: std::sync::Arc::new(gb),
        sensor: a.sensor.into(),
        grid: g.clone(),
        settings,
        created_by,
    };
    let partial = partial_path(&output);
    if a.fresh {
        let _ = std::fs::remove_file(&partial);
    }
    let total = g.ea.len() * g.omega1.len();
    eprintln!(
        "precompute: {} ea × {} Ω1 × {} seeds = {} runs on {} threads; partial results in {}",
        g.ea.len(),
        g.omega1.len(),
        g.seeds,
        total * g.seeds,
        rayon::current_num_threads(),
        partial.display()
    );
    let pb = progress_bar(total as u64, "grid points");
    let table = precompute(&spec, Some(&partial), &|| pb.inc(1))?;
    pb.finish_and_clear();
    let json = table.to_json()?;
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&output, json).with_context(|| format!("writing {}", output.display()))?;
    let _ = std::fs::remove_file(&partial);
    let failed: usize = table.entries.iter().map(|e| e.failed).sum();
    eprintln!(
        "wrote {} ({} entries, {failed} failed seeds) in {:.1} s",
        output.display(),
        table.entries.len(),
        table.precompute_seconds
    );
    Ok(())
}

/// `gearwear diagnose`: the record's [`Assessment`], built by the same core function as the
/// service's answer to `POST /v1/machines/{id}/records` — the `--baseline` files (or the
/// `--baseline-manifest`'s) as the machine's baseline, `--calibration` as its calibration,
/// `--warning-ea`/`--alarm-ea` as its thresholds.
pub fn diagnose_cmd(a: DiagnoseArgs) -> Result<()> {
    if !(a.warning_ea < a.alarm_ea) {
        bail!("--warning-ea must be below --alarm-ea");
    }
    // A unit that cannot be converted fails before anything is read.
    a.units.check(None, None)?;
    let opts = ReadOptions {
        format: a.format.map(|f| match f {
            FormatArg::Csv => Format::Csv,
            FormatArg::F32 => Format::F32,
            FormatArg::Wav => Format::Wav,
        }),
        sample_rate: a.sample_rate,
        column: None,
    };
    let calibration = a.calibration.as_deref().map(read_calibration).transpose()?;
    let load = a.load.as_deref().and_then(Load::parse);
    // Baseline files first: a wrong one should fail before anything is computed.
    let files = baseline_files(&a, &load)?;
    let mut rec = load_record(&a.input, &a, &opts)?;
    let gearbox = match (&a.table, &a.gearbox) {
        (Some(t), None) => load_table(None, Some(t), a.allow_stale)?.gearbox().clone(),
        (_, g) => load_gearbox(g.as_deref())?,
    };
    let (diagnoser, table_note) = table_for(&a, &gearbox, &files, &rec, &opts, &load)?;
    let no_baseline = BTreeMap::new();
    let no_states = BTreeMap::new();
    let no_counts = BTreeMap::new();
    let no_paths = BTreeMap::new();
    let mut machine = Machine {
        gearbox: &gearbox,
        gearbox_ref: gearbox_ref(&a, &gearbox, diagnoser.is_some()),
        // The paper's rig by default reads as with `--gearbox configs/gearboxes/wang2019.toml`.
        described: reads_as_described(&gearbox, rec.tacho.is_some()),
        diagnoser: diagnoser.as_ref(),
        table_note,
        input_shaft_hz: None,
        baselines: &no_baseline,
        state_baselines: &no_states,
        baseline_counts: &no_counts,
        calibration: calibration.as_ref(),
        paths: &no_paths,
        own_model: None,
        extends_tables: false,
        thresholds: Thresholds {
            warning: a.warning_ea,
            alarm: a.alarm_ea,
        },
        units: Default::default(),
    };
    let (fitted, ratios) = if files.is_empty() {
        (Baselines::default(), BTreeMap::new())
    } else {
        baseline::fit(
            &files,
            &machine,
            &|p| load_record(p, &a, &opts),
            &|f, rec| facts_of(rec, f.shaft_hz.or(a.shaft_hz), f.load.clone(), true),
        )?
    };
    let own = own_model_for(&a, &gearbox, diagnoser.as_ref(), &ratios)?;
    machine.own_model = own.as_ref();
    if let Some(path) = &a.model_report {
        write_model_report(path, &fitted)?;
    }
    machine.baselines = &fitted.pooled;
    machine.state_baselines = &fitted.states;
    machine.paths = &fitted.paths;
    machine.baseline_counts = &fitted.counts;
    let names: Vec<String> = rec
        .chosen
        .iter()
        .map(|&i| rec.channels[i].0.clone())
        .collect();
    machine.units = a
        .units
        .machine_units(&names, rec.tacho.as_ref().map(|t| t.name.as_str()))?;
    let facts = facts_of(&rec, a.shaft_hz, load, false);
    let assessment = assess(
        &mut rec.channels,
        &rec.chosen,
        &facts,
        &machine,
        &mut |_| {},
    )
    .map_err(with_flag_hint)?;
    println!("{}", serde_json::to_string_pretty(&assessment)?);
    Ok(())
}

/// The machine's calibrated model of every state-aware channel, as JSON at `path`.
fn write_model_report(path: &std::path::Path, fitted: &Baselines) -> Result<()> {
    if fitted.states.is_empty() {
        bail!(
            "--model-report needs a state-aware baseline: give --baseline-manifest with healthy \
             records at three speeds or more, and --gearbox"
        );
    }
    let report: serde_json::Map<String, serde_json::Value> = fitted
        .states
        .iter()
        .map(|(ch, b)| (ch.clone(), crate::views::machine_model_json(b)))
        .collect();
    std::fs::write(path, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("writing the model report {}", path.display()))
}

/// The `gearbox` object of the answer: the description file's stem, the built-in rig's id, or
/// the table's gearbox name.
fn gearbox_ref(a: &DiagnoseArgs, gearbox: &crate::gearbox::Gearbox, table: bool) -> GearboxRef {
    GearboxRef {
        id: match &a.gearbox {
            Some(p) => p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            None if gearbox.name() == crate::gearbox::Gearbox::paper_rig().name() => {
                crate::machine::BUILTIN_GEARBOX_ID.to_string()
            }
            None => gearbox.name().to_string(),
        },
        name: gearbox.name().to_string(),
        hash: gearbox.hash.clone(),
        table_status: if table {
            TableStatus::Ready
        } else {
            TableStatus::Missing
        },
        table_progress: if table { 1.0 } else { 0.0 },
    }
}

/// The signature table's diagnoser: `--table`, else the gearbox's table over the speeds the
/// baseline and the record ran at, from the cache (computed or extended as needed; with
/// `--cached-only` only what is there). Without one — the speeds would need more simulations
/// than a table may take, or nothing cached covers them — and with a baseline to judge the
/// record: none, with the note that says why there is no wear figure.
fn table_for(
    a: &DiagnoseArgs,
    gb: &Gearbox,
    files: &[BaselineFile],
    rec: &Loaded,
    opts: &ReadOptions,
    load: &Option<Load>,
) -> Result<(Option<TableDiagnoser>, Option<String>)> {
    let baseline = !files.is_empty();
    let diagnose_opts = DiagnoseOptions {
        credible_level: a.level,
        ..Default::default()
    };
    if a.table.is_some() {
        let t = load_table(a.gearbox.as_deref(), a.table.as_deref(), a.allow_stale)?;
        return Ok((Some(TableDiagnoser::new(t, diagnose_opts)?), None));
    }
    let spans = record_spans(a, gb, files, rec, opts, load);
    let table = if a.cached_only {
        cache::cached_table(gb, &spans).ok_or_else(|| {
            anyhow::anyhow!(
                "no cached or committed table of `{}` covers the records' speeds (--cached-only)",
                gb.name()
            )
        })
    } else {
        cache::table_for(gb, &spans)
    };
    match table {
        Ok(t) => Ok((Some(TableDiagnoser::new(t, diagnose_opts)?), None)),
        Err(e) if baseline => Ok((
            None,
            Some(format!(
                "no wear figure: {e:#}; the record is judged against its baseline only"
            )),
        )),
        Err(e) => Err(e),
    }
}

/// The spans of input-shaft rates the table must cover: each baseline record's and the
/// record's measured rate (tachometer, else tacho-less around its declared rate), else its
/// declared rate's span; none for a record whose rate is neither measured nor declared.
fn record_spans(
    a: &DiagnoseArgs,
    gb: &Gearbox,
    files: &[BaselineFile],
    rec: &Loaded,
    opts: &ReadOptions,
    load: &Option<Load>,
) -> Vec<SpeedSpan> {
    let empty = Baselines::default();
    let m = Machine::described("cli", gb, None, &empty);
    let span = |l: &Loaded, hz: Option<f64>, ld: Option<Load>| -> Option<SpeedSpan> {
        let facts = facts_of(l, hz, ld, false);
        measure_record(&l.channels, &l.chosen, &facts, &m)
            .ok()
            .and_then(|s| s.state)
            .map(|s| SpeedSpan::measured(s.shaft_hz))
            .or(hz.map(SpeedSpan::configured))
    };
    let mut spans: Vec<SpeedSpan> = files
        .iter()
        .filter_map(|f| {
            let l = load_record(&f.path, a, opts).ok()?;
            span(&l, f.shaft_hz.or(a.shaft_hz), f.load.clone())
        })
        .collect();
    spans.extend(span(rec, a.shaft_hz, load.clone()));
    spans
}

/// The machine's own model from the baseline's line ratios (none with `--no-own-model`,
/// without a table, or when the fit is refused — said on stderr and in `--physics-report`).
fn own_model_for(
    a: &DiagnoseArgs,
    gb: &Gearbox,
    diagnoser: Option<&TableDiagnoser>,
    ratios: &BTreeMap<String, Vec<LineRatios>>,
) -> Result<Option<OwnModel>> {
    let Some(d) = diagnoser.filter(|_| !a.no_own_model) else {
        return Ok(None);
    };
    let enough = ratios.values().any(|r| r.len() >= MIN_PHYSICS_RECORDS);
    if !enough {
        return Ok(None);
    }
    let (fit, model) = cache::own_model(gb, d.table(), &d.options(None), ratios, !a.cached_only)?;
    if let Some(path) = &a.physics_report {
        std::fs::write(path, serde_json::to_string_pretty(&fit)?)
            .with_context(|| format!("writing the physics report {}", path.display()))?;
    }
    if let cache::CachedFit::Refused { reason } = &fit {
        eprintln!("the machine's own model is not used: {reason}");
    }
    Ok(model)
}

fn facts_of(rec: &Loaded, shaft_hz: Option<f64>, load: Option<Load>, healthy: bool) -> RecordFacts {
    RecordFacts {
        sample_rate_hz: rec.sample_rate_hz,
        shaft_hz,
        sensor: None,
        declared_healthy: healthy,
        load,
        tacho: rec.tacho.clone(),
    }
}

/// The healthy records: the `--baseline` files (at the command line's --shaft-hz and --load)
/// and the `--baseline-manifest`'s.
fn baseline_files(a: &DiagnoseArgs, load: &Option<Load>) -> Result<Vec<BaselineFile>> {
    let mut files: Vec<BaselineFile> = a
        .baseline
        .iter()
        .map(|p| BaselineFile {
            path: p.clone(),
            shaft_hz: a.shaft_hz,
            load: load.clone(),
        })
        .collect();
    if let Some(m) = &a.baseline_manifest {
        files.extend(baseline::read_manifest(m)?);
    }
    Ok(files)
}

/// A record's channels to assess (the `--column`s, else every channel but the tachometer)
/// and its tachometer. One column and no tachometer: read as a single-channel record (a
/// `time,value` CSV, a WAV's first channel), named by `--column` or `"0"`.
fn load_record(path: &std::path::Path, a: &DiagnoseArgs, opts: &ReadOptions) -> Result<Loaded> {
    if a.tacho_column.is_none() && a.column.len() <= 1 {
        let opts = ReadOptions {
            column: a.column.first().map(|c| Column::parse(c)),
            ..opts.clone()
        };
        let r = read_record(path, &opts)?;
        return Ok(Loaded {
            channels: vec![(a.column.first().cloned().unwrap_or("0".into()), r.samples)],
            chosen: vec![0],
            sample_rate_hz: r.sample_rate,
            tacho: None,
        });
    }
    let m = read_record_channels_with_pulses(path, opts, a.tacho_column.as_deref())?;
    let tacho = match &a.tacho_column {
        Some(t) => Some(TachoChannel {
            name: m.channel(t)?.name.clone(),
            pulses_per_rev: a.tacho_ppr,
        }),
        None => None,
    };
    let names = m.names();
    let chosen: Vec<usize> = if a.column.is_empty() {
        (0..names.len())
            .filter(|&i| tacho.as_ref().is_none_or(|t| t.name != names[i]))
            .collect()
    } else {
        a.column
            .iter()
            .map(|c| {
                let n = &m.channel(c)?.name;
                Ok(names.iter().position(|x| x == n).unwrap_or(0))
            })
            .collect::<Result<_>>()?
    };
    if chosen.is_empty() {
        bail!(
            "{} has no channel to assess besides the tachometer",
            path.display()
        );
    }
    Ok(Loaded {
        channels: m
            .channels
            .into_iter()
            .map(|c| (c.name, c.samples))
            .collect(),
        chosen,
        sample_rate_hz: m.sample_rate,
        tacho,
    })
}

/// The library's errors speak of quantities; on the command line, name the flag that gives it.
fn with_flag_hint(e: crate::Error) -> anyhow::Error {
    match e {
        crate::Error::NoMeshLine { .. } => {
            anyhow::anyhow!("{e}; give --shaft-hz if the input-shaft speed is known")
        }
        crate::Error::SpeedNotMeasured(_) => anyhow::anyhow!(
            "{e}; give the tachometer's column (--tacho-column NAME --tacho-ppr N) or the \
             nominal input-shaft rate (--shaft-hz)"
        ),
        crate::Error::TooFewSamples { .. } | crate::Error::TooFewRevolutions { .. } => {
            anyhow::anyhow!("{e}: give a longer record")
        }
        e => e.into(),
    }
}

/// A machine's calibration from the JSON of `GET /v1/machines/{id}/calibration` (or of the
/// `POST` that made it): its `id`, `created_at` and accepted `effects`.
fn read_calibration(path: &std::path::Path) -> Result<MachineCalibration> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the calibration {}", path.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("the calibration {} is not JSON", path.display()))?;
    let field = |k: &str| -> Result<String> {
        v[k].as_str().map(str::to_string).with_context(|| {
            format!(
                "the calibration {} has no `{k}`: give the JSON of GET \
                 /v1/machines/{{id}}/calibration",
                path.display()
            )
        })
    };
    if !v["effects"].is_array() {
        bail!(
            "the calibration {} has no `effects` list: give the JSON of GET \
             /v1/machines/{{id}}/calibration",
            path.display()
        );
    }
    Ok(MachineCalibration {
        id: field("id")?,
        calibrated_at: field("created_at")?,
        effects: v["effects"].clone(),
    })
}
