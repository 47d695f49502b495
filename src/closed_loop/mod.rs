//! Closing the loop with measured data: fit the model to a record, look at the residual,
//! attribute it to an effect the model lacks (or say it is unexplained), add the effect and
//! refit. See `docs/closed-loop.md`.
//!
//! [`calibrate`] in steps:
//! 1. **Diagnose** ([`crate::diagnosis::diagnose`]): f1, Ω1 and the table posterior of `ea`.
//! 2. **Measured spectrum** `M_j` on the normalised grid ([`spectrum`]).
//! 3. **Fit before**: simulate the model at (ea, Ω1, planetary 0.1) → `S_j`; fit the sensor
//!    gain `g` and the flat measurement-noise floor `n` by Levenberg–Marquardt on
//!    `F_j = 10 log10(g² S_j² |H_j|² + n²)` (dB; `H ≡ 1` without a path stage).
//! 4. **Candidates**: no effect, each effect of [`effects`] and the pairs, each fitted
//!    (resonance by grid + LM on the spectrum, element effects by re-simulation with the
//!    amplitude scaled from the residual at their fingerprint lines), scored by
//!    `BIC = J ln(RSS/J) + k ln J` (J grid points, k fitted parameters).
//! 5. **Selection**: the lowest BIC of the single effects wins if it beats "no effect" by
//!    [`CalibrateOptions::bic_margin`]; a pair replaces it only if each member is significant
//!    on its own and the pair beats the best single by that margin.
//! 6. **Refit**: the chosen effect enters the model; the wear is re-estimated (line features
//!    de-coloured by a path stage before the table likelihood) and everything is re-simulated
//!    and re-fitted.
//! 7. **Unexplained**: runs of the final residual beyond ±[`CalibrateOptions::unexplained_db`].

pub mod effects;
pub mod held;
pub mod spectrum;
pub mod virtual_rig;

use std::collections::{BTreeMap, HashMap};
use std::sync::Mutex;

use rayon::prelude::*;
use std::f64::consts::{LN_10, TAU};

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::diagnosis::{DiagnoseOptions, Matcher, diagnose, posterior};
use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signal::lines::measure_lines;
use crate::signature::precompute::{SimOptions, random_initial, simulate_sensor};
use crate::signature::{SignatureTable, SplitMix64, line_ratios};
use crate::solver::Dopri5Options;
use effects::{
    Effect, ElementParams, PATH_RESONANCE, PLANETARY_WEAR, Resonance, SHAFT_MODULATION,
    build_model, shaft_ratio,
};
use spectrum::{grid, grid_index, log_spectrum, rms_distance, running_median};

/// Tuning of [`calibrate`].
#[derive(Debug, Clone, Serialize)]
pub struct CalibrateOptions {
    /// Options of the underlying diagnosis (shaft rate, table likelihood).
    pub diagnose: DiagnoseOptions,
    /// Length of each model simulation in f1 periods (32 samples a period).
    pub sim_periods: usize,
    /// Seed of the model simulations' initial state.
    pub sim_seed: u64,
    /// BIC improvement an effect must bring to be claimed (≈ 10: "very strong" evidence).
    pub bic_margin: f64,
    /// A residual run beyond ± this many dB is reported (unexplained if the final model has it).
    pub unexplained_db: f64,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        CalibrateOptions {
            diagnose: DiagnoseOptions::default(),
            sim_periods: 640,
            sim_seed: 0xC105ED,
            bic_margin: 10.0,
            unexplained_db: 10.0,
        }
    }
}

/// A wear state of the model.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct WearEstimate {
    /// Fixed-axis wear degree (units of b = 5 µm).
    pub ea: f64,
    /// Credible interval of `ea` from the table likelihood.
    pub ea_lower: f64,
    pub ea_upper: f64,
    /// Planetary composite-error amplitude (units of b; baseline 0.1).
    pub planetary: f64,
}

