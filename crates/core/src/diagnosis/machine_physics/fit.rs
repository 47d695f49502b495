//! [`MachinePhysics::fit`] and the reading's shift: the search, the leave-one-speed-out
//! report, the yardstick and the uncertainty.

use std::collections::BTreeMap;
use std::sync::atomic::Ordering;

use nalgebra::DMatrix;

use super::simulate::{Simulated, Simulator};
use super::solve::{Data, Eval, Param, Term, factors_of, levenberg_marquardt, residuals, weighted};
use super::*;

/// The empirical yardstick's path smoothness weights (those of
/// [`super::super::machine_path`]).
const YARDSTICK_LAMBDAS: [f64; 5] = [0.1, 1.0, 10.0, 100.0, 1000.0];
/// The model reads wear while it predicts a left-out healthy speed within this many times the
/// diagnosis's measurement floor per feature (`feature_sigma`, 2.2 dB by default: 6.5 dB).
/// Chosen after looking: the simulated machines of `examples/calibrated_wear` (seeds 11–18)
/// were predicted to 1.7–6.1 dB, the PHM 2009 spur train's to 9.3 dB (where a healthy record
/// read alarm-level wear against it).
const PREDICTIVE_SIGMAS: f64 = 3.0;
/// Factors the coarse scan tries.
const SCAN_FACTORS: [f64; 6] = [0.5, 0.7, 0.85, 1.2, 1.45, 2.0];
/// Smallest scatter of a feature (ln units).
const MIN_SIGMA: f64 = 0.05;
/// A factor whose posterior width is above this share of the prior's is "not identified".
const IDENTIFIED_BELOW: f64 = 0.7;

/// The objective of one fit: the data, how to simulate, the parameters and the prior.
struct Objective<'a> {
    gb: &'a Gearbox,
    data: &'a Data,
    sim: &'a Simulator,
    params: Vec<Param>,
    stages: usize,
    prior_sigma: f64,
}

impl Objective<'_> {
    fn simulate(&self, theta: &[f64]) -> Option<Vec<Simulated>> {
        self.sim
            .run(
                self.gb,
                &factors_of(&self.params, theta, self.stages),
                &self.data.f1,
            )
            .ok()
    }

    /// The weighted residuals at `theta` with smoothness `lambda`, the records of group
    /// `exclude` left out of the path and of the objective (their terms are still returned).
    fn eval(&self, theta: &[f64], lambda: f64, exclude: Option<usize>) -> Option<Eval> {
        let sims = self.simulate(theta)?;
        self.eval_sims(&sims, theta, lambda, exclude)
    }

    fn eval_sims(
        &self,
        sims: &[Simulated],
        theta: &[f64],
        lambda: f64,
        exclude: Option<usize>,
    ) -> Option<Eval> {
        let (terms, _) = residuals(self.data, sims, lambda, exclude)?;
        let mut r = weighted(&terms, self.data, exclude);
        r.extend(theta.iter().map(|t| t / self.prior_sigma));
        Some(Eval { r, terms })
    }

    /// A coarse coordinate scan: each stage's stiffness, then its error, over a few factors
    /// within its bounds, the others held; each kept where the cost is lowest.
    fn scan(&self, theta0: &[f64], lambda: f64) -> Vec<f64> {
        let mut theta = theta0.to_vec();
        let mut cost = self
            .eval(&theta, lambda, None)
            .map_or(f64::INFINITY, |e| e.cost());
        for which in [0usize, 3] {
            for (i, p) in self.params.iter().enumerate() {
                if !matches!(p.knob, solve::Knob::Stage(_, k) if k == which) {
                    continue;
                }
                for f in SCAN_FACTORS {
                    let t = f.ln();
                    if t < p.lo || t > p.hi || t == theta[i] {
                        continue;
                    }
                    let mut trial = theta.clone();
                    trial[i] = t;
                    if let Some(e) = self.eval(&trial, lambda, None)
                        && e.cost() < cost
                    {
                        cost = e.cost();
                        theta = trial;
                    }
                }
            }
        }
        theta
    }

    fn search(
        &self,
        theta0: &[f64],
        lambda: f64,
        exclude: Option<usize>,
        iterations: usize,
        step: f64,
    ) -> Option<(Vec<f64>, Eval, DMatrix<f64>)> {
        levenberg_marquardt(&self.params, theta0, step, iterations, &|t| {
            self.eval(t, lambda, exclude)
        })
    }
}

