//! Our DOPRI5 against well-kept crates on the same gear model.
//!
//! `cargo bench --features compare-solvers --bench solvers` (harness = false) prints three tables:
//!
//! 1. **Work–precision on a single mesh with backlash** against the exact piecewise closed-form
//!    solution (the same reference as `tests/physics.rs`): max error of x over τ ∈ [0, 60]
//!    sampled every 0.02, against RHS evaluations, for a ladder of tolerances.
//! 2. **Accuracy on Model A** (ea = 0.8) over a short horizon (τ ∈ [0, 40], before chaos
//!    amplifies differences) against a tight reference (our DOPRI5 at rtol 1e-12, cross-checked
//!    against fixed-step RK4 at h = 1e-4).
//! 3. **Cost on Model A** (ea = 0.8, Ω1 = 0.3, 1.0, 3.0): the default transient
//!    (max(400 τ, 20 T1)) then 80 periods × 256 samples, wall time (median of `REPS` runs),
//!    RHS evaluations, accepted / rejected steps.
//!
//! Solvers: `ours` ([`gearwear::solver::Dopri5`], switch location on), `ours-nolocate` (off),
//! `de-dopri5` / `de-dop853` (`differential-equations`, `ExplicitRungeKutta::dopri5/dop853`),
//! `de-dopri5+restart` / `de-dop853+restart` (the same, plus switch location through the crate's
//! public hooks: a `Solout` that finds the first switch in each accepted step on the crate's
//! interpolant and returns `ControlFlag::ModifyState` to restart the solver there — the crate's
//! own `Event` only reports a crossing, it does not shorten the step), `de-dopri5+redo` /
//! `de-dop853+redo` (our switch handling on the crate's stepper, driven by hand through its public
//! `OrdinaryNumericalMethod` trait: a straddling step is undone and redone to end on the switch),
//! `os-dopri5` (`ode_solvers`,
//! Hairer's DOPRI5 port with its own dense output; no event location).
//!
//! All solvers integrate the same `GearOde::rhs` and deliver the same samples on the same grid
//! from their dense output.

use std::f64::consts::TAU;
use std::hint::black_box;
use std::time::Instant;

use differential_equations::{
    control::ControlFlag,
    interpolate::Interpolation,
    methods::{DormandPrince, ExplicitRungeKutta, Ordinary},
    ode::{ODE, OrdinaryNumericalMethod, solve_ode},
    solout::Solout,
    solution::Solution,
    status::Status,
};
use gearwear::model::{GearOde, Wear};
use gearwear::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Rk4, advance_to, sample_uniform,
};

/// Repetitions for the timings (median reported).
const REPS: usize = 5;

// ---------------------------------------------------------------------------------------------
// Problem and results
// ---------------------------------------------------------------------------------------------

/// Integrate from τ = 0 (state `y0`) and sample every `dt` from `t0`, `n` samples.
struct Problem<'a> {
    sys: &'a GearOde,
    y0: Vec<f64>,
    t0: f64,
    dt: f64,
    n: usize,
}

impl Problem<'_> {
    fn t_end(&self) -> f64 {
        self.t0 + (self.n - 1) as f64 * self.dt
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    rhs: usize,
    accepted: usize,
    rejected: usize,
    /// Switches located (steps shortened for ours, restarts for the crate).
    switches: usize,
}

/// Samples (row-major, `dim` per grid time) and counters.
struct Run {
    samples: Vec<f64>,
    counts: Counts,
}

/// How switches are handled with `differential-equations`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DeMode {
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
enum Solver {
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
    fn label(&self) -> &'static str {
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