/// The fitted sensor: gain and flat noise floor (dB of the record's unit, the gain relative to
/// the model's dimensionless ẍ̄1).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SensorFit {
    pub gain_db: f64,
    pub noise_db: f64,
    pub resonance: Option<Resonance>,
}

/// One candidate model of the selection.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Effects, joined by `+` (`none` for the plain model).
    pub name: String,
    pub effects: Vec<Effect>,
    /// Fitted parameters k (gain, noise, ea, plus the effects').
    pub parameters: usize,
    /// Residual sum of squares (dB²) over the grid.
    pub rss: f64,
    /// RMS log-spectral distance (dB).
    pub error_db: f64,
    pub bic: f64,
    /// BIC minus the BIC of `none` (negative: better).
    pub delta_bic: f64,
}

/// A residual feature: a run of grid points beyond the threshold.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualFeature {
    /// `extra` (measured above the model: a line the model lacks) or `missing` (a model line the
    /// measurement lacks).
    pub kind: &'static str,
    /// Frequency of the extreme point over f1.
    pub frequency_ratio: f64,
    pub frequency_hz: f64,
    /// Residual (measured − fitted) at the extreme point (dB).
    pub size_db: f64,
    /// Measured level there, dB re the measured f1 line.
    pub level_db: f64,
    /// Width of the run (units of f1).
    pub width_ratio: f64,
}

/// The spectra behind the report, dB re the measured f1 line, on [`spectrum::grid`].
#[derive(Debug, Clone, Serialize)]
pub struct Spectra {
    pub frequency_ratio: Vec<f64>,
    pub measured_db: Vec<f64>,
    pub fitted_before_db: Vec<f64>,
    pub fitted_after_db: Vec<f64>,
    pub residual_before_db: Vec<f64>,
    pub residual_after_db: Vec<f64>,
    /// Running median (±0.1 f1) of the residual after: the smooth trend left over.
    pub trend_after_db: Vec<f64>,
}

/// The answer of [`calibrate`] (and the JSON of `gearwear calibrate`).
#[derive(Debug, Clone, Serialize)]
pub struct CalibrationReport {
    pub f1_hz: f64,
    pub omega1: f64,
    /// The effects added to the model (empty: none claimed).
    pub effects: Vec<Effect>,
    /// Residual features the final model leaves (frequencies and sizes).
    pub unexplained: Vec<ResidualFeature>,
    /// Residual features of the plain model (before).
    pub residual_features_before: Vec<ResidualFeature>,
    /// RMS log-spectral distance before / after (dB, see [`spectrum`]).
    pub error_before: f64,
    pub error_after: f64,
    pub wear_before: WearEstimate,
    pub wear_after: WearEstimate,
    pub sensor_before: SensorFit,
    pub sensor_after: SensorFit,
    /// Smooth residual trend after: RMS of the running median (dB).
    pub trend_rms_db: f64,
    pub candidates: Vec<Candidate>,
    pub spectra: Spectra,
    pub diagnosis_warnings: Vec<String>,
    pub options: CalibrateOptions,
}

/// Simulated model spectra, cached by parameters.
struct Simulator<'a> {
    gb: &'a Gearbox,
    omega1: f64,
    periods: usize,
    seed: u64,
    cache: Mutex<HashMap<[u64; 3], Vec<f64>>>,
}

