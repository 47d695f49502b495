//! The load drop: how the response decays after the output torque drops, with and without
//! the return difference.

use serde::Serialize;

use super::{Prepared, SolverSettings, integrate};
use crate::error::{Error, Result};
use crate::model::rig_b::MeshDamping;
use crate::model::{LoadCase, ModelBConfig, ModelBOptions, StiffnessForm};
use crate::solver::Stats;

/// Decay measures of a response after a load drop.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct DecayMeasures {
    /// |r| at the first extremum after the drop (arcmin), where `r = DTE − DTE_final`.
    pub first_peak_arcmin: f64,
    /// Time after the drop (s) from which |r| stays below 5 % of the first peak (the window's
    /// end if it never does).
    pub decay_time_s: f64,
    /// True when |r| was still above the level at the end of the window.
    pub still_oscillating: bool,
    /// Local extrema of `r` above the 5 % level, over 2 (oscillations; may end in .5).
    pub oscillations: f64,
    /// Final transmission error (mean over the window's last 5 %), arcmin.
    pub final_dte_arcmin: f64,
}

/// Measure decay of `x(t)` after `t_drop` (see [`DecayMeasures`]).
pub fn decay_measures(t: &[f64], x: &[f64], t_drop: f64) -> DecayMeasures {
    let t_end = *t.last().unwrap_or(&t_drop);
    let tail: Vec<f64> = t
        .iter()
        .zip(x)
        .filter(|(tt, _)| **tt >= t_end - 0.05 * (t_end - t_drop))
        .map(|(_, v)| *v)
        .collect();
    let fin = tail.iter().sum::<f64>() / tail.len().max(1) as f64;
    let r: Vec<(f64, f64)> = t
        .iter()
        .zip(x)
        .filter(|(tt, _)| **tt >= t_drop)
        .map(|(tt, v)| (*tt, v - fin))
        .collect();
    // The first extremum of r after the drop (not the starting offset).
    let first_peak = (1..r.len().saturating_sub(1))
        .find(|&k| {
            let (a, b, c) = (r[k - 1].1, r[k].1, r[k + 1].1);
            (b > a && b >= c) || (b < a && b <= c)
        })
        .map_or(0.0, |k| r[k].1.abs());
    let level = 0.05 * first_peak;
    let last_above = r.iter().rposition(|(_, v)| v.abs() > level);
    let (decay, still) = match last_above {
        Some(k) if k + 1 < r.len() => (r[k + 1].0 - t_drop, false),
        Some(_) => (t_end - t_drop, true),
        None => (0.0, false),
    };
    let mut extrema = 0usize;
    for k in 1..r.len().saturating_sub(1) {
        let (a, b, c) = (r[k - 1].1, r[k].1, r[k + 1].1);
        let is_ext = (b > a && b >= c) || (b < a && b <= c);
        if is_ext && b.abs() > level {
            extrema += 1;
        }
    }
    DecayMeasures {
        first_peak_arcmin: first_peak,
        decay_time_s: decay,
        still_oscillating: still,
        oscillations: extrema as f64 / 2.0,
        final_dte_arcmin: fin,
    }
}

/// One load-drop run.
#[derive(Debug, Clone, Serialize)]
pub struct LoadDropRun {
    pub backlash: bool,
    pub measures: DecayMeasures,
    pub stats: Stats,
    #[serde(skip)]
    pub t: Vec<f64>,
    #[serde(skip)]
    pub dte: Vec<f64>,
}

/// The load-drop comparison: with and without return difference (configured backlash vs 0).
#[derive(Debug, Clone, Serialize)]
pub struct LoadDropReport {
    /// Where the mesh damping acts in both runs.
    pub mesh_damping: MeshDamping,
    pub at_s: f64,
    pub end_s: f64,
    pub torque_nm: f64,
    pub with_return_difference: LoadDropRun,
    pub without_return_difference: LoadDropRun,
    /// with / without: decay time, oscillations, first peak.
    pub decay_time_ratio: f64,
    pub oscillation_ratio: f64,
    pub first_peak_ratio: f64,
    /// Extrema of the response with return difference (above its 5 % level) that are larger
    /// than every excursion the drive without return difference still makes from that time on:
    /// the paper's "several oscillations larger than without".
    pub larger_extrema_than_without: usize,
}

/// Extrema `(t, r)` of `r = x − x_final` after `t_drop`.
fn extrema_after(t: &[f64], x: &[f64], t_drop: f64, fin: f64) -> Vec<(f64, f64)> {
    let r: Vec<(f64, f64)> = t
        .iter()
        .zip(x)
        .filter(|(tt, _)| **tt >= t_drop)
        .map(|(tt, v)| (*tt, v - fin))
        .collect();
    (1..r.len().saturating_sub(1))
        .filter(|&k| {
            let (a, b, c) = (r[k - 1].1, r[k].1, r[k + 1].1);
            (b > a && b >= c) || (b < a && b <= c)
        })
        .map(|k| r[k])
        .collect()
}

