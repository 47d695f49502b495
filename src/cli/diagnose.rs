//! The `precompute` and `diagnose` commands (argument structs and bodies; [`crate::cli`]
//! dispatches to them).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};

use super::common::{RigArgs, default_table_for, load_table, parse_range, progress_bar};
use crate::analysis::bifurcation::grid;
use crate::diagnosis::{DiagnoseOptions, diagnose};
use crate::novelty::{MIN_BASELINE_RECORDS, MachineBaseline, record_features};
use crate::record::{Column, Format, ReadOptions, read_record};
use crate::signal::lines::SEGMENT_PERIODS;
use crate::signature::SensorQuantity;
use crate::signature::precompute::{
    PrecomputeSpec, default_grid, paper_grid, partial_path, precompute,
};
use crate::signature::table::SimulationSettings;

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
    /// found in the spectrum.
    #[arg(long)]
    pub shaft_hz: Option<f64>,
    /// CSV column (0-based index or header name) or WAV channel.
    #[arg(long)]
    pub column: Option<String>,
    /// File format (default: from the extension).
    #[arg(long, value_enum)]
    pub format: Option<FormatArg>,
    /// Signature table (default: the committed `signatures/model_a_accel.json` for the paper's
    /// rig, `signatures/<name>.json` for a described gearbox).
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
    /// least three (`--baseline a.csv --baseline b.csv …`). The diagnosis then carries
    /// `novelty`: the record's score against these records' features, the threshold calibrated
    /// on them by leave-one-out, and the features that deviate most.
    #[arg(long, value_name = "FILE")]
    pub baseline: Vec<PathBuf>,
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

/// `gearwear diagnose`.
pub fn diagnose_cmd(a: DiagnoseArgs) -> Result<()> {
    let table = load_table(a.gearbox.as_deref(), a.table.as_deref(), a.allow_stale)?;
    let opts = ReadOptions {
        format: a.format.map(|f| match f {
            FormatArg::Csv => Format::Csv,
            FormatArg::F32 => Format::F32,
            FormatArg::Wav => Format::Wav,
        }),
        sample_rate: a.sample_rate,
        column: a.column.as_deref().map(Column::parse),
    };
    let record = read_record(&a.input, &opts)?;
    // Baseline first: a wrong baseline file should fail before the diagnosis runs.
    let baseline = if a.baseline.is_empty() {
        None
    } else {
        // Order tracking needs the gearbox's tooth counts: only with a description.
        let gb = a.gearbox.is_some().then(|| table.gearbox());
        let mut feats = Vec::with_capacity(a.baseline.len());
        for path in &a.baseline {
            let rec = read_record(path, &opts)
                .with_context(|| format!("baseline record {}", path.display()))?;
            feats.push(
                record_features(&rec, gb, a.shaft_hz)
                    .with_context(|| format!("baseline record {}", path.display()))?,
            );
        }
        let b = MachineBaseline::fit(&feats).with_context(|| {
            format!(
                "{} --baseline file(s) given; give at least {MIN_BASELINE_RECORDS} healthy \
                 records of the machine",
                a.baseline.len()
            )
        })?;
        let f = record_features(&record, gb, a.shaft_hz)?;
        Some(b.score(&f))
    };
    let d = diagnose(
        &record,
        &table,
        &DiagnoseOptions {
            shaft_hz: a.shaft_hz,
            credible_level: a.level,
            ..Default::default()
        },
    )?;
    /// The diagnosis's fields in their order, then `novelty`.
    #[derive(serde::Serialize)]
    struct WithNovelty<'a> {
        #[serde(flatten)]
        diagnosis: &'a crate::diagnosis::Diagnosis,
        novelty: crate::novelty::Novelty,
    }
    let json = match baseline {
        Some(novelty) => serde_json::to_string_pretty(&WithNovelty {
            diagnosis: &d,
            novelty,
        })?,
        None => serde_json::to_string_pretty(&d)?,
    };
    println!("{json}");
    Ok(())
}
