//! The model's simulations for the closed loop ([`Simulator`]): spectra on the grid cached by
//! parameters and initial state, line features, and wear profiles (the residual score over
//! `ea` with everything else held).

use std::collections::HashMap;
use std::f64::consts::TAU;
use std::sync::Mutex;

use rayon::prelude::*;

use super::CalibrateOptions;
use super::SensorFit;
use super::effects::{ElementParams, Resonance, build_model};
use super::fit::{Weights, fit_sensor};
use super::spectrum::log_spectrum;
use crate::error::Result;
use crate::gearbox::Gearbox;
use crate::signal::lines::measure_lines;
use crate::signature::precompute::{SimOptions, random_initial, simulate_sensor};
use crate::signature::{LineDef, SplitMix64, line_ratios, mix_seed};
use crate::solver::Dopri5Options;

/// Cache key of a simulated spectrum: the element parameters and the initial state's seed.
type SpectrumKey = ([u64; 6], u64);

/// Samples per stage-1 mesh period of the closed loop's simulations.
const SIM_SPP: usize = 32;

/// Simulated model spectra, cached by parameters and seed.
pub(super) struct Simulator<'a> {
    gb: &'a Gearbox,
    omega1: f64,
    periods: usize,
    seed: u64,
    cache: Mutex<HashMap<SpectrumKey, Vec<f64>>>,
}

/// One point of a wear profile: the element parameters, the fitted sensor and the score.
pub(super) type ProfilePoint = (ElementParams, SensorFit, f64);

impl Simulator<'_> {
    pub(super) fn new<'a>(gb: &'a Gearbox, omega1: f64, opts: &CalibrateOptions) -> Simulator<'a> {
        Simulator {
            gb,
            omega1,
            periods: opts.sim_periods,
            seed: opts.sim_seed,
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// The first `n` initial-state seeds: the loop's own, then the model seeds derived from it
    /// (the model's scatter and the held refit's shift use the same ones).
    pub(super) fn seeds(&self, n: u64) -> Vec<u64> {
        (0..n)
            .map(|k| {
                if k == 0 {
                    self.seed
                } else {
                    mix_seed(&[self.seed, k, 0x5EED])
                }
            })
            .collect()
    }

    /// Model spectrum (dB, dimensionless ẍ̄1) on the grid.
    pub(super) fn spectrum(&self, p: &ElementParams) -> Result<Vec<f64>> {
        self.spectrum_seeded(p, self.seed)
    }

    /// [`Simulator::spectrum`] from the initial state of another seed.
    pub(super) fn spectrum_seeded(&self, p: &ElementParams, seed: u64) -> Result<Vec<f64>> {
        let key = (p.key(), seed);
        if let Some(s) = self.cache.lock().expect("cache lock").get(&key) {
            return Ok(s.clone());
        }
        let s = log_spectrum(&self.series(p, seed)?, SIM_SPP as f64, 1.0)?;
        self.cache
            .lock()
            .expect("cache lock")
            .insert(key, s.clone());
        Ok(s)
    }

    /// [`Simulator::spectrum_seeded`] from each of `seeds`' initial states, in parallel.
    pub(super) fn spectra_seeded(&self, p: &ElementParams, seeds: &[u64]) -> Result<Vec<Vec<f64>>> {
        seeds
            .par_iter()
            .map(|&sd| self.spectrum_seeded(p, sd))
            .collect()
    }

    /// The model's accelerometer series (dimensionless ẍ̄1, [`SIM_SPP`] samples per mesh period
    /// of stage 1) from the initial state of `seed`, after the transient.
    fn series(&self, p: &ElementParams, seed: u64) -> Result<Vec<f64>> {
        let model = build_model(self.gb, p)?;
        let mut rng = SplitMix64::new(seed);
        let initial = random_initial(model.n(), 2.0, self.omega1, &mut rng);
        let period = TAU / self.omega1;
        let rec = simulate_sensor(
            &model,
            &initial,
            &SimOptions {
                omega1: self.omega1,
                transient_tau: 400.0_f64.max(30.0 * period),
                dt_tau: period / SIM_SPP as f64,
                samples: self.periods * SIM_SPP,
                sensor: crate::signature::SensorQuantity::Accel,
                poincare_every: 0,
                solver: Dopri5Options::default(),
            },
        )?;
        Ok(rec.series)
    }

    /// The signature table's unclipped features ([`LineMeasurement::features`] of `lines`) of
    /// the model at `p`, one vector per initial state of `seeds` (in parallel).
    ///
    /// [`LineMeasurement::features`]: crate::signal::lines::LineMeasurement::features
    pub(super) fn line_features(
        &self,
        p: &ElementParams,
        seeds: &[u64],
        lines: &[LineDef],
    ) -> Result<Vec<Vec<f64>>> {
        let ratios = line_ratios(lines);
        seeds
            .par_iter()
            .map(|&s| {
                let x = self.series(p, s)?;
                Ok(measure_lines(&x, SIM_SPP as f64, 1.0, &ratios)?.features(lines))
            })
            .collect()
    }

    /// The residual score (of `w`) over `eas` with everything else of `base` held: at each ea
    /// the model is simulated and the sensor fitted (a path resonance `res`, when given,
    /// re-fitted from there; `fixed_res` held fixed instead). In parallel (rayon), sorted by ea.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn profile(
        &self,
        m: &[f64],
        r: &[f64],
        base: ElementParams,
        eas: &[f64],
        res: Option<Resonance>,
        fixed_res: Option<Resonance>,
        w: &Weights,
    ) -> Result<Vec<ProfilePoint>> {
        let mut out: Vec<ProfilePoint> = eas
            .par_iter()
            .map(|&ea| {
                let p = ElementParams { ea, ..base };
                let s = self.spectrum(&p)?;
                Ok(match fixed_res {
                    Some(h) => {
                        let hs: Vec<f64> =
                            s.iter().zip(r).map(|(a, b)| a + h.gain_db(*b)).collect();
                        let (mut sens, rss) = fit_sensor(m, &hs, r, None, w);
                        sens.resonance = Some(h);
                        (p, sens, rss)
                    }
                    None => {
                        let (sens, rss) = fit_sensor(m, &s, r, res, w);
                        (p, sens, rss)
                    }
                })
            })
            .collect::<Result<Vec<_>>>()?;
        out.sort_by(|a, b| a.0.ea.total_cmp(&b.0.ea));
        Ok(out)
    }
}

