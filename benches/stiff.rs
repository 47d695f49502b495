//! Stiff-solver benchmark on Model B: the crate's RODAS4 and DOPRI5 against `diffsol`'s BDF and
//! SDIRK methods (TR-BDF2, ESDIRK34), all on the same right-hand side and the same case as
//! `gearwear model-b solvers` (3.5 s of the default steady run, square-wave stiffness, samples at
//! 20 kHz), measured against DOPRI5 at rtol 1e-11, atol 1e-13.
//!
//! ```text
//! CARGO_TARGET_DIR=/work/target-modelb2 cargo bench --features compare-solvers --bench stiff            # full table
//! CARGO_TARGET_DIR=/work/target-modelb2 cargo bench --features compare-solvers --bench stiff -- --quick # 1 repetition
//! ```
//!
//! diffsol gets the model through `OdeBuilder::rhs_implicit`: the right-hand side is
//! `GearOde::rhs` behind `EdgeAware` and the Jacobian–vector product is a forward difference
//! (the same information RODAS4 uses: a finite-difference Jacobian, one extra right-hand-side
//! call per column, `f(y)` cached per point). The contact-ratio edge breakpoints are given as
//! stop times (`set_stop_time`, the solver lands on each exactly without restarting) and the
//! backlash switches `x ∓ b` as root functions: on `RootFound` the state is moved back to the
//! root (`state_mut_back`) and integration restarts from there, as diffsol documents for hybrid
//! systems. Mode `across` integrates with neither, to show what the stops buy.
//!
//! Wall and thread-CPU times are medians of 5 runs (`--quick`: 1), single-threaded, release
//! build. The wall time of our solvers is the integration alone (`Record::wall_s`); the CPU time
//! is the whole job for every solver (setup, integration, sampling ÿ).

use std::cell::{Cell, RefCell};
use std::time::Instant;

use diffsol::{
    NalgebraLU, NalgebraMat, OdeBuilder, OdeSolverMethod, OdeSolverStopReason, VectorCommon,
};
use gearwear::analysis::model_b::{self, Prepared, SimSpec, SolverKind, SolverSettings};
use gearwear::model::{ModelBConfig, ModelBOptions};
use gearwear::solver::OdeSystem;

type M = NalgebraMat<f64>;
type LS = NalgebraLU<f64>;

const SAMPLE_HZ: f64 = 20_000.0;

#[derive(Clone, Copy, PartialEq)]
enum Method {
    Bdf,
    TrBdf2,
    Esdirk34,
}

impl Method {
    fn name(self) -> &'static str {
        match self {
            Method::Bdf => "diffsol BDF",
            Method::TrBdf2 => "diffsol TR-BDF2",
            Method::Esdirk34 => "diffsol ESDIRK34",
        }
    }
}

/// What a run produced: ÿ1..ÿ4 on the sample grid (m/s²) and counters.
struct Run {
    acc: [Vec<f64>; 4],
    steps: usize,
    rejected: usize,
    rhs_evals: usize,
    lu: usize,
    restarts: usize,
    newton_fails: usize,
    wall_s: f64,
}

/// ÿ on the grid from sampled states: the bearing rows of the right-hand side.
struct Sampler<'a> {
    p: &'a Prepared,
    iy: [usize; 4],
    scale: f64,
    dy: Vec<f64>,
    acc: [Vec<f64>; 4],
}

impl<'a> Sampler<'a> {
    fn new(p: &'a Prepared) -> Self {
        let wh = p.omega_h();
        let iy = [1, 2, 3, 4].map(|i| p.model.index(&format!("y{i}")).unwrap());
        Sampler {
            p,
            iy,
            scale: p.model.length_ref * wh * wh,
            dy: vec![0.0; 2 * p.model.n()],
            acc: Default::default(),
        }
    }
    fn push(&mut self, tau: f64, y: &[f64]) {
        let n = self.p.model.n();
        self.p.sys.rhs(tau, y, &mut self.dy);
        for (k, &j) in self.iy.iter().enumerate() {
            self.acc[k].push(self.dy[n + j] * self.scale);
        }
    }
}

/// One benchmark case: a prepared Model B variant and how long to run it.
struct Case {
    name: &'static str,
    p: Prepared,
    duration_s: f64,
}

