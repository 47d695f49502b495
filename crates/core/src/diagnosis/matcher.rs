//! The table side of the match: per-entry feature statistics ([`Matcher`]) and the posterior
//! over `(ea, Ω1)` ([`posterior`]).

use super::options::DiagnoseOptions;
use crate::error::Result;
use crate::signature::{LineDef, SignatureTable};

/// Per-entry statistics of the clipped features.
#[derive(Debug, Clone)]
pub struct Matcher {
    /// Feature indices used for ea.
    pub(super) wear_features: Vec<usize>,
    /// The first other wear stage's mesh line (`f2` of the paper's rig): the single-ratio
    /// baseline reads it.
    f2_feature: Option<usize>,
    /// The first planetary stage's mesh line when the wear leaves that stage out (`f3` of the
    /// paper's rig): the planetary check reads it.
    pub(super) f3_feature: Option<usize>,
    /// mean and variance per entry per feature (entry-major).
    mean: Vec<Vec<f64>>,
    var: Vec<Vec<f64>>,
    /// The same statistics of the wear features only, flat (`entry × wear_features.len()`,
    /// in `wear_features` order): what the posterior's inner loop reads.
    wear_mean: Vec<f64>,
    wear_var: Vec<f64>,
    floor: f64,
    n_ea: usize,
    n_om: usize,
    ea: Vec<f64>,
    om: Vec<f64>,
}

/// Feature index of a line (features skip f1).
pub(super) fn feature_index(lines: &[LineDef], name: &str) -> Option<usize> {
    let i1 = lines.iter().position(|l| l.name == "f1")?;
    let i = lines.iter().position(|l| l.name == name)?;
    if i == i1 {
        None
    } else if i < i1 {
        Some(i)
    } else {
        Some(i - 1)
    }
}

impl Matcher {
    /// Precompute the clipped statistics of a table.
    pub fn new(table: &SignatureTable, opts: &DiagnoseOptions) -> Result<Self> {
        let lines = &table.features.lines;
        let nf = table.features.names.len();
        let floor = opts.floor_db * std::f64::consts::LN_10 / 20.0;
        let mut wear_features = Vec::new();
        for (k, l) in lines.iter().filter(|l| l.name != "f1").enumerate() {
            if !l.planetary {
                wear_features.push(k);
            }
        }
        wear_features.push(nf - 1); // f1_power_fraction
        // Mesh lines of other stages are named `f<stage>` (see signature::line_set).
        let is_mesh_line = |l: &&LineDef| {
            l.name.len() > 1
                && l.name.starts_with('f')
                && l.name[1..].chars().all(|c| c.is_ascii_digit())
                && l.name != "f1"
        };
        let first_mesh = |planetary: bool| {
            lines
                .iter()
                .filter(is_mesh_line)
                .filter(|l| l.planetary == planetary)
                .min_by_key(|l| l.name[1..].parse::<usize>().unwrap_or(usize::MAX))
                .and_then(|l| feature_index(lines, &l.name))
        };
        let f2_feature = first_mesh(false);
        let f3_feature = first_mesh(true);
        let mut mean = Vec::with_capacity(table.entries.len());
        let mut var = Vec::with_capacity(table.entries.len());
        for e in &table.entries {
            let n = e.samples.len() as f64;
            let mut m = vec![0.0; nf];
            let mut v = vec![0.0; nf];
            for s in &e.samples {
                for d in 0..nf {
                    m[d] += s[d].max(floor);
                }
            }
            for x in m.iter_mut() {
                *x /= n;
            }
            for s in &e.samples {
                for d in 0..nf {
                    v[d] += (s[d].max(floor) - m[d]).powi(2);
                }
            }
            for x in v.iter_mut() {
                // Unbiased; one seed gives no spread.
                *x /= (n - 1.0).max(1.0);
            }
            mean.push(m);
            var.push(v);
        }
        let wear_mean = mean
            .iter()
            .flat_map(|m| wear_features.iter().map(|&d| m[d]))
            .collect();
        let wear_var = var
            .iter()
            .flat_map(|v| wear_features.iter().map(|&d| v[d]))
            .collect();
        Ok(Matcher {
            wear_features,
            f2_feature,
            f3_feature,
            mean,
            var,
            wear_mean,
            wear_var,
            floor,
            n_ea: table.grid.ea.len(),
            n_om: table.grid.omega1.len(),
            ea: table.grid.ea.clone(),
            om: table.grid.omega1.clone(),
        })
    }

