//! The problem every solver integrates, what a run returns, and the solvers compared.

use differential_equations::methods::{DormandPrince, ExplicitRungeKutta, Ordinary};
use gearwear::model::GearOde;
use gearwear::solver::{Dopri5Options, OdeSystem};

use crate::de::run_de;
use crate::os::run_os;
use crate::ours::{run_ours, run_rk4};

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

#[derive(Debug, Clone, Copy)]
pub(crate) enum Solver {
    Ours {
        rtol: f64,
        atol: f64,
        locate: bool,
    },
    De {
        dop853: bool,
        rtol: f64,
        atol: f64,
        mode: DeMode,
    },
    Os {
        rtol: f64,
        atol: f64,
    },
    Rk4 {
        h: f64,
    },
}

impl Solver {
    pub(crate) fn label(&self) -> &'static str {
        match self {
            Solver::Ours { locate: true, .. } => "ours",
            Solver::Ours { locate: false, .. } => "ours-nolocate",
            Solver::De { dop853, mode, .. } => match (dop853, mode) {
                (false, DeMode::Plain) => "de-dopri5",
                (false, DeMode::Restart) => "de-dopri5+restart",
                (false, DeMode::Redo) => "de-dopri5+redo",
                (true, DeMode::Plain) => "de-dop853",
                (true, DeMode::Restart) => "de-dop853+restart",
                (true, DeMode::Redo) => "de-dop853+redo",
            },
            Solver::Os { .. } => "os-dopri5",
            Solver::Rk4 { .. } => "rk4",
        }
    }

    pub(crate) fn with_tol(self, rtol: f64, atol: f64) -> Self {
        match self {
            Solver::Ours { locate, .. } => Solver::Ours { rtol, atol, locate },
            Solver::De { dop853, mode, .. } => Solver::De {
                dop853,
                rtol,
                atol,
                mode,
            },
            Solver::Os { .. } => Solver::Os { rtol, atol },
            s => s,
        }
    }

    pub(crate) fn run<const N: usize>(&self, p: &Problem) -> Run {
        assert_eq!(p.sys.dim(), N);
        match *self {
            Solver::Ours { rtol, atol, locate } => run_ours(
                p,
                Dopri5Options {
                    rtol,
                    atol,
                    locate_switches: locate,
                    ..Default::default()
                },
            ),
            Solver::Rk4 { h } => run_rk4(p, h),
            Solver::De {
                dop853,
                rtol,
                atol,
                mode,
            } => {
                if dop853 {
                    let mut m: ExplicitRungeKutta<
                        Ordinary,
                        DormandPrince,
                        f64,
                        [f64; N],
                        8,
                        12,
                        16,
                    > = ExplicitRungeKutta::dop853()
                        .rtol(rtol)
                        .atol(atol)
                        .max_steps(usize::MAX);
                    run_de::<N, _>(p, &mut m, mode)
                } else {
                    let mut m: ExplicitRungeKutta<Ordinary, DormandPrince, f64, [f64; N], 5, 7, 7> =
                        ExplicitRungeKutta::dopri5()
                            .rtol(rtol)
                            .atol(atol)
                            .max_steps(usize::MAX);
                    run_de::<N, _>(p, &mut m, mode)
                }
            }
            Solver::Os { rtol, atol } => run_os::<N>(p, rtol, atol),
        }
    }
}
