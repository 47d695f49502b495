//! The offline job: simulate the configured gearbox over a grid of wear degrees `ea` and
//! operating points `Ω1`, several random initial states per point, and collect the features
//! of [`crate::signature`] into a [`SignatureTable`].
//!
//! Grid points run in parallel (rayon). Every finished point is appended as one JSON line to a
//! partial file next to the output (`<output>.partial.jsonl`); a restarted job with the same
//! header (model hash, grid, settings) skips the points already there, so an interrupted run
//! loses at most the points in flight.

use std::collections::HashMap;
use std::f64::consts::TAU;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use rayon::prelude::*;

use super::table::{Entry, FORMAT, FeatureDefs, Grid, SimulationSettings, VERSION};
use super::{
    LineDef, SensorQuantity, SignatureTable, SplitMix64, feature_names, line_ratios, mix_seed,
    model_hash,
};
use crate::analysis::motion::{ClassifyOptions, classify};
use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::model::{DimensionlessModel, Wear};
use crate::signal::lines::{BAND_HI, BAND_LO, SEGMENT_PERIODS, measure_lines};
use crate::solver::{Dopri5, Dopri5Options, Integrator, OdeSystem, advance_to, sample_uniform};

impl Default for SimulationSettings {
    /// 384 retained periods (11 half-overlapping 64-period segments), 32 samples a period
    /// (Nyquist at 16 f1, far above the highest line 2.5 f1), transient 400 τ + U(0, 200) τ and
    /// at least 30 periods, initial states ±2 (units of b), default solver tolerances.
    fn default() -> Self {
        SimulationSettings {
            periods: 384,
            samples_per_period: 32,
            transient_tau: 400.0,
            transient_jitter_tau: 200.0,
            transient_periods: 30.0,
            initial_amplitude: 2.0,
            base_seed: 0x7AB1E,
            rtol: Dopri5Options::default().rtol,
            atol: Dopri5Options::default().atol,
        }
    }
}

/// The committed paper-rig table's grid: ea 0.1 … 1 step 0.025, Ω1 0.5 … 1.6 step 0.05, 6 seeds.
pub fn paper_grid() -> Grid {
    let round = |v: f64| (v * 1e6).round() / 1e6;
    Grid {
        ea: (0..=36).map(|k| round(0.1 + 0.025 * k as f64)).collect(),
        omega1: (0..=22).map(|k| round(0.5 + 0.05 * k as f64)).collect(),
        seeds: 6,
    }
}

/// The default grid for a described gearbox: ea 0.1 … 1 step 0.05 (19 degrees), 3 seeds, and
/// Ω1 at five input rates over ±15 % of its `nominal_input_hz` (without one: 0.5 … 1.6 step
/// 0.1, the paper's band).
pub fn default_grid(gb: &Gearbox) -> Grid {
    let round = |v: f64| (v * 1e6).round() / 1e6;
    let omega1 = match gb.description.nominal_input_hz {
        Some(n) => {
            let f_ref = gb.reference_frequency_hz();
            (0..5)
                .map(|k| round(gb.f1_hz(n * (0.85 + 0.075 * k as f64)) / f_ref))
                .collect()
        }
        None => (0..=11).map(|k| round(0.5 + 0.1 * k as f64)).collect(),
    };
    Grid {
        ea: (0..=18).map(|k| round(0.1 + 0.05 * k as f64)).collect(),
        omega1,
        seeds: 3,
    }
}

/// A simulated sensor record.
#[derive(Debug, Clone)]
pub struct SimRecord {
    /// Sensor quantity at the sample times (dimensionless units of the model).
    pub series: Vec<f64>,
    /// Poincaré points `(x̄1, x̄1')`, every `poincare_every` samples (if requested).
    pub poincare: Vec<(f64, f64)>,
    /// Peak-to-peak of x̄1 and x̄1' over the record (scale for the motion classifier).
    pub scale: (f64, f64),
}

/// Options of one simulated record.
#[derive(Debug, Clone, Copy)]
pub struct SimOptions {
    pub omega1: f64,
    /// Transient before the first sample (τ).
    pub transient_tau: f64,
    /// Sample spacing (τ).
    pub dt_tau: f64,
    pub samples: usize,
    pub sensor: SensorQuantity,
    /// Keep a Poincaré point every this many samples (0: none).
    pub poincare_every: usize,
    pub solver: Dopri5Options,
}

/// A random initial state `[x̄ (n), x̄' (n)]` with `x̄_j ~ U(−a, a)`, `x̄'_j ~ U(−a, a)·Ω1`.
pub fn random_initial(n: usize, amplitude: f64, omega1: f64, rng: &mut SplitMix64) -> Vec<f64> {
    let mut y = Vec::with_capacity(2 * n);
    for _ in 0..n {
        y.push(rng.range(-amplitude, amplitude));
    }
    for _ in 0..n {
        y.push(rng.range(-amplitude, amplitude) * omega1);
    }
    y
}