impl Simulator<'_> {
    /// Model spectrum (dB, dimensionless ẍ̄1) on the grid.
    fn spectrum(&self, p: &ElementParams) -> Result<Vec<f64>> {
        let key = [
            p.ea.to_bits(),
            p.planetary.to_bits(),
            p.eccentricity.to_bits(),
        ];
        if let Some(s) = self.cache.lock().expect("cache lock").get(&key) {
            return Ok(s.clone());
        }
        let model = build_model(self.gb, p)?;
        let mut rng = SplitMix64::new(self.seed);
        let initial = random_initial(model.n(), 2.0, self.omega1, &mut rng);
        let spp = 32usize;
        let period = TAU / self.omega1;
        let rec = simulate_sensor(
            &model,
            &initial,
            &SimOptions {
                omega1: self.omega1,
                transient_tau: 400.0_f64.max(30.0 * period),
                dt_tau: period / spp as f64,
                samples: self.periods * spp,
                sensor: crate::signature::SensorQuantity::Accel,
                poincare_every: 0,
                solver: Dopri5Options::default(),
            },
        )?;
        let s = log_spectrum(&rec.series, spp as f64, 1.0)?;
        self.cache
            .lock()
            .expect("cache lock")
            .insert(key, s.clone());
        Ok(s)
    }

    /// Refine `ea` by simulation: the grid `EA_GRID` plus `base.ea`, the sensor (and a path
    /// resonance starting at `res`) re-fitted at each; the lowest RSS wins.
    fn best_over_ea(
        &self,
        m: &[f64],
        r: &[f64],
        base: ElementParams,
        res: Option<Resonance>,
    ) -> Result<(ElementParams, SensorFit, f64)> {
        let mut eas: Vec<f64> = (0..EA_GRID_N).map(|k| 0.1 + 0.05 * k as f64).collect();
        eas.push(base.ea);
        let fits: Vec<Result<(ElementParams, SensorFit, f64)>> = eas
            .par_iter()
            .map(|&ea| {
                let p = ElementParams { ea, ..base };
                let s = self.spectrum(&p)?;
                let (sens, rss) = fit_sensor(m, &s, r, res);
                Ok((p, sens, rss))
            })
            .collect();
        let mut best: Option<(ElementParams, SensorFit, f64)> = None;
        for f in fits {
            let f = f?;
            if best.as_ref().is_none_or(|b| f.2 < b.2) {
                best = Some(f);
            }
        }
        Ok(best.expect("non-empty ea grid"))
    }
}

/// Number of points of the ea refinement grid 0.1, 0.15, …, 1.0.
const EA_GRID_N: usize = 19;

