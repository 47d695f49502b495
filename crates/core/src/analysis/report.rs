//! A single-run report: spectral lines, motion state, Poincaré section (figures: the plot crate).

use serde::Serialize;

use super::motion::{Classification, ClassifyOptions, classify, classify_forced};
use super::simulate::{RunSpec, Trajectory, run};
use crate::error::Result;
use std::collections::BTreeMap;

use crate::model::DimensionlessModel;

use crate::signal;
use crate::solver::Stats;

/// One-sided peak amplitudes of the named lines (a sine of amplitude A reads A), in units of
/// the analysed quantity (x̄ = deflection / b_ref for the deflections).
/// Keyed by line name (`f1`, `f2`, `2f2`, `f1/2`, `f1-f2`, … as the gearbox's
/// [`report_lines`](crate::gearbox::Gearbox::report_lines) name them).
#[derive(Debug, Clone, Serialize)]
#[serde(transparent)]
pub struct Lines(pub BTreeMap<String, f64>);

impl Lines {
    /// Measure the lines `lines` (name, ratio to f1) of `x`, sampled `spp` times per stage-1
    /// mesh period (so frequencies are in units of f1).
    pub fn measure(x: &[f64], spp: f64, lines: &[(String, f64)]) -> Result<Self> {
        let mut m = BTreeMap::new();
        for (name, r) in lines {
            m.insert(name.clone(), signal::line_amplitude(x, spp, *r)?);
        }
        Ok(Lines(m))
    }

    /// The amplitude of a line by name (NaN when it was not measured).
    pub fn get(&self, name: &str) -> f64 {
        self.0.get(name).copied().unwrap_or(f64::NAN)
    }
}

/// Summary statistics of a series.
#[derive(Debug, Clone, Serialize)]
pub struct SeriesSummary {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub rms_ac: f64,
}

impl SeriesSummary {
    fn of(x: &[f64]) -> Self {
        let n = x.len().max(1) as f64;
        let mean = x.iter().sum::<f64>() / n;
        SeriesSummary {
            min: x.iter().cloned().fold(f64::INFINITY, f64::min),
            max: x.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            mean,
            rms_ac: (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt(),
        }
    }
}

/// What `gearwear simulate` prints.
#[derive(Debug, Clone, Serialize)]
pub struct SimulationReport {
    pub model: String,
    pub omega1: f64,
    pub ea: f64,
    pub planetary_error: f64,
    /// Stage-1 mesh frequency in Hz at this Ω1 (`Ω1 ω_h / 2π`).
    pub f1_hz: f64,
    pub omega_h_rad_s: f64,
    pub periods: usize,
    pub samples_per_period: usize,
    pub transient_tau: f64,
    /// Element whose response the lines, motion state and Poincaré section describe.
    pub element: String,
    /// Lines of x̄1 over the retained periods.
    pub lines: Lines,
    pub motion_state: String,
    pub classification: Classification,
    pub x: SeriesSummary,
    /// Poincaré points (x̄, x̄') once per stage-1 mesh period.
    pub poincare: Vec<(f64, f64)>,
    pub solver: Stats,
}

/// Run and report on element `element` (0: x1).
pub fn simulate_report(
    model: &DimensionlessModel,
    lines: &[(String, f64)],
    spec: &RunSpec,
    ea: f64,
    planetary_error: f64,
    element: usize,
) -> Result<(SimulationReport, Trajectory)> {
    let traj = run(model, spec)?;
    let x = traj.series(element);
    let v = traj.series(model.n() + element);
    let lines = Lines::measure(&x, traj.sample_rate_per_f1(), lines)?;
    let poincare = traj.poincare(element);
    let sx = SeriesSummary::of(&x);
    let sv = SeriesSummary::of(&v);
    let scale = ((sx.max - sx.min).max(1e-12), (sv.max - sv.min).max(1e-12));
    let opts = ClassifyOptions::default();
    let classification = match traj.lyapunov_per_period {
        Some(l) => classify_forced(&poincare, scale, l, &model.other_frequency_ratios(), &opts)?,
        None => classify(&poincare, scale, &opts)?,
    };
    Ok((
        SimulationReport {
            model: model.name.clone(),
            omega1: spec.omega1,
            ea,
            planetary_error,
            f1_hz: spec.omega1 * model.omega_h / std::f64::consts::TAU,
            omega_h_rad_s: model.omega_h,
            periods: spec.periods,
            samples_per_period: spec.samples_per_period,
            transient_tau: spec.transient.length(spec.omega1),
            element: model.names[element].clone(),
            lines,
            motion_state: classification.state.label(),
            classification,
            x: sx,
            poincare,
            solver: traj.stats,
        },
        traj,
    ))
}