/// Simulate the sensor quantity of `model` at `opts.omega1` from `initial` (made kinematically
/// consistent first).
pub fn simulate_sensor(
    model: &DimensionlessModel,
    initial: &[f64],
    opts: &SimOptions,
) -> Result<SimRecord> {
    let sys = model.system(opts.omega1)?;
    let n = model.n();
    let dim = sys.dim();
    if initial.len() != dim {
        return Err(Error::InvalidConfig(format!(
            "initial state has {} components, the model needs {dim}",
            initial.len()
        )));
    }
    if opts.samples == 0
        || opts.dt_tau.is_nan()
        || opts.dt_tau <= 0.0
        || opts.transient_tau.is_nan()
        || opts.transient_tau < 0.0
    {
        return Err(Error::param(
            "samples / dt",
            opts.dt_tau,
            "need samples ≥ 1, dt > 0, transient ≥ 0",
        ));
    }
    let mut y0 = initial.to_vec();
    model.project_consistent(opts.omega1, 0.0, &mut y0);
    let mut integ = Dopri5::new(&sys, 0.0, &y0, opts.solver)?;
    advance_to(&mut integ, opts.transient_tau)?;
    let t0 = opts.transient_tau;
    let t_end = t0 + (opts.samples - 1) as f64 * opts.dt_tau;
    let mut series = Vec::with_capacity(opts.samples);
    let mut poincare = Vec::new();
    let (mut xr, mut vr) = (
        (f64::INFINITY, f64::NEG_INFINITY),
        (f64::INFINITY, f64::NEG_INFINITY),
    );
    let mut dy = vec![0.0; dim];
    let mut forces = vec![0.0; n];
    let mut finite = true;
    // The sensor's element (0, the reference mesh, unless the gearbox places it elsewhere).
    let s = model.sensor;
    sample_uniform(&mut integ, t0, opts.dt_tau, t_end, |k, t, y| {
        let v = match opts.sensor {
            SensorQuantity::X1 => y[s],
            SensorQuantity::Accel => {
                sys.rhs(t, y, &mut dy);
                dy[n + s]
            }
            SensorQuantity::MeshForce => {
                sys.element_forces(t, y, &mut forces);
                forces[s]
            }
        };
        finite &= v.is_finite() && y[s].is_finite();
        series.push(v);
        xr = (xr.0.min(y[s]), xr.1.max(y[s]));
        vr = (vr.0.min(y[n + s]), vr.1.max(y[n + s]));
        if opts.poincare_every > 0 && k % opts.poincare_every == 0 {
            poincare.push((y[s], y[n + s]));
        }
    })?;
    if !finite {
        return Err(Error::NonFinite { t: integ.t() });
    }
    Ok(SimRecord {
        series,
        poincare,
        scale: ((xr.1 - xr.0).max(1e-12), (vr.1 - vr.0).max(1e-12)),
    })
}

/// Feature vector and motion state of one seed at one grid point.
pub fn simulate_seed(
    model: &DimensionlessModel,
    omega1: f64,
    settings: &SimulationSettings,
    sensor: SensorQuantity,
    lines: &[LineDef],
    seed: u64,
) -> Result<(Vec<f64>, String)> {
    let mut rng = SplitMix64::new(seed);
    let initial = random_initial(model.n(), settings.initial_amplitude, omega1, &mut rng);
    let period = TAU / omega1;
    let transient = (settings.transient_tau + rng.range(0.0, settings.transient_jitter_tau))
        .max(settings.transient_periods * period);
    let spp = settings.samples_per_period;
    let rec = simulate_sensor(
        model,
        &initial,
        &SimOptions {
            omega1,
            transient_tau: transient,
            dt_tau: period / spp as f64,
            samples: settings.periods * spp,
            sensor,
            poincare_every: spp,
            solver: Dopri5Options {
                rtol: settings.rtol,
                atol: settings.atol,
                ..Default::default()
            },
        },
    )?;
    let m = measure_lines(&rec.series, spp as f64, 1.0, &line_ratios(lines))?;
    let motion = classify(&rec.poincare, rec.scale, &ClassifyOptions::default())
        .map(|c| c.state.label())
        .unwrap_or_else(|_| "unknown".into());
    Ok((m.features(lines), motion))
}

/// What to precompute.
#[derive(Debug, Clone)]
pub struct PrecomputeSpec {
    pub gearbox: std::sync::Arc<Gearbox>,
    pub sensor: SensorQuantity,
    pub grid: Grid,
    pub settings: SimulationSettings,
    pub created_by: String,
}

