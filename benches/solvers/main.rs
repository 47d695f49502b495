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

mod de;
mod os;
mod ours;
mod problem;
mod solver;

#[path = "../../crates/core/tests/support/one_mesh.rs"]
mod one_mesh;

use std::f64::consts::TAU;
use std::hint::black_box;
use std::time::Instant;

use gearwear::model::Wear;

use crate::problem::{DeMode, Problem, Run};
use crate::solver::Solver;
use one_mesh::{OneMesh, one_mesh_assembly};

/// Repetitions for the timings (median reported).
const REPS: usize = 5;

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