/// One smoothness's fit: its left-out score (dB), `λ`, `θ`, evaluation and Jacobian.
type Candidate = (f64, f64, Vec<f64>, Eval, DMatrix<f64>);

/// The left-out errors `(term, e)` of every group with the simulations fixed (`θ` fixed):
/// each group's records predicted through a path fitted on the others.
fn path_left_out(data: &Data, sims: &[Simulated], lambda: f64) -> Vec<Term> {
    let mut out = Vec::new();
    for g in 0..data.groups.len() {
        if let Some((terms, _)) = residuals(data, sims, lambda, Some(g)) {
            out.extend(
                terms
                    .into_iter()
                    .filter(|t| t.present && data.obs[t.obs].group == g),
            );
        }
    }
    out
}

fn errors(terms: &[Term]) -> Vec<f64> {
    terms.iter().filter(|t| t.present).map(|t| t.e).collect()
}

impl MachinePhysics {
    /// Fit the machine's physics to its healthy records' line ratios (per channel, as the
    /// plain table read them; see the [module docs](self)). `table` is the description's own
    /// table (its lines, sensor and simulation settings; its lowest wear is the healthy
    /// machine's).
    ///
    /// Errors: too few records or speeds ([`Error::BaselineTooSmall`]), a table of another
    /// description ([`Error::StaleTable`]), a description the search cannot simulate, and a fit
    /// no better at a left-out speed than the empirical calibration
    /// ([`Error::PhysicsNoBetter`]).
    pub fn fit(
        gb: &Gearbox,
        table: &SignatureTable,
        opts: &DiagnoseOptions,
        healthy: &BTreeMap<String, Vec<LineRatios>>,
        fo: &PhysicsFitOptions,
    ) -> Result<MachinePhysics> {
        let t0 = std::time::Instant::now();
        table.check_model(gb)?;
        let data = gather(table, opts, healthy)?;
        let sim = Simulator::new(table, fo.periods, fo.seeds);
        let obj = Objective {
            gb,
            data: &data,
            sim: &sim,
            params: parameters(gb),
            stages: gb.topology.stages.len(),
            prior_sigma: fo.prior_sigma,
        };
        let p = obj.params.len();
        let unusable = |what: &str| Error::InvalidConfig(format!("the physics fit: {what}"));
        let zero = vec![0.0; p];
        let sims0 = obj
            .simulate(&zero)
            .ok_or_else(|| unusable("the description's own physics cannot be simulated"))?;
        let plain: Vec<f64> = data
            .obs
            .iter()
            .flat_map(|o| {
                let s = &sims0[o.speed];
                o.y.iter()
                    .enumerate()
                    .filter(|(_, y)| **y > data.floor + solve::FLOOR_MARGIN)
                    .map(move |(k, y)| y - s.mean[k].max(data.floor))
            })
            .collect();
        let yardstick = YARDSTICK_LAMBDAS
            .iter()
            .map(|&l| rms_db(&errors(&path_left_out(&data, &sims0, l))))
            .fold(f64::INFINITY, f64::min);
        // The search at each smoothness, warm-started from the previous one (the first from a
        // coarse scan of the stiffnesses, which place the resonances: the cost has a minimum
        // per resonance position and a local search stays in the first it meets); the
        // smoothness whose fit predicts a left-out speed best (θ fixed, path refitted) is kept.
        let mut best: Option<Candidate> = None;
        let mut theta = obj.scan(&zero, fo.lambdas[0]);
        for (i, &lambda) in fo.lambdas.iter().enumerate() {
            let iters = if i == 0 {
                fo.iterations
            } else {
                fo.iterations.div_ceil(2)
            };
            let Some((t, e, j)) = obj.search(&theta, lambda, None, iters, fo.step) else {
                continue;
            };
            let sims = obj.simulate(&t).ok_or_else(|| unusable("a fitted point"))?;
            let score = rms_db(&errors(&path_left_out(&data, &sims, lambda)));
            theta = t.clone();
            if best.as_ref().is_none_or(|b| score < b.0) {
                best = Some((score, lambda, t, e, j));
            }
        }
        let (_, lambda, theta, full, jac) =
            best.ok_or_else(|| unusable("no smoothness gave a usable fit"))?;
        // Leave one speed out, the physics refitted without it.
        let mut left_out: Vec<Term> = Vec::new();
        for g in 0..data.groups.len() {
            let Some((_, e, _)) =
                obj.search(&theta, lambda, Some(g), fo.left_out_iterations, fo.step)
            else {
                continue;
            };
            left_out.extend(
                e.terms
                    .into_iter()
                    .filter(|t| t.present && data.obs[t.obs].group == g),
            );
        }
        let left_out_db = rms_db(&errors(&left_out));
        if !(left_out_db < yardstick) {
            return Err(Error::PhysicsNoBetter {
                physics_db: left_out_db,
                empirical_db: yardstick,
            });
        }
        let sims = obj.simulate(&theta).ok_or_else(|| unusable("the fit"))?;
        let (_, paths) =
            residuals(&data, &sims, lambda, None).ok_or_else(|| unusable("the paths"))?;
        let covariance = covariance(&jac, &full, obj.params.len(), fo.prior_sigma);
        let report = Report {
            data: &data,
            table,
            full: &full.terms,
            left_out: &left_out,
        };
        Ok(MachinePhysics {
            gearbox_hash: gb.hash.clone(),
            factors: factors_of(&obj.params, &theta, obj.stages),
            parameters: fitted_factors(&obj.params, &theta, &covariance, fo.prior_sigma),
            healthy_ea: table.grid.ea[0],
            records: healthy.values().map(Vec::len).max().unwrap_or(0),
            f1_hz: data.groups.clone(),
            lambda,
            channels: report.channels(&paths),
            states: report.states(),
            in_sample_db: rms_db(&errors(&full.terms)),
            left_out_db,
            left_out_median_db: median_abs_db(&errors(&left_out)),
            predictive_limit_db: PREDICTIVE_SIGMAS * opts.feature_sigma * 20.0
                / std::f64::consts::LN_10,
            yardstick_db: yardstick.is_finite().then_some(yardstick),
            plain_db: rms_db(&plain),
            sensitivity: sensitivity(&data, &full.terms, &jac),
            covariance: (0..p)
                .map(|i| (0..p).map(|j| covariance[(i, j)]).collect())
                .collect(),
            simulations: sim.runs.load(Ordering::Relaxed),
            seconds: t0.elapsed().as_secs_f64(),
        })
    }
}

