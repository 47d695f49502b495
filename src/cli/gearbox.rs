//! The `gearbox` command group: check a description, show what it resolves to, print its
//! kinematics.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, Subcommand};

use super::common::load_gearbox;
use crate::signature::line_set::gearbox_line_set;
use crate::signature::precompute::default_grid;

#[derive(Debug, Args)]
pub struct GearboxArgs {
    #[command(subcommand)]
    pub command: GearboxCommand,
}

#[derive(Debug, Subcommand)]
pub enum GearboxCommand {
    /// Every shaft rate and mesh frequency at an input-shaft rate (JSON).
    Kinematics(KinematicsArgs),
    /// Validate a description and show what it resolves to: the assumed values, the model's
    /// reference frequency, the measured lines and the default signature grid (JSON).
    Show(ShowArgs),
}

#[derive(Debug, Args)]
pub struct KinematicsArgs {
    /// Gearbox description, TOML or JSON (default: the first paper's rig).
    #[arg(long, value_name = "FILE")]
    pub gearbox: Option<PathBuf>,
    /// Input-shaft rate in Hz.
    #[arg(long)]
    pub input_hz: f64,
}

#[derive(Debug, Args)]
pub struct ShowArgs {
    /// Gearbox description, TOML or JSON (default: the first paper's rig).
    #[arg(long, value_name = "FILE")]
    pub gearbox: Option<PathBuf>,
}

/// `gearwear gearbox …`.
pub fn run(a: GearboxArgs) -> Result<()> {
    match a.command {
        GearboxCommand::Kinematics(k) => {
            if !(k.input_hz.is_finite() && k.input_hz > 0.0) {
                bail!(
                    "--input-hz must be a positive rate in Hz, got {}",
                    k.input_hz
                );
            }
            let gb = load_gearbox(k.gearbox.as_deref())?;
            let mut v = serde_json::to_value(gb.kinematics(k.input_hz))?;
            v["gearbox"] = serde_json::json!(gb.name());
            if !gb.warnings.is_empty() {
                v["warnings"] = serde_json::json!(gb.warnings);
            }
            println!("{}", serde_json::to_string_pretty(&v)?);
        }
        GearboxCommand::Show(s) => {
            let gb = load_gearbox(s.gearbox.as_deref())?;
            let f_ref = gb.reference_frequency_hz();
            let v = serde_json::json!({
                "name": gb.name(),
                "hash": gb.hash,
                "valid": true,
                "warnings": gb.warnings,
                "dynamics_estimated": gb.dynamics_estimated(),
                "reference_frequency_hz": f_ref,
                "input_hz_at_omega1_1": f_ref / gb.f1_hz(1.0),
                "mesh_ratios": gb.mesh_ratios,
                "wear_stages": gb.wear_stages(),
                "sensor_element": gb.physics.meshes[gb.physics.sensor_element].name,
                "lines": gearbox_line_set(&gb),
                "default_grid": default_grid(&gb),
                "assumed": gb.assumed,
                "coordinates": gb.physics.dofs,
                "meshes": gb.physics.meshes,
                "description": gb.description,
            });
            println!("{}", serde_json::to_string_pretty(&v)?);
        }
    }
    Ok(())
}