    /// This matcher with the variance of every feature `d` raised by `extra[d]` at every
    /// entry (same length as the features; non-finite or negative values count as 0): a
    /// feature known less well than the table says — one an effect outside the table changes
    /// by an uncertain amount ([`diagnose_shifted`](super::diagnose_shifted)) — weighs less in the likelihood.
    pub fn with_extra_variance(&self, extra: &[f64]) -> Matcher {
        let add = |d: usize| extra.get(d).copied().filter(|v| *v > 0.0).unwrap_or(0.0);
        let mut m = self.clone();
        for v in m.var.iter_mut() {
            for (d, x) in v.iter_mut().enumerate() {
                *x += add(d);
            }
        }
        let nw = m.wear_features.len();
        for (i, x) in m.wear_var.iter_mut().enumerate() {
            *x += add(m.wear_features[i % nw]);
        }
        m
    }

    /// Clip a measured feature vector at the floor.
    pub fn clip(&self, y: &[f64]) -> Vec<f64> {
        y.iter().map(|v| v.max(self.floor)).collect()
    }

    /// Bracketing index and weight of `v` on an ascending axis (clamped).
    fn bracket(axis: &[f64], v: f64) -> (usize, f64) {
        if axis.len() == 1 || v <= axis[0] {
            return (0, 0.0);
        }
        let last = axis.len() - 1;
        if v >= axis[last] {
            return (last - 1, 1.0);
        }
        let i = axis.partition_point(|&a| a <= v) - 1;
        (i, (v - axis[i]) / (axis[i + 1] - axis[i]))
    }

    /// Bracket of `ea` on the ea axis.
    fn ea_bracket(&self, ea: f64) -> (usize, f64) {
        Self::bracket(&self.ea, ea)
    }

    /// Bracket of `om` on the Ω1 axis (a one-column table: column 0).
    fn om_bracket(&self, om: f64) -> (usize, f64) {
        if self.n_om > 1 {
            Self::bracket(&self.om, om)
        } else {
            (0, 0.0)
        }
    }

    /// The four bilinear corners `(entry, weight)` of the brackets `(i, u)` (ea) and `(j, w)`
    /// (Ω1), in the fixed summation order every interpolation here uses.
    fn corners(&self, (i, u): (usize, f64), (j, w): (usize, f64)) -> [(usize, f64); 4] {
        let j1 = (j + 1).min(self.n_om - 1);
        let i1 = (i + 1).min(self.n_ea - 1);
        let at = |a: usize, b: usize| a * self.n_om + b;
        [
            (at(i, j), (1.0 - u) * (1.0 - w)),
            (at(i1, j), u * (1.0 - w)),
            (at(i, j1), (1.0 - u) * w),
            (at(i1, j1), u * w),
        ]
    }

    /// Bilinear mean and variance of feature `d` at `(ea, Ω1)`.
    pub fn stats_at(&self, d: usize, ea: f64, om: f64) -> (f64, f64) {
        let mut m = 0.0;
        let mut v = 0.0;
        for (idx, wt) in self.corners(self.ea_bracket(ea), self.om_bracket(om)) {
            m += wt * self.mean[idx][d];
            v += wt * self.var[idx][d];
        }
        (m, v)
    }

    /// Tempered log-likelihood of the clipped features `y` at `(ea, Ω1)`.
    pub fn log_likelihood(&self, y: &[f64], ea: f64, om: f64, opts: &DiagnoseOptions) -> f64 {
        let yw: Vec<f64> = self.wear_features.iter().map(|&d| y[d]).collect();
        let s0 = opts.feature_sigma * opts.feature_sigma;
        let corners = self.corners(self.ea_bracket(ea), self.om_bracket(om));
        self.wear_log_likelihood(&yw, &corners, s0) / opts.temperature.max(1e-9)
    }

