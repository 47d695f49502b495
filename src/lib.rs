//! # gearwear
//!
//! Gearbox wear diagnosis from one accelerometer record, by simulating the gearbox's
//! nonlinear dynamics (backlash, time-varying mesh stiffness, composite transmission error).
//!
//! A short tour:
//! - [`model`]: lumped-parameter gear-train elements (bodies, meshes, shafts, bearings, loads),
//!   one generic assembly into the relative-coordinate form `ẍ + A F(x, ẋ, t) = F̄ − ë`, and the
//!   two paper rigs as configurations of it.
//! - [`solver`]: an adaptive Dormand–Prince 5(4) integrator with dense output and exact location
//!   of the backlash contact switches, and a fixed-step RK4 reference.
//! - [`analysis`]: characteristic frequencies, motion-state classification, bifurcation sweeps,
//!   single-run simulations with spectra.
//! - [`signal`]: windows and amplitude spectra (one-sided peak amplitude scaling), and the line
//!   estimator ([`signal::lines`]) that the signature table, the diagnosis and the closed loop
//!   share.
//! - [`signature`]: the model's line set, the gain-invariant features and the precomputed
//!   signature table.
//! - [`novelty`]: features of a record (order tracking, TSA metrics, band levels), a machine's
//!   healthy baseline and the novelty score against it.
//! - [`plot`]: PNG/SVG figures (plotters, embedded font: no system font needed).
//!
//! The numeric modules import nothing from a web framework or a database.

// Numeric kernels index several arrays with one loop variable; iterator chains would hide the
// equations. `!(x > 0.0)` is used on purpose: it is true for NaN, which must be refused too.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod analysis;
pub mod cli;
pub mod closed_loop;
pub mod configuration;
pub mod diagnosis;
pub mod error;
#[doc(hidden)]
pub mod fuzzing;
pub mod gearbox;
pub mod keys;
pub mod model;
pub mod novelty;
pub mod plot;
pub mod record;
pub mod service;
pub mod signal;
pub mod signature;
pub mod solver;
pub mod store;
pub mod telemetry;

pub use error::{Error, Result};
