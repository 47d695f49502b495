//! The problem every solver integrates and what a run returns.

use gearwear::model::GearOde;

/// Integrate from τ = 0 (state `y0`) and sample every `dt` from `t0`, `n` samples.
pub(crate) struct Problem<'a> {
    pub(crate) sys: &'a GearOde,
    pub(crate) y0: Vec<f64>,
    pub(crate) t0: f64,
    pub(crate) dt: f64,
    pub(crate) n: usize,
}

impl Problem<'_> {
    pub(crate) fn t_end(&self) -> f64 {
        self.t0 + (self.n - 1) as f64 * self.dt
    }
}

#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Counts {
    pub(crate) rhs: usize,
    pub(crate) accepted: usize,
    pub(crate) rejected: usize,
    /// Switches located (steps shortened for ours, restarts for the crate).
    pub(crate) switches: usize,
}

/// Samples (row-major, `dim` per grid time) and counters.
pub(crate) struct Run {
    pub(crate) samples: Vec<f64>,
    pub(crate) counts: Counts,
}

/// How switches are handled with `differential-equations`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DeMode {
    /// None: the crate's `solve_ode` with a grid-sampling `Solout`.
    Plain,
    /// The crate's hooks: the `Solout` locates the switch in the accepted step and restarts the
    /// solver there (`ControlFlag::ModifyState`); the straddling step itself is kept.
    Restart,
    /// Our switch location on the crate's stepper, driven by hand through the public
    /// `OrdinaryNumericalMethod` trait: a step that straddles a switch is undone (`init` at its
    /// start) and redone with `set_h` so that it ends on the switch — what ours does inside.
    Redo,
}