    /// Untempered log-likelihood of the wear features `yw` (in `wear_features` order) at the
    /// bilinear `corners`, from the flat per-entry arrays. Same arithmetic, in the same order,
    /// as [`Matcher::stats_at`] per feature (the results are bit-identical).
    #[inline]
    fn wear_log_likelihood(&self, yw: &[f64], corners: &[(usize, f64); 4], s0: f64) -> f64 {
        let nw = yw.len();
        let rows = corners.map(|(idx, _)| idx * nw);
        // −½ Σ_q [(y_q − m_q)²/σ_q² + ln σ_q²], with ln of the product of up to eight σ² at a
        // time instead of one ln per feature (the logarithm was the costliest step of the
        // posterior): σ² ≥ s0 > 0, so a product of eight stays normal unless the variances are
        // extreme, and then that group takes one ln per feature.
        const GROUP: usize = 8;
        let (mut chi2, mut ln_var) = (0.0, 0.0);
        for (g, ys) in yw.chunks(GROUP).enumerate() {
            let mut prod = 1.0;
            let mut vars = [0.0; GROUP];
            for (k, &yq) in ys.iter().enumerate() {
                let q = g * GROUP + k;
                let mut m = 0.0;
                let mut v = 0.0;
                for (r, &(_, wt)) in rows.iter().zip(corners) {
                    m += wt * self.wear_mean[r + q];
                    v += wt * self.wear_var[r + q];
                }
                let var = v + s0;
                chi2 += (yq - m).powi(2) / var;
                prod *= var;
                vars[k] = var;
            }
            ln_var += if prod.is_normal() {
                prod.ln()
            } else {
                vars[..ys.len()].iter().map(|v| v.ln()).sum()
            };
        }
        -0.5 * (chi2 + ln_var)
    }

    /// χ² of the clipped features `y` at `(ea, Ω1)` and the number of features in it.
    pub fn chi2(&self, y: &[f64], ea: f64, om: f64, opts: &DiagnoseOptions) -> (f64, usize) {
        let s0 = opts.feature_sigma * opts.feature_sigma;
        let c = self
            .wear_features
            .iter()
            .map(|&d| {
                let (m, v) = self.stats_at(d, ea, om);
                (y[d] - m).powi(2) / (v + s0)
            })
            .sum();
        (c, self.wear_features.len())
    }

    /// Log-likelihood at a grid entry (no interpolation).
    pub(super) fn entry_log_likelihood(&self, y: &[f64], k: usize, opts: &DiagnoseOptions) -> f64 {
        let s0 = opts.feature_sigma * opts.feature_sigma;
        let mut ll = 0.0;
        for &d in &self.wear_features {
            let var = self.var[k][d] + s0;
            ll += -0.5 * (y[d] - self.mean[k][d]).powi(2) / var - 0.5 * var.ln();
        }
        ll / opts.temperature.max(1e-9)
    }

    /// The paper's single-ratio estimate: the ea whose table mean of ln(A_f2/A_f1) at Ω1 is
    /// closest to the measured one.
    pub fn baseline(&self, y: &[f64], om: f64, step: f64) -> Option<f64> {
        let f2 = self.f2_feature?;
        let (lo, hi) = (self.ea[0], self.ea[self.n_ea - 1]);
        let n = ((hi - lo) / step).round() as usize;
        let mut best = (f64::INFINITY, lo);
        for k in 0..=n {
            let ea = lo + k as f64 * step;
            let (m, _) = self.stats_at(f2, ea, om);
            let d = (y[f2] - m).abs();
            if d < best.0 {
                best = (d, ea);
            }
        }
        Some(best.1)
    }
}

/// Posterior over ea.
#[derive(Debug, Clone)]
pub struct Posterior {
    pub ea: Vec<f64>,
    /// Normalised to sum 1.
    pub p: Vec<f64>,
    pub omega_mean: f64,
}

impl Posterior {
    /// Quantile `q` (linear within a grid cell).
    pub fn quantile(&self, q: f64) -> f64 {
        let mut c = 0.0;
        for (k, p) in self.p.iter().enumerate() {
            if c + p >= q {
                let frac = if *p > 0.0 { (q - c) / p } else { 0.0 };
                let step = if self.ea.len() > 1 {
                    self.ea[1] - self.ea[0]
                } else {
                    0.0
                };
                return (self.ea[k] - 0.5 * step + frac * step)
                    .clamp(self.ea[0], self.ea[self.ea.len() - 1]);
            }
            c += p;
        }
        self.ea[self.ea.len() - 1]
    }
    /// Mode.
    pub fn mode(&self) -> f64 {
        let k = self
            .p
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(k, _)| k)
            .unwrap_or(0);
        self.ea[k]
    }
}

