//! The fits of the closed loop: Levenberg–Marquardt, the sensor (gain, noise floor, path
//! stage), the path-resonance search over the whole band, the wear profile and its interval,
//! and the effective number of independent grid points.

use nalgebra::{DMatrix, DVector};

use super::SensorFit;
use super::effects::Resonance;
use super::spectrum::grid_index;

/// Levenberg–Marquardt on a residual vector with a forward-difference Jacobian, parameters
/// clamped to `[lo, hi]`. Returns the parameters and the residual sum of squares.
pub(crate) fn lm<F: Fn(&[f64]) -> Vec<f64>>(
    f: F,
    p0: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> (Vec<f64>, f64) {
    let np = p0.len();
    let mut p: Vec<f64> = p0
        .iter()
        .zip(lo.iter().zip(hi))
        .map(|(v, (a, b))| v.clamp(*a, *b))
        .collect();
    let mut r = f(&p);
    let mut cost: f64 = r.iter().map(|v| v * v).sum();
    let mut lambda = 1e-2;
    for _ in 0..60 {
        let m = r.len();
        let mut j = DMatrix::<f64>::zeros(m, np);
        for k in 0..np {
            let h = 1e-5 * (1.0 + p[k].abs());
            let mut q = p.clone();
            q[k] += h;
            let rq = f(&q);
            for i in 0..m {
                j[(i, k)] = (rq[i] - r[i]) / h;
            }
        }
        let rv = DVector::from_vec(r.clone());
        let jtj = j.transpose() * &j;
        let g = j.transpose() * rv;
        let mut improved = false;
        for _ in 0..8 {
            let mut a = jtj.clone();
            for k in 0..np {
                a[(k, k)] += lambda * (jtj[(k, k)] + 1e-9);
            }
            let Some(step) = a.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let q: Vec<f64> = (0..np)
                .map(|k| (p[k] + step[k]).clamp(lo[k], hi[k]))
                .collect();
            let rq = f(&q);
            let c: f64 = rq.iter().map(|v| v * v).sum();
            if c < cost {
                let rel = (cost - c) / cost.max(1e-300);
                p = q;
                r = rq;
                cost = c;
                lambda = (lambda * 0.3).max(1e-9);
                improved = true;
                if rel < 1e-9 {
                    return (p, cost);
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (p, cost)
}

/// `10 log10(10^(a/10) + 10^(b/10))`.
pub(crate) fn db_add(a: f64, b: f64) -> f64 {
    let m = a.max(b);
    m + 10.0 * (10f64.powf((a - m) / 10.0) + 10f64.powf((b - m) / 10.0)).log10()
}

/// How the residual `d_j = M_j − F_j` (dB) is scored: `u_j = d_j / σ_j` with a per-point
/// standard deviation `σ_j` (the model's own seed-to-seed scatter, the record's Welch scatter,
/// see `closed_loop::model_scatter`), and Huber's `ρ(u)` (`u²` up to `huber`, linear beyond) so
/// that a few points of a line the library does not hold cannot dominate. [`Weights::unit`]
/// is the plain sum of squares.
#[derive(Debug, Clone)]
pub struct Weights {
    /// `1 / σ_j` per grid point.
    pub inv_sigma: Vec<f64>,
    /// Huber's threshold in units of `σ_j` (`f64::INFINITY`: least squares).
    pub huber: f64,
}

impl Weights {
    /// Unit weights, least squares (the plain RSS in dB²).
    pub fn unit(n: usize) -> Weights {
        Weights {
            inv_sigma: vec![1.0; n],
            huber: f64::INFINITY,
        }
    }

    /// The pseudo-residual of `d` at point `j`: its square is `ρ(u_j)`.
    pub fn pseudo(&self, j: usize, d: f64) -> f64 {
        let u = d * self.inv_sigma[j];
        let c = self.huber;
        if u.abs() <= c {
            u
        } else {
            u.signum() * (2.0 * c * u.abs() - c * c).sqrt()
        }
    }

    /// `Σ_j ρ(u_j)` of the residual `m − f`.
    pub fn score(&self, m: &[f64], f: &[f64]) -> f64 {
        m.iter()
            .zip(f)
            .enumerate()
            .map(|(j, (a, b))| self.pseudo(j, a - b).powi(2))
            .sum()
    }

    /// The standardised residual `u_j` (no Huber cap).
    pub fn standardised(&self, m: &[f64], f: &[f64]) -> Vec<f64> {
        m.iter()
            .zip(f)
            .zip(&self.inv_sigma)
            .map(|((a, b), w)| (a - b) * w)
            .collect()
    }
}

/// The fitted spectrum `F_j` (dB) of a model spectrum `s` through a sensor.
pub(crate) fn sensor_model(s: &[f64], r: &[f64], sensor: &SensorFit) -> Vec<f64> {
    s.iter()
        .zip(r)
        .map(|(sj, rj)| {
            let h = sensor.resonance.map_or(0.0, |res| res.gain_db(*rj));
            db_add(sensor.gain_db + sj + h, sensor.noise_db)
        })
        .collect()
}

/// Bounds of a fitted path resonance: `ρ` (units of f1), `ζ`, peak gain `g`.
pub const RHO_RANGE: (f64, f64) = (0.1, 3.5);
/// See [`RHO_RANGE`].
pub const ZETA_RANGE: (f64, f64) = (0.02, 0.5);
/// See [`RHO_RANGE`].
pub const PEAK_GAIN_RANGE: (f64, f64) = (0.3, 40.0);

/// Fit gain and noise (and, with `resonance`, the resonance of the same form starting there)
/// of `s` to `m`, minimising the score of `w` (returned: `Σ ρ(u_j)`, the RSS in dB² with
/// [`Weights::unit`]).
pub(crate) fn fit_sensor(
    m: &[f64],
    s: &[f64],
    r: &[f64],
    resonance: Option<Resonance>,
    w: &Weights,
) -> (SensorFit, f64) {
    let i1 = grid_index(1.0).unwrap_or(0);
    let h1 = resonance.map_or(0.0, |h| h.gain_db(1.0));
    let g0 = m[i1] - s[i1] - h1;
    let mut sorted = m.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n0 = sorted[sorted.len() / 2];
    let peaking = resonance.is_some_and(|h| h.peak_gain.is_some());
    let make = |p: &[f64]| SensorFit {
        gain_db: p[0],
        noise_db: p[1],
        resonance: (p.len() >= 4).then(|| Resonance {
            rho: p[2].exp(),
            zeta: p[3].exp(),
            peak_gain: (p.len() == 5).then(|| p[4].exp()),
        }),
    };
    let resid = |p: &[f64]| -> Vec<f64> {
        let f = sensor_model(s, r, &make(p));
        m.iter()
            .zip(&f)
            .enumerate()
            .map(|(j, (a, b))| w.pseudo(j, a - b))
            .collect()
    };
    let (p, rss) = match resonance {
        None => lm(resid, &[g0, n0], &[-400.0, -400.0], &[400.0, 400.0]),
        Some(res) => {
            let mut p0 = vec![g0, n0, res.rho.ln(), res.zeta.ln()];
            let mut lo = vec![-400.0, -400.0, RHO_RANGE.0.ln(), ZETA_RANGE.0.ln()];
            let mut hi = vec![400.0, 400.0, RHO_RANGE.1.ln(), ZETA_RANGE.1.ln()];
            if peaking {
                p0.push(res.peak_gain.unwrap_or(1.0).ln());
                lo.push(PEAK_GAIN_RANGE.0.ln());
                hi.push(PEAK_GAIN_RANGE.1.ln());
            }
            lm(resid, &p0, &lo, &hi)
        }
    };
    (make(&p), rss)
}

/// Search a path resonance over the whole band without one starting guess: every point of a
/// grid of `ρ` (64 points, log-spaced over [`RHO_RANGE`]) × `ζ` (0.02 … 0.25) × form
/// (low-pass; peaking with `g` = 3, 8) is scored with only gain and noise fitted; the four
/// best grid points at distinct frequencies (more than 8 % apart) each start a full
/// Levenberg–Marquardt fit of every parameter; the lowest residual wins.
pub(crate) fn search_resonance(m: &[f64], s: &[f64], r: &[f64], w: &Weights) -> (SensorFit, f64) {
    let n_rho = 64;
    let mut scored: Vec<(Resonance, f64)> = Vec::new();
    for i in 0..n_rho {
        let rho = RHO_RANGE.0 * (RHO_RANGE.1 / RHO_RANGE.0).powf(i as f64 / (n_rho - 1) as f64);
        for zeta in [0.02, 0.05, 0.12, 0.25] {
            for g in [None, Some(3.0), Some(8.0)] {
                let res = Resonance {
                    rho,
                    zeta,
                    peak_gain: g,
                };
                let hs: Vec<f64> = s.iter().zip(r).map(|(a, b)| a + res.gain_db(*b)).collect();
                let (_, rss) = fit_sensor(m, &hs, r, None, w);
                scored.push((res, rss));
            }
        }
    }
    scored.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut starts: Vec<Resonance> = Vec::new();
    for (res, _) in &scored {
        if starts.iter().all(|s0| (s0.rho / res.rho).ln().abs() > 0.08) {
            starts.push(*res);
        }
        if starts.len() == 4 {
            break;
        }
    }
    let mut best: Option<(SensorFit, f64)> = None;
    for st in starts {
        // Both forms from every start: the grid's form is not always the fit's.
        let alt = Resonance {
            peak_gain: if st.peak_gain.is_some() {
                None
            } else {
                Some(3.0)
            },
            ..st
        };
        for start in [st, alt] {
            let f = fit_sensor(m, s, r, Some(start), w);
            if best.as_ref().is_none_or(|b| f.1 < b.1) {
                best = Some(f);
            }
        }
    }
    best.expect("non-empty resonance grid")
}

/// The effective number of independent points of a residual over the grid: `J / (1 + 2 Σ ρ_k)`
/// with `ρ_k` its autocorrelation at lag k, summed while positive (Bartlett), clamped to
/// `[10, J]`. Neighbouring grid points share a Hann window's main lobe and the model mismatch
/// is structured, so the points are not independent; likelihood ratios and BIC use this count.
pub fn effective_points(resid: &[f64]) -> f64 {
    let n = resid.len();
    let mean = resid.iter().sum::<f64>() / n.max(1) as f64;
    let e: Vec<f64> = resid.iter().map(|v| v - mean).collect();
    let c0: f64 = e.iter().map(|v| v * v).sum();
    if c0 <= 0.0 || n < 4 {
        return n as f64;
    }
    let mut sum = 0.0;
    for k in 1..(n / 4).min(40) {
        let ck: f64 = (0..n - k).map(|j| e[j] * e[j + k]).sum::<f64>() / c0;
        if ck <= 0.0 {
            break;
        }
        sum += ck;
    }
    (n as f64 / (1.0 + 2.0 * sum)).clamp(10.0_f64.min(n as f64), n as f64)
}

/// A profile of the residual over the wear degree: `(ea, RSS)` pairs, any order.
/// Returns `(ea, lower, upper)`: the minimum of a parabola through the best point and its two
/// neighbours (continuous; the best point itself at an edge), and the interval where the
/// profile likelihood ratio `J_eff ln(RSS(ea) / RSS_min)` (linearly interpolated between the
/// simulated points) stays below the χ²₁ quantile of `level`. An interval reaching the end of
/// the simulated range stops there.
pub fn profile_interval(points: &[(f64, f64)], j_eff: f64, level: f64) -> (f64, f64, f64) {
    interpolated_interval(points, j_eff, level, 0.0)
}

/// Half-width (units of ea) of the window of profile points a parabola is fitted to
/// ([`profile_interval_noisy`]).
pub const PROFILE_WINDOW: f64 = 0.25;

/// The profile interval when every profile point is a simulation with its own scatter (a
/// chaotic model from one initial state: the deviance `D(ea) = J_eff ln RSS(ea)` of each point
/// carries a random error of about `noise_sd`, the spread of `D` over model seeds at one ea).
/// A parabola `D ≈ c0 + c1 t + c2 t²` (t = ea − best) is fitted by least squares to the points
/// within [`PROFILE_WINDOW`] of the best one (at least four); `ea` is its vertex and the
/// interval `ea ± z sqrt(1/c2 + var(vertex))`: the likelihood interval of the smooth profile
/// (`D − D_min ≤ z²`) widened by the vertex's own uncertainty, from the larger of the points'
/// scatter about the parabola and `noise_sd` (delta method). Without a usable parabola (too few
/// points, not convex, vertex outside the window) the interpolated profile is read as in
/// [`profile_interval`] with the threshold raised by `z √2 noise_sd`. The interval stops at
/// the simulated range.
pub fn profile_interval_noisy(
    points: &[(f64, f64)],
    j_eff: f64,
    level: f64,
    noise_sd: f64,
) -> (f64, f64, f64) {
    let Some(DevianceProfile {
        points: p,
        dev,
        best: ib,
    }) = deviance_profile(points, j_eff)
    else {
        return (f64::NAN, f64::NAN, f64::NAN);
    };
    let xb = p[ib].0;
    let (x_lo, x_hi) = (p[0].0, p[p.len() - 1].0);
    let z = normal_quantile(0.5 + level / 2.0);
    let win: Vec<usize> = (0..p.len())
        .filter(|&i| (p[i].0 - xb).abs() <= PROFILE_WINDOW + 1e-9)
        .collect();
    if win.len() >= 4 {
        let n = win.len();
        let x = DMatrix::<f64>::from_fn(n, 3, |i, k| (p[win[i]].0 - xb).powi(k as i32));
        let y = DVector::<f64>::from_iterator(n, win.iter().map(|&i| dev[i]));
        if let Some(inv) = (x.transpose() * &x).try_inverse() {
            let c = &inv * x.transpose() * &y;
            let (c1, c2) = (c[1], c[2]);
            let span = win
                .iter()
                .map(|&i| (p[i].0 - xb).abs())
                .fold(0.0_f64, f64::max);
            if c2 > 0.0 {
                let v = -c1 / (2.0 * c2);
                if v.abs() <= span {
                    let fitted = &x * &c;
                    let ss: f64 = (0..n).map(|i| (y[i] - fitted[i]).powi(2)).sum();
                    let sp = if n > 3 {
                        (ss / (n - 3) as f64).sqrt()
                    } else {
                        0.0
                    };
                    let s = sp.max(noise_sd);
                    let g = DVector::from_vec(vec![0.0, -1.0 / (2.0 * c2), c1 / (2.0 * c2 * c2)]);
                    let var_v = s * s * (g.transpose() * &inv * &g)[(0, 0)];
                    let half = z * (1.0 / c2 + var_v.max(0.0)).sqrt();
                    let ea = (xb + v).clamp(x_lo, x_hi);
                    return (ea, (ea - half).max(x_lo), (ea + half).min(x_hi));
                }
            }
        }
    }
    interpolated_interval(
        points,
        j_eff,
        level,
        z * std::f64::consts::SQRT_2 * noise_sd,
    )
}

/// A profile's usable points in ea order with their deviances `J_eff ln RSS`, and the index of
/// the smallest deviance.
struct DevianceProfile {
    points: Vec<(f64, f64)>,
    dev: Vec<f64>,
    best: usize,
}

/// `None` without a usable point.
fn deviance_profile(points: &[(f64, f64)], j_eff: f64) -> Option<DevianceProfile> {
    let points = clean_profile(points);
    let dev: Vec<f64> = points.iter().map(|(_, v)| j_eff * v.ln()).collect();
    let best = (0..points.len()).min_by(|&a, &b| dev[a].total_cmp(&dev[b]))?;
    Some(DevianceProfile { points, dev, best })
}

fn clean_profile(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(e, v)| e.is_finite() && v.is_finite() && *v > 0.0)
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    p.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
    p
}

/// [`profile_interval`] with the χ²₁ threshold raised by `extra`.
fn interpolated_interval(
    points: &[(f64, f64)],
    j_eff: f64,
    level: f64,
    extra: f64,
) -> (f64, f64, f64) {
    let Some(DevianceProfile {
        points: p,
        dev,
        best: ib,
    }) = deviance_profile(points, j_eff)
    else {
        return (f64::NAN, f64::NAN, f64::NAN);
    };
    let (mut ea, mut dmin) = (p[ib].0, dev[ib]);
    if ib > 0 && ib + 1 < p.len() {
        let (x0, x1, x2) = (p[ib - 1].0, p[ib].0, p[ib + 1].0);
        let (y0, y1, y2) = (dev[ib - 1], dev[ib], dev[ib + 1]);
        // Parabola through three points (unequal spacing allowed).
        let d01 = (y1 - y0) / (x1 - x0);
        let d12 = (y2 - y1) / (x2 - x1);
        let a = (d12 - d01) / (x2 - x0);
        if a > 0.0 {
            let b = d01 - a * (x0 + x1);
            let v = -b / (2.0 * a);
            // A vertex outside the bracketing points (close, unequal spacing) is not trusted:
            // the best simulated point stands.
            if v > x0 && v < x2 {
                let c = y1 - a * x1 * x1 - b * x1;
                ea = v;
                dmin = (a * v * v + b * v + c).min(y1);
            }
        }
    }
    let z = normal_quantile(0.5 + level / 2.0);
    let thr = dmin + z * z + extra;
    let cross = |i: usize, j: usize| -> f64 {
        // Linear interpolation of the deviance between p[i] (below thr) and p[j] (above).
        let (xa, ya, xb, yb) = (p[i].0, dev[i], p[j].0, dev[j]);
        if (yb - ya).abs() < 1e-300 {
            xb
        } else {
            xa + (thr - ya) / (yb - ya) * (xb - xa)
        }
    };
    let mut lower = p[0].0;
    for i in (0..ib).rev() {
        if dev[i] > thr {
            lower = cross(i + 1, i);
            break;
        }
    }
    let mut upper = p[p.len() - 1].0;
    for i in ib + 1..p.len() {
        if dev[i] > thr {
            upper = cross(i - 1, i);
            break;
        }
    }
    (ea, lower.min(ea), upper.max(ea))
}

/// The standard normal quantile `Φ⁻¹(p)`, `0 < p < 1` (Acklam's rational approximation,
/// relative error below 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let pl = 0.02425;
    if p < pl {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - pl {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_of_a_parabola_gives_its_vertex_and_the_chi2_interval() {
        // J ln RSS = (ea − 0.42)² / 0.01 + const → interval ± 0.1 · 1.645 at 90 %.
        let j = 100.0;
        let pts: Vec<(f64, f64)> = (0..19)
            .map(|k| {
                let ea = 0.1 + 0.05 * k as f64;
                (ea, (((ea - 0.42).powi(2) / 0.01 + 50.0) / j).exp())
            })
            .collect();
        let (ea, lo, hi) = profile_interval(&pts, j, 0.9);
        assert!((ea - 0.42).abs() < 1e-9, "{ea}");
        // Linear interpolation of a parabola between 0.05-spaced points: within 0.01.
        assert!((lo - (0.42 - 0.1645)).abs() < 0.01, "{lo}");
        assert!((hi - (0.42 + 0.1645)).abs() < 0.01, "{hi}");
    }

    #[test]
    fn noisy_profile_gives_a_smooth_vertex_and_a_wider_interval() {
        // The parabola of the test above with a scatter of sd 3 on every point's deviance
        // (simulations from one initial state): the vertex of the fitted parabola is near the
        // truth and the interval widens with the scatter.
        let j = 100.0;
        let mut rng = crate::signature::SplitMix64::new(3);
        let pts: Vec<(f64, f64)> = (0..19)
            .map(|k| {
                let ea = 0.1 + 0.05 * k as f64;
                let d = (ea - 0.42).powi(2) / 0.01 + 50.0 + 3.0 * rng.normal();
                (ea, (d / j).exp())
            })
            .collect();
        let (ea0, lo0, hi0) = profile_interval_noisy(&pts, j, 0.9, 0.0);
        let (ea, lo, hi) = profile_interval_noisy(&pts, j, 0.9, 6.0);
        assert!((ea - 0.42).abs() < 0.06, "{ea}");
        assert!((ea - ea0).abs() < 1e-12);
        assert!(
            lo <= ea && ea <= hi && lo < 0.42 && 0.42 < hi,
            "[{lo}, {hi}]"
        );
        assert!(hi - lo > hi0 - lo0, "[{lo}, {hi}] vs [{lo0}, {hi0}]");
        // Without scatter it is the parabola's own χ² interval, ± 0.1645.
        let exact: Vec<(f64, f64)> = (0..19)
            .map(|k| {
                let ea = 0.1 + 0.05 * k as f64;
                (ea, (((ea - 0.42).powi(2) / 0.01 + 50.0) / j).exp())
            })
            .collect();
        let (e, l, h) = profile_interval_noisy(&exact, j, 0.9, 0.0);
        assert!((e - 0.42).abs() < 1e-6 && (l - 0.2555).abs() < 1e-3 && (h - 0.5845).abs() < 1e-3);
    }

    #[test]
    fn huber_weights_cap_a_large_residual() {
        let w = Weights {
            inv_sigma: vec![0.5; 3],
            huber: 3.0,
        };
        assert!((w.pseudo(0, 4.0) - 2.0).abs() < 1e-12);
        // u = 10: ρ = 2·3·10 − 9 = 51 instead of 100.
        assert!((w.pseudo(1, 20.0).powi(2) - 51.0).abs() < 1e-9);
        assert!(w.pseudo(2, -20.0) < 0.0);
    }

    #[test]
    fn normal_quantile_matches_tables() {
        assert!((normal_quantile(0.95) - 1.644_853_6).abs() < 1e-6);
        assert!((normal_quantile(0.975) - 1.959_964_0).abs() < 1e-6);
        assert!((normal_quantile(0.01) + 2.326_347_9).abs() < 1e-6);
    }

    #[test]
    fn white_residual_counts_every_point_and_a_smooth_one_fewer() {
        let mut rng = crate::signature::SplitMix64::new(7);
        let white: Vec<f64> = (0..400).map(|_| rng.normal()).collect();
        let smooth: Vec<f64> = (0..400).map(|j| (j as f64 / 15.0).sin()).collect();
        assert!(effective_points(&white) > 300.0);
        assert!(effective_points(&smooth) < 40.0);
    }

    #[test]
    fn peaking_resonance_has_unit_gain_far_away_and_one_plus_g_at_the_mode() {
        let h = Resonance {
            rho: 0.8,
            zeta: 0.05,
            peak_gain: Some(4.0),
        };
        assert!((h.gain_db(0.8) - 20.0 * 5f64.log10()).abs() < 1e-9);
        assert!(h.gain_db(0.05).abs() < 0.2);
        assert!(h.gain_db(2.5).abs() < 1.0);
    }

    #[test]
    fn resonance_search_finds_a_mode_far_from_any_start() {
        // A flat "model" with lines every 0.1 f1, coloured by a mode at 0.37 f1.
        let r = super::super::spectrum::grid();
        let s: Vec<f64> = r
            .iter()
            .map(|x| {
                if ((x * 10.0).round() - x * 10.0).abs() < 0.02 {
                    0.0
                } else {
                    -60.0
                }
            })
            .collect();
        let truth = Resonance {
            rho: 0.37,
            zeta: 0.04,
            peak_gain: Some(6.0),
        };
        let sens = SensorFit {
            gain_db: 3.0,
            noise_db: -40.0,
            resonance: Some(truth),
        };
        let m = sensor_model(&s, &r, &sens);
        let (fit, rss) = search_resonance(&m, &s, &r, &Weights::unit(r.len()));
        let h = fit.resonance.unwrap();
        assert!(rss < 1e-3, "rss {rss}");
        assert!((h.rho / 0.37 - 1.0).abs() < 0.02, "{h:?}");
    }
}