impl PrecomputeSpec {
    /// Feature definitions for this configuration.
    pub fn feature_defs(&self) -> FeatureDefs {
        let lines = super::line_set::gearbox_line_set(&self.gearbox);
        FeatureDefs {
            names: feature_names(&lines),
            lines,
            segment_periods: SEGMENT_PERIODS,
            band: (BAND_LO, BAND_HI),
            definition: "Welch: segments of segment_periods stage-1 mesh periods, 50 % overlap, \
                         mean removed, periodic Hann window, power average. Line amplitude: \
                         Hann DTFT at exactly ratio·f1, peak scaled. Features: ln(A_line/A_f1) \
                         for each line except f1, then f1_power_fraction = \
                         ln((A_f1²/2)/P_band), P_band = power in band·f1."
                .into(),
        }
    }

    /// The header line of the partial file: everything that must match for a resume.
    fn resume_key(&self) -> String {
        serde_json::json!({
            "format": FORMAT,
            "version": VERSION,
            "model_hash": model_hash(&self.gearbox),
            "sensor": self.sensor,
            "grid": self.grid,
            "settings": self.settings,
            "features": self.feature_defs(),
        })
        .to_string()
    }
}

/// Partial-file path for an output path.
pub fn partial_path(output: &Path) -> PathBuf {
    let mut s = output.as_os_str().to_owned();
    s.push(".partial.jsonl");
    PathBuf::from(s)
}

/// Run the precompute, resuming from `partial` if it holds points of the same job.
/// `on_point` is called once per finished grid point (also for those resumed); `total` points.
pub fn precompute(
    spec: &PrecomputeSpec,
    partial: Option<&Path>,
    on_point: &(dyn Fn() + Sync),
) -> Result<SignatureTable> {
    let t_start = std::time::Instant::now();
    let g = &spec.grid;
    if g.ea.len() < 2 || g.omega1.is_empty() || g.seeds == 0 {
        return Err(Error::InvalidConfig(
            "the grid needs ≥ 2 wear degrees, ≥ 1 Ω1 and ≥ 1 seed".into(),
        ));
    }
    let defs = spec.feature_defs();
    let key = spec.resume_key();
    let mut done: HashMap<(usize, usize), Entry> = HashMap::new();
    let mut writer = None;
    if let Some(p) = partial {
        let io = |source| Error::Io {
            path: p.display().to_string(),
            source,
        };
        let mut resume = false;
        if let Ok(f) = std::fs::File::open(p) {
            let mut lines = std::io::BufReader::new(f).lines();
            if let Some(Ok(first)) = lines.next()
                && first == key
            {
                resume = true;
                for l in lines.map_while(|l| l.ok()) {
                    // A line cut by an interruption fails to parse and is simply redone.
                    if let Ok((i, j, e)) = serde_json::from_str::<(usize, usize, Entry)>(&l)
                        && i < g.ea.len()
                        && j < g.omega1.len()
                    {
                        done.insert((i, j), e);
                    }
                }
            }
        }
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let mut f = if resume {
            std::fs::OpenOptions::new()
                .append(true)
                .open(p)
                .map_err(io)?
        } else {
            std::fs::File::create(p).map_err(io)?
        };
        if !resume {
            writeln!(f, "{key}").map_err(io)?;
        }
        writer = Some(Mutex::new(f));
    }
    let models: Vec<DimensionlessModel> =
        g.ea.iter()
            .map(|&ea| spec.gearbox.assembly(Wear::fixed_axis(ea))?.resolve())
            .collect::<Result<_>>()?;
    let todo: Vec<(usize, usize)> = (0..g.ea.len())
        .flat_map(|i| (0..g.omega1.len()).map(move |j| (i, j)))
        .filter(|ij| !done.contains_key(ij))
        .collect();
    for _ in 0..done.len() {
        on_point();
    }
    let fresh: Vec<((usize, usize), Entry)> = todo
        .par_iter()
        .map(|&(i, j)| -> Result<((usize, usize), Entry)> {
            let (ea, omega1) = (g.ea[i], g.omega1[j]);
            let mut samples = Vec::with_capacity(g.seeds);
            let mut motion = Vec::with_capacity(g.seeds);
            let mut failed = 0;
            for s in 0..g.seeds {
                let seed = mix_seed(&[
                    spec.settings.base_seed,
                    ea.to_bits(),
                    omega1.to_bits(),
                    s as u64,
                ]);
                match simulate_seed(
                    &models[i],
                    omega1,
                    &spec.settings,
                    spec.sensor,
                    &defs.lines,
                    seed,
                ) {
                    Ok((f, m)) => {
                        samples.push(f);
                        motion.push(m);
                    }
                    Err(_) => failed += 1,
                }
            }
            if samples.is_empty() {
                return Err(Error::InvalidConfig(format!(
                    "every seed failed at ea = {ea}, Ω1 = {omega1}"
                )));
            }
            let e = Entry {
                ea,
                omega1,
                samples,
                motion,
                failed,
            };
            if let Some(w) = &writer {
                let line = serde_json::to_string(&(i, j, &e)).unwrap_or_default();
                let mut f = w.lock().unwrap_or_else(|p| p.into_inner());
                // A failed write only costs the resume of this point.
                let _ = writeln!(f, "{line}").and_then(|_| f.flush());
            }
            on_point();
            Ok(((i, j), e))
        })
        .collect::<Result<_>>()?;
    done.extend(fresh);
    let mut entries = Vec::with_capacity(g.ea.len() * g.omega1.len());
    for i in 0..g.ea.len() {
        for j in 0..g.omega1.len() {
            entries.push(done.remove(&(i, j)).ok_or_else(|| {
                Error::InvalidConfig(format!("grid point ({i}, {j}) missing after precompute"))
            })?);
        }
    }
    Ok(SignatureTable {
        format: FORMAT.into(),
        version: VERSION,
        model_hash: model_hash(&spec.gearbox),
        gearbox: spec.gearbox.description.clone(),
        resolved: Some(spec.gearbox.clone()),
        sensor: spec.sensor,
        grid: spec.grid.clone(),
        simulation: spec.settings.clone(),
        features: defs,
        created_by: spec.created_by.clone(),
        precompute_seconds: t_start.elapsed().as_secs_f64(),
        entries,
    })
}

