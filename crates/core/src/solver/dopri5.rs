//! Dormand–Prince 5(4) with dense output and switch location.
//!
//! Coefficients and the continuous extension are those of Hairer, Nørsett & Wanner,
//! *Solving Ordinary Differential Equations I*, 2nd ed., §II.5–II.6 (the `DOPRI5` code): a
//! 5th-order step with an embedded 4th-order error estimate, FSAL, a PI step-size controller
//! (β = 0.04) and a 4th-order interpolant on every step.
//!
//! **Switches.** For a piecewise-smooth right-hand side (the backlash dead zone `f_b` has kinks
//! at `x = ±b`) an error-controlled step that straddles a kink loses its order and the
//! controller reacts by shrinking steps blindly. Here, after a step passes the error test, the
//! switching functions are checked at its end and at its midpoint (to catch an in-and-out
//! crossing); if one changed sign, its first root is found on the dense output (Illinois
//! method) and the step is redone ending exactly there. The next step then starts on the
//! switching surface in the new smooth piece. Load jumps ([`OdeSystem::breakpoints`]) are landed
//! on the same way and the FSAL derivative is re-evaluated after them.

use super::switch::first_root;
use super::{Integrator, OdeSystem, Stats};
use crate::error::{Error, Result};

/// Tolerances and limits.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Dopri5Options {
    /// Relative tolerance per component.
    pub rtol: f64,
    /// Absolute tolerance per component.
    pub atol: f64,
    /// Largest step (0: no limit).
    pub h_max: f64,
    /// First step to try (0: chosen from the initial derivative).
    pub h_init: f64,
    /// Maximum number of steps (accepted + rejected) in the integrator's lifetime.
    pub max_steps: usize,
    /// Locate switches (turn off only to measure what it buys).
    pub locate_switches: bool,
}

impl Default for Dopri5Options {
    fn default() -> Self {
        Dopri5Options {
            rtol: 1e-6,
            atol: 1e-8,
            h_max: 0.0,
            h_init: 0.0,
            max_steps: 200_000_000,
            locate_switches: true,
        }
    }
}

const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// The Dormand–Prince 5(4) integrator (see the module docs).
pub struct Dopri5<'a, S: OdeSystem + ?Sized> {
    sys: &'a S,
    opts: Dopri5Options,
    t: f64,
    t_prev: f64,
    h: f64,
    y: Vec<f64>,
    k: [Vec<f64>; 7],
    ynew: Vec<f64>,
    ytmp: Vec<f64>,
    /// Dense-output coefficients of the last accepted step.
    rcont: [Vec<f64>; 5],
    g_old: Vec<f64>,
    g_new: Vec<f64>,
    g_mid: Vec<f64>,
    g_work: Vec<f64>,
    facold: f64,
    /// The last accepted step was shortened to end on a switch.
    on_switch: bool,
    /// The last attempt was rejected (the next accepted step may not grow, HNW's rule).
    rejected_last: bool,
    breaks: Vec<f64>,
    next_break: usize,
    stats: Stats,
}

