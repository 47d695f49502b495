//! Step 4 of [`calibrate`](super::calibrate): the model's own scatter and the null. The plain
//! model's seed-to-seed scatter at its operating point gives the weights of every later fit
//! and score ([`model_scatter`]); candidate "no effect" is the plain model at its best wear
//! under those weights, and its deviance from the other initial states is what luck alone
//! gives ([`Null`]).

use super::SensorFit;
use super::effects::ElementParams;
use super::fit::{Weights, effective_points, fit_sensor, sensor_model};
use super::measured::{Before, Measured};
use super::simulator::{ProfilePoint, Simulator, best_point, pointwise_mean};
use super::spectrum;
use crate::error::Result;

/// Floor of the per-point standard deviation (dB): the model's lines agree across seeds.
const SIGMA_FLOOR_DB: f64 = 0.5;
/// Uncertainty of a line's position (grid points: f1's estimate, interpolation): a steep flank
/// scatters by this much times its slope.
const LINE_JITTER: f64 = 0.2;
/// Huber threshold of the standardised residual.
const HUBER: f64 = 3.0;

/// The model's own scatter at one operating point.
struct Scatter {
    /// Weights of every fit: `σ_j` from the scatter, scaled so that the plain model's
    /// standardised residual has a robust standard deviation of 1.
    weights: Weights,
    /// The plain model's spectra from the extra seeds (not the main one).
    seed_spectra: Vec<Vec<f64>>,
}

/// The model's own seed-to-seed scatter at `p`: the plain model is simulated from
/// `1 + extra` initial states (the main seed's spectrum is cached), each fitted to the record
/// (gain, noise floor), and per grid point
///
/// `v_j = 2 var_k(F_kj) + (LINE_JITTER · dF̄/dj)² + w_j var_Welch + SIGMA_FLOOR_DB²`
///
/// — the record is one more draw of the chaotic model, hence twice the model's variance (the
/// variance smoothed over ±2 points: five draws are few); a line's flank moves with a small
/// error of f1; where the fitted noise floor dominates (share `w_j` of the power) the record's
/// Welch estimate scatters by `(10/ln 10)² ψ'(ν/2)` with `ν ≈ 1.9 × segments` degrees of
/// freedom. `σ_j = τ √v_j` with `τ` the robust scale (median |u| / 0.6745) of the main seed's
/// residual, so the Huber threshold means "`HUBER` standard deviations".
fn model_scatter(
    sim: &Simulator,
    m: &[f64],
    r: &[f64],
    p: ElementParams,
    extra: usize,
    segments: usize,
) -> Result<Scatter> {
    let n = r.len();
    let unit = Weights::unit(n);
    let spectra = sim.spectra_seeded(&p, &sim.seeds(extra as u64 + 1))?;
    let fits: Vec<(SensorFit, Vec<f64>)> = spectra
        .iter()
        .map(|s| {
            let (sens, _) = fit_sensor(m, s, r, None, &unit);
            (sens, sensor_model(s, r, &sens))
        })
        .collect();
    let kk = fits.len() as f64;
    let fitted: Vec<Vec<f64>> = fits.iter().map(|f| f.1.clone()).collect();
    let mean = pointwise_mean(&fitted);
    let var: Vec<f64> = (0..n)
        .map(|j| {
            if kk < 2.0 {
                0.0
            } else {
                fits.iter().map(|f| (f.1[j] - mean[j]).powi(2)).sum::<f64>() / (kk - 1.0)
            }
        })
        .collect();
    let var_s: Vec<f64> = (0..n)
        .map(|j| {
            let (a, b) = (j.saturating_sub(2), (j + 2).min(n - 1));
            var[a..=b].iter().sum::<f64>() / (b - a + 1) as f64
        })
        .collect();
    let nu = (1.9 * segments.max(1) as f64).max(1.0);
    let x = nu / 2.0;
    let trigamma = 1.0 / x + 1.0 / (2.0 * x * x) + 1.0 / (6.0 * x * x * x);
    let var_welch = (10.0 / std::f64::consts::LN_10).powi(2) * trigamma;
    let noise = fits[0].0.noise_db;
    let v: Vec<f64> = (0..n)
        .map(|j| {
            let slope = (mean[(j + 1).min(n - 1)] - mean[j.saturating_sub(1)]) / 2.0;
            let share = 10f64.powf((noise - mean[j]) / 10.0).min(1.0);
            2.0 * var_s[j]
                + (LINE_JITTER * slope).powi(2)
                + share * var_welch
                + SIGMA_FLOOR_DB * SIGMA_FLOOR_DB
        })
        .collect();
    let mut u: Vec<f64> = (0..n)
        .map(|j| ((m[j] - fits[0].1[j]) / v[j].sqrt()).abs())
        .collect();
    u.sort_by(f64::total_cmp);
    let tau = (u[n / 2] / 0.6745).max(1e-6);
    Ok(Scatter {
        weights: Weights {
            inv_sigma: v.iter().map(|vj| 1.0 / (tau * vj.sqrt())).collect(),
            huber: HUBER,
        },
        seed_spectra: spectra.into_iter().skip(1).collect(),
    })
}

