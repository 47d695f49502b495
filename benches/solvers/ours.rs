//! Drivers of our integrators: DOPRI5 (switch location on or off) and fixed-step RK4.

use gearwear::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Rk4, advance_to, sample_uniform,
};

use crate::problem::{Counts, Problem, Run};

pub(crate) fn run_ours(p: &Problem, opts: Dopri5Options) -> Run {
    let dim = p.sys.dim();
    let mut samples = Vec::with_capacity(p.n * dim);
    let mut integ = Dopri5::new(p.sys, 0.0, &p.y0, opts).expect("start");
    advance_to(&mut integ, p.t0).expect("transient");
    sample_uniform(&mut integ, p.t0, p.dt, p.t_end(), |_, _, y| {
        samples.extend_from_slice(y)
    })
    .expect("sampling");
    let s = integ.stats();
    Run {
        samples,
        counts: Counts {
            rhs: s.rhs_evals,
            accepted: s.steps,
            rejected: s.rejected,
            switches: s.switches,
        },
    }
}

pub(crate) fn run_rk4(p: &Problem, h: f64) -> Run {
    let dim = p.sys.dim();
    let mut samples = Vec::with_capacity(p.n * dim);
    let mut integ = Rk4::new(p.sys, 0.0, &p.y0, h).expect("start");
    advance_to(&mut integ, p.t0).expect("transient");
    sample_uniform(&mut integ, p.t0, p.dt, p.t_end(), |_, _, y| {
        samples.extend_from_slice(y)
    })
    .expect("sampling");
    let s = integ.stats();
    Run {
        samples,
        counts: Counts {
            rhs: s.rhs_evals,
            accepted: s.steps,
            ..Counts::default()
        },
    }
}
