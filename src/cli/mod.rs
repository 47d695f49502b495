//! Command-line interface: argument parsing and dispatch. Every command is a thin wrapper
//! around library functions; `main` only calls [`run`].
//!
//! One file per command group, each with its argument structs and bodies: [`simulate`]
//! (`simulate`, `bifurcation`, `wear-lines`), [`model`] (`model`, `frequencies`), [`gearbox`],
//! [`synth`],
//! [`diagnose`] (`precompute`, `diagnose`), [`calibrate`] and [`model_b`]; what they share
//! (rig and solver options, grids, output) is in [`common`], which they import and never each
//! other. `serve` and `keys` live with the service, in [`crate::service::cli`].

use anyhow::Result;
use clap::{Parser, Subcommand};

pub mod alerts;
pub mod baseline;
pub mod cache;
pub mod calibrate;
pub mod common;
pub mod diagnose;
pub mod gearbox;
pub mod machine;
pub mod model;
pub mod model_b;
pub mod simulate;
pub mod synth;
pub mod units;

pub use common::{RigArgs, SolveArgs, parse_range};

/// gearwear: gearbox wear from one accelerometer record, by simulating the gearbox.
#[derive(Debug, Parser)]
#[command(name = "gearwear", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Describe a gearbox: validate a description, show what it resolves to, its kinematics.
    Gearbox(gearbox::GearboxArgs),
    /// Simulate a gearbox (default: the first paper's rig) at one (Ω1, ea): lines, motion
    /// state, plots.
    Simulate(simulate::SimulateArgs),
    /// Bifurcation diagram over Ω1 (the first seed's Figure 2).
    Bifurcation(simulate::BifurcationArgs),
    /// Print or export the resolved dimensionless model.
    Model(model::ModelArgs),
    /// Characteristic frequencies of a gearbox (the first seed's Table 2 for its rig).
    Frequencies(model::FrequenciesArgs),
    /// Line amplitudes of x̄1 versus wear at one Ω1 (the first seed's Figure 17).
    WearLines(simulate::WearLinesArgs),
    /// Write a virtual accelerometer record (the model plus optional effects, gain and noise)
    /// to try `diagnose`, `calibrate` or the service with.
    Synth(synth::SynthArgs),
    /// The second seed's 10-DOF space drive (Model B).
    ModelB(model_b::ModelBArgs),
    /// Run the wear-diagnosis HTTP service (API v1, dashboard, webhooks).
    Serve(crate::service::cli::ServeArgs),
    /// Create, list and revoke the service's API keys.
    Keys(crate::service::cli::KeysArgs),
    /// A machine's configuration in the service's database: its gearbox, input-shaft rate,
    /// channels.
    Machine(machine::MachineArgs),
    /// The service's alerts in its database: list them, acknowledge one with a note.
    Alerts(alerts::AlertsArgs),
    /// Simulate the signature table for diagnosis (ea × Ω1 × seeds).
    Precompute(diagnose::PrecomputeArgs),
    /// Estimate the wear degree from an accelerometer record.
    Diagnose(diagnose::DiagnoseArgs),
    /// Close the loop: fit, residual, effect attribution, refit (JSON report, plots).
    Calibrate(calibrate::CalibrateArgs),
}

/// Run the CLI.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Gearbox(a) => gearbox::run(a),
        Command::Simulate(a) => simulate::simulate_cmd(a),
        Command::Bifurcation(a) => simulate::bifurcation_cmd(a),
        Command::Model(a) => model::model_cmd(a),
        Command::Frequencies(a) => model::frequencies_cmd(a),
        Command::WearLines(a) => simulate::wear_lines_cmd(a),
        Command::Synth(a) => synth::synth_cmd(a),
        Command::ModelB(a) => model_b::run(a),
        Command::Serve(a) => crate::service::cli::serve_cmd(a),
        Command::Keys(a) => crate::service::cli::keys_cmd(a),
        Command::Machine(a) => machine::run(a),
        Command::Alerts(a) => alerts::run(a),
        Command::Precompute(a) => diagnose::precompute_cmd(a),
        Command::Diagnose(a) => diagnose::diagnose_cmd(a),
        Command::Calibrate(a) => calibrate::calibrate_cmd(a),
    }
}
