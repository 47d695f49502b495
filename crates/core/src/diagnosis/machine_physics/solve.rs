//! The fit's arithmetic: the healthy records' residuals against the simulated machine seen
//! through each channel's path, and a bounded Levenberg–Marquardt search over the log factors
//! with a Gaussian prior around the description's values (`θ = 0`).

use nalgebra::{DMatrix, DVector};

use super::simulate::Simulated;
use crate::diagnosis::machine_path::{KNOTS_PER_DECADE, Path, Residual};
use crate::gearbox::{PhysicsFactors, StageFactors};

/// A measured feature within this much (ln, ≈ 6 dB) of the clipping floor is "absent": it only
/// penalises a prediction that stands above it.
pub(super) const FLOOR_MARGIN: f64 = 0.7;

/// Which factor a parameter is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Knob {
    /// Stage (1-based) and the index of [`StageFactors::as_array`].
    Stage(usize, usize),
    Load,
    Clearance,
}

/// One fitted parameter: `ln` of its factor, within `lo ..= hi`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Param {
    pub(super) knob: Knob,
    pub(super) lo: f64,
    pub(super) hi: f64,
}

/// The factors of a parameter vector (`ln` factors).
pub(super) fn factors_of(params: &[Param], theta: &[f64], stages: usize) -> PhysicsFactors {
    let mut f = PhysicsFactors {
        stages: vec![StageFactors::default(); stages],
        ..Default::default()
    };
    for (p, t) in params.iter().zip(theta) {
        let v = t.exp();
        match p.knob {
            Knob::Stage(s, i) => {
                let mut a = f.stages[s - 1].as_array();
                a[i] = v;
                f.stages[s - 1] = StageFactors::from_array(a);
            }
            Knob::Load => f.load = v,
            Knob::Clearance => f.clearance = v,
        }
    }
    f
}

/// One healthy record as one channel measured it.
#[derive(Debug, Clone)]
pub(super) struct Obs {
    pub(super) channel: usize,
    /// Index of its speed in [`Data::f1`].
    pub(super) speed: usize,
    /// Its speed group.
    pub(super) group: usize,
    /// Measured features (ln, the table's order without the power fraction).
    pub(super) y: Vec<f64>,
}

/// The healthy records, flattened.
#[derive(Debug, Clone)]
pub(super) struct Data {
    pub(super) channels: Vec<String>,
    /// Distinct stage-1 mesh frequencies (Hz) of the records: what is simulated.
    pub(super) f1: Vec<f64>,
    /// Centres of the speed groups (Hz).
    pub(super) groups: Vec<f64>,
    pub(super) obs: Vec<Obs>,
    /// Each feature's line frequency over f1.
    pub(super) ratios: Vec<f64>,
    /// Clipping floor (ln).
    pub(super) floor: f64,
    /// Measurement floor of every feature (ln).
    pub(super) s0: f64,
}

/// One residual: record `obs`, feature `k`, the error `e` (ln) after the path and its weight.
#[derive(Debug, Clone, Copy)]
pub(super) struct Term {
    pub(super) obs: usize,
    pub(super) k: usize,
    pub(super) e: f64,
    pub(super) w: f64,
    /// A measured line above the floor (not a one-sided "absent" term).
    pub(super) present: bool,
}

/// Every record's residuals against `sims` through each channel's path, the path fitted with
/// smoothness `lambda` on the records outside group `exclude` (all of them for `None`);
/// `None` when a path cannot be fitted. Also returns the paths (one per channel).
pub(super) fn residuals(
    data: &Data,
    sims: &[Simulated],
    lambda: f64,
    exclude: Option<usize>,
) -> Option<(Vec<Term>, Vec<Path>)> {
    let mut terms = Vec::new();
    let mut paths = Vec::with_capacity(data.channels.len());
    for c in 0..data.channels.len() {
        let mine: Vec<(usize, &Obs)> = data
            .obs
            .iter()
            .enumerate()
            .filter(|(_, o)| o.channel == c)
            .collect();
        let mut present = Vec::new();
        let mut absent = Vec::new();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(i, o) in &mine {
            let f1 = data.f1[o.speed];
            let s = &sims[o.speed];
            for (k, &y) in o.y.iter().enumerate() {
                let x = (data.ratios[k] * f1).log10();
                let x1 = f1.log10();
                lo = lo.min(x.min(x1));
                hi = hi.max(x.max(x1));
                let m = s.mean[k].max(data.floor);
                let r = Residual {
                    k,
                    g: i,
                    x,
                    x1,
                    d: y - m,
                    w: 1.0 / (s.var[k] + data.s0 * data.s0),
                };
                if y > data.floor + FLOOR_MARGIN {
                    present.push((o.group, r));
                } else {
                    absent.push((m, r));
                }
            }
        }
        if mine.is_empty() {
            paths.push(Path {
                lo: 0.0,
                values: vec![0.0; 2],
            });
            continue;
        }
        let train: Vec<&Residual> = present
            .iter()
            .filter(|(g, _)| Some(*g) != exclude)
            .map(|(_, r)| r)
            .collect();
        let path = Path::fit(&train, lo, hi.max(lo + 1.0 / KNOTS_PER_DECADE), lambda)?;
        for (_, r) in &present {
            terms.push(Term {
                obs: r.g,
                k: r.k,
                e: r.d - (path.at(r.x) - path.at(r.x1)),
                w: r.w,
                present: true,
            });
        }
        for (m, r) in &absent {
            let predicted = m + path.at(r.x) - path.at(r.x1);
            terms.push(Term {
                obs: r.g,
                k: r.k,
                e: (predicted - (data.floor + FLOOR_MARGIN)).max(0.0),
                w: r.w,
                present: false,
            });
        }
        paths.push(path);
    }
    Some((terms, paths))
}

