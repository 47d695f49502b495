//! The `differential-equations` crate's DOPRI5 / DOP853: plain, with restarts at switches
//! through its output hook, and with our switch handling on its stepper driven by hand.

use differential_equations::control::ControlFlag;
use differential_equations::interpolate::Interpolation;
use differential_equations::ode::{ODE, OrdinaryNumericalMethod, solve_ode};
use differential_equations::solout::Solout;
use differential_equations::solution::Solution;
use differential_equations::status::Status;
use gearwear::model::GearOde;
use gearwear::solver::OdeSystem;

use crate::problem::{Counts, DeMode, Problem, Run};

/// `GearOde` seen through `differential-equations`' trait.
pub(crate) struct DeSys<'a>(&'a GearOde);

impl<const N: usize> ODE<f64, [f64; N]> for DeSys<'_> {
    fn diff(&self, t: f64, y: &[f64; N], dydt: &mut [f64; N]) {
        self.0.rhs(t, y, dydt);
    }
}

/// Output handler for `differential-equations`: samples the grid from the crate's interpolant
/// and, with `restart`, locates the first switch (`OdeSystem::switches`) in every accepted step
/// — sign check at the step's end and midpoint, Illinois root finding on the interpolant, as
/// ours does — and restarts the solver on the far side of it (`ControlFlag::ModifyState`).
pub(crate) struct GridSolout<'a, const N: usize> {
    pub(crate) sys: &'a GearOde,
    pub(crate) t0: f64,
    pub(crate) dt: f64,
    pub(crate) n: usize,
    pub(crate) k: usize,
    pub(crate) samples: Vec<f64>,
    pub(crate) restart: bool,
    pub(crate) started: bool,
    pub(crate) g_prev: Vec<f64>,
    pub(crate) g_end: Vec<f64>,
    pub(crate) g_mid: Vec<f64>,
    pub(crate) g_tmp: Vec<f64>,
    pub(crate) restarts: usize,
}

impl<'a, const N: usize> GridSolout<'a, N> {
    pub(crate) fn new(p: &Problem<'a>, restart: bool) -> Self {
        let ns = p.sys.n_switches();
        GridSolout {
            sys: p.sys,
            t0: p.t0,
            dt: p.dt,
            n: p.n,
            k: 0,
            samples: Vec::with_capacity(p.n * N),
            restart,
            started: false,
            g_prev: vec![0.0; ns],
            g_end: vec![0.0; ns],
            g_mid: vec![0.0; ns],
            g_tmp: vec![0.0; ns],
            restarts: 0,
        }
    }

    fn grid(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }

    /// Emit the grid samples in `(.., t_hi]` (with the usual 1e-9·dt slack).
    fn emit<I: Interpolation<f64, [f64; N]> + ?Sized>(
        &mut self,
        t_lo: f64,
        t_hi: f64,
        y_hi: &[f64; N],
        interp: &mut I,
    ) {
        let slack = 1e-9 * self.dt;
        while self.k < self.n && self.grid(self.k) <= t_hi + slack {
            let t = self.grid(self.k);
            if t >= t_hi - slack {
                self.samples.extend_from_slice(y_hi);
            } else {
                let y = interp
                    .interpolate(t.max(t_lo))
                    .expect("interpolation inside the step");
                self.samples.extend_from_slice(&y);
            }
            self.k += 1;
        }
    }

    /// Earliest switch in `(t_prev, t_curr]`, as the time just past the root.
    fn locate<I: Interpolation<f64, [f64; N]> + ?Sized>(
        &mut self,
        t_prev: f64,
        t_curr: f64,
        y_curr: &[f64; N],
        interp: &mut I,
    ) -> Option<f64> {
        let sys = self.sys;
        sys.switches(t_curr, y_curr, &mut self.g_end);
        let tm = 0.5 * (t_prev + t_curr);
        let ym = interp.interpolate(tm).expect("midpoint");
        sys.switches(tm, &ym, &mut self.g_mid);
        let mut best: Option<f64> = None;
        let t_min = t_prev + 1e-12 * t_prev.abs().max(1.0);
        for i in 0..self.g_prev.len() {
            let (g0, gm, g1) = (self.g_prev[i], self.g_mid[i], self.g_end[i]);
            let bracket = if g0 != 0.0 && (g0 > 0.0) != (gm > 0.0) {
                Some((t_prev, g0, tm, gm))
            } else if gm != 0.0 && g1 != 0.0 && (gm > 0.0) != (g1 > 0.0) {
                Some((tm, gm, t_curr, g1))
            } else {
                None
            };
            let Some((mut a, mut ga, mut b, mut gb)) = bracket else {
                continue;
            };
            if best.is_some_and(|bst| a >= bst) {
                continue;
            }
            let mut side = 0i8;
            for _ in 0..60 {
                let c = (a * gb - b * ga) / (gb - ga);
                let c = if c.is_finite() && c > a && c < b {
                    c
                } else {
                    0.5 * (a + b)
                };
                let yc = interp.interpolate(c).expect("root bracket");
                sys.switches(c, &yc, &mut self.g_tmp);
                let gc = self.g_tmp[i];
                if (gc > 0.0) == (gb > 0.0) {
                    b = c;
                    gb = gc;
                    if side == 1 {
                        ga *= 0.5;
                    }
                    side = 1;
                } else {
                    a = c;
                    ga = gc;
                    if side == -1 {
                        gb *= 0.5;
                    }
                    side = -1;
                }
                if b - a < 1e-13 * t_curr.abs().max(1.0) {
                    break;
                }
            }
            if b > t_min && best.is_none_or(|bst| b < bst) {
                best = Some(b);
            }
        }
        best
    }
}