/// Posterior of ea given clipped features `y` and the measured Ω1.
pub fn posterior(m: &Matcher, y: &[f64], omega1: f64, opts: &DiagnoseOptions) -> Posterior {
    let (lo, hi) = (m.ea[0], m.ea[m.n_ea - 1]);
    let step = opts.ea_step.max(1e-4);
    let n = ((hi - lo) / step).round() as usize + 1;
    let ea: Vec<f64> = (0..n).map(|k| (lo + k as f64 * step).min(hi)).collect();
    let (olo, ohi) = (m.om[0], m.om[m.n_om - 1]);
    let sig = opts.omega1_sigma.max(0.0);
    let oms: Vec<(f64, f64)> = if sig == 0.0 || m.n_om == 1 {
        vec![(omega1.clamp(olo, ohi), 1.0)]
    } else {
        (-4..=4)
            .map(|k| {
                let z = k as f64 * 0.6;
                ((omega1 + z * sig).clamp(olo, ohi), (-0.5 * z * z).exp())
            })
            .collect()
    };
    // Brackets of every Ω1 node and every ea node, found once (not per feature and point).
    let yw: Vec<f64> = m.wear_features.iter().map(|&d| y[d]).collect();
    let s0 = opts.feature_sigma * opts.feature_sigma;
    let temp = opts.temperature.max(1e-9);
    let om_nodes: Vec<((usize, f64), f64)> = oms
        .iter()
        .map(|&(o, w)| (m.om_bracket(o), w.ln()))
        .collect();
    let no = oms.len();
    let mut ll = vec![0.0; n * no];
    let mut max = f64::NEG_INFINITY;
    for (k, &e) in ea.iter().enumerate() {
        let eb = m.ea_bracket(e);
        for (j, &(ob, lnw)) in om_nodes.iter().enumerate() {
            let corners = m.corners(eb, ob);
            let v = m.wear_log_likelihood(&yw, &corners, s0) / temp + lnw;
            ll[k * no + j] = v;
            max = max.max(v);
        }
    }
    let mut p = vec![0.0; n];
    let mut om_acc = 0.0;
    for k in 0..n {
        for (j, &(o, _)) in oms.iter().enumerate() {
            let v = (ll[k * no + j] - max).exp();
            p[k] += v;
            om_acc += v * o;
        }
    }
    let total: f64 = p.iter().sum();
    let (p, omega_mean) = if total > 0.0 && total.is_finite() {
        (p.iter().map(|v| v / total).collect(), om_acc / total)
    } else {
        (vec![1.0 / n as f64; n], omega1)
    };
    Posterior { ea, p, omega_mean }
}

#[cfg(test)]
mod likelihood_tests {
    use super::*;

    /// The grouped logarithm of [`Matcher::wear_log_likelihood`] against one ln per feature
    /// from [`Matcher::stats_at`], on the committed table, and with the table's variances
    /// scaled by 1e-50 (and feature σ 1e-60) so that the products of eight underflow and the
    /// per-feature fallback runs.
    #[test]
    fn grouped_log_likelihood_matches_per_feature_sum() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join("signatures")
            .join("model_a_accel.json");
        let table = SignatureTable::load(&path).expect("committed table");
        for sigma in [DiagnoseOptions::default().feature_sigma, 1e-60] {
            let opts = DiagnoseOptions {
                feature_sigma: sigma,
                ..DiagnoseOptions::default()
            };
            let mut m = Matcher::new(&table, &opts).unwrap();
            if sigma < 1e-30 {
                m.wear_var.iter_mut().for_each(|v| *v *= 1e-50);
                m.var.iter_mut().flatten().for_each(|v| *v *= 1e-50);
            }
            let k = m.mean.len() / 3;
            let y: Vec<f64> = m.mean[k].iter().map(|v| v + 0.05).collect();
            let y = m.clip(&y);
            let s0 = sigma * sigma;
            for (ea, om) in [
                (0.1, m.om[0]),
                (0.47, 0.5 * (m.om[0] + m.om[m.n_om - 1])),
                (1.0, m.om[m.n_om - 1]),
            ] {
                let direct: f64 = m
                    .wear_features
                    .iter()
                    .map(|&d| {
                        let (mu, v) = m.stats_at(d, ea, om);
                        let var = v + s0;
                        -0.5 * (y[d] - mu).powi(2) / var - 0.5 * var.ln()
                    })
                    .sum();
                let got = m.log_likelihood(
                    &y,
                    ea,
                    om,
                    &DiagnoseOptions {
                        temperature: 1.0,
                        ..opts.clone()
                    },
                );
                assert!(
                    (got - direct).abs() <= 1e-9 * direct.abs().max(1.0),
                    "σ {sigma}, ea {ea}: {got} vs {direct}"
                );
            }
        }
    }
}
