//! The return difference against backlash: the formula's terms and the simulated reversal.

use serde::Serialize;

use super::{Prepared, SolverSettings, integrate};
use crate::error::{Error, Result};
use crate::model::rig_b::ARCMIN_PER_RAD;
use crate::model::{LoadCase, ModelBConfig, ModelBOptions, StiffnessForm};
use crate::solver::Stats;

/// The return-difference formula's terms (arcmin at the output shaft), `docs/model-b.md`:
///
/// ```text
/// RD = 2 [ b1 / (rb2 i2) + b2 / rb4 ]                                   (backlash)
///    + 2 T_L [ 1/(k_s1 R²) + C_m1/(rb2² i2²) + 1/(k_s2 i2²) + C_m2/rb4² + 1/k_s3 ]  (wind-up)
/// C_mi = 1/k_ti + 1/k_y,a + 1/k_y,b,   i1 = rb2/rb1,  i2 = rb4/rb3,  R = i1 i2
/// ```
///
/// `b1, b2` are the half-clearances (m), `T_L` the output torque (N·m), `k_ti` the mean mesh
/// stiffness (N/m), `k_y` the bearing stiffness (N/m), `k_s` the shaft stiffness (N·m/rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReturnDifferenceTerms {
    pub backlash_stage1: f64,
    pub backlash_stage2: f64,
    pub windup_shaft1: f64,
    pub windup_mesh1: f64,
    pub windup_shaft2: f64,
    pub windup_mesh2: f64,
    pub windup_shaft3: f64,
    pub total: f64,
    pub torque_nm: f64,
    /// Stage ratios, for checks.
    pub i1: f64,
    pub i2: f64,
}

/// Evaluate the return-difference formula for a configuration at output torque `torque_nm`
/// (with or without the configured backlash).
pub fn return_difference_formula(
    cfg: &ModelBConfig,
    torque_nm: f64,
    backlash: bool,
) -> ReturnDifferenceTerms {
    let r = cfg.radii();
    let (i1, i2) = (r.i1(), r.i2());
    let ratio = i1 * i2;
    let um = if backlash { 1e-6 } else { 0.0 };
    let (b1, b2) = (
        cfg.mesh1.half_backlash_um * um,
        cfg.mesh2.half_backlash_um * um,
    );
    let ky = cfg.bearing.stiffness;
    let cm1 = 1.0 / cfg.mesh1.stiffness + 2.0 / ky;
    let cm2 = 1.0 / cfg.mesh2.stiffness + 2.0 / ky;
    let t = torque_nm.abs();
    let a = ARCMIN_PER_RAD;
    let backlash_stage1 = 2.0 * b1 / (r.rb2 * i2) * a;
    let backlash_stage2 = 2.0 * b2 / r.rb4 * a;
    let windup_shaft1 = 2.0 * t / (cfg.shaft1.stiffness * ratio * ratio) * a;
    let windup_mesh1 = 2.0 * t * cm1 / (r.rb2 * r.rb2 * i2 * i2) * a;
    let windup_shaft2 = 2.0 * t / (cfg.shaft2.stiffness * i2 * i2) * a;
    let windup_mesh2 = 2.0 * t * cm2 / (r.rb4 * r.rb4) * a;
    let windup_shaft3 = 2.0 * t / cfg.shaft3.stiffness * a;
    ReturnDifferenceTerms {
        backlash_stage1,
        backlash_stage2,
        windup_shaft1,
        windup_mesh1,
        windup_shaft2,
        windup_mesh2,
        windup_shaft3,
        total: backlash_stage1
            + backlash_stage2
            + windup_shaft1
            + windup_mesh1
            + windup_shaft2
            + windup_mesh2
            + windup_shaft3,
        torque_nm: t,
        i1,
        i2,
    }
}

/// A simulated reversal: forward-loaded, then both torques reversed.
#[derive(Debug, Clone, Serialize)]
pub struct ReversalResult {
    /// Output transmission error `θ5 − θ0/R` settled forward and reversed, arcmin.
    pub dte_forward_arcmin: f64,
    pub dte_reverse_arcmin: f64,
    /// The dead angle at the output: `|forward − reverse|`, arcmin.
    pub simulated_arcmin: f64,
    /// Largest deviation from the settled value over the averaging windows (arcmin): how well
    /// the response had settled.
    pub settle_spread_arcmin: f64,
    pub at_s: f64,
    pub end_s: f64,
    pub stats: Stats,
    /// Samples for a plot: t (s), DTE (arcmin).
    #[serde(skip)]
    pub t: Vec<f64>,
    #[serde(skip)]
    pub dte: Vec<f64>,
}

/// Drive forward at output torque `torque_nm` (from the static forward state), reverse both
/// torques at `at_s`, run to `end_s`, and measure the output dead angle from the settled
/// transmission errors (mean over the last 10 % before the reversal and before the end). The
/// mesh stiffness is the mean one, as in the formula.
pub fn simulate_reversal(
    cfg: &ModelBConfig,
    torque_nm: f64,
    backlash: bool,
    at_s: f64,
    end_s: f64,
    solver: &SolverSettings,
) -> Result<ReversalResult> {
    if !(at_s > 0.0 && end_s > at_s) {
        return Err(Error::param("reversal times", at_s, "need 0 < at < end"));
    }
    let opts = ModelBOptions {
        stiffness: StiffnessForm::Mean,
        backlash,
        loads: LoadCase::Reversal { at_s },
        load_torque_nm: Some(torque_nm),
        ..Default::default()
    };
    let p = Prepared::new(cfg, &opts)?;
    let wh = p.omega_h();
    let y0 = p.static_start()?;
    let sample_hz = 2000.0;
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
    let window = |a: f64, b: f64| -> (f64, f64) {
        let v: Vec<f64> = t
            .iter()
            .zip(&dte)
            .filter(|(tt, _)| **tt >= a && **tt < b)
            .map(|(_, d)| *d)
            .collect();
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let spread = v.iter().fold(0.0_f64, |m, d| m.max((d - mean).abs()));
        (mean, spread)
    };
    let (fwd, s1) = window(0.9 * at_s, at_s);
    let (rev, s2) = window(end_s - 0.1 * (end_s - at_s), end_s + 1.0);
    Ok(ReversalResult {
        dte_forward_arcmin: fwd,
        dte_reverse_arcmin: rev,
        simulated_arcmin: (fwd - rev).abs(),
        settle_spread_arcmin: s1.max(s2),
        at_s,
        end_s,
        stats,
        t,
        dte,
    })
}
