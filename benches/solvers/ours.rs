//! Drivers of our integrators: DOPRI5 (switch location on or off) and fixed-step RK4.

use gearwear::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Rk4, Stats, advance_to, sample_uniform,
};

use crate::problem::{Counts, Problem, Run};

pub(crate) fn run_ours(p: &Problem, opts: Dopri5Options) -> Run {
    let mut integ = Dopri5::new(p.sys, 0.0, &p.y0, opts).expect("start");
    let (samples, s) = sample(&mut integ, p);
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
    let mut integ = Rk4::new(p.sys, 0.0, &p.y0, h).expect("start");
    let (samples, s) = sample(&mut integ, p);
    Run {
        samples,
        counts: Counts {
            rhs: s.rhs_evals,
            accepted: s.steps,
            ..Counts::default()
        },
    }
}

/// Integrate through the transient to `p.t0`, then sample the problem's grid; the samples
/// (row-major) and the integrator's counters.
fn sample(integ: &mut impl Integrator, p: &Problem) -> (Vec<f64>, Stats) {
    let mut samples = Vec::with_capacity(p.n * p.sys.dim());
    advance_to(integ, p.t0).expect("transient");
    sample_uniform(integ, p.t0, p.dt, p.t_end(), |_, _, y| {
        samples.extend_from_slice(y)
    })
    .expect("sampling");
    (samples, integ.stats())
}
