//! Classical fixed-step 4th-order Runge–Kutta: the plain reference the adaptive solver is
//! checked against. It knows nothing about switches, so near a backlash kink its error is
//! first order in the step locally; use a tiny step for reference solutions.

use super::{Integrator, OdeSystem, Stats};
use crate::error::{Error, Result};

/// Fixed-step RK4 with cubic Hermite dense output.
pub struct Rk4<'a, S: OdeSystem + ?Sized> {
    sys: &'a S,
    h: f64,
    t: f64,
    t_prev: f64,
    y: Vec<f64>,
    y_prev: Vec<f64>,
    f_prev: Vec<f64>,
    f: Vec<f64>,
    k: [Vec<f64>; 3],
    tmp: Vec<f64>,
    stats: Stats,
}

impl<'a, S: OdeSystem + ?Sized> Rk4<'a, S> {
    /// Start at `(t0, y0)` with step `h`.
    pub fn new(sys: &'a S, t0: f64, y0: &[f64], h: f64) -> Result<Self> {
        let n = sys.dim();
        if y0.len() != n {
            return Err(Error::InvalidConfig(format!(
                "initial state has {} components, the system {n}",
                y0.len()
            )));
        }
        if !(h.is_finite() && h > 0.0) {
            return Err(Error::param("h", h, "the RK4 step must be positive"));
        }
        let mut f = vec![0.0; n];
        sys.rhs(t0, y0, &mut f);
        Ok(Rk4 {
            sys,
            h,
            t: t0,
            t_prev: t0,
            y: y0.to_vec(),
            y_prev: y0.to_vec(),
            f_prev: f.clone(),
            f,
            k: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            tmp: vec![0.0; n],
            stats: Stats {
                rhs_evals: 1,
                ..Stats::default()
            },
        })
    }
}

impl<S: OdeSystem + ?Sized> Integrator for Rk4<'_, S> {
    fn t(&self) -> f64 {
        self.t
    }
    fn y(&self) -> &[f64] {
        &self.y
    }
    fn stats(&self) -> Stats {
        self.stats
    }
    fn step(&mut self, t_max: f64) -> Result<()> {
        let mut h = self.h;
        if self.t + h > t_max - 1e-9 * h {
            h = t_max - self.t;
        }
        if h <= 0.0 {
            return Ok(());
        }
        let n = self.y.len();
        let (t, sys) = (self.t, self.sys);
        let [k2, k3, k4] = &mut self.k;
        let k1 = &self.f;
        for i in 0..n {
            self.tmp[i] = self.y[i] + 0.5 * h * k1[i];
        }
        sys.rhs(t + 0.5 * h, &self.tmp, k2);
        for i in 0..n {
            self.tmp[i] = self.y[i] + 0.5 * h * k2[i];
        }
        sys.rhs(t + 0.5 * h, &self.tmp, k3);
        for i in 0..n {
            self.tmp[i] = self.y[i] + h * k3[i];
        }
        sys.rhs(t + h, &self.tmp, k4);
        self.y_prev.copy_from_slice(&self.y);
        self.f_prev.copy_from_slice(&self.f);
        for i in 0..n {
            self.y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if self.y.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite { t: t + h });
        }
        self.t_prev = t;
        self.t = t + h;
        sys.rhs(self.t, &self.y, &mut self.f);
        self.stats.rhs_evals += 4;
        self.stats.steps += 1;
        Ok(())
    }
    fn dense(&self, t: f64, out: &mut [f64]) {
        let h = self.t - self.t_prev;
        if h <= 0.0 {
            out.copy_from_slice(&self.y);
            return;
        }
        let s = (t - self.t_prev) / h;
        let (h00, h10, h01, h11) = (
            (1.0 + 2.0 * s) * (1.0 - s) * (1.0 - s),
            s * (1.0 - s) * (1.0 - s),
            s * s * (3.0 - 2.0 * s),
            s * s * (s - 1.0),
        );
        for i in 0..out.len() {
            out[i] = h00 * self.y_prev[i]
                + h10 * h * self.f_prev[i]
                + h01 * self.y[i]
                + h11 * h * self.f[i];
        }
    }
}
