//! ODE solvers for the gear models.
//!
//! - [`Dopri5`]: adaptive Dormand–Prince 5(4) with Hairer's 4th-order dense output and
//!   location of the contact switches of piecewise-smooth systems (backlash): a step that
//!   would carry a switch inside it is shortened so that it ends on the switch, so every step
//!   integrates one smooth piece and keeps its order.
//! - [`Rk4`]: classical fixed-step Runge–Kutta, the plain reference.
//! - [`Rodas4`]: L-stable Rosenbrock 4(3) with a finite-difference Jacobian, dense output and
//!   the same switch location, for stiff models (Model B).
//!
//! Both integrate `y' = f(τ, y)` given by an [`OdeSystem`] and are driven through
//! [`Integrator`], which [`sample_uniform`] uses to deliver the solution on an exact grid.

mod dopri5;
mod rk4;
mod rodas4;
mod switch;

pub use dopri5::{Dopri5, Dopri5Options};
pub use rk4::Rk4;
pub use rodas4::{Rodas4, Rodas4Options};

use crate::error::Result;

/// A first-order system `y' = f(τ, y)`, optionally piecewise smooth.
pub trait OdeSystem {
    /// Length of the state vector.
    fn dim(&self) -> usize;
    /// Write `f(τ, y)` into `dy`.
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]);
    /// Number of switching functions `g_i(τ, y)` whose zero sets bound the smooth pieces.
    fn n_switches(&self) -> usize {
        0
    }
    /// Write the switching functions into `g` (length [`OdeSystem::n_switches`]).
    fn switches(&self, _t: f64, _y: &[f64], _g: &mut [f64]) {}
    /// Times at which `f` jumps (load steps): the integrator lands on each exactly. `f` must be
    /// left-continuous there (the value before the jump at `τ_b` itself); a solver starting a
    /// step at `τ_b` evaluates the right limit at `τ_b.next_up()`.
    fn breakpoints(&self) -> Vec<f64> {
        Vec::new()
    }
}

/// Counters reported by an integration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Stats {
    pub steps: usize,
    pub rejected: usize,
    pub rhs_evals: usize,
    /// Steps shortened to end on a located switch.
    pub switches: usize,
}

/// A one-step integrator with continuous output on its last step.
pub trait Integrator {
    /// Current time.
    fn t(&self) -> f64;
    /// Current state.
    fn y(&self) -> &[f64];
    /// Take one accepted step, never past `t_max`.
    fn step(&mut self, t_max: f64) -> Result<()>;
    /// Interpolate the state at `t` in the last step `[t_prev, t]` into `out`.
    fn dense(&self, t: f64, out: &mut [f64]);
    /// Counters so far.
    fn stats(&self) -> Stats;
}

/// Integrate until `t_end`, calling `on_sample(k, t_k, y(t_k))` at every grid time
/// `t_k = t_start + k·dt` for `k = 0, 1, …` with `t_k ≤ t_end (+1e-9·dt)`. The grid must start at
/// or after the integrator's current time. Samples come from the dense output, so they land
/// exactly on the grid whatever the steps are.
pub fn sample_uniform<I: Integrator>(
    integ: &mut I,
    t_start: f64,
    dt: f64,
    t_end: f64,
    mut on_sample: impl FnMut(usize, f64, &[f64]),
) -> Result<()> {
    let n = integ.y().len();
    let mut buf = vec![0.0; n];
    let mut k = 0usize;
    let t_grid = |k: usize| t_start + k as f64 * dt;
    let slack = 1e-9 * dt;
    // Samples at or before the current time (only the start point can be).
    while t_grid(k) <= integ.t() + slack && t_grid(k) <= t_end + slack {
        if (t_grid(k) - integ.t()).abs() <= slack {
            on_sample(k, t_grid(k), integ.y());
        }
        k += 1;
    }
    while integ.t() < t_end - slack {
        integ.step(t_end)?;
        while t_grid(k) <= integ.t() + slack && t_grid(k) <= t_end + slack {
            integ.dense(t_grid(k).min(integ.t()), &mut buf);
            on_sample(k, t_grid(k), &buf);
            k += 1;
        }
    }
    Ok(())
}

/// Advance to exactly `t_end` with no output.
pub fn advance_to<I: Integrator>(integ: &mut I, t_end: f64) -> Result<()> {
    while integ.t() < t_end {
        integ.step(t_end)?;
    }
    Ok(())
}
