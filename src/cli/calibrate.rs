//! `gearwear calibrate`: the closed loop on a record file (anyhow here, the library is
//! [`crate::closed_loop`]).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::common::load_table;
use crate::closed_loop::{CalibrateOptions, CalibrationReport, calibrate};
use crate::diagnosis::DiagnoseOptions;
use crate::plot::{Panel, Series, panels};
use crate::record::{Column, ReadOptions, read_record};

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Record file (CSV — `.gz` ok —, raw f32 or WAV; see `gearwear diagnose`).
    #[arg(long)]
    pub input: PathBuf,
    /// Sample rate in Hz (required for f32 and CSV without a time column).
    #[arg(long)]
    pub sample_rate: Option<f64>,
    /// Input (motor) shaft rate in Hz; without it f1 is found in the spectrum.
    #[arg(long)]
    pub shaft_hz: Option<f64>,
    /// CSV column (0-based index or header name) or WAV channel.
    #[arg(long)]
    pub column: Option<String>,
    /// Signature table (default: the gearbox's, `signatures/model_a_accel.json` for the
    /// paper's rig).
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// Gearbox description the table must match (default: the paper's rig, or the table's own
    /// when only --table is given).
    #[arg(long, value_name = "FILE")]
    pub gearbox: Option<PathBuf>,
    /// Write the JSON report here (default: stdout).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Write the figures (spectra, residuals) into this directory.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// `gearwear calibrate`.
pub fn calibrate_cmd(a: CalibrateArgs) -> Result<()> {
    let table = load_table(a.gearbox.as_deref(), a.table.as_deref(), false)?;
    let record = read_record(
        &a.input,
        &ReadOptions {
            format: None,
            sample_rate: a.sample_rate,
            column: a.column.as_deref().map(Column::parse),
        },
    )?;
    let opts = CalibrateOptions {
        diagnose: DiagnoseOptions {
            shaft_hz: a.shaft_hz,
            ..Default::default()
        },
        ..Default::default()
    };
    let rep = calibrate(&record, &table, &opts)?;
    let json = serde_json::to_string_pretty(&rep)?;
    match &a.output {
        Some(p) => std::fs::write(p, json).with_context(|| format!("writing {}", p.display()))?,
        None => println!("{json}"),
    }
    if let Some(dir) = &a.plot {
        plot_report(&rep, dir)?;
    }
    Ok(())
}

/// Two panels: measured / fitted before / fitted after (dB re f1), and the residuals with the
/// smooth trend.
pub fn plot_report(rep: &CalibrationReport, dir: &std::path::Path) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    let s = &rep.spectra;
    let x = &s.frequency_ratio;
    let top = Panel {
        title: "Measured and fitted spectra",
        x_label: "f / f1",
        y_label: "dB re measured f1",
        series: vec![
            Series {
                label: "measured",
                x,
                y: &s.measured_db,
            },
            Series {
                label: "fitted before",
                x,
                y: &s.fitted_before_db,
            },
            Series {
                label: "fitted after",
                x,
                y: &s.fitted_after_db,
            },
        ],
        dots: false,
        log_y: false,
        markers: vec![],
    };
    let bottom = Panel {
        title: "Residual (measured − fitted)",
        x_label: "f / f1",
        y_label: "dB",
        series: vec![
            Series {
                label: "before",
                x,
                y: &s.residual_before_db,
            },
            Series {
                label: "after",
                x,
                y: &s.residual_after_db,
            },
            Series {
                label: "trend after",
                x,
                y: &s.trend_after_db,
            },
        ],
        dots: false,
        log_y: false,
        markers: vec![],
    };
    let title = format!(
        "Closed loop: error {:.2} → {:.2} dB, effects: {}",
        rep.error_before,
        rep.error_after,
        if rep.effects.is_empty() {
            "none".to_string()
        } else {
            rep.effects
                .iter()
                .map(|e| e.name.as_str())
                .collect::<Vec<_>>()
                .join(" + ")
        }
    );
    panels(&dir.join("calibration.png"), &title, 2, 1, &[top, bottom])?;
    Ok(())
}
