//! # gearwear-core
//!
//! The numeric core of gearwear: everything from a record's samples to an assessment of the
//! gearbox, with no async runtime, HTTP or SQL in it (the product crate at the repository's top
//! level wraps it in a CLI and a service; figures are in `gearwear-plot`).
//!
//! A short tour, from the bottom up:
//! - [`record`]: record formats (CSV, gzip, raw f32, WAV, multichannel) and their checks.
//! - [`signal`]: windows and amplitude spectra (one-sided peak amplitude scaling), the line
//!   estimator ([`signal::lines`]) that the signature table, the diagnosis and the closed loop
//!   share, order tracking and TSA.
//! - [`model`]: lumped-parameter gear-train elements (bodies, meshes, shafts, bearings, loads),
//!   one generic assembly into the relative-coordinate form `ẍ + A F(x, ẋ, t) = F̄ − ë`, and the
//!   second paper's rig as a configuration of it.
//! - [`solver`]: an adaptive Dormand–Prince 5(4) integrator with dense output and exact location
//!   of the backlash contact switches, a Rosenbrock stiff solver and a fixed-step RK4 reference.
//! - [`gearbox`]: any gearbox described from its tooth counts, resolved to a model.
//! - [`analysis`]: characteristic frequencies, motion-state classification, bifurcation sweeps,
//!   single-run simulations with spectra.
//! - [`signature`]: the model's line set, the gain-invariant features and the precomputed
//!   signature table.
//! - [`diagnosis`]: one record against the signature table: wear degree with an interval.
//! - [`novelty`]: features of a record (order tracking, TSA metrics, band levels), a machine's
//!   healthy baseline and the novelty score against it.
//! - [`closed_loop`]: fit, residual, attribution to an effect of the library, refit.
//! - [`units`]: a channel's declared unit and its conversion to SI; acceleration RMS and peak,
//!   velocity RMS over 10–1000 Hz and the ISO 20816-3 zone.

// Numeric kernels index several arrays with one loop variable; iterator chains would hide the
// equations. `!(x > 0.0)` is used on purpose: it is true for NaN, which must be refused too.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod analysis;
pub mod assessment;
pub mod closed_loop;
pub mod condition;
pub mod diagnosis;
pub mod error;
pub mod gearbox;
pub mod machine;
pub mod model;
pub mod novelty;
pub mod quality_finding;
pub mod record;
pub mod signal;
pub mod signature;
pub mod solver;
pub mod trend;
pub mod units;
pub mod words;

pub use error::{Error, Result};
