//! RODAS4: an L-stable, stiffly accurate Rosenbrock method of order 4(3) with dense output,
//! for the stiff gear models (Model B: bearing and mesh modes four decades above the load mode).
//!
//! Method (Hairer & Wanner, *Solving Ordinary Differential Equations II*, 2nd ed., §IV.7, the
//! `RODAS` code, coefficients of its `ROCOE` table for `METH = 1`), written in the transformed
//! form that needs one LU decomposition per step and no matrix–vector products:
//!
//! ```text
//! W = I/(γ h) − J,     J ≈ ∂f/∂y (t0, y0),   f_t ≈ ∂f/∂t (t0, y0),   γ = 1/4
//! W k_i = f(t0 + α_i h, y0 + Σ_{j<i} a_ij k_j) + Σ_{j<i} (c_ij / h) k_j + h γ_i f_t
//! y1 = y0 + Σ a_6j k_j + k6   (stiffly accurate: the last stage is the solution)
//! err = k6                    (the embedded 3rd-order solution is y1 − k6)
//! ```
//!
//! The Jacobian and `f_t` are forward differences (`δ_j = sqrt(u · max(1e-5, |y_j|))`, u the unit
//! round-off, as in `RODAS`), recomputed on every step (the gear models have 2n ≤ 40
//! components: `2n + 1` right-hand-side calls). A position column is differenced in the
//! direction the state is moving so that, on a piecewise-linear model sitting on a contact
//! switch, `J` belongs to the piece the step enters. Step sizes: Hairer's controller
//! (`fac ∈ [1/6, 5]`, safety 0.9) with Gustafsson's predictive correction after accepted steps.
//! Dense output: Hairer's 3rd-order continuous extension
//! `y(θ) = y0 + θ (y1 − y0 + (1 − θ)(d2 + θ d3))`, `d2 = Σ d2j k_j`, `d3 = Σ d3j k_j`.
//!
//! **Switches and breakpoints** are handled as in [`super::Dopri5`]: after a step passes the
//! error test the switching functions are checked at its end and midpoint; a sign change is
//! located on the dense output (Illinois) and the step is redone ending just past the switch.
//! Load jumps ([`OdeSystem::breakpoints`]) are landed on exactly.

use nalgebra::{DMatrix, DVector};

use super::switch::first_root;
use super::{Integrator, OdeSystem, Stats};
use crate::error::{Error, Result};

/// Tolerances and limits of [`Rodas4`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rodas4Options {
    /// Relative tolerance per component.
    pub rtol: f64,
    /// Absolute tolerance per component.
    pub atol: f64,
    /// Largest step (0: no limit).
    pub h_max: f64,
    /// First step (0: a small fraction of the problem's time scale from `|f|`).
    pub h_init: f64,
    /// Maximum number of steps (accepted + rejected).
    pub max_steps: usize,
    /// Locate switches (turn off only to measure what it buys).
    pub locate_switches: bool,
    /// Fixed steps of `h_init` with no error control (for order-of-convergence checks).
    pub fixed_step: bool,
}

impl Default for Rodas4Options {
    fn default() -> Self {
        Rodas4Options {
            rtol: 1e-6,
            atol: 1e-8,
            h_max: 0.0,
            h_init: 0.0,
            max_steps: 50_000_000,
            locate_switches: true,
            fixed_step: false,
        }
    }
}