/// The Gauss–Newton covariance of the `ln` factors, scaled by the data's χ² per residual when
/// above 1 (the prior's rows are the last `p` of the Jacobian and do not count).
fn covariance(jac: &DMatrix<f64>, at: &Eval, p: usize, prior_sigma: f64) -> DMatrix<f64> {
    let n = at.r.len().saturating_sub(p);
    let chi2: f64 = at.r[..n].iter().map(|v| v * v).sum();
    let scale = (chi2 / n.max(1) as f64).max(1.0);
    let jtj = jac.transpose() * jac;
    match jtj.clone().try_inverse() {
        Some(inv) => inv * scale,
        None => DMatrix::from_diagonal_element(p, p, prior_sigma * prior_sigma),
    }
}

fn fitted_factors(
    params: &[Param],
    theta: &[f64],
    cov: &DMatrix<f64>,
    prior_sigma: f64,
) -> Vec<FittedFactor> {
    const Z90: f64 = 1.6449;
    params
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let sd = cov[(i, i)].max(0.0).sqrt();
            FittedFactor {
                name: param_name(p),
                value: theta[i].exp(),
                lower: (theta[i] - Z90 * sd).max(p.lo).exp(),
                upper: (theta[i] + Z90 * sd).min(p.hi).exp(),
                bounds: [p.lo.exp(), p.hi.exp()],
                identified: sd < IDENTIFIED_BELOW * prior_sigma,
            }
        })
        .collect()
}