/// A simulated "measurement" for validation: what a housing accelerometer would deliver
/// according to the model, in physical time.
#[derive(Debug, Clone, Copy)]
pub struct MeasurementSpec {
    pub ea: f64,
    pub omega1: f64,
    /// Sample rate (Hz).
    pub sample_rate: f64,
    /// Record length (s).
    pub duration: f64,
    /// Overall sensor gain (the diagnosis must not care).
    pub gain: f64,
    /// Additive white Gaussian noise: signal-to-noise power ratio in dB (`None`: no noise).
    pub snr_db: Option<f64>,
    /// Seed of the initial state, transient length and noise.
    pub seed: u64,
    pub sensor: SensorQuantity,
    /// Planetary composite-error amplitude (units of b); `None`: the configuration's baseline.
    pub planetary: Option<f64>,
}

/// Simulate a measured record of the configured gearbox (random initial state, transient as in
/// the table, gain and noise applied). The sample rate must exceed 2 × the highest line.
pub fn simulate_measurement(gb: &Gearbox, spec: &MeasurementSpec) -> Result<crate::record::Record> {
    let model = gb
        .assembly(Wear {
            ea: spec.ea,
            planetary: spec.planetary,
        })?
        .resolve()?;
    simulate_measurement_with(&model, spec)
}

/// [`simulate_measurement`] with a resolved model for `spec.ea` (and `spec.planetary`).
pub fn simulate_measurement_with(
    model: &DimensionlessModel,
    spec: &MeasurementSpec,
) -> Result<crate::record::Record> {
    if !(spec.sample_rate > 0.0 && spec.duration > 0.0 && spec.gain.is_finite()) {
        return Err(Error::param(
            "sample rate / duration",
            spec.sample_rate,
            "both must be positive",
        ));
    }
    let settings = SimulationSettings::default();
    let mut rng = SplitMix64::new(spec.seed);
    let initial = random_initial(model.n(), settings.initial_amplitude, spec.omega1, &mut rng);
    let period = TAU / spec.omega1;
    let transient = (settings.transient_tau + rng.range(0.0, settings.transient_jitter_tau))
        .max(settings.transient_periods * period);
    let samples = (spec.sample_rate * spec.duration).round() as usize;
    let rec = simulate_sensor(
        model,
        &initial,
        &SimOptions {
            omega1: spec.omega1,
            transient_tau: transient,
            dt_tau: model.omega_h / spec.sample_rate,
            samples,
            sensor: spec.sensor,
            poincare_every: 0,
            solver: Dopri5Options::default(),
        },
    )?;
    let mut x: Vec<f64> = rec.series.iter().map(|v| v * spec.gain).collect();
    if let Some(snr) = spec.snr_db {
        let n = x.len().max(1) as f64;
        let mean = x.iter().sum::<f64>() / n;
        let power = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        let sigma = (power / 10f64.powf(snr / 10.0)).sqrt();
        for v in x.iter_mut() {
            *v += sigma * rng.normal();
        }
    }
    Ok(crate::record::Record {
        samples: x,
        sample_rate: spec.sample_rate,
    })
}