const GAMMA: f64 = 0.25;
const C2: f64 = 0.386;
const C3: f64 = 0.21;
const C4: f64 = 0.63;
const D1: f64 = 0.25;
const D2: f64 = -0.1043;
const D3: f64 = 0.1035;
const D4: f64 = -0.362_000_000_000_002_3e-1;
const A21: f64 = 0.1544e1;
const A31: f64 = 0.946_678_528_081_582_6;
const A32: f64 = 0.255_701_169_898_328_4;
const A41: f64 = 0.331_482_518_706_852_1e1;
const A42: f64 = 0.289_612_401_597_220_1e1;
const A43: f64 = 0.998_641_913_997_781_7;
const A51: f64 = 0.122_122_450_922_664_1e1;
const A52: f64 = 0.601_913_448_128_862_9e1;
const A53: f64 = 0.125_370_833_293_208_7e2;
const A54: f64 = -0.687_886_036_105_895;
const C21: f64 = -0.56688e1;
const C31: f64 = -0.243_009_335_683_387_5e1;
const C32: f64 = -0.206_359_915_709_191_5;
const C41: f64 = -0.107_352_905_815_137_5;
const C42: f64 = -0.959_456_225_102_335_5e1;
const C43: f64 = -0.204_702_861_480_961_6e2;
const C51: f64 = 0.749_644_331_396_764_7e1;
const C52: f64 = -0.102_468_043_146_435_2e2;
const C53: f64 = -0.339_999_035_281_990_5e2;
const C54: f64 = 0.117_089_089_320_616e2;
const C61: f64 = 0.808_324_679_592_152_2e1;
const C62: f64 = -0.798_113_298_806_489_3e1;
const C63: f64 = -0.315_215_943_287_437_1e2;
const C64: f64 = 0.163_193_054_312_313_6e2;
const C65: f64 = -0.605_881_823_883_405_4e1;
const DD21: f64 = 0.101_262_350_834_458_6e2;
const DD22: f64 = -0.748_799_587_761_016_7e1;
const DD23: f64 = -0.348_009_186_155_574_7e2;
const DD24: f64 = -0.799_277_170_756_882_3e1;
const DD25: f64 = 0.102_513_772_329_566_2e1;
const DD31: f64 = -0.676_280_339_280_125_3;
const DD32: f64 = 0.608_771_465_168_001_5e1;
const DD33: f64 = 0.164_308_432_089_247_8e2;
const DD34: f64 = 0.247_672_251_141_838_6e2;
const DD35: f64 = -0.659_438_912_571_687_2e1;

/// The RODAS4 integrator (see the module docs).
pub struct Rodas4<'a, S: OdeSystem + ?Sized> {
    sys: &'a S,
    opts: Rodas4Options,
    n: usize,
    t: f64,
    t_prev: f64,
    h: f64,
    y: Vec<f64>,
    ynew: Vec<f64>,
    /// f(t, y) at the current point.
    f0: Vec<f64>,
    jac: DMatrix<f64>,
    fx: Vec<f64>,
    k: [DVector<f64>; 6],
    ytmp: Vec<f64>,
    ftmp: Vec<f64>,
    /// Dense output of the last accepted step: y0, y1 − y0, d2, d3.
    cont: [Vec<f64>; 4],
    g_old: Vec<f64>,
    g_new: Vec<f64>,
    g_mid: Vec<f64>,
    breaks: Vec<f64>,
    next_break: usize,
    /// The current point is a load jump: evaluate `f` (and its derivatives) as the right limit.
    right_limit: bool,
    /// Gustafsson controller memory: last accepted step and its error.
    hacc: f64,
    erracc: f64,
    n_accepted: usize,
    /// LU decompositions done.
    pub decompositions: usize,
    stats: Stats,
}

