//! The `ode_solvers` crate's DOPRI5 (Hairer's port, dense output, no event location).

use gearwear::model::GearOde;
use gearwear::solver::OdeSystem;

use crate::problem::{Counts, Problem, Run};

/// `GearOde` seen through `ode_solvers`' trait.
pub(crate) struct OsSys<'a>(&'a GearOde);

impl<const N: usize> ode_solvers::System<f64, ode_solvers::SVector<f64, N>> for OsSys<'_> {
    fn system(
        &self,
        t: f64,
        y: &ode_solvers::SVector<f64, N>,
        dy: &mut ode_solvers::SVector<f64, N>,
    ) {
        self.0.rhs(t, y.as_slice(), dy.as_mut_slice());
    }
}

pub(crate) fn run_os<const N: usize>(p: &Problem, rtol: f64, atol: f64) -> Run {
    use ode_solvers::{Dopri5 as OsDopri5, OutputType, SVector};
    let mk = |t_a: f64, t_b: f64, y: SVector<f64, N>, out: OutputType| {
        OsDopri5::from_param(
            OsSys(p.sys),
            t_a,
            t_b,
            p.dt,
            y,
            rtol,
            atol,
            0.9,
            0.04,
            0.2,
            10.0,
            t_b - t_a,
            0.0,
            u32::MAX,
            1000,
            out,
        )
    };
    let mut counts = Counts::default();
    let mut y = SVector::<f64, N>::from_column_slice(&p.y0);
    // Transient without output, then a dense-output run on the grid from t0.
    if p.t0 > 0.0 {
        let mut tr = mk(0.0, p.t0, y, OutputType::Sparse);
        let st = tr.integrate().expect("ode_solvers transient");
        y = *tr.y_out().last().expect("end state");
        counts.rhs += st.num_eval as usize;
        counts.accepted += st.accepted_steps as usize;
        counts.rejected += st.rejected_steps as usize;
    }
    let mut s = mk(p.t0, p.t_end(), y, OutputType::Dense);
    let st = s.integrate().expect("ode_solvers");
    counts.rhs += st.num_eval as usize;
    counts.accepted += st.accepted_steps as usize;
    counts.rejected += st.rejected_steps as usize;
    let mut samples = Vec::with_capacity(p.n * N);
    for v in s.y_out().iter().take(p.n) {
        samples.extend_from_slice(v.as_slice());
    }
    assert!(
        samples.len() >= (p.n - 1) * N,
        "ode_solvers gave {} samples of {}",
        samples.len() / N,
        p.n
    );
    // The accumulated output time may miss the very last grid point by rounding: add it.
    if samples.len() < p.n * N {
        samples.extend_from_slice(s.y_out().last().unwrap().as_slice());
    }
    Run { samples, counts }
}
