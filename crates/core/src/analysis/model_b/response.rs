//! The time response of Model B: a simulated record of physical quantities and its summary.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{Prepared, SolverSettings, integrate};
use crate::error::{Error, Result};
use crate::model::ModelBOptions;
use crate::solver::{OdeSystem, Stats};

/// What to simulate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimSpec {
    /// Simulated time after t = 0, s.
    pub duration_s: f64,
    /// Output sample rate, Hz.
    pub sample_hz: f64,
    pub solver: SolverSettings,
}

/// A sampled Model B response in physical units.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    /// Sample times, s.
    pub t: Vec<f64>,
    /// Transverse accelerations `ÿ1..ÿ4`, m/s².
    pub acc: [Vec<f64>; 4],
    /// Mesh deflections `δ1, δ2` (dynamic transmission error along each line of action), µm.
    pub mesh_um: [Vec<f64>; 2],
    /// Transmission error at the output `θ5 − θ0/R`, arcmin.
    pub dte_arcmin: Vec<f64>,
    /// Speed of gear 4 (the paper's output) and of the load, rad/s.
    pub omega4: Vec<f64>,
    pub omega5: Vec<f64>,
    pub stats: Stats,
    /// Wall-clock time of the integration (s), for the solver comparison.
    pub wall_s: f64,
}

/// Simulate from the static operating point.
pub fn simulate(p: &Prepared, spec: &SimSpec) -> Result<Record> {
    if !(spec.duration_s > 0.0 && spec.sample_hz > 0.0) {
        return Err(Error::param(
            "duration / sample rate",
            spec.duration_s.min(spec.sample_hz),
            "must be positive",
        ));
    }
    let wh = p.omega_h();
    let y0 = p.static_start()?;
    let n = p.model.n();
    let dt = wh / spec.sample_hz;
    let t_end = spec.duration_s * wh;
    let n_samples = (spec.duration_s * spec.sample_hz).floor() as usize + 1;
    let mut rec = Record {
        t: Vec::with_capacity(n_samples),
        acc: Default::default(),
        mesh_um: Default::default(),
        dte_arcmin: Vec::with_capacity(n_samples),
        omega4: Vec::with_capacity(n_samples),
        omega5: Vec::with_capacity(n_samples),
        stats: Stats::default(),
        wall_s: 0.0,
    };
    let iy: Vec<usize> = (1..=4)
        .map(|i| p.model.index(&format!("y{i}")))
        .collect::<Result<_>>()?;
    let (i4, i5) = (p.recon.dof("theta4")?, p.recon.dof("theta5")?);
    let (im1, im2) = (p.model.index("mesh1")?, p.model.index("mesh2")?);
    let b_um = p.model.length_ref * 1e6;
    let acc_scale = p.model.length_ref * wh * wh;
    let mut dy = vec![0.0; 2 * n];
    let start = Instant::now();
    let mut finite = true;
    let sys = p.edge_aware(t_end);
    let stats = integrate(&sys, &y0, &spec.solver, 0.0, dt, t_end, |_, tau, y| {
        finite &= y.iter().all(|v| v.is_finite());
        p.sys.rhs(tau, y, &mut dy);
        rec.t.push(tau / wh);
        for (k, &j) in iy.iter().enumerate() {
            // The bearing deflection is y_i itself: ÿ_i = b_ref ω_h² x̄''_i.
            rec.acc[k].push(dy[n + j] * acc_scale);
        }
        rec.mesh_um[0].push(y[im1] * b_um);
        rec.mesh_um[1].push(y[im2] * b_um);
        rec.dte_arcmin.push(p.dte_arcmin(y));
        let v = p.recon.velocities(tau, y);
        rec.omega4.push(v[i4]);
        rec.omega5.push(v[i5]);
    })?;
    rec.wall_s = start.elapsed().as_secs_f64();
    rec.stats = stats;
    if !finite {
        return Err(Error::NonFinite { t: t_end });
    }
    Ok(rec)
}

/// Summary of one series.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SeriesSummary {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub rms: f64,
}

impl SeriesSummary {
    /// Summarise a series.
    pub fn of(x: &[f64]) -> Self {
        let n = x.len().max(1) as f64;
        let mean = x.iter().sum::<f64>() / n;
        SeriesSummary {
            min: x.iter().cloned().fold(f64::INFINITY, f64::min),
            max: x.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            mean,
            rms: (x.iter().map(|v| v * v).sum::<f64>() / n).sqrt(),
        }
    }
}

/// Times (s) of the shocks in an acceleration record: the starts of the excursions of `|a|`
/// above `fraction` of its peak, separated by at least `gap_s`.
pub fn shock_times(t: &[f64], a: &[f64], fraction: f64, gap_s: f64) -> Vec<f64> {
    let peak = a.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let level = fraction * peak;
    let mut out: Vec<f64> = Vec::new();
    for (k, v) in a.iter().enumerate() {
        if v.abs() >= level && out.last().is_none_or(|&last| t[k] - last > gap_s) {
            out.push(t[k]);
        }
    }
    out
}

/// The JSON report of `gearwear model-b simulate`.
#[derive(Debug, Clone, Serialize)]
pub struct SimulateReport {
    pub model: String,
    pub options: ModelBOptions,
    pub spec: SimSpec,
    /// Stage-1 and stage-2 mesh periods, s.
    pub mesh_periods_s: (f64, f64),
    pub total_ratio: f64,
    pub omega_h: f64,
    pub omega1: f64,
    pub natural_frequencies_hz: Vec<f64>,
    /// Per `y1..y4`: summary of `ÿ` (m/s²) and the shock times (|ÿ| above 30 % of its peak,
    /// at least 5 % of a stage-1 mesh period apart).
    pub acc: Vec<(String, SeriesSummary, Vec<f64>)>,
    pub mesh1_um: SeriesSummary,
    pub mesh2_um: SeriesSummary,
    pub dte_arcmin: SeriesSummary,
    pub omega4_rad_s: SeriesSummary,
    pub omega5_rad_s: SeriesSummary,
    pub stats: Stats,
    pub wall_s: f64,
}

/// Build the simulate report.
pub fn simulate_report(p: &Prepared, spec: &SimSpec, rec: &Record) -> SimulateReport {
    let periods = p.cfg.mesh_periods_s();
    SimulateReport {
        model: p.cfg.name.clone(),
        options: p.opts,
        spec: *spec,
        mesh_periods_s: periods,
        total_ratio: p.cfg.radii().ratio(),
        omega_h: p.omega_h(),
        omega1: p.omega1,
        natural_frequencies_hz: p.natural_frequencies_hz(),
        acc: (0..4)
            .map(|k| {
                (
                    format!("y{}", k + 1),
                    SeriesSummary::of(&rec.acc[k]),
                    shock_times(&rec.t, &rec.acc[k], 0.3, 0.05 * periods.0),
                )
            })
            .collect(),
        mesh1_um: SeriesSummary::of(&rec.mesh_um[0]),
        mesh2_um: SeriesSummary::of(&rec.mesh_um[1]),
        dte_arcmin: SeriesSummary::of(&rec.dte_arcmin),
        omega4_rad_s: SeriesSummary::of(&rec.omega4),
        omega5_rad_s: SeriesSummary::of(&rec.omega5),
        stats: rec.stats,
        wall_s: rec.wall_s,
    }
}