    fn with_tol(self, rtol: f64, atol: f64) -> Self {
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

    fn run<const N: usize>(&self, p: &Problem) -> Run {
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

// ---------------------------------------------------------------------------------------------
// Drivers
// ---------------------------------------------------------------------------------------------

fn run_ours(p: &Problem, opts: Dopri5Options) -> Run {
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

fn run_rk4(p: &Problem, h: f64) -> Run {
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

/// `GearOde` seen through `differential-equations`' trait.
struct DeSys<'a>(&'a GearOde);

impl<const N: usize> ODE<f64, [f64; N]> for DeSys<'_> {
    fn diff(&self, t: f64, y: &[f64; N], dydt: &mut [f64; N]) {
        self.0.rhs(t, y, dydt);
    }
}

/// Output handler for `differential-equations`: samples the grid from the crate's interpolant
/// and, with `restart`, locates the first switch (`OdeSystem::switches`) in every accepted step
/// — sign check at the step's end and midpoint, Illinois root finding on the interpolant, as
/// ours does — and restarts the solver on the far side of it (`ControlFlag::ModifyState`).
struct GridSolout<'a, const N: usize> {
    sys: &'a GearOde,
    t0: f64,
    dt: f64,
    n: usize,
    k: usize,
    samples: Vec<f64>,
    restart: bool,
    started: bool,
    g_prev: Vec<f64>,
    g_end: Vec<f64>,
    g_mid: Vec<f64>,
    g_tmp: Vec<f64>,
    restarts: usize,
}

impl<'a, const N: usize> GridSolout<'a, N> {
    fn new(p: &Problem<'a>, restart: bool) -> Self {
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

fn run_de<const N: usize, M>(p: &Problem, method: &mut M, mode: DeMode) -> Run
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
fn run_de_redo<const N: usize, M>(p: &Problem, m: &mut M) -> Run
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

/// `GearOde` seen through `ode_solvers`' trait.
struct OsSys<'a>(&'a GearOde);

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

fn run_os<const N: usize>(p: &Problem, rtol: f64, atol: f64) -> Run {
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

// ---------------------------------------------------------------------------------------------
// Timing helpers
// ---------------------------------------------------------------------------------------------

fn median(mut v: Vec<f64>) -> f64 {
    gearwear::signal::median(&mut v)
}

/// Median wall time of `reps` runs after one warm-up run, and the last run.
fn timed<const N: usize>(s: &Solver, p: &Problem, reps: usize) -> (f64, Run) {
    let mut times = Vec::with_capacity(reps);
    // One untimed warm-up run (caches, CPU clock).
    let mut last = Some(black_box(s.run::<N>(p)));
    for _ in 0..reps {
        let t = Instant::now();
        let r = black_box(s.run::<N>(p));
        times.push(t.elapsed().as_secs_f64());
        last = Some(r);
    }
    (median(times), last.unwrap())
}

/// Max abs difference over the first `ncomp` components of every sample.
fn max_err(a: &[f64], b: &[f64], dim: usize, ncomp: usize) -> f64 {
    assert_eq!(a.len(), b.len());
    a.chunks(dim)
        .zip(b.chunks(dim))
        .flat_map(|(x, y)| (0..ncomp).map(move |i| (x[i] - y[i]).abs()))
        .fold(0.0, f64::max)
}

// ---------------------------------------------------------------------------------------------
// 1. Single mesh with backlash: exact reference (`crates/core/tests/support/one_mesh.rs`, shared with
//    tests/physics.rs)
// ---------------------------------------------------------------------------------------------

#[path = "../crates/core/tests/support/one_mesh.rs"]
mod one_mesh;
use one_mesh::{OneMesh, one_mesh_assembly};

fn all_adaptive() -> Vec<Solver> {
    let (rtol, atol) = (1e-6, 1e-8);
    let mut v = vec![
        Solver::Ours {
            rtol,
            atol,
            locate: true,
        },
        Solver::Ours {
            rtol,
            atol,
            locate: false,
        },
    ];
    for dop853 in [false, true] {
        for mode in [DeMode::Plain, DeMode::Restart, DeMode::Redo] {
            v.push(Solver::De {
                dop853,
                rtol,
                atol,
                mode,
            });
        }
    }
    v.push(Solver::Os { rtol, atol });
    v
}

fn single_mesh() {
    let p = OneMesh {
        c: 0.1,
        k: 1.0,
        b: 1.0,
        f: 0.1,
        a: 0.8,
        w: 0.9,
        phi: 0.3,
    };
    let model = one_mesh_assembly(&p).resolve().unwrap();
    let sys = model.system(p.w).unwrap();
    let (dt, n) = (0.02, 3001);
    let grid: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let reference = p.reference(0.0, 0.0, &grid);
    let crossings = reference
        .windows(2)
        .filter(|w| p.region(w[0]) != p.region(w[1]))
        .count();
    let prob = Problem {
        sys: &sys,
        y0: vec![0.0, 0.0],
        t0: 0.0,
        dt,
        n,
    };
    println!(
        "\n## 1. Single mesh with backlash vs exact piecewise closed form\n\n\
         τ ∈ [0, 60], 3001 samples (dt = 0.02), {crossings} region changes; error = max |x − x_exact|; \
         atol = rtol·1e-2; time = median of {REPS} runs.\n"
    );
    println!(
        "| solver | rtol | max error | RHS evals | accepted | rejected | switches | time (µs) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for s in all_adaptive() {
        for rtol in [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10] {
            let s = s.with_tol(rtol, rtol * 1e-2);
            let (t, r) = timed::<2>(&s, &prob, REPS);
            let e = max_err(
                &r.samples,
                &reference.iter().flat_map(|&x| [x, 0.0]).collect::<Vec<_>>(),
                2,
                1,
            );
            println!(
                "| {} | {rtol:.0e} | {e:.2e} | {} | {} | {} | {} | {:.0} |",
                s.label(),
                r.counts.rhs,
                r.counts.accepted,
                r.counts.rejected,
                r.counts.switches,
                t * 1e6
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 2./3. Model A
// ---------------------------------------------------------------------------------------------

fn model_a_accuracy(model: &gearwear::model::DimensionlessModel) {
    println!(
        "\n## 2. Model A (ea = 0.8): accuracy over τ ∈ [0, 40] from the zero state\n\n\
         Error = max over samples (dt = 0.05) of |x̄_j − x̄_j,ref| over the 10 deflections \
         (amplitudes are O(1)). Reference: ours at rtol 1e-12, atol 1e-14; its distance to RK4 \
         at h = 1e-4 is given per Ω1.\n"
    );
    println!(
        "| Ω1 | solver | rtol / atol | max error | RHS evals | accepted | rejected | switches |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for omega1 in [0.3, 1.0, 3.0] {
        let sys = model.system(omega1).unwrap();
        let prob = Problem {
            sys: &sys,
            y0: vec![0.0; 20],
            t0: 0.0,
            dt: 0.05,
            n: 801,
        };
        let reference = Solver::Ours {
            rtol: 1e-12,
            atol: 1e-14,
            locate: true,
        }
        .run::<20>(&prob);
        let rk = Solver::Rk4 { h: 1e-4 }.run::<20>(&prob);
        println!(
            "| {omega1} | reference vs rk4(h=1e-4) | – | {:.2e} | {} | {} | {} | {} |",
            max_err(&reference.samples, &rk.samples, 20, 10),
            reference.counts.rhs,
            reference.counts.accepted,
            reference.counts.rejected,
            reference.counts.switches
        );
        for (rtol, atol) in [(1e-6, 1e-8), (1e-9, 1e-11)] {
            for s in all_adaptive() {
                let s = s.with_tol(rtol, atol);
                let r = s.run::<20>(&prob);
                println!(
                    "| {omega1} | {} | {rtol:.0e} / {atol:.0e} | {:.2e} | {} | {} | {} | {} |",
                    s.label(),
                    max_err(&r.samples, &reference.samples, 20, 10),
                    r.counts.rhs,
                    r.counts.accepted,
                    r.counts.rejected,
                    r.counts.switches
                );
            }
        }
    }
}

fn model_a_cost(model: &gearwear::model::DimensionlessModel) {
    let tr = gearwear::analysis::simulate::Transient::default();
    println!(
        "\n## 3. Model A (ea = 0.8): cost of one paper run\n\n\
         Transient max({} τ, {} T1) from the zero state, then 80 periods × 256 samples; \
         rtol 1e-6, atol 1e-8; time = median of {REPS} runs, one thread. \
         `ratio` = time / time(ours) at the same Ω1, measured in this process.\n",
        tr.tau, tr.periods
    );
    println!("| Ω1 | solver | time (ms) | ratio | RHS evals | accepted | rejected | switches |");
    println!("|---|---|---|---|---|---|---|---|");
    for omega1 in [0.3, 1.0, 3.0] {
        let sys = model.system(omega1).unwrap();
        let period = TAU / omega1;
        let prob = Problem {
            sys: &sys,
            y0: vec![0.0; 20],
            t0: tr.length(omega1),
            dt: period / 256.0,
            n: 80 * 256,
        };
        let mut t_ours = None;
        for s in all_adaptive() {
            let (t, r) = timed::<20>(&s, &prob, REPS);
            let base = *t_ours.get_or_insert(t);
            println!(
                "| {omega1} | {} | {:.2} | {:.2} | {} | {} | {} | {} |",
                s.label(),
                t * 1e3,
                t / base,
                r.counts.rhs,
                r.counts.accepted,
                r.counts.rejected,
                r.counts.switches
            );
        }
    }
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument selects sections by name.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let want = |name: &str| args.is_empty() || args.iter().any(|a| name.contains(a.as_str()));
    println!(
        "# Solver benchmark (gearwear DOPRI5 vs differential-equations 0.7 and ode_solvers 0.6)"
    );
    if want("single-mesh") {
        single_mesh();
    }
    let model = gearwear::gearbox::Gearbox::paper_rig()
        .assembly(Wear::fixed_axis(0.8))
        .unwrap()
        .resolve()
        .unwrap();
    if want("accuracy") {
        model_a_accuracy(&model);
    }
    if want("cost") {
        model_a_cost(&model);
    }
}