/// The weighted residual vector of `terms` (only those of records in `keep`, when given).
pub(super) fn weighted(terms: &[Term], data: &Data, skip_group: Option<usize>) -> Vec<f64> {
    terms
        .iter()
        .filter(|t| Some(data.obs[t.obs].group) != skip_group)
        .map(|t| t.e * t.w.sqrt())
        .collect()
}

/// What one evaluation of the objective gives: the weighted residuals (data then prior) and
/// the terms behind them.
pub(super) struct Eval {
    pub(super) r: Vec<f64>,
    pub(super) terms: Vec<Term>,
}

impl Eval {
    pub(super) fn cost(&self) -> f64 {
        self.r.iter().map(|v| v * v).sum()
    }
}

/// Levenberg–Marquardt over `theta` within the parameters' bounds: `eval` gives the weighted
/// residuals (the prior's rows appended) at a parameter vector, `None` where the model cannot
/// be simulated. Forward differences of step `h` (backwards at an upper bound). Returns the
/// final parameters, their evaluation and the last Jacobian (rows: the residuals).
pub(super) fn levenberg_marquardt(
    params: &[Param],
    theta0: &[f64],
    h: f64,
    iterations: usize,
    eval: &dyn Fn(&[f64]) -> Option<Eval>,
) -> Option<(Vec<f64>, Eval, DMatrix<f64>)> {
    let p = params.len();
    let mut theta = theta0.to_vec();
    let mut cur = eval(&theta)?;
    let mut jac = jacobian(params, &theta, &cur, h, eval)?;
    let mut mu = 1e-2;
    for _ in 0..iterations {
        let r = DVector::from_column_slice(&cur.r);
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        let mut improved = false;
        for _ in 0..4 {
            let mut a = jtj.clone();
            for i in 0..p {
                a[(i, i)] += mu * jtj[(i, i)].max(1e-9);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&(-&g))) else {
                mu *= 10.0;
                continue;
            };
            let trial: Vec<f64> = (0..p)
                .map(|i| (theta[i] + step[i]).clamp(params[i].lo, params[i].hi))
                .collect();
            match eval(&trial) {
                Some(e) if e.cost() < cur.cost() => {
                    let gain = (cur.cost() - e.cost()) / cur.cost().max(1e-300);
                    theta = trial;
                    cur = e;
                    mu = (mu / 3.0).max(1e-6);
                    improved = gain > 1e-4;
                    break;
                }
                _ => mu *= 4.0,
            }
        }
        if !improved {
            break;
        }
        jac = jacobian(params, &theta, &cur, h, eval)?;
    }
    Some((theta, cur, jac))
}

/// Forward-difference Jacobian of the residuals at `theta` (`at` their evaluation there).
pub(super) fn jacobian(
    params: &[Param],
    theta: &[f64],
    at: &Eval,
    h: f64,
    eval: &dyn Fn(&[f64]) -> Option<Eval>,
) -> Option<DMatrix<f64>> {
    let n = at.r.len();
    let mut j = DMatrix::<f64>::zeros(n, params.len());
    for i in 0..params.len() {
        let mut t = theta.to_vec();
        let step = if t[i] + h <= params[i].hi { h } else { -h };
        t[i] += step;
        let e = eval(&t)?;
        if e.r.len() != n {
            return None;
        }
        for row in 0..n {
            j[(row, i)] = (e.r[row] - at.r[row]) / step;
        }
    }
    Some(j)
}