/// Per channel and speed group, each feature's mean sensitivity `∂e/∂θ` over the group's
/// records (rows of features without a measured line are zero).
fn sensitivity(data: &Data, terms: &[Term], jac: &DMatrix<f64>) -> Vec<Sensitivity> {
    let nf = data.ratios.len();
    let p = jac.ncols();
    let mut out = Vec::new();
    // Row `i` of the Jacobian is term `i` (the weighted residual, in order).
    for (c, name) in data.channels.iter().enumerate() {
        for (g, &f1) in data.groups.iter().enumerate() {
            let mut sum = vec![vec![0.0; p]; nf];
            let mut n = vec![0usize; nf];
            for (i, t) in terms.iter().enumerate() {
                let o = &data.obs[t.obs];
                if o.channel != c || o.group != g || !t.present {
                    continue;
                }
                let sw = t.w.sqrt();
                for j in 0..p {
                    sum[t.k][j] += jac[(i, j)] / sw;
                }
                n[t.k] += 1;
            }
            let rows = sum
                .into_iter()
                .zip(n)
                .map(|(r, n)| r.into_iter().map(|v| v / n.max(1) as f64).collect())
                .collect();
            out.push(Sensitivity {
                channel: name.clone(),
                f1_hz: f1,
                rows,
            });
        }
    }
    out
}

/// The report's per-channel and per-state summaries.
struct Report<'a> {
    data: &'a Data,
    table: &'a SignatureTable,
    full: &'a [Term],
    left_out: &'a [Term],
}

impl Report<'_> {
    fn families(&self) -> Vec<String> {
        self.table
            .features
            .lines
            .iter()
            .filter(|l| l.name != "f1")
            .map(|l| family(&l.name))
            .collect()
    }

    fn channels(&self, paths: &[Path]) -> BTreeMap<String, ChannelPath> {
        let db = 20.0 / std::f64::consts::LN_10;
        let nf = self.data.ratios.len();
        self.data
            .channels
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let sigma = (0..nf)
                    .map(|k| {
                        let e: Vec<f64> = self
                            .left_out
                            .iter()
                            .filter(|t| t.k == k && self.data.obs[t.obs].channel == c)
                            .map(|t| t.e)
                            .collect();
                        if e.is_empty() {
                            MIN_SIGMA
                        } else {
                            (rms_db(&e) / db).max(MIN_SIGMA)
                        }
                    })
                    .collect();
                (
                    name.clone(),
                    ChannelPath {
                        lo_log10_hz: paths[c].lo,
                        path_db: paths[c].values.iter().map(|v| v * db).collect(),
                        sigma,
                    },
                )
            })
            .collect()
    }

    fn states(&self) -> Vec<StateFit> {
        let fam = self.families();
        let mut names: Vec<String> = fam.clone();
        names.sort();
        names.dedup();
        let pick = |terms: &[Term], g: usize, f: &str| -> Vec<f64> {
            terms
                .iter()
                .filter(|t| t.present && self.data.obs[t.obs].group == g && fam[t.k] == f)
                .map(|t| t.e)
                .collect()
        };
        (0..self.data.groups.len())
            .map(|g| StateFit {
                f1_hz: self.data.groups[g],
                records: self
                    .data
                    .obs
                    .iter()
                    .filter(|o| o.group == g && o.channel == 0)
                    .count(),
                families: names
                    .iter()
                    .filter_map(|f| {
                        let a = pick(self.full, g, f);
                        (!a.is_empty()).then(|| FamilyFit {
                            family: f.clone(),
                            lines: a.len(),
                            in_sample_db: rms_db(&a),
                            left_out_db: rms_db(&pick(self.left_out, g, f)),
                        })
                    })
                    .collect(),
            })
            .collect()
    }
}

