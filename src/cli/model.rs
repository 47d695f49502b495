//! The `model` and `frequencies` commands: the resolved model of a gearbox and its
//! characteristic frequencies.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};

use super::common::{RigArgs, wear, write_or_print};
use crate::gearbox::export::ModelExport;

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
    let gb = a.rig.load()?;
    let model = gb.assembly(wear(&a.rig, a.ea)?)?.resolve()?;
    let ExportFormat::Json = a.export;
    let export = ModelExport::new(&model, &gb);
    write_or_print(a.output.as_deref(), &serde_json::to_string_pretty(&export)?)
}

/// `gearwear frequencies`.
pub fn frequencies_cmd(a: FrequenciesArgs) -> Result<()> {
    let gb = a.rig.load()?;
    // Ratios to f1: the report lines, then every shaft's rate (`shaft_<name>`).
    let mut ratios = serde_json::Map::new();
    for (name, r) in gb.report_lines() {
        ratios.insert(name, serde_json::json!(r));
    }
    for (name, r) in gb.shaft_ratios() {
        ratios.insert(format!("shaft_{name}"), serde_json::json!(r.abs()));
    }
    for p in gb.kinematics(gb.input_shaft_ratio()).planetary {
        ratios.insert(
            format!("planet_spin_stage{}", p.stage),
            serde_json::json!(p.planet_spin_hz),
        );
        ratios.insert(
            format!("planet_pass_stage{}", p.stage),
            serde_json::json!(p.planet_pass_hz),
        );
    }
    let mut v = serde_json::json!({ "gearbox": gb.name(), "ratio_to_f1": ratios });
    if let Some(hz) = a.shaft_hz {
        if !(hz.is_finite() && hz > 0.0) {
            bail!("--shaft-hz must be a positive rate in Hz, got {hz}");
        }
        let f1 = gb.f1_hz(hz);
        let abs: serde_json::Map<String, serde_json::Value> = ratios
            .iter()
            .map(|(k, r)| (k.clone(), serde_json::json!(r.as_f64().unwrap_or(0.0) * f1)))
            .collect();
        v["hz"] = serde_json::json!(abs);
        v["shaft_hz"] = serde_json::json!(hz);
        v["kinematics"] = serde_json::to_value(gb.kinematics(hz))?;
    }
    println!("{}", serde_json::to_string_pretty(&v)?);
    Ok(())
}
