//! The solvers compared and how each is run on a [`Problem`].

use differential_equations::methods::{DormandPrince, ExplicitRungeKutta, Ordinary};
use gearwear::solver::{Dopri5Options, OdeSystem};

use crate::de::run_de;
use crate::os::run_os;
use crate::ours::{run_ours, run_rk4};
use crate::problem::{DeMode, Problem, Run};

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