impl MachinePhysics {
    /// The machine's own gearbox: `gb` (the description fitted) with the fitted factors.
    pub fn gearbox(&self, gb: &Gearbox) -> Result<Gearbox> {
        if gb.hash != self.gearbox_hash {
            return Err(Error::InvalidConfig(format!(
                "the machine's physics were fitted to gearbox description {}…, not {}…",
                &self.gearbox_hash[..12.min(self.gearbox_hash.len())],
                &gb.hash[..12.min(gb.hash.len())]
            )));
        }
        Ok(gb.with_factors(&self.factors)?)
    }

    /// The uncertainty (standard deviation, ln) of the wear stages' common transmission-error
    /// factor: the wear degree is the amplitude of that error, so a record read through
    /// factors `η` reads `ea · η / η_true` — this is the relative uncertainty of the wear
    /// degree the healthy records leave, whatever the record.
    pub fn wear_scale_sigma(&self, wear_stages: &[usize]) -> f64 {
        let idx: Vec<usize> = self
            .parameters
            .iter()
            .enumerate()
            .filter(|(_, p)| {
                wear_stages
                    .iter()
                    .any(|s| p.name == format!("stage {s} {}", STAGE_FACTOR_NAMES[3]))
            })
            .map(|(i, _)| i)
            .collect();
        if idx.is_empty() {
            return 0.0;
        }
        let w = 1.0 / idx.len() as f64;
        let mut v = 0.0;
        for &a in &idx {
            for &b in &idx {
                v += w * w * self.covariance[a][b];
            }
        }
        v.max(0.0).sqrt()
    }

    /// Whether the model predicts a left-out healthy speed within its limit
    /// ([`MachinePhysics::predictive_limit_db`]): only then does it read wear.
    pub fn predictive(&self) -> bool {
        self.left_out_db <= self.predictive_limit_db
    }

    /// Whether `f1` lies within the fitted speeds (± 3 %).
    pub fn covers(&self, f1_hz: f64) -> bool {
        let (Some(lo), Some(hi)) = (self.f1_hz.first(), self.f1_hz.last()) else {
            return false;
        };
        f1_hz >= lo * (1.0 - SAME_SPEED) && f1_hz <= hi * (1.0 + SAME_SPEED)
    }

    /// Channel `channel`'s path colouring of each feature at `f1` (ln units, the table's
    /// feature order; 0 for the power fraction) and its variance: the path's left-out scatter
    /// plus the factors' uncertainty carried to the feature, `J C Jᵀ` with `J` interpolated
    /// in `log f1` between the nearest fitted speeds. `None` for a channel not fitted.
    pub fn shift_at(
        &self,
        channel: &str,
        table: &SignatureTable,
        f1_hz: f64,
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let ch = self.channels.get(channel)?;
        let path = Path {
            lo: ch.lo_log10_hz,
            values: ch
                .path_db
                .iter()
                .map(|v| v * std::f64::consts::LN_10 / 20.0)
                .collect(),
        };
        let x1 = f1_hz.log10();
        let mut shift: Vec<f64> = table
            .features
            .lines
            .iter()
            .filter(|l| l.name != "f1")
            .map(|l| path.at((l.ratio * f1_hz).log10()) - path.at(x1))
            .collect();
        shift.push(0.0);
        let rows = self.sensitivity_at(channel, f1_hz);
        let p = self.covariance.len();
        let mut var: Vec<f64> = ch.sigma.iter().map(|s| s * s).collect();
        for (k, v) in var.iter_mut().enumerate() {
            if let Some(j) = rows.as_ref().and_then(|r| r.get(k)) {
                let mut q = 0.0;
                for a in 0..p {
                    for b in 0..p {
                        q += j[a] * self.covariance[a][b] * j[b];
                    }
                }
                *v += q.max(0.0);
            }
        }
        var.push(0.0);
        Some((shift, var))
    }

