//! # gearwear
//!
//! The product crate: the `gearwear` CLI and the HTTP service around the numeric core.
//!
//! - [`gearwear_core`] (re-exported here module by module, so `gearwear::diagnosis` and
//!   `gearwear_core::diagnosis` are the same thing): records, signal processing, models,
//!   solvers, gearboxes, signature tables, diagnosis, novelty, the closed loop, units.
//! - [`gearwear_plot`] (re-exported as [`plot`]): figures.
//! - [`cli`]: the subcommands.
//! - [`service`]: the HTTP API, the dashboard and the webhooks; [`store`]: SQLite and
//!   PostgreSQL behind one trait; [`keys`]: API keys; [`configuration`], [`database`] (where
//!   the database is), [`telemetry`]; [`views`]: the JSON of stored rows and of webhook
//!   events, shared by the API and the CLI.

// Numeric kernels index several arrays with one loop variable; iterator chains would hide the
// equations. `!(x > 0.0)` is used on purpose: it is true for NaN, which must be refused too.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub use gearwear_core::{
    Error, Result, analysis, assessment, closed_loop, condition, diagnosis, error, gearbox,
    machine, model, novelty, record, signal, signature, solver, trend, units,
};
pub use gearwear_plot as plot;
pub use gearwear_store::{self as store, time};

pub mod cli;
pub mod configuration;
pub mod database;
pub mod keys;
pub mod service;
pub mod telemetry;
pub mod views;

/// The async runtime the CLI's store calls and `serve` run on.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    use anyhow::Context;
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}