impl<'a, S: OdeSystem + ?Sized> Dopri5<'a, S> {
    /// Start at `(t0, y0)`.
    pub fn new(sys: &'a S, t0: f64, y0: &[f64], opts: Dopri5Options) -> Result<Self> {
        let n = sys.dim();
        if y0.len() != n {
            return Err(Error::InvalidConfig(format!(
                "initial state has {} components, the system {n}",
                y0.len()
            )));
        }
        if !(opts.rtol > 0.0 && opts.atol > 0.0) {
            return Err(Error::param(
                "rtol/atol",
                opts.rtol.min(opts.atol),
                "tolerances must be positive",
            ));
        }
        if y0.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite { t: t0 });
        }
        let z = || vec![0.0; n];
        let ns = sys.n_switches();
        let mut me = Dopri5 {
            sys,
            opts,
            t: t0,
            t_prev: t0,
            h: 0.0,
            y: y0.to_vec(),
            k: [z(), z(), z(), z(), z(), z(), z()],
            ynew: z(),
            ytmp: z(),
            rcont: [z(), z(), z(), z(), z()],
            g_old: vec![0.0; ns],
            g_new: vec![0.0; ns],
            g_mid: vec![0.0; ns],
            g_work: vec![0.0; ns],
            facold: 1e-4,
            on_switch: false,
            rejected_last: false,
            breaks: sys.breakpoints(),
            next_break: 0,
            stats: Stats::default(),
        };
        me.breaks.sort_by(f64::total_cmp);
        while me.next_break < me.breaks.len() && me.breaks[me.next_break] <= t0 {
            me.next_break += 1;
        }
        sys.rhs(t0, &me.y, &mut me.k[0]);
        me.stats.rhs_evals += 1;
        if ns > 0 {
            sys.switches(t0, &me.y, &mut me.g_old);
        }
        me.h = if opts.h_init > 0.0 {
            opts.h_init
        } else {
            me.initial_step()
        };
        // Dense output of the (empty) last step: constant.
        me.rcont[0].copy_from_slice(y0);
        Ok(me)
    }

    /// Hairer's starting-step heuristic (HNW I, §II.4).
    fn initial_step(&mut self) -> f64 {
        let n = self.y.len();
        let sk = |i: usize, y: &[f64]| self.opts.atol + self.opts.rtol * y[i].abs();
        let (mut d0, mut d1) = (0.0, 0.0);
        for i in 0..n {
            let s = sk(i, &self.y);
            d0 += (self.y[i] / s).powi(2);
            d1 += (self.k[0][i] / s).powi(2);
        }
        let (d0, d1) = ((d0 / n as f64).sqrt(), (d1 / n as f64).sqrt());
        let mut h0 = if d0 < 1e-5 || d1 < 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        };
        if self.opts.h_max > 0.0 {
            h0 = h0.min(self.opts.h_max);
        }
        for i in 0..n {
            self.ytmp[i] = self.y[i] + h0 * self.k[0][i];
        }
        self.sys.rhs(self.t + h0, &self.ytmp, &mut self.k[1]);
        self.stats.rhs_evals += 1;
        let mut d2 = 0.0;
        for i in 0..n {
            d2 += ((self.k[1][i] - self.k[0][i]) / sk(i, &self.y)).powi(2);
        }
        let d2 = (d2 / n as f64).sqrt() / h0;
        let h1 = if d1.max(d2) <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / d1.max(d2)).powf(0.2)
        };
        let mut h = (100.0 * h0).min(h1);
        if self.opts.h_max > 0.0 {
            h = h.min(self.opts.h_max);
        }
        h
    }

    /// Try a step of size `h` from the current state: fills `k[1..7]`, `ynew` and returns the
    /// scaled error norm.
    fn attempt(&mut self, h: f64) -> f64 {
        let n = self.y.len();
        let (t, sys) = (self.t, self.sys);
        let [k1, k2, k3, k4, k5, k6, k7] = &mut self.k;
        let (y, yt) = (&self.y, &mut self.ytmp);
        for i in 0..n {
            yt[i] = y[i] + h * A21 * k1[i];
        }
        sys.rhs(t + C2 * h, yt, k2);
        for i in 0..n {
            yt[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        sys.rhs(t + C3 * h, yt, k3);
        for i in 0..n {
            yt[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        sys.rhs(t + C4 * h, yt, k4);
        for i in 0..n {
            yt[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        sys.rhs(t + C5 * h, yt, k5);
        for i in 0..n {
            yt[i] =
                y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        sys.rhs(t + h, yt, k6);
        let yn = &mut self.ynew;
        for i in 0..n {
            yn[i] =
                y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        sys.rhs(t + h, yn, k7);
        self.stats.rhs_evals += 6;
        let mut err = 0.0;
        for i in 0..n {
            let e =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            let sk = self.opts.atol + self.opts.rtol * y[i].abs().max(yn[i].abs());
            err += (e / sk) * (e / sk);
        }
        (err / n as f64).sqrt()
    }

    /// Dense-output coefficients for a tentative step of size `h` (HNW's `CONTD5`).
    fn build_dense(&mut self, h: f64) {
        let n = self.y.len();
        let [k1, _, k3, k4, k5, k6, k7] = &self.k;
        let [r0, r1, r2, r3, r4] = &mut self.rcont;
        for i in 0..n {
            let ydiff = self.ynew[i] - self.y[i];
            let bspl = h * k1[i] - ydiff;
            r0[i] = self.y[i];
            r1[i] = ydiff;
            r2[i] = bspl;
            r3[i] = ydiff - h * k7[i] - bspl;
            r4[i] =
                h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
        }
    }

    fn dense_theta(&self, theta: f64, out: &mut [f64]) {
        let t1 = 1.0 - theta;
        let [r0, r1, r2, r3, r4] = &self.rcont;
        for i in 0..out.len() {
            out[i] = r0[i] + theta * (r1[i] + t1 * (r2[i] + theta * (r3[i] + t1 * r4[i])));
        }
    }

    /// Earliest switch root in the tentative step `(0, 1]` of size `h`, as a fraction θ, when
    /// one exists beyond the first `theta_min`.
    fn locate_switch(&mut self, h: f64) -> Option<f64> {
        let sys = self.sys;
        sys.switches(self.t + h, &self.ynew, &mut self.g_new);
        let mut y_mid = std::mem::take(&mut self.ytmp);
        self.dense_theta(0.5, &mut y_mid);
        sys.switches(self.t + 0.5 * h, &y_mid, &mut self.g_mid);
        // Right after a step that ended on a switch, the state sits within the local error of
        // the switching surface: a root in the first 0.1 % of the next step is that same
        // switch, already handled (chasing it costs a tiny extra step).
        let theta_min = if self.on_switch {
            1e-3
        } else {
            1e-12 * self.t.abs().max(1.0) / h
        };
        let mut g = std::mem::take(&mut self.g_work);
        let time_tol = 1e-13 * self.t.abs().max(1.0);
        let best = first_root(
            &self.g_old,
            &self.g_mid,
            &self.g_new,
            theta_min,
            h,
            time_tol,
            |i, c| {
                self.dense_theta(c, &mut y_mid);
                sys.switches(self.t + c * h, &y_mid, &mut g);
                g[i]
            },
        );
        self.ytmp = y_mid;
        self.g_work = g;
        best
    }

    fn accept(&mut self, h: f64) {
        self.t_prev = self.t;
        self.t += h;
        std::mem::swap(&mut self.y, &mut self.ynew);
        self.k.swap(0, 6);
        std::mem::swap(&mut self.g_old, &mut self.g_new);
        self.stats.steps += 1;
    }

    /// The step size the controller proposes next.
    pub fn proposed_step(&self) -> f64 {
        self.h
    }

    /// Time of the previous accepted step's start.
    pub fn t_prev(&self) -> f64 {
        self.t_prev
    }
}

impl<S: OdeSystem + ?Sized> Integrator for Dopri5<'_, S> {
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
        const BETA: f64 = 0.04;
        const EXPO1: f64 = 0.2 - BETA * 0.75;
        const SAFE: f64 = 0.9;
        let t_stop = match self.breaks.get(self.next_break) {
            Some(&b) if b < t_max => b,
            _ => t_max,
        };
        if t_stop <= self.t {
            return Ok(());
        }
        let has_switches = self.opts.locate_switches && !self.g_old.is_empty();
        let mut shortened = 0;
        let mut forced_h: Option<f64> = None;
        loop {
            if self.stats.steps + self.stats.rejected >= self.opts.max_steps {
                return Err(Error::TooManySteps {
                    t: self.t,
                    max_steps: self.opts.max_steps,
                });
            }
            let mut h = forced_h.unwrap_or(self.h);
            if self.opts.h_max > 0.0 {
                h = h.min(self.opts.h_max);
            }
            let mut lands = false;
            if self.t + h >= t_stop || self.t + 1.01 * h >= t_stop {
                h = t_stop - self.t;
                lands = true;
            }
            if h <= 1e-14 * self.t.abs().max(1.0) {
                return Err(Error::StepSizeTooSmall { t: self.t, h });
            }
            let err = self.attempt(h);
            if !err.is_finite() {
                self.stats.rejected += 1;
                self.h = h * 0.1;
                forced_h = None;
                if self.h < 1e-14 * self.t.abs().max(1.0) {
                    return Err(Error::NonFinite { t: self.t });
                }
                continue;
            }
            let fac11 = err.powf(EXPO1);
            if err > 1.0 {
                self.stats.rejected += 1;
                self.h = h / (1.0 / 0.2f64).min(fac11 / SAFE);
                forced_h = None;
                self.rejected_last = true;
                continue;
            }
            self.build_dense(h);
            if has_switches && shortened < 12 {
                if let Some(theta) = self.locate_switch(h) {
                    // A redone step whose end is within 0.1 % of the switch is kept: the
                    // interpolant and the step differ by the local error, so chasing the last
                    // digits only adds steps.
                    let near_end = if shortened > 0 { 1e-3 } else { 1e-6 };
                    if theta < 1.0 - near_end {
                        // Redo the step so that it ends on the switch.
                        shortened += 1;
                        self.stats.switches += 1;
                        forced_h = Some(theta * h);
                        continue;
                    }
                }
            } else if has_switches {
                self.sys.switches(self.t + h, &self.ynew, &mut self.g_new);
            }
            // Accepted: next step size from the PI controller.
            let mut fac = fac11 / self.facold.powf(BETA);
            fac = (1.0 / 10.0f64).max((1.0 / 0.2f64).min(fac / SAFE));
            self.facold = err.max(1e-4);
            let mut h_next = h / fac;
            if self.rejected_last {
                // Hairer's rule: no growth right after a rejection.
                h_next = h_next.min(h);
                self.rejected_last = false;
            }
            self.accept(h);
            self.on_switch = forced_h.is_some();
            if forced_h.is_none() || h_next > self.h {
                self.h = h_next;
            }
            if lands
                && self.next_break < self.breaks.len()
                && self.t >= self.breaks[self.next_break]
            {
                self.t = self.breaks[self.next_break];
                self.next_break += 1;
                // The right-hand side jumps here: the FSAL derivative is the left limit; the
                // next step needs the right one.
                self.sys.rhs(self.t.next_up(), &self.y, &mut self.k[0]);
                self.stats.rhs_evals += 1;
            }
            return Ok(());
        }
    }

    fn dense(&self, t: f64, out: &mut [f64]) {
        let h = self.t - self.t_prev;
        if h <= 0.0 {
            out.copy_from_slice(&self.y);
            return;
        }
        let theta = (t - self.t_prev) / h;
        self.dense_theta(theta, out);
    }
}