/// Levenberg–Marquardt on a residual vector with a forward-difference Jacobian, parameters
/// clamped to `[lo, hi]`. Returns the parameters and the residual sum of squares.
fn lm<F: Fn(&[f64]) -> Vec<f64>>(f: F, p0: &[f64], lo: &[f64], hi: &[f64]) -> (Vec<f64>, f64) {
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
fn db_add(a: f64, b: f64) -> f64 {
    let m = a.max(b);
    m + 10.0 * (10f64.powf((a - m) / 10.0) + 10f64.powf((b - m) / 10.0)).log10()
}

/// The fitted spectrum `F_j` (dB) of a model spectrum `s` through a sensor.
fn sensor_model(s: &[f64], r: &[f64], sensor: &SensorFit) -> Vec<f64> {
    s.iter()
        .zip(r)
        .map(|(sj, rj)| {
            let h = sensor.resonance.map_or(0.0, |res| res.gain_db(*rj));
            db_add(sensor.gain_db + sj + h, sensor.noise_db)
        })
        .collect()
}

/// Fit gain and noise (and, with `resonance`, the resonance starting there) of `s` to `m`.
fn fit_sensor(m: &[f64], s: &[f64], r: &[f64], resonance: Option<Resonance>) -> (SensorFit, f64) {
    let i1 = grid_index(1.0).unwrap_or(0);
    let g0 = m[i1] - s[i1];
    let mut sorted = m.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n0 = sorted[sorted.len() / 2];
    let make = |p: &[f64]| SensorFit {
        gain_db: p[0],
        noise_db: p[1],
        resonance: (p.len() == 4).then(|| Resonance {
            rho: p[2].exp(),
            zeta: p[3].exp(),
        }),
    };
    let resid = |p: &[f64]| -> Vec<f64> {
        let f = sensor_model(s, r, &make(p));
        m.iter().zip(&f).map(|(a, b)| a - b).collect()
    };
    let (p, rss) = match resonance {
        None => lm(resid, &[g0, n0], &[-400.0, -400.0], &[400.0, 400.0]),
        Some(res) => lm(
            resid,
            &[g0, n0, res.rho.ln(), res.zeta.ln()],
            &[-400.0, -400.0, 0.04f64.ln(), 0.02f64.ln()],
            &[400.0, 400.0, 3.0f64.ln(), 0.5f64.ln()],
        ),
    };
    (make(&p), rss)
}

/// Fit a path resonance: coarse grid over (ρ, ζ), then LM from the best.
fn fit_resonance(m: &[f64], s: &[f64], r: &[f64]) -> (SensorFit, f64) {
    let mut best: Option<(SensorFit, f64)> = None;
    for i in 0..36 {
        let rho = 0.08 * (2.8f64 / 0.08).powf(i as f64 / 35.0);
        for zeta in [0.03, 0.08, 0.2] {
            let res = Resonance { rho, zeta };
            // Gain and noise only at the grid point (fast), full LM at the best.
            let hs: Vec<f64> = s.iter().zip(r).map(|(a, b)| a + res.gain_db(*b)).collect();
            let (fit, rss) = fit_sensor(m, &hs, r, None);
            if best.as_ref().is_none_or(|b| rss < b.1) {
                best = Some((
                    SensorFit {
                        resonance: Some(res),
                        ..fit
                    },
                    rss,
                ));
            }
        }
    }
    let (start, _) = best.expect("non-empty grid");
    fit_sensor(m, s, r, start.resonance)
}

/// Lines of one residual beyond ±`thr` dB (runs, reported at their extreme point).
fn residual_features(
    resid: &[f64],
    measured_rel: &[f64],
    r: &[f64],
    f1: f64,
    thr: f64,
) -> Vec<ResidualFeature> {
    let mut out = Vec::new();
    let mut j = 0;
    while j < resid.len() {
        let sign = if resid[j] > thr {
            1.0
        } else if resid[j] < -thr {
            -1.0
        } else {
            j += 1;
            continue;
        };
        let start = j;
        let mut best = j;
        while j < resid.len() && sign * resid[j] > thr {
            if sign * resid[j] > sign * resid[best] {
                best = j;
            }
            j += 1;
        }
        out.push(ResidualFeature {
            kind: if sign > 0.0 { "extra" } else { "missing" },
            frequency_ratio: r[best],
            frequency_hz: r[best] * f1,
            size_db: resid[best],
            level_db: measured_rel[best],
            width_ratio: (j - start) as f64 / spectrum::GRID_PERIODS,
        });
    }
    out
}

/// Mean of `m − f` over the grid points nearest `ratios` where the measurement stands `min_db`
/// above the fitted noise floor (`None`: no such point).
fn fingerprint_gap(
    m: &[f64],
    f: &[f64],
    noise_db: f64,
    ratios: &[f64],
    min_db: f64,
) -> Option<f64> {
    let v: Vec<f64> = ratios
        .iter()
        .filter_map(|&x| grid_index(x))
        .filter(|&j| m[j] > noise_db + min_db)
        .map(|j| m[j] - f[j])
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

struct Fitted {
    name: String,
    effects: Vec<Effect>,
    params: ElementParams,
    sensor: SensorFit,
    rss: f64,
    k: usize,
}

fn effect_shaft(e: f64, gb: &Gearbox) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("sideband_amplitude_b".into(), e);
    p.insert("shaft_ratio".into(), shaft_ratio(gb));
    Effect {
        name: SHAFT_MODULATION.into(),
        kind: "element",
        parameters: p,
    }
}

fn effect_resonance(res: &Resonance, f1: f64) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("frequency_ratio".into(), res.rho);
    p.insert("frequency_hz".into(), res.rho * f1);
    p.insert("damping_ratio".into(), res.zeta);
    Effect {
        name: PATH_RESONANCE.into(),
        kind: "sensor-stage",
        parameters: p,
    }
}

