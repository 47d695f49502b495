//! The `model` and `frequencies` commands: the resolved Model A and its characteristic
//! frequencies.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};

use super::common::{RigArgs, wear, write_or_print};
use crate::model::export::ModelExport;

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ExportFormat {
    Json,
}

#[derive(Debug, Args)]
pub struct ModelArgs {
    /// Export format.
    #[arg(long, value_enum, default_value_t = ExportFormat::Json)]
    pub export: ExportFormat,
    /// Wear degree ea used for the error amplitudes.
    #[arg(long, default_value_t = 0.1)]
    pub ea: f64,
    /// Output file (default: stdout).
    #[arg(long)]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
}

#[derive(Debug, Args)]
pub struct FrequenciesArgs {
    /// Motor (input shaft) rate in Hz, to print absolute frequencies too.
    #[arg(long)]
    pub shaft_hz: Option<f64>,
    #[command(flatten)]
    pub rig: RigArgs,
}

/// `gearwear model`.
pub fn model_cmd(a: ModelArgs) -> Result<()> {
    let cfg = a.rig.load()?;
    let model = cfg.assembly(wear(&a.rig, a.ea)?)?.resolve()?;
    let ExportFormat::Json = a.export;
    let export = ModelExport::new(&model, &cfg);
    write_or_print(a.output.as_deref(), &serde_json::to_string_pretty(&export)?)
}

/// `gearwear frequencies`.
pub fn frequencies_cmd(a: FrequenciesArgs) -> Result<()> {
    let cfg = a.rig.load()?;
    let fr = cfg.tooth_counts().frequencies();
    let mut v = serde_json::to_value(fr)?;
    if let Some(hz) = a.shaft_hz {
        if !(hz.is_finite() && hz > 0.0) {
            bail!("--shaft-hz must be a positive rate in Hz, got {hz}");
        }
        let f1 = cfg.f1_hz(hz);
        let abs: serde_json::Map<String, serde_json::Value> = v
            .as_object()
            .expect("struct serialises to an object")
            .iter()
            .map(|(k, r)| (k.clone(), serde_json::json!(r.as_f64().unwrap_or(0.0) * f1)))
            .collect();
        v = serde_json::json!({ "ratio_to_f1": v, "hz": abs, "shaft_hz": hz });
    }
    println!("{}", serde_json::to_string_pretty(&v)?);
    Ok(())
}
