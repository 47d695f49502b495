//! Bifurcation sweeps over the operating frequency Ω1 (the first seed's Figure 2).
//!
//! For every Ω1 of the grid the model is run from the same initial state (zero, the paper's
//! choice), the transient discarded, and the Poincaré samples (once per stage-1 mesh period)
//! of the chosen elements kept together with a motion-state classification of the first one.
//! Grid points run in parallel (rayon); a progress bar shows on a terminal.

use serde::Serialize;

use super::motion::{ClassifyOptions, MotionState, classify, classify_forced};
use super::simulate::{RunSpec, observe};
use crate::error::Result;
use crate::model::DimensionlessModel;
use crate::solver::Stats;
use rayon::prelude::*;

/// One grid point of a sweep.
#[derive(Debug, Clone, Serialize)]
pub struct BifurcationPoint {
    pub omega1: f64,
    /// Per tracked element: the Poincaré points `(x̄, x̄')`.
    pub poincare: Vec<Vec<(f64, f64)>>,
    /// Per tracked element: min and max of `x̄` over all retained samples.
    pub range: Vec<(f64, f64)>,
    /// Motion state of the first tracked element.
    pub state: MotionState,
    /// Largest Lyapunov exponent per stage-1 mesh period, when computed.
    pub lyapunov_per_period: Option<f64>,
    pub stats: Stats,
}

/// A sweep's result.
#[derive(Debug, Clone, Serialize)]
pub struct Bifurcation {
    pub elements: Vec<String>,
    pub points: Vec<BifurcationPoint>,
}

/// The inclusive grid `start, start + step, …, ≤ end` (robust to rounding).
pub fn grid(start: f64, end: f64, step: f64) -> Vec<f64> {
    if !(step > 0.0) || end < start {
        return vec![start];
    }
    let n = ((end - start) / step + 1e-9).floor() as usize;
    // Rounded to 1e-9 so that 0.1 + 2·0.05 prints as 0.2, not 0.20000000000000004.
    (0..=n)
        .map(|i| ((start + i as f64 * step) * 1e9).round() / 1e9)
        .collect()
}

/// Run one grid point.
pub fn point(
    model: &DimensionlessModel,
    spec: &RunSpec,
    elements: &[usize],
) -> Result<BifurcationPoint> {
    let sys = model.system(spec.omega1)?;
    let n = model.n();
    let spp = spec.samples_per_period;
    let mut poincare = vec![Vec::with_capacity(spec.periods); elements.len()];
    let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); elements.len()];
    let mut v_range = (f64::INFINITY, f64::NEG_INFINITY);
    let obs = observe(&sys, Some(model), spec, |k, _, y| {
        for (e, &j) in elements.iter().enumerate() {
            let x = y[j];
            range[e].0 = range[e].0.min(x);
            range[e].1 = range[e].1.max(x);
            if k % spp == 0 {
                poincare[e].push((x, y[n + j]));
            }
        }
        let v = y[n + elements[0]];
        v_range = (v_range.0.min(v), v_range.1.max(v));
    })?;
    let scale = (
        (range[0].1 - range[0].0).max(1e-12),
        (v_range.1 - v_range.0).max(1e-12),
    );
    let opts = ClassifyOptions::default();
    let state = match obs.lyapunov_per_period {
        Some(l) => {
            classify_forced(
                &poincare[0],
                scale,
                l,
                &model.other_frequency_ratios(),
                &opts,
            )?
            .state
        }
        None => classify(&poincare[0], scale, &opts)?.state,
    };
    Ok(BifurcationPoint {
        omega1: spec.omega1,
        poincare,
        range,
        state,
        lyapunov_per_period: obs.lyapunov_per_period,
        stats: obs.stats,
    })
}

/// Sweep `omegas` in parallel. `template` gives periods, sampling, transient, tolerances and
/// initial state; its `omega1` is replaced per point. `progress` is called after each point
/// (from worker threads) with the number of points done.
pub fn sweep(
    model: &DimensionlessModel,
    omegas: &[f64],
    template: &RunSpec,
    elements: &[usize],
    progress: &(dyn Fn() + Sync),
) -> Result<Bifurcation> {
    let points: Result<Vec<BifurcationPoint>> = omegas
        .par_iter()
        .map(|&w| {
            let mut spec = template.clone();
            spec.omega1 = w;
            let p = point(model, &spec, elements);
            progress();
            p
        })
        .collect();
    Ok(Bifurcation {
        elements: elements.iter().map(|&j| model.names[j].clone()).collect(),
        points: points?,
    })
}

impl Bifurcation {
    /// CSV with one row per Poincaré sample:
    /// `omega1,state,<el>,<el>_velocity,…` for the tracked elements.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("omega1,state,lyapunov_per_period");
        for e in &self.elements {
            s.push_str(&format!(",{e},{e}_velocity"));
        }
        s.push('\n');
        for p in &self.points {
            let m = p.poincare.iter().map(|v| v.len()).min().unwrap_or(0);
            for k in 0..m {
                let l = p
                    .lyapunov_per_period
                    .map(|l| format!("{l:.5}"))
                    .unwrap_or_default();
                s.push_str(&format!("{},{},{l}", p.omega1, p.state.label()));
                for e in &p.poincare {
                    s.push_str(&format!(",{:.9},{:.9}", e[k].0, e[k].1));
                }
                s.push('\n');
            }
        }
        s
    }

    /// CSV with one row per grid point: the motion state, the Lyapunov exponent, and per
    /// tracked element the range of `x̄` over the retained samples and the extent of its
    /// Poincaré set (`max − min` of the Poincaré displacements).
    pub fn summary_csv(&self) -> String {
        let mut s = String::from("omega1,state,lyapunov_per_period");
        for e in &self.elements {
            s.push_str(&format!(",{e}_min,{e}_max,{e}_poincare_extent"));
        }
        s.push('\n');
        for p in &self.points {
            let l = p
                .lyapunov_per_period
                .map(|l| format!("{l:.5}"))
                .unwrap_or_default();
            s.push_str(&format!("{},{},{l}", p.omega1, p.state.label()));
            for (e, pts) in p.poincare.iter().enumerate() {
                let (lo, hi) = pts
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| {
                        (a.min(q.0), b.max(q.0))
                    });
                s.push_str(&format!(
                    ",{:.6},{:.6},{:.6}",
                    p.range[e].0,
                    p.range[e].1,
                    hi - lo
                ));
            }
            s.push('\n');
        }
        s
    }

    /// Flatten element `e`'s Poincaré displacements into (Ω1, x̄) pairs for plotting.
    pub fn scatter(&self, e: usize) -> (Vec<f64>, Vec<f64>) {
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for p in &self.points {
            for &(x, _) in &p.poincare[e] {
                xs.push(p.omega1);
                ys.push(x);
            }
        }
        (xs, ys)
    }

    /// Total solver counters over the sweep.
    pub fn total_stats(&self) -> Stats {
        self.points.iter().fold(Stats::default(), |a, p| Stats {
            steps: a.steps + p.stats.steps,
            rejected: a.rejected + p.stats.rejected,
            rhs_evals: a.rhs_evals + p.stats.rhs_evals,
            switches: a.switches + p.stats.switches,
        })
    }
}