fn effect_planetary(pl: f64) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("planetary_error_b".into(), pl);
    Effect {
        name: PLANETARY_WEAR.into(),
        kind: "element",
        parameters: p,
    }
}

fn cands_res(s: &SensorFit) -> Option<Resonance> {
    s.resonance
}

/// Close the loop on one record; see the [module docs](self).
pub fn calibrate(
    record: &Record,
    table: &SignatureTable,
    opts: &CalibrateOptions,
) -> Result<CalibrationReport> {
    let gb = table.gearbox();
    let d = diagnose(record, table, &opts.diagnose)?;
    let f1 = d.f1_hz;
    let (olo, ohi) = table.omega_band();
    let omega1 = d.omega1.clamp(olo, ohi);
    let fs = record.sample_rate;
    let r = grid();
    let m = log_spectrum(&record.samples, fs, f1)?;
    let j_n = m.len() as f64;
    let bic = |rss: f64, k: usize| j_n * (rss / j_n).max(1e-300).ln() + k as f64 * j_n.ln();

    // Table features of the record (for the re-estimate after a path stage).
    let lines = &table.features.lines;
    let meas = measure_lines(&record.samples, fs, f1, &line_ratios(lines))?;
    let matcher = Matcher::new(table, &opts.diagnose)?;
    let feats = meas.features(lines);

    let baseline_planetary = gb.planetary_baseline().unwrap_or(0.0);
    let wear_before = WearEstimate {
        ea: d.wear_degree.estimate,
        ea_lower: d.wear_degree.lower,
        ea_upper: d.wear_degree.upper,
        planetary: baseline_planetary,
    };
    let sim = Simulator {
        gb,
        omega1,
        periods: opts.sim_periods,
        seed: opts.sim_seed,
        cache: Mutex::new(HashMap::new()),
    };
    let p0 = ElementParams {
        ea: wear_before.ea,
        planetary: baseline_planetary,
        eccentricity: 0.0,
    };
    // Before: the plain model at the table's estimate (the diagnosis as it stands).
    let s0 = sim.spectrum(&p0)?;
    let (sens0, _) = fit_sensor(&m, &s0, &r, None);
    let f0 = sensor_model(&s0, &r, &sens0);

    // Candidate "none": the plain model, ea refined by simulation.
    let mut cands: Vec<Fitted> = Vec::new();
    let (pn, sn, rn) = sim.best_over_ea(&m, &r, p0, None)?;
    cands.push(Fitted {
        name: "none".into(),
        effects: vec![],
        params: pn,
        sensor: sn,
        rss: rn,
        k: 3,
    });

    // Path resonance (sensor stage): fitted at the table's ea, line features de-coloured,
    // table estimate again, then ea refined with the resonance in the model.
    let (sens_r0, _) = fit_resonance(&m, &s0, &r);
    let res0 = sens_r0.resonance.expect("fitted resonance");
    let (ea_dc, post_dc) = {
        let h1 = res0.gain_db(1.0);
        let mut y = feats.clone();
        for (k, l) in lines.iter().filter(|l| l.name != "f1").enumerate() {
            y[k] -= (res0.gain_db(l.ratio) - h1) * LN_10 / 20.0;
        }
        let post = posterior(&matcher, &matcher.clip(&y), omega1, &opts.diagnose);
        (post.quantile(0.5), post)
    };
    let (pr, sr_, rr) = sim.best_over_ea(&m, &r, ElementParams { ea: ea_dc, ..p0 }, Some(res0))?;
    cands.push(Fitted {
        name: PATH_RESONANCE.into(),
        effects: vec![effect_resonance(&sr_.resonance.expect("fitted"), f1)],
        params: pr,
        sensor: sr_,
        rss: rr,
        k: 5,
    });

    // Element effects: amplitude from the gap at the fingerprint lines (one probe simulation),
    // ea refined, amplitude re-fitted at the refined ea.
    let shaft = shaft_ratio(gb);
    let sb: Vec<f64> = [1.0, 2.0]
        .iter()
        .flat_map(|c| [c - shaft, c + shaft])
        .collect();
    // The planetary-wear fingerprint: the first planetary stage's mesh line family (none
    // without a planetary stage that the wear does not act on: the effect is then not tried).
    let f3 = gb.planetary_ratio();
    let fam: Vec<f64> = f3
        .map(|f3| vec![f3, 2.0 * f3, 1.0 - f3, 1.0 + f3])
        .unwrap_or_default();
    let fit_amp = |make: &dyn Fn(f64) -> ElementParams,
                   probe: f64,
                   ratios: &[f64],
                   lo: f64,
                   hi: f64|
     -> Result<f64> {
        let sp = sim.spectrum(&make(probe))?;
        let (sens, _) = fit_sensor(&m, &sp, &r, None);
        let fp = sensor_model(&sp, &r, &sens);
        Ok(match fingerprint_gap(&m, &fp, sens.noise_db, ratios, 6.0) {
            Some(gap) => (probe * 10f64.powf(gap.clamp(-40.0, 40.0) / 20.0)).clamp(lo, hi),
            None => lo,
        })
    };
    let element_fit = |base: ElementParams, which: &str| -> Result<ElementParams> {
        let amp = |b: ElementParams| -> Result<ElementParams> {
            Ok(if which == SHAFT_MODULATION {
                let e = fit_amp(
                    &|e| ElementParams {
                        eccentricity: e,
                        ..b
                    },
                    0.05,
                    &sb,
                    1e-3,
                    2.0,
                )?;
                ElementParams {
                    eccentricity: e,
                    ..b
                }
            } else {
                let p = fit_amp(
                    &|p| ElementParams { planetary: p, ..b },
                    1.0,
                    &fam,
                    baseline_planetary,
                    5.0,
                )?;
                ElementParams { planetary: p, ..b }
            })
        };
        let first = amp(base)?;
        let (refined, _, _) = sim.best_over_ea(&m, &r, first, None)?;
        amp(refined)
    };
    let pe = element_fit(pn, SHAFT_MODULATION)?;
    let pp = if f3.is_some() {
        Some(element_fit(pn, PLANETARY_WEAR)?)
    } else {
        None
    };
    let mut push =
        |name: String, p: ElementParams, res: Option<Resonance>, k: usize| -> Result<()> {
            let s = sim.spectrum(&p)?;
            let (sens, rss) = match res {
                Some(res) => fit_sensor(&m, &s, &r, Some(res)),
                None => fit_sensor(&m, &s, &r, None),
            };
            let mut effects = Vec::new();
            if p.eccentricity > 0.0 {
                effects.push(effect_shaft(p.eccentricity, gb));
            }
            if name.contains(PLANETARY_WEAR) {
                effects.push(effect_planetary(p.planetary));
            }
            if let Some(res) = sens.resonance {
                effects.push(effect_resonance(&res, f1));
            }
            cands.push(Fitted {
                name,
                effects,
                params: p,
                sensor: sens,
                rss,
                k,
            });
            Ok(())
        };
    let res_r = cands_res(&sr_);
    push(SHAFT_MODULATION.into(), pe, None, 4)?;
    if let Some(pp) = pp {
        push(PLANETARY_WEAR.into(), pp, None, 4)?;
    }
    push(format!("{SHAFT_MODULATION}+{PATH_RESONANCE}"), pe, res_r, 6)?;
    if let Some(pp) = pp {
        push(format!("{PLANETARY_WEAR}+{PATH_RESONANCE}"), pp, res_r, 6)?;
        let pep = ElementParams {
            planetary: pp.planetary,
            ..pe
        };
        push(format!("{SHAFT_MODULATION}+{PLANETARY_WEAR}"), pep, None, 5)?;
    }

    // Selection.
    let bic0 = bic(cands[0].rss, 3);
    let scores: Vec<f64> = cands.iter().map(|c| bic(c.rss, c.k)).collect();
    let best_of = |pred: &dyn Fn(&Fitted) -> bool| {
        (0..cands.len())
            .filter(|&i| pred(&cands[i]))
            .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
    };
    let single = best_of(&|c| c.effects.len() == 1).expect("single candidates");
    let pair = best_of(&|c| c.effects.len() == 2).expect("pair candidates");
    let mut chosen = 0;
    if scores[single] < bic0 - opts.bic_margin {
        chosen = single;
        // A pair needs every member significant on its own, and to beat the best single.
        let members_ok = cands[pair].effects.iter().all(|e| {
            cands
                .iter()
                .zip(&scores)
                .any(|(c, b)| c.name == e.name && *b < bic0 - opts.bic_margin)
        });
        if members_ok && scores[pair] < scores[single] - opts.bic_margin {
            chosen = pair;
        }
    }
    let candidates: Vec<Candidate> = cands
        .iter()
        .zip(&scores)
        .map(|(c, b)| Candidate {
            name: c.name.clone(),
            effects: c.effects.clone(),
            parameters: c.k,
            rss: c.rss,
            error_db: (c.rss / j_n).sqrt(),
            bic: *b,
            delta_bic: b - bic0,
        })
        .collect();

    // The chosen model, refitted (its ea already refined by simulation).
    let ch = &cands[chosen];
    let wear_after = if ch.sensor.resonance.is_some() && ch.params.ea == ea_dc {
        WearEstimate {
            ea: ch.params.ea,
            ea_lower: post_dc.quantile(0.5 - opts.diagnose.credible_level / 2.0),
            ea_upper: post_dc.quantile(0.5 + opts.diagnose.credible_level / 2.0),
            planetary: ch.params.planetary,
        }
    } else {
        WearEstimate {
            ea: ch.params.ea,
            ea_lower: ch.params.ea,
            ea_upper: ch.params.ea,
            planetary: ch.params.planetary,
        }
    };
    let sensor_after = ch.sensor;
    let f_after = sensor_model(&sim.spectrum(&ch.params)?, &r, &sensor_after);
    let error_before = rms_distance(&m, &f0);
    let error_after = rms_distance(&m, &f_after);

    let i1 = grid_index(1.0).unwrap_or(0);
    let ref_db = m[i1];
    let rel = |v: &[f64]| v.iter().map(|x| x - ref_db).collect::<Vec<f64>>();
    let res_before: Vec<f64> = m.iter().zip(&f0).map(|(a, b)| a - b).collect();
    let res_after: Vec<f64> = m.iter().zip(&f_after).map(|(a, b)| a - b).collect();
    let trend = running_median(&res_after, (0.1 * spectrum::GRID_PERIODS) as usize);
    let trend_rms_db = rms_distance(&trend, &vec![0.0; trend.len()]);
    let m_rel = rel(&m);
    let unexplained = residual_features(&res_after, &m_rel, &r, f1, opts.unexplained_db);
    let residual_features_before =
        residual_features(&res_before, &m_rel, &r, f1, opts.unexplained_db);
    if !(error_before.is_finite() && error_after.is_finite()) {
        return Err(Error::Signal(
            "the closed-loop fit produced a non-finite error".into(),
        ));
    }
    Ok(CalibrationReport {
        f1_hz: f1,
        omega1,
        effects: ch.effects.clone(),
        unexplained,
        residual_features_before,
        error_before,
        error_after,
        wear_before,
        wear_after,
        sensor_before: sens0,
        sensor_after,
        trend_rms_db,
        candidates,
        spectra: Spectra {
            frequency_ratio: r.clone(),
            measured_db: m_rel.clone(),
            fitted_before_db: rel(&f0),
            fitted_after_db: rel(&f_after),
            residual_before_db: res_before,
            residual_after_db: res_after,
            trend_after_db: trend,
        },
        diagnosis_warnings: d.warnings.clone(),
        options: opts.clone(),
    })
}