/// Number of Welch segments [`log_spectrum`](super::spectrum::log_spectrum) averages for a record.
fn welch_segments(samples: usize, fs: f64, f1: f64) -> usize {
    let len = (spectrum::GRID_PERIODS * fs / f1).round() as usize;
    let hop = ((len as f64 * 0.5).round() as usize).max(1);
    if samples < len {
        0
    } else {
        1 + (samples - len) / hop
    }
}

/// The plain model under the scatter's weights: candidate "no effect" and the null level an
/// effect must beat.
pub(super) struct Null {
    /// Weights of every later fit and score ([`Scatter::weights`]).
    pub weights: Weights,
    /// "No effect": the plain model's wear profile's best point over the whole grid.
    pub point: ProfilePoint,
    /// Effective number of independent grid points of its standardised residual (for the
    /// wear interval only).
    pub j_eff: f64,
    /// The plain model's deviance `J ln(score/J)`: its profile's best point, then from each
    /// extra model seed at the operating point.
    pub deviances: Vec<f64>,
    /// Standard deviation of `deviances`: the model's own scatter, the null level.
    pub spread: f64,
}

impl Null {
    /// The plain model's operating point (least squares), the model's own scatter there (other
    /// seeds) and from it the weights; then "no effect" with `ea` profiled over the whole grid,
    /// and the same plain model from the other initial states fitted to the record.
    pub(super) fn measure(ms: &Measured, sim: &Simulator, before: &Before) -> Result<Null> {
        let (m, r) = (&ms.m, &ms.r);
        let p0 = before.params;
        let unit = Weights::unit(r.len());
        let prof_plain = sim.profile_adaptive(m, r, p0, None, None, &unit)?;
        let scatter = model_scatter(
            sim,
            m,
            r,
            best_point(&prof_plain).0,
            ms.opts.model_seeds,
            welch_segments(ms.record.samples.len(), ms.fs, ms.f1),
        )?;
        let w = scatter.weights;

        // Candidate "none": the plain model, ea profiled over the whole grid.
        let prof_none = sim.profile_adaptive(m, r, p0, None, None, &w)?;
        let (pn, sn, rn) = best_point(&prof_none);
        let u_none = w.standardised(m, &sensor_model(&sim.spectrum(&pn)?, r, &sn));
        let j_eff = effective_points(&u_none);
        // The null: the same plain model from other initial states, fitted to the record.
        let deviances: Vec<f64> = std::iter::once(ms.deviance(rn))
            .chain(
                scatter
                    .seed_spectra
                    .iter()
                    .map(|s| ms.deviance(fit_sensor(m, s, r, None, &w).1)),
            )
            .collect();
        let spread = spread_of(&deviances);
        Ok(Null {
            weights: w,
            point: (pn, sn, rn),
            j_eff,
            deviances,
            spread,
        })
    }
}

/// Sample standard deviation of the null deviances (0 for a single one).
fn spread_of(null_dev: &[f64]) -> f64 {
    let k = null_dev.len() as f64;
    let mu = null_dev.iter().sum::<f64>() / k;
    if k > 1.0 {
        (null_dev.iter().map(|d| (d - mu).powi(2)).sum::<f64>() / (k - 1.0)).sqrt()
    } else {
        0.0
    }
}