impl<'a, S: OdeSystem + ?Sized> Rodas4<'a, S> {
    /// Start at `(t0, y0)`.
    pub fn new(sys: &'a S, t0: f64, y0: &[f64], opts: Rodas4Options) -> Result<Self> {
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
        if opts.fixed_step && (opts.h_init.is_nan() || opts.h_init <= 0.0) {
            return Err(Error::param(
                "h_init",
                opts.h_init,
                "fixed steps need a positive step",
            ));
        }
        if y0.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite { t: t0 });
        }
        let ns = sys.n_switches();
        let z = || vec![0.0; n];
        let zv = || DVector::zeros(n);
        let mut me = Rodas4 {
            sys,
            opts,
            n,
            t: t0,
            t_prev: t0,
            h: 0.0,
            y: y0.to_vec(),
            ynew: z(),
            f0: z(),
            jac: DMatrix::zeros(n, n),
            fx: z(),
            k: [zv(), zv(), zv(), zv(), zv(), zv()],
            ytmp: z(),
            ftmp: z(),
            cont: [y0.to_vec(), z(), z(), z()],
            g_old: vec![0.0; ns],
            g_new: vec![0.0; ns],
            g_mid: vec![0.0; ns],
            breaks: sys.breakpoints(),
            next_break: 0,
            right_limit: false,
            hacc: 0.0,
            erracc: 1e-2,
            n_accepted: 0,
            decompositions: 0,
            stats: Stats::default(),
        };
        me.breaks.sort_by(f64::total_cmp);
        while me.next_break < me.breaks.len() && me.breaks[me.next_break] <= t0 {
            me.next_break += 1;
        }
        sys.rhs(t0, &me.y, &mut me.f0);
        me.stats.rhs_evals += 1;
        if ns > 0 {
            sys.switches(t0, &me.y, &mut me.g_old);
        }
        me.h = if opts.h_init > 0.0 {
            opts.h_init
        } else {
            // A step that changes y by ~1e-3 of its tolerance-weighted size.
            let mut d0 = 0.0_f64;
            let mut d1 = 0.0_f64;
            for i in 0..n {
                let sk = opts.atol + opts.rtol * me.y[i].abs();
                d0 = d0.max((me.y[i] / sk).abs());
                d1 = d1.max((me.f0[i] / sk).abs());
            }
            if d1 <= 1e-10 {
                1e-6
            } else {
                (1e-2 * d0.max(1.0) / d1).max(1e-10)
            }
        };
        if opts.h_max > 0.0 {
            me.h = me.h.min(opts.h_max);
        }
        Ok(me)
    }

    /// Forward-difference Jacobian `∂f/∂y` and time derivative `∂f/∂t` at the current point.
    fn jacobian(&mut self) {
        let n = self.n;
        let u = f64::EPSILON;
        let t0 = if self.right_limit {
            self.t.next_up()
        } else {
            self.t
        };
        self.ytmp.copy_from_slice(&self.y);
        for j in 0..n {
            let yj = self.y[j];
            let mut delta = (u * yj.abs().max(1e-5)).sqrt();
            // Difference in the direction the component moves (see the module docs).
            if self.f0[j] < 0.0 {
                delta = -delta;
            }
            self.ytmp[j] = yj + delta;
            self.sys.rhs(t0, &self.ytmp, &mut self.ftmp);
            for i in 0..n {
                self.jac[(i, j)] = (self.ftmp[i] - self.f0[i]) / delta;
            }
            self.ytmp[j] = yj;
        }
        let dt = (u * self.t.abs().max(1e-5)).sqrt();
        self.sys.rhs(t0 + dt, &self.y, &mut self.ftmp);
        for i in 0..n {
            self.fx[i] = (self.ftmp[i] - self.f0[i]) / dt;
        }
        self.stats.rhs_evals += n + 1;
    }

    /// One tentative step of size `h` from the current point: fills `ynew`, the dense output
    /// and returns the scaled error norm (∞ if `W` is singular or the stages are not finite).
    fn attempt(&mut self, h: f64) -> f64 {
        let n = self.n;
        let fac = 1.0 / (h * GAMMA);
        let mut w = -self.jac.clone();
        for i in 0..n {
            w[(i, i)] += fac;
        }
        let lu = w.lu();
        self.decompositions += 1;
        let (t, sys) = (self.t, self.sys);
        let y = &self.y;
        let yt = &mut self.ytmp;
        let ft = &mut self.ftmp;
        let [k1, k2, k3, k4, k5, k6] = &mut self.k;
        // Stage 1.
        for i in 0..n {
            k1[i] = self.f0[i] + h * D1 * self.fx[i];
        }
        if !lu.solve_mut(k1) {
            return f64::INFINITY;
        }
        // Stage 2.
        for i in 0..n {
            yt[i] = y[i] + A21 * k1[i];
        }
        sys.rhs(t + C2 * h, yt, ft);
        for i in 0..n {
            k2[i] = ft[i] + C21 / h * k1[i] + h * D2 * self.fx[i];
        }
        lu.solve_mut(k2);
        // Stage 3.
        for i in 0..n {
            yt[i] = y[i] + A31 * k1[i] + A32 * k2[i];
        }
        sys.rhs(t + C3 * h, yt, ft);
        for i in 0..n {
            k3[i] = ft[i] + (C31 * k1[i] + C32 * k2[i]) / h + h * D3 * self.fx[i];
        }
        lu.solve_mut(k3);
        // Stage 4.
        for i in 0..n {
            yt[i] = y[i] + A41 * k1[i] + A42 * k2[i] + A43 * k3[i];
        }
        sys.rhs(t + C4 * h, yt, ft);
        for i in 0..n {
            k4[i] = ft[i] + (C41 * k1[i] + C42 * k2[i] + C43 * k3[i]) / h + h * D4 * self.fx[i];
        }
        lu.solve_mut(k4);
        // Stage 5 (at t + h).
        for i in 0..n {
            yt[i] = y[i] + A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i];
        }
        sys.rhs(t + h, yt, ft);
        for i in 0..n {
            k5[i] = ft[i] + (C51 * k1[i] + C52 * k2[i] + C53 * k3[i] + C54 * k4[i]) / h;
        }
        lu.solve_mut(k5);
        // Stage 6: y + Σ a6j k_j with a6j = a5j, a65 = 1.
        for i in 0..n {
            yt[i] += k5[i];
        }
        sys.rhs(t + h, yt, ft);
        for i in 0..n {
            k6[i] =
                ft[i] + (C61 * k1[i] + C62 * k2[i] + C63 * k3[i] + C64 * k4[i] + C65 * k5[i]) / h;
        }
        lu.solve_mut(k6);
        self.stats.rhs_evals += 5;
        let mut err = 0.0;
        for i in 0..n {
            self.ynew[i] = yt[i] + k6[i];
            let sk = self.opts.atol + self.opts.rtol * y[i].abs().max(self.ynew[i].abs());
            err += (k6[i] / sk).powi(2);
        }
        let err = (err / n as f64).sqrt();
        // Dense output.
        let [c0, c1, c2, c3] = &mut self.cont;
        for i in 0..n {
            c0[i] = y[i];
            c1[i] = self.ynew[i] - y[i];
            c2[i] = DD21 * k1[i] + DD22 * k2[i] + DD23 * k3[i] + DD24 * k4[i] + DD25 * k5[i];
            c3[i] = DD31 * k1[i] + DD32 * k2[i] + DD33 * k3[i] + DD34 * k4[i] + DD35 * k5[i];
        }
        if self.ynew.iter().all(|v| v.is_finite()) {
            err
        } else {
            f64::INFINITY
        }
    }

    fn dense_theta(&self, theta: f64, out: &mut [f64]) {
        let [c0, c1, c2, c3] = &self.cont;
        let s1 = 1.0 - theta;
        for i in 0..out.len() {
            out[i] = c0[i] + theta * (c1[i] + s1 * (c2[i] + theta * c3[i]));
        }
    }

    /// Earliest switch root in the tentative step, as a fraction θ of it.
    fn locate_switch(&mut self, h: f64) -> Option<f64> {
        let sys = self.sys;
        sys.switches(self.t + h, &self.ynew, &mut self.g_new);
        let mut y_mid = vec![0.0; self.n];
        self.dense_theta(0.5, &mut y_mid);
        sys.switches(self.t + 0.5 * h, &y_mid, &mut self.g_mid);
        let theta_min = 1e-12 * self.t.abs().max(1.0) / h;
        let time_tol = 1e-13 * self.t.abs().max(1.0);
        let mut g = vec![0.0; self.g_old.len()];
        first_root(
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
        )
    }

    /// Time of the previous accepted step's start.
    pub fn t_prev(&self) -> f64 {
        self.t_prev
    }
}

