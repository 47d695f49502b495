//! Integrating Model B: the solver choice and its settings, and the edge-aware system that
//! tells the integrator where the stiffness steps and contact switches are.

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::model::{DimensionlessModel, StiffnessShape};
use crate::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Rodas4, Rodas4Options, Stats, sample_uniform,
};

/// Which integrator to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SolverKind {
    /// Explicit Dormand–Prince 5(4).
    Dopri5,
    /// Linearly implicit Rosenbrock RODAS4 (stiff).
    Rodas4,
}

/// Integrator and tolerances (on the dimensionless state: deflections in units of `b_ref`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SolverSettings {
    pub kind: SolverKind,
    pub rtol: f64,
    pub atol: f64,
}

impl Default for SolverSettings {
    /// RODAS4 at `rtol = 1e-6`, `atol = 1e-8`.
    fn default() -> Self {
        SolverSettings {
            kind: SolverKind::Rodas4,
            rtol: 1e-6,
            atol: 1e-8,
        }
    }
}

/// Integrate `sys` from `(0, y0)` and hand the samples on the grid `t0 + k dt ≤ t_end` (all in
/// τ) to `on_sample`. Returns the counters.
pub fn integrate<S: OdeSystem>(
    sys: &S,
    y0: &[f64],
    solver: &SolverSettings,
    t0: f64,
    dt: f64,
    t_end: f64,
    on_sample: impl FnMut(usize, f64, &[f64]),
) -> Result<Stats> {
    match solver.kind {
        SolverKind::Dopri5 => {
            let opts = Dopri5Options {
                rtol: solver.rtol,
                atol: solver.atol,
                ..Default::default()
            };
            let mut integ = Dopri5::new(sys, 0.0, y0, opts)?;
            sample_uniform(&mut integ, t0, dt, t_end, on_sample)?;
            Ok(integ.stats())
        }
        SolverKind::Rodas4 => {
            let opts = Rodas4Options {
                rtol: solver.rtol,
                atol: solver.atol,
                ..Default::default()
            };
            let mut integ = Rodas4::new(sys, 0.0, y0, opts)?;
            sample_uniform(&mut integ, t0, dt, t_end, on_sample)?;
            Ok(integ.stats())
        }
    }
}

/// A right-hand side with the square-wave stiffness edges added as breakpoints.
///
/// A contact-ratio edge lasts `smoothing` of a mesh period (33 µs at stage 1), i.e. a few
/// dimensionless time units, while a stiff solver on the quasi-static stretches between edges
/// takes steps of 10⁴ and more: without help it steps straight over an edge and never sees the
/// shock. The integrators land exactly on each breakpoint, so placing them at `e − 3w`, `e`,
/// `e + 3w` for every edge `e` (width `w`) forces steps no longer than `3w` across the edge;
/// the error control then resolves the ringing that follows. The explicit solver's steps are
/// shorter than an edge anyway; it gets the same breakpoints for a like-for-like comparison.
pub struct EdgeAware<'a, S: OdeSystem> {
    inner: &'a S,
    breaks: Vec<f64>,
}

impl<'a, S: OdeSystem> EdgeAware<'a, S> {
    /// Breakpoints of `inner` plus the square-wave edges of `model` at `Ω1` inside `(0, t_end)`.
    pub fn new(inner: &'a S, model: &DimensionlessModel, omega1: f64, t_end: f64) -> Self {
        use std::f64::consts::TAU;
        let mut breaks = inner.breakpoints();
        for j in 0..model.n() {
            let StiffnessShape::SquareWave {
                contact_ratio,
                smoothing,
                ..
            } = model.shape[j]
            else {
                continue;
            };
            let w = model.omega_ratio[j] * omega1;
            if w <= 0.0 {
                continue;
            }
            let period = TAU / w;
            let width = smoothing * period;
            let shift = model.phase[j] / w;
            let k_max = (t_end / period).ceil() as i64 + 1;
            for k in -1..=k_max {
                for u in [0.0, contact_ratio - 1.0] {
                    let e = (k as f64 + u) * period - shift;
                    for t in [e - 3.0 * width, e, e + 3.0 * width] {
                        if t > 0.0 && t < t_end {
                            breaks.push(t);
                        }
                    }
                }
            }
        }
        breaks.sort_by(f64::total_cmp);
        breaks.dedup();
        EdgeAware { inner, breaks }
    }
}

impl<S: OdeSystem> OdeSystem for EdgeAware<'_, S> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        self.inner.rhs(t, y, dy)
    }
    fn n_switches(&self) -> usize {
        self.inner.n_switches()
    }
    fn switches(&self, t: f64, y: &[f64], g: &mut [f64]) {
        self.inner.switches(t, y, g)
    }
    fn breakpoints(&self) -> Vec<f64> {
        self.breaks.clone()
    }
}