/// The sampling and restart schedule of one diffsol run (see [`drive!`]).
struct Drive<'a> {
    sampler: Sampler<'a>,
    y0: &'a [f64],
    /// The system's breakpoints after t = 0: the stop times when `stops`.
    breaks: &'a [f64],
    /// Load steps: the right-hand side jumps there, so the solver is restarted (as after a root).
    load_steps: &'a [f64],
    stops: bool,
    /// Lift diffsol's cap on Newton convergence failures over the whole run.
    lift_newton_cap: bool,
    /// Sample step and end time (dimensionless).
    dt: f64,
    t_end: f64,
    /// Restarts so far (roots and load steps).
    restarts: usize,
}

/// Run one diffsol method (`bdf`, `tr_bdf2`, `esdirk34`) on `$problem` through the schedule
/// `$drive` ([`Drive`]): sample on the grid, restart at switches (roots) and load steps, stop
/// at the breakpoints when `stops`. A macro, not a function: the three solvers share no trait
/// that exposes their configuration. Evaluates to (steps, rejected steps, LU setups, Newton
/// failures); `?` returns from the caller.
macro_rules! drive {
    ($method:ident, $problem:expr, $drive:expr) => {{
        let d: &mut Drive = $drive;
        let (breaks, load_steps, stops, dt, t_end) =
            (d.breaks, d.load_steps, d.stops, d.dt, d.t_end);
        let problem = $problem;
        let mut s = problem.$method::<LS>().map_err(|e| format!("{e}"))?;
        if d.lift_newton_cap {
            // diffsol stops after 50 Newton convergence failures summed over the whole run
            // (not per step); a long run through many stiffness edges reaches that.
            s.config_mut().maximum_newton_fails = usize::MAX;
        }
        let slack = 1e-9 * dt;
        let mut k = 0usize;
        d.sampler.push(0.0, d.y0);
        k += 1;
        let mut bi = 0usize;
        let next_stop = |bi: usize| -> f64 {
            if stops && bi < breaks.len() {
                breaks[bi]
            } else {
                t_end
            }
        };
        s.set_stop_time(next_stop(bi)).map_err(|e| format!("{e}"))?;
        let mut last_root = f64::NEG_INFINITY;
        loop {
            let reason = s.step().map_err(|e| format!("{e}"))?;
            let t_now = match reason {
                OdeSolverStopReason::RootFound(tr, _) => tr,
                _ => s.state().t,
            };
            while (k as f64) * dt <= t_now.min(t_end) + slack {
                let tk = ((k as f64) * dt).min(t_now);
                let y = s.interpolate(tk).map_err(|e| format!("{e}"))?;
                d.sampler.push(tk, y.inner().as_slice());
                k += 1;
            }
            match reason {
                OdeSolverStopReason::RootFound(tr, _) => {
                    // Restart at the switch unless it is the one just restarted from.
                    if tr > last_root + 1e-9 * dt.max(tr.abs() * 1e-6) {
                        s.state_mut_back(tr).map_err(|e| format!("{e}"))?;
                        last_root = tr;
                        d.restarts += 1;
                    }
                }
                OdeSolverStopReason::TstopReached => {
                    if s.state().t >= t_end - slack {
                        break;
                    }
                    let t = s.state().t;
                    if load_steps.iter().any(|&b| (b - t).abs() <= slack) {
                        // Touching the state marks it modified: the next step restarts.
                        let _ = s.state_mut();
                        d.restarts += 1;
                    }
                    bi += 1;
                    while stops && bi < breaks.len() && breaks[bi] <= s.state().t + slack {
                        bi += 1;
                    }
                    s.set_stop_time(next_stop(bi)).map_err(|e| format!("{e}"))?;
                }
                OdeSolverStopReason::InternalTimestep => {}
            }
        }
        let st = s.get_statistics().clone();
        (
            st.number_of_steps,
            st.number_of_error_test_failures,
            st.number_of_linear_solver_setups,
            st.number_of_nonlinear_solver_fails,
        )
    }};
}