impl<const N: usize> Solout<f64, [f64; N]> for GridSolout<'_, N> {
    fn solout<I>(
        &mut self,
        t_curr: f64,
        t_prev: f64,
        y_curr: &[f64; N],
        _y_prev: &[f64; N],
        interp: &mut I,
        _solution: &mut Solution<f64, [f64; N]>,
    ) -> ControlFlag<f64, [f64; N]>
    where
        I: Interpolation<f64, [f64; N]> + ?Sized,
    {
        if !self.started {
            self.started = true;
            self.sys.switches(t_curr, y_curr, &mut self.g_prev);
            // Only the start point can be on the grid here.
            let slack = 1e-9 * self.dt;
            if self.n > 0 && (self.grid(0) - t_curr).abs() <= slack {
                self.samples.extend_from_slice(y_curr);
                self.k = 1;
            }
            return ControlFlag::Continue;
        }
        if self.restart
            && !self.g_prev.is_empty()
            && let Some(t_ev) = self.locate(t_prev, t_curr, y_curr, interp)
            && t_ev < t_curr - 1e-12 * t_curr.abs().max(1.0)
        {
            let y_ev = interp.interpolate(t_ev).expect("event state");
            self.emit(t_prev, t_ev, &y_ev, interp);
            self.sys.switches(t_ev, &y_ev, &mut self.g_prev);
            self.restarts += 1;
            return ControlFlag::ModifyState(t_ev, y_ev);
        }
        self.emit(t_prev, t_curr, y_curr, interp);
        if self.restart {
            std::mem::swap(&mut self.g_prev, &mut self.g_end);
        }
        ControlFlag::Continue
    }
}

pub(crate) fn run_de<const N: usize, M>(p: &Problem, method: &mut M, mode: DeMode) -> Run
where
    M: OrdinaryNumericalMethod<f64, [f64; N]> + Interpolation<f64, [f64; N]>,
{
    if mode == DeMode::Redo {
        return run_de_redo::<N, M>(p, method);
    }
    let sys = DeSys(p.sys);
    let mut y0 = [0.0; N];
    y0.copy_from_slice(&p.y0);
    let mut out = GridSolout::<N>::new(p, mode == DeMode::Restart);
    let sol = solve_ode(method, &sys, 0.0, p.t_end(), &y0, &mut out).expect("crate solve");
    assert_eq!(out.k, p.n, "{} of {} samples", out.k, p.n);
    Run {
        samples: out.samples,
        counts: Counts {
            rhs: sol.evals.function,
            accepted: sol.steps.accepted,
            rejected: sol.steps.rejected,
            switches: out.restarts,
        },
    }
}

/// The crate's stepper driven by hand with our switch handling (see [`DeMode::Redo`]). An
/// undone step counts as rejected; each undo costs one extra RHS evaluation (`init`).
pub(crate) fn run_de_redo<const N: usize, M>(p: &Problem, m: &mut M) -> Run
where
    M: OrdinaryNumericalMethod<f64, [f64; N]> + Interpolation<f64, [f64; N]>,
{
    let ode = DeSys(p.sys);
    let t_end = p.t_end();
    let mut y0 = [0.0; N];
    y0.copy_from_slice(&p.y0);
    let mut c = Counts::default();
    c.rhs += m.init(&ode, 0.0, t_end, &y0).expect("init").function;
    let mut out = GridSolout::<N>::new(p, true);
    p.sys.switches(0.0, &y0, &mut out.g_prev);
    out.started = true;
    if p.n > 0 && p.t0.abs() <= 1e-9 * p.dt {
        out.samples.extend_from_slice(&y0);
        out.k = 1;
    }
    let mut shortened = 0usize;
    let mut h_before: Option<f64> = None;
    while m.t() < t_end - 1e-12 * t_end.abs().max(1.0) {
        if m.t() + m.h() > t_end {
            let h = t_end - m.t();
            m.set_h(h);
        }
        let (t_start, y_start) = (m.t(), *m.y());
        c.rhs += m.step(&ode).expect("crate step").function;
        if matches!(m.status(), Status::RejectedStep) {
            c.rejected += 1;
            continue;
        }
        let (t_curr, y_curr) = (m.t(), *m.y());
        if shortened < 12
            && let Some(t_ev) = out.locate(t_start, t_curr, &y_curr, m)
        {
            let near_end = if shortened > 0 { 1e-3 } else { 1e-6 };
            if t_ev - t_start < (1.0 - near_end) * (t_curr - t_start) {
                // Undo: restart at the step's start and end the next step on the switch.
                h_before.get_or_insert(m.h());
                c.rhs += m
                    .init(&ode, t_start, t_end, &y_start)
                    .expect("init")
                    .function;
                m.set_h(t_ev - t_start);
                shortened += 1;
                c.switches += 1;
                c.rejected += 1;
                continue;
            }
        }
        c.accepted += 1;
        if shortened > 0 {
            // As ours: after a shortened step keep the larger of the two proposals.
            let h = m.h().max(h_before.take().unwrap_or(0.0));
            m.set_h(h);
            shortened = 0;
        }
        out.emit(t_start, t_curr, &y_curr, m);
        std::mem::swap(&mut out.g_prev, &mut out.g_end);
    }
    assert_eq!(out.k, p.n, "{} of {} samples", out.k, p.n);
    Run {
        samples: out.samples,
        counts: c,
    }
}