    /// The channel's feature sensitivities at `f1`, interpolated in `log f1` between the two
    /// nearest fitted speeds (the nearest one outside them).
    fn sensitivity_at(&self, channel: &str, f1_hz: f64) -> Option<Vec<Vec<f64>>> {
        let mine: Vec<&Sensitivity> = self
            .sensitivity
            .iter()
            .filter(|s| s.channel == channel)
            .collect();
        let first = mine.first()?;
        let last = mine.last()?;
        if f1_hz <= first.f1_hz || mine.len() == 1 {
            return Some(first.rows.clone());
        }
        if f1_hz >= last.f1_hz {
            return Some(last.rows.clone());
        }
        let i = mine.windows(2).position(|w| f1_hz <= w[1].f1_hz)?;
        let (a, b) = (mine[i], mine[i + 1]);
        let u = (f1_hz / a.f1_hz).ln() / (b.f1_hz / a.f1_hz).ln();
        Some(
            a.rows
                .iter()
                .zip(&b.rows)
                .map(|(ra, rb)| {
                    ra.iter()
                        .zip(rb)
                        .map(|(x, y)| (1.0 - u) * x + u * y)
                        .collect()
                })
                .collect(),
        )
    }
}

/// Knots of a path report (`log10 Hz`).
pub fn knots(ch: &ChannelPath) -> Vec<f64> {
    (0..ch.path_db.len())
        .map(|j| ch.lo_log10_hz + j as f64 / KNOTS_PER_DECADE)
        .collect()
}

/// Relative margin of the machine's own table beyond the fitted speeds, and its largest
/// relative step between speeds.
const TABLE_MARGIN: f64 = 0.07;
const TABLE_STEP: f64 = 0.06;

impl MachinePhysics {
    /// What to precompute for the machine's own table: the machine's own gearbox
    /// ([`MachinePhysics::gearbox`] of `gb`), the base table's sensor and simulation settings,
    /// the default 19 wear degrees (0.1 … 1) and 3 seeds, and Ω1 over the fitted speeds
    /// ± [`TABLE_MARGIN`] in steps of at most [`TABLE_STEP`] — in the machine's own Ω1 (its
    /// reference frequency moves with the stage-1 stiffness).
    pub fn table_spec(
        &self,
        gb: &Gearbox,
        base: &SignatureTable,
    ) -> Result<crate::signature::precompute::PrecomputeSpec> {
        use crate::signature::table::Grid;
        let own = self.gearbox(gb)?;
        let f_ref = own.reference_frequency_hz();
        let (lo, hi) = (
            self.f1_hz[0] * (1.0 - TABLE_MARGIN) / f_ref,
            self.f1_hz[self.f1_hz.len() - 1] * (1.0 + TABLE_MARGIN) / f_ref,
        );
        let n = ((hi / lo).ln() / (1.0 + TABLE_STEP).ln()).ceil().max(1.0) as usize;
        let round = |v: f64| (v * 1e6).round() / 1e6;
        let grid = Grid {
            ea: (0..=18).map(|k| round(0.1 + 0.05 * k as f64)).collect(),
            omega1: (0..=n)
                .map(|k| round(lo * (hi / lo).powf(k as f64 / n as f64)))
                .collect(),
            seeds: 3,
        };
        Ok(crate::signature::precompute::PrecomputeSpec {
            gearbox: std::sync::Arc::new(own),
            sensor: base.sensor,
            grid,
            settings: base.simulation.clone(),
            created_by: format!(
                "gearwear: the machine's own table (physics fitted to {} healthy records)",
                self.records
            ),
        })
    }
}