#[allow(clippy::too_many_arguments)]
fn run_diffsol(
    case: &Case,
    method: Method,
    rtol: f64,
    atol: f64,
    stops: bool,
    lift_newton_cap: bool,
) -> Result<Run, String> {
    let p = &case.p;
    let wh = p.omega_h();
    let t_end = case.duration_s * wh;
    let dt = wh / SAMPLE_HZ;
    let sys = p.edge_aware(t_end);
    // Load steps: the right-hand side jumps there, so the solver is restarted (as after a root).
    let load_steps = p.sys.breakpoints();
    let dim = sys.dim();
    let y0 = p.static_start().map_err(|e| e.to_string())?;
    let evals = Cell::new(0usize);
    // f(y) at the last point a Jacobian column was differenced at: (t, y, f).
    let cache: RefCell<(f64, Vec<f64>, Vec<f64>)> =
        RefCell::new((f64::NAN, vec![f64::NAN; dim], vec![0.0; dim]));
    let scratch = RefCell::new((vec![0.0; dim], vec![0.0; dim]));
    let n_sw = sys.n_switches();
    let start = Instant::now();
    let y0c = y0.clone();
    let builder = OdeBuilder::<M>::new()
        .rtol(rtol)
        .atol([atol])
        .h0(1.0)
        .rhs_implicit(
            |x: &[f64], _p: &[f64], t: f64, y: &mut [f64]| {
                evals.set(evals.get() + 1);
                sys.rhs(t, x, y);
            },
            |x: &[f64], _p: &[f64], t: f64, v: &[f64], jv: &mut [f64]| {
                let mut c = cache.borrow_mut();
                if c.0 != t || c.1 != x {
                    c.0 = t;
                    c.1.copy_from_slice(x);
                    evals.set(evals.get() + 1);
                    sys.rhs(t, x, &mut c.2);
                }
                let vmax = v.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
                if vmax == 0.0 {
                    jv.fill(0.0);
                    return;
                }
                let xmax = x.iter().fold(1.0_f64, |m, a| m.max(a.abs()));
                let eps = f64::EPSILON.sqrt() * xmax / vmax;
                let mut s = scratch.borrow_mut();
                let (xp, fp) = &mut *s;
                for i in 0..x.len() {
                    xp[i] = x[i] + eps * v[i];
                }
                evals.set(evals.get() + 1);
                sys.rhs(t, xp, fp);
                for i in 0..x.len() {
                    jv[i] = (fp[i] - c.2[i]) / eps;
                }
            },
        )
        .init(
            move |_p: &[f64], _t: f64, y: &mut [f64]| y.copy_from_slice(&y0c),
            dim,
        );
    let breaks: Vec<f64> = sys.breakpoints().into_iter().filter(|&b| b > 0.0).collect();
    let mut d = Drive {
        sampler: Sampler::new(p),
        y0: &y0,
        breaks: &breaks,
        load_steps: &load_steps,
        stops,
        lift_newton_cap,
        dt,
        t_end,
        restarts: 0,
    };
    let (steps, rejected, lu, newton_fails) = if stops && n_sw > 0 {
        let problem = builder
            .root(
                |x: &[f64], _p: &[f64], t: f64, g: &mut [f64]| sys.switches(t, x, g),
                n_sw,
            )
            .build()
            .map_err(|e| format!("{e}"))?;
        match method {
            Method::Bdf => drive!(bdf, problem, &mut d),
            Method::TrBdf2 => drive!(tr_bdf2, problem, &mut d),
            Method::Esdirk34 => drive!(esdirk34, problem, &mut d),
        }
    } else {
        let problem = builder.build().map_err(|e| format!("{e}"))?;
        match method {
            Method::Bdf => drive!(bdf, problem, &mut d),
            Method::TrBdf2 => drive!(tr_bdf2, problem, &mut d),
            Method::Esdirk34 => drive!(esdirk34, problem, &mut d),
        }
    };
    let wall_s = start.elapsed().as_secs_f64();
    Ok(Run {
        acc: d.sampler.acc,
        steps,
        rejected,
        rhs_evals: evals.get(),
        lu,
        restarts: d.restarts,
        newton_fails,
        wall_s,
    })
}

fn run_own(case: &Case, kind: SolverKind, rtol: f64, atol: f64) -> Run {
    let p = &case.p;
    let spec = SimSpec {
        duration_s: case.duration_s,
        sample_hz: SAMPLE_HZ,
        solver: SolverSettings { kind, rtol, atol },
    };
    let r = model_b::simulate(p, &spec).expect("simulate");
    Run {
        acc: r.acc,
        steps: r.stats.steps,
        rejected: r.stats.rejected,
        rhs_evals: r.stats.rhs_evals,
        lu: if kind == SolverKind::Rodas4 {
            r.stats.steps + r.stats.rejected
        } else {
            0
        },
        restarts: r.stats.switches,
        newton_fails: 0,
        wall_s: r.wall_s,
    }
}

fn max_err(a: &[Vec<f64>; 4], b: &[Vec<f64>; 4]) -> Option<f64> {
    let mut m = 0.0_f64;
    for i in 0..4 {
        if a[i].len() != b[i].len() {
            return None;
        }
        for (x, y) in a[i].iter().zip(&b[i]) {
            m = m.max((x - y).abs());
        }
    }
    Some(m)
}