impl Simulator<'_> {
    /// [`Simulator::profile`] over the coarse grid 0.1, 0.2, …, 1.0 plus `base.ea`, then the
    /// points 0.05 either side of the best one (the profile's minimum and the interval are
    /// read from this adaptive set).
    pub(super) fn profile_adaptive(
        &self,
        m: &[f64],
        r: &[f64],
        base: ElementParams,
        res: Option<Resonance>,
        fixed_res: Option<Resonance>,
        w: &Weights,
    ) -> Result<Vec<ProfilePoint>> {
        let mut eas: Vec<f64> = (1..=10).map(|k| 0.1 * k as f64).collect();
        if eas.iter().all(|x| (x - base.ea).abs() > 1e-9) && base.ea.is_finite() {
            eas.push(base.ea);
        }
        let mut prof = self.profile(m, r, base, &eas, res, fixed_res, w)?;
        let best = best_point(&prof).0.ea;
        let more: Vec<f64> = [best - 0.05, best + 0.05]
            .into_iter()
            .filter(|x| (0.1 - 1e-9..=1.0 + 1e-9).contains(x))
            .filter(|x| prof.iter().all(|p| (p.0.ea - x).abs() > 1e-9))
            .collect();
        if !more.is_empty() {
            prof.extend(self.profile(m, r, base, &more, res, fixed_res, w)?);
            prof.sort_by(|a, b| a.0.ea.total_cmp(&b.0.ea));
        }
        Ok(prof)
    }
}

/// The lowest-RSS point of a profile.
pub(super) fn best_point(prof: &[ProfilePoint]) -> ProfilePoint {
    *prof
        .iter()
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .expect("non-empty profile")
}

/// Number of points of the ea refinement grid 0.1, 0.15, …, 1.0.
const EA_GRID_N: usize = 19;

/// The full wear grid 0.1, 0.15, …, 1.0 plus `start`.
fn ea_grid(start: f64) -> Vec<f64> {
    let mut v: Vec<f64> = (0..EA_GRID_N).map(|k| 0.1 + 0.05 * k as f64).collect();
    if v.iter().all(|x| (x - start).abs() > 1e-9) && start.is_finite() {
        v.push(start);
    }
    v
}

/// The grid points within ±0.05 of `centre`, plus `centre` (a local profile).
pub(super) fn ea_window(centre: f64) -> Vec<f64> {
    let mut v: Vec<f64> = ea_grid(centre)
        .into_iter()
        .filter(|x| (x - centre).abs() <= 0.05 + 1e-9)
        .collect();
    if v.iter().all(|x| (x - centre).abs() > 1e-9) {
        v.push(centre);
    }
    v
}

/// The point-by-point mean of equal-length rows (spectra on the grid).
pub(super) fn pointwise_mean(rows: &[Vec<f64>]) -> Vec<f64> {
    let n = rows.len() as f64;
    (0..rows.first().map_or(0, Vec::len))
        .map(|j| rows.iter().map(|row| row[j]).sum::<f64>() / n)
        .collect()
}