/// The wear re-estimated with a machine's calibrated effects held fixed ([`refit_held`]).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct HeldRefit {
    /// Fixed-axis wear `ea` of the best simulation (grid 0.1, 0.15, …, 1.0 plus the start).
    pub ea: f64,
    /// Planetary error and shaft-modulation amplitude the model held (units of b).
    pub planetary_error_b: f64,
    pub eccentricity_b: f64,
    /// RMS log-spectral distance (dB) of the model with the held effects at `ea`.
    pub error_db: f64,
    /// The same for the plain model at the start value (the uncalibrated diagnosis).
    pub error_plain_db: f64,
    pub f1_hz: f64,
    pub omega1: f64,
}

/// Re-estimate the wear of `record` with `held` in the model: element effects in the
/// assembly, a path resonance as a fixed sensor stage (its Hz frequency mapped to `f1`).
/// `ea` is refined by simulation over the same grid as [`calibrate`], gain and noise floor by
/// Levenberg–Marquardt; nothing about the effects is re-fitted.
pub fn refit_held(
    record: &Record,
    table: &SignatureTable,
    opts: &CalibrateOptions,
    f1: f64,
    omega1: f64,
    ea_start: f64,
    held: &held::HeldEffects,
) -> Result<HeldRefit> {
    let gb = table.gearbox();
    let (olo, ohi) = table.omega_band();
    let omega1 = omega1.clamp(olo, ohi);
    let r = grid();
    let m = log_spectrum(&record.samples, record.sample_rate, f1)?;
    let j_n = m.len() as f64;
    let sim = Simulator {
        gb,
        omega1,
        periods: opts.sim_periods,
        seed: opts.sim_seed,
        cache: Mutex::new(HashMap::new()),
    };
    let baseline = gb.planetary_baseline().unwrap_or(0.0);
    let p0 = ElementParams {
        ea: ea_start,
        planetary: baseline,
        eccentricity: 0.0,
    };
    let s0 = sim.spectrum(&p0)?;
    let (sens0, _) = fit_sensor(&m, &s0, &r, None);
    let error_plain_db = rms_distance(&m, &sensor_model(&s0, &r, &sens0));
    let res = held.resonance_at(f1);
    let base = ElementParams {
        ea: ea_start,
        planetary: held.planetary_error_b.unwrap_or(baseline),
        eccentricity: held.eccentricity_b,
    };
    let mut eas: Vec<f64> = (0..EA_GRID_N).map(|k| 0.1 + 0.05 * k as f64).collect();
    eas.push(ea_start);
    let fits: Vec<Result<(f64, f64)>> = eas
        .par_iter()
        .map(|&ea| {
            let s = sim.spectrum(&ElementParams { ea, ..base })?;
            let hs: Vec<f64> = match res {
                Some(h) => s.iter().zip(&r).map(|(a, b)| a + h.gain_db(*b)).collect(),
                None => s,
            };
            let (_, rss) = fit_sensor(&m, &hs, &r, None);
            Ok((ea, rss))
        })
        .collect();
    let mut best: Option<(f64, f64)> = None;
    for f in fits {
        let f = f?;
        if best.is_none_or(|b| f.1 < b.1) {
            best = Some(f);
        }
    }
    let (ea, rss) = best.expect("non-empty ea grid");
    let error_db = (rss / j_n).sqrt();
    if !(error_db.is_finite() && error_plain_db.is_finite()) {
        return Err(Error::Signal(
            "the refit with the calibrated effects produced a non-finite error".into(),
        ));
    }
    Ok(HeldRefit {
        ea,
        planetary_error_b: base.planetary,
        eccentricity_b: base.eccentricity,
        error_db,
        error_plain_db,
        f1_hz: f1,
        omega1,
    })
}