impl<S: OdeSystem + ?Sized> Integrator for Rodas4<'_, S> {
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
        const SAFE: f64 = 0.9;
        const FAC_MIN: f64 = 1.0 / 6.0; // h may grow 6×
        const FAC_MAX: f64 = 5.0; // and shrink 5× at most
        let t_stop = match self.breaks.get(self.next_break) {
            Some(&b) if b < t_max => b,
            _ => t_max,
        };
        if t_stop <= self.t {
            return Ok(());
        }
        self.jacobian();
        let has_switches = self.opts.locate_switches && !self.g_old.is_empty();
        let mut shortened = 0;
        let mut forced_h: Option<f64> = None;
        let mut rejected_here = false;
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
            if self.t + 1.01 * h >= t_stop {
                h = t_stop - self.t;
                lands = true;
            }
            if h <= 1e-14 * self.t.abs().max(1.0) {
                return Err(Error::StepSizeTooSmall { t: self.t, h });
            }
            let err = self.attempt(h);
            if !err.is_finite() {
                if self.opts.fixed_step {
                    return Err(Error::NonFinite { t: self.t });
                }
                self.stats.rejected += 1;
                self.h = h * 0.1;
                forced_h = None;
                rejected_here = true;
                continue;
            }
            let fac_err = (err.powf(0.25) / SAFE).clamp(FAC_MIN, FAC_MAX);
            if err > 1.0 && !self.opts.fixed_step {
                self.stats.rejected += 1;
                self.h = h / fac_err;
                forced_h = None;
                rejected_here = true;
                continue;
            }
            if has_switches && shortened < 12 {
                if let Some(theta) = self.locate_switch(h) {
                    let near_end = if shortened > 0 { 1e-3 } else { 1e-6 };
                    if theta < 1.0 - near_end {
                        shortened += 1;
                        self.stats.switches += 1;
                        forced_h = Some(theta * h);
                        continue;
                    }
                }
            } else if has_switches {
                self.sys.switches(self.t + h, &self.ynew, &mut self.g_new);
            }
            // Accepted: next step from the error, with Gustafsson's predictive correction.
            let mut fac = fac_err;
            if self.n_accepted > 0 && self.hacc > 0.0 {
                let facgus = (self.hacc / h) * (err * err / self.erracc).powf(0.25) / SAFE;
                fac = fac.max(facgus.clamp(FAC_MIN, FAC_MAX));
            }
            self.hacc = h;
            self.erracc = err.max(1e-2);
            self.n_accepted += 1;
            let mut h_next = h / fac;
            if rejected_here {
                h_next = h_next.min(h);
            }
            self.t_prev = self.t;
            self.t += h;
            std::mem::swap(&mut self.y, &mut self.ynew);
            std::mem::swap(&mut self.g_old, &mut self.g_new);
            self.stats.steps += 1;
            if self.opts.fixed_step {
                self.h = self.opts.h_init;
            } else if forced_h.is_none() || h_next > self.h {
                self.h = h_next;
            }
            self.right_limit = false;
            if lands
                && self.next_break < self.breaks.len()
                && self.t >= self.breaks[self.next_break]
            {
                self.t = self.breaks[self.next_break];
                self.next_break += 1;
                self.right_limit = true;
            }
            let t_eval = if self.right_limit {
                self.t.next_up()
            } else {
                self.t
            };
            self.sys.rhs(t_eval, &self.y, &mut self.f0);
            self.stats.rhs_evals += 1;
            return Ok(());
        }
    }

    fn dense(&self, t: f64, out: &mut [f64]) {
        let h = self.t - self.t_prev;
        if h <= 0.0 {
            out.copy_from_slice(&self.y);
            return;
        }
        self.dense_theta((t - self.t_prev) / h, out);
    }
}