/// See [`LoadDropReport::larger_extrema_than_without`].
fn larger_extrema(with: &LoadDropRun, without: &LoadDropRun, t_drop: f64) -> usize {
    let level = 0.05 * with.measures.first_peak_arcmin;
    let fin = without.measures.final_dte_arcmin;
    // Remaining envelope of the run without: max |r| over [t, end], from the back.
    let mut env = vec![0.0_f64; without.t.len()];
    let mut m = 0.0_f64;
    for k in (0..without.t.len()).rev() {
        m = m.max((without.dte[k] - fin).abs());
        env[k] = m;
    }
    let env_at = |t: f64| {
        let k = without.t.partition_point(|&tt| tt < t);
        env.get(k).copied().unwrap_or(0.0)
    };
    extrema_after(&with.t, &with.dte, t_drop, with.measures.final_dte_arcmin)
        .iter()
        .filter(|(t, r)| r.abs() > level && r.abs() > env_at(*t))
        .count()
}

/// The load drop under both mesh-damping models.
#[derive(Debug, Clone, Serialize)]
pub struct LoadDropComparison {
    /// Damping `ct δ̇` everywhere (the paper's equations as written).
    pub viscous: LoadDropReport,
    /// Damping only while the teeth are in contact (free flight in the clearance).
    pub contact_only: LoadDropReport,
}

/// [`load_drop`] under both mesh-damping models.
pub fn load_drop_comparison(
    cfg: &ModelBConfig,
    stiffness: StiffnessForm,
    at_s: f64,
    end_s: f64,
    sample_hz: f64,
    solver: &SolverSettings,
) -> Result<LoadDropComparison> {
    let run = |d| load_drop(cfg, stiffness, d, at_s, end_s, sample_hz, solver);
    Ok(LoadDropComparison {
        viscous: run(MeshDamping::Viscous)?,
        contact_only: run(MeshDamping::ContactOnly)?,
    })
}

/// Run the load drop at `at_s` (load and motor torque to zero) until `end_s`, sampled at
/// `sample_hz`, for one backlash setting. The response is the output transmission error.
#[allow(clippy::too_many_arguments)]
pub fn load_drop_run(
    cfg: &ModelBConfig,
    stiffness: StiffnessForm,
    mesh_damping: MeshDamping,
    backlash: bool,
    at_s: f64,
    end_s: f64,
    sample_hz: f64,
    solver: &SolverSettings,
) -> Result<LoadDropRun> {
    if !(at_s > 0.0 && end_s > at_s && sample_hz > 0.0) {
        return Err(Error::param("load-drop times", at_s, "need 0 < at < end"));
    }
    let opts = ModelBOptions {
        stiffness,
        backlash,
        loads: LoadCase::LoadDrop { at_s },
        load_torque_nm: None,
        mesh_damping,
    };
    let p = Prepared::new(cfg, &opts)?;
    let wh = p.omega_h();
    let y0 = p.static_start()?;
    let (mut t, mut dte) = (Vec::new(), Vec::new());
    let sys = p.edge_aware(end_s * wh);
    let stats = integrate(
        &sys,
        &y0,
        solver,
        0.0,
        wh / sample_hz,
        end_s * wh,
        |_, tau, y| {
            t.push(tau / wh);
            dte.push(p.dte_arcmin(y));
        },
    )?;
    let measures = decay_measures(&t, &dte, at_s);
    Ok(LoadDropRun {
        backlash,
        measures,
        stats,
        t,
        dte,
    })
}

/// Both load-drop runs (with and without backlash, same mesh-damping model) and their ratios.
pub fn load_drop(
    cfg: &ModelBConfig,
    stiffness: StiffnessForm,
    mesh_damping: MeshDamping,
    at_s: f64,
    end_s: f64,
    sample_hz: f64,
    solver: &SolverSettings,
) -> Result<LoadDropReport> {
    let run = |backlash| {
        load_drop_run(
            cfg,
            stiffness,
            mesh_damping,
            backlash,
            at_s,
            end_s,
            sample_hz,
            solver,
        )
    };
    let with = run(true)?;
    let without = run(false)?;
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::INFINITY };
    Ok(LoadDropReport {
        mesh_damping,
        at_s,
        end_s,
        torque_nm: cfg.load_torque_nm,
        decay_time_ratio: ratio(with.measures.decay_time_s, without.measures.decay_time_s),
        oscillation_ratio: ratio(with.measures.oscillations, without.measures.oscillations),
        first_peak_ratio: ratio(
            with.measures.first_peak_arcmin,
            without.measures.first_peak_arcmin,
        ),
        larger_extrema_than_without: larger_extrema(&with, &without, at_s),
        with_return_difference: with,
        without_return_difference: without,
    })
}