/// CPU time of this thread (s), from the scheduler's statistics: less sensitive than wall time
/// to other work on a shared machine.
fn thread_cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps = if args.iter().any(|a| a == "--quick") {
        1
    } else {
        5
    };
    let cfg = ModelBConfig::default_rig();
    let cases = [Case {
        name: "steady run, 3.5 s (as `gearwear model-b solvers`)",
        p: Prepared::new(&cfg, &ModelBOptions::default()).unwrap(),
        duration_s: 3.5,
    }];
    for case in &cases {
        bench_case(case, reps);
    }
}

fn bench_case(case: &Case, reps: usize) {
    let reference = run_own(case, SolverKind::Dopri5, 1e-11, 1e-13);
    let peak = reference.acc[0].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    println!(
        "\n### {}\n\n{SAMPLE_HZ} Hz samples; reference DOPRI5 rtol 1e-11: {} steps, {} switches, \
         {:.3} s, peak |ÿ1| {peak:.2} m/s²; wall = median of {reps}\n",
        case.name, reference.steps, reference.restarts, reference.wall_s
    );
    println!(
        "| solver | mode | rtol (atol = rtol/100) | steps | rejected | Newton failures | rhs calls | LU | restarts/switches | wall (s) | CPU (s) | max error ÿ (m/s²) | relative to peak ÿ1 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    type Job<'a> = (
        String,
        String,
        f64,
        Box<dyn Fn() -> Result<Run, String> + 'a>,
    );
    let mut jobs: Vec<Job> = Vec::new();
    for rtol in [1e-6, 1e-8] {
        jobs.push((
            "DOPRI5".into(),
            "stops+switches".into(),
            rtol,
            Box::new(move || Ok(run_own(case, SolverKind::Dopri5, rtol, rtol * 1e-2))),
        ));
    }
    for rtol in [1e-6, 1e-7, 1e-8, 1e-9, 1e-10] {
        jobs.push((
            "RODAS4".into(),
            "stops+switches".into(),
            rtol,
            Box::new(move || Ok(run_own(case, SolverKind::Rodas4, rtol, rtol * 1e-2))),
        ));
    }
    for method in [Method::Bdf, Method::TrBdf2, Method::Esdirk34] {
        let lift = method == Method::Bdf;
        if lift {
            jobs.push((
                method.name().into(),
                "stops+roots, default limits".into(),
                1e-8,
                Box::new(move || run_diffsol(case, method, 1e-8, 1e-10, true, false)),
            ));
        }
        for rtol in [1e-6, 1e-7, 1e-8, 1e-9, 1e-10] {
            jobs.push((
                method.name().into(),
                if lift {
                    "stops+roots, Newton-failure cap lifted".into()
                } else {
                    "stops+roots".into()
                },
                rtol,
                Box::new(move || run_diffsol(case, method, rtol, rtol * 1e-2, true, lift)),
            ));
        }
        jobs.push((
            method.name().into(),
            "across (no stops, no roots)".into(),
            1e-8,
            Box::new(move || run_diffsol(case, method, 1e-8, 1e-10, false, lift)),
        ));
    }
    for (name, mode, rtol, job) in &jobs {
        let mut walls = Vec::new();
        let mut cpus = Vec::new();
        let mut first: Option<Run> = None;
        let mut failed = None;
        for _ in 0..reps {
            let c0 = thread_cpu_s();
            let res = job();
            cpus.push(thread_cpu_s() - c0);
            match res {
                Ok(r) => {
                    walls.push(r.wall_s);
                    first.get_or_insert(r);
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        match (first, failed) {
            (Some(r), None) => {
                let err = max_err(&r.acc, &reference.acc);
                let (e, rel) = match err {
                    Some(e) => (format!("{e:.2e}"), format!("{:.1e}", e / peak)),
                    None => ("grid mismatch".into(), "-".into()),
                };
                println!(
                    "| {name} | {mode} | {rtol:.0e} | {} | {} | {} | {} | {} | {} | {:.3} | {:.3} | {e} | {rel} |",
                    r.steps,
                    r.rejected,
                    r.newton_fails,
                    r.rhs_evals,
                    r.lu,
                    r.restarts,
                    median(walls),
                    median(cpus)
                );
            }
            (_, e) => {
                println!(
                    "| {name} | {mode} | {rtol:.0e} | failed: {} |",
                    e.unwrap_or_default()
                );
            }
        }
    }
}
