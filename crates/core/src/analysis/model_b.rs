//! Model B experiments: the time response (transverse accelerations, transmission error, output
//! speed), the return difference against backlash, and the load drop.
//!
//! Everything runs on the generic relative form of [`crate::model::rig_b`] and reports physical
//! quantities through [`Reconstructor`]: `ÿ_i` (m/s²), the mesh deflections `δ1, δ2` (µm along
//! the lines of action), the transmission error at the output `θ5 − θ0/R` (arcmin) and the
//! speeds `θ̇4, θ̇5` (rad/s).

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::rig_b::{ARCMIN_PER_RAD, ELEMENTS, MeshDamping};
use crate::model::{
    Assembly, DimensionlessModel, GearOde, LoadCase, ModelBConfig, ModelBOptions, Reconstructor,
    StiffnessForm, StiffnessShape, static_state,
};
use crate::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Rodas4, Rodas4Options, Stats, sample_uniform,
};

/// Which integrator to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SolverKind {
    /// Explicit Dormand–Prince 5(4).
    Dopri5,
    /// Linearly implicit Rosenbrock RODAS4 (stiff).
    Rodas4,
}

/// Integrator and tolerances (on the dimensionless state: deflections in units of `b_ref`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SolverSettings {
    pub kind: SolverKind,
    pub rtol: f64,
    pub atol: f64,
}

impl Default for SolverSettings {
    /// RODAS4 at `rtol = 1e-6`, `atol = 1e-8`.
    fn default() -> Self {
        SolverSettings {
            kind: SolverKind::Rodas4,
            rtol: 1e-6,
            atol: 1e-8,
        }
    }
}

/// Integrate `sys` from `(0, y0)` and hand the samples on the grid `t0 + k dt ≤ t_end` (all in
/// τ) to `on_sample`. Returns the counters.
pub fn integrate<S: OdeSystem>(
    sys: &S,
    y0: &[f64],
    solver: &SolverSettings,
    t0: f64,
    dt: f64,
    t_end: f64,
    on_sample: impl FnMut(usize, f64, &[f64]),
) -> Result<Stats> {
    match solver.kind {
        SolverKind::Dopri5 => {
            let opts = Dopri5Options {
                rtol: solver.rtol,
                atol: solver.atol,
                ..Default::default()
            };
            let mut integ = Dopri5::new(sys, 0.0, y0, opts)?;
            sample_uniform(&mut integ, t0, dt, t_end, on_sample)?;
            Ok(integ.stats())
        }
        SolverKind::Rodas4 => {
            let opts = Rodas4Options {
                rtol: solver.rtol,
                atol: solver.atol,
                ..Default::default()
            };
            let mut integ = Rodas4::new(sys, 0.0, y0, opts)?;
            sample_uniform(&mut integ, t0, dt, t_end, on_sample)?;
            Ok(integ.stats())
        }
    }
}

/// A right-hand side with the square-wave stiffness edges added as breakpoints.
///
/// A contact-ratio edge lasts `smoothing` of a mesh period (33 µs at stage 1), i.e. a few
/// dimensionless time units, while a stiff solver on the quasi-static stretches between edges
/// takes steps of 10⁴ and more: without help it steps straight over an edge and never sees the
/// shock. The integrators land exactly on each breakpoint, so placing them at `e − 3w`, `e`,
/// `e + 3w` for every edge `e` (width `w`) forces steps no longer than `3w` across the edge;
/// the error control then resolves the ringing that follows. The explicit solver's steps are
/// shorter than an edge anyway; it gets the same breakpoints for a like-for-like comparison.
pub struct EdgeAware<'a, S: OdeSystem> {
    inner: &'a S,
    breaks: Vec<f64>,
}

impl<'a, S: OdeSystem> EdgeAware<'a, S> {
    /// Breakpoints of `inner` plus the square-wave edges of `model` at `Ω1` inside `(0, t_end)`.
    pub fn new(inner: &'a S, model: &DimensionlessModel, omega1: f64, t_end: f64) -> Self {
        use std::f64::consts::TAU;
        let mut breaks = inner.breakpoints();
        for j in 0..model.n() {
            let StiffnessShape::SquareWave {
                contact_ratio,
                smoothing,
                ..
            } = model.shape[j]
            else {
                continue;
            };
            let w = model.omega_ratio[j] * omega1;
            if w <= 0.0 {
                continue;
            }
            let period = TAU / w;
            let width = smoothing * period;
            let shift = model.phase[j] / w;
            let k_max = (t_end / period).ceil() as i64 + 1;
            for k in -1..=k_max {
                for u in [0.0, contact_ratio - 1.0] {
                    let e = (k as f64 + u) * period - shift;
                    for t in [e - 3.0 * width, e, e + 3.0 * width] {
                        if t > 0.0 && t < t_end {
                            breaks.push(t);
                        }
                    }
                }
            }
        }
        breaks.sort_by(f64::total_cmp);
        breaks.dedup();
        EdgeAware { inner, breaks }
    }
}

impl<S: OdeSystem> OdeSystem for EdgeAware<'_, S> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        self.inner.rhs(t, y, dy)
    }
    fn n_switches(&self) -> usize {
        self.inner.n_switches()
    }
    fn switches(&self, t: f64, y: &[f64], g: &mut [f64]) {
        self.inner.switches(t, y, g)
    }
    fn breakpoints(&self) -> Vec<f64> {
        self.breaks.clone()
    }
}

/// A configured Model B ready to integrate.
pub struct Prepared {
    pub cfg: ModelBConfig,
    pub opts: ModelBOptions,
    pub asm: Assembly,
    pub model: DimensionlessModel,
    pub sys: GearOde,
    pub recon: Reconstructor,
    /// Stage-1 mesh frequency over `ω_h`.
    pub omega1: f64,
    /// Row mapping `d` (m) to the output transmission error `θ5 − θ0/R` (rad).
    dte_row: Vec<f64>,
}

impl Prepared {
    /// Assemble, resolve and set up the reconstruction.
    pub fn new(cfg: &ModelBConfig, opts: &ModelBOptions) -> Result<Self> {
        let asm = cfg.assembly(opts)?;
        let model = asm.resolve()?;
        let omega1 = cfg.omega1(&model);
        let sys = model.system(omega1)?;
        let recon = Reconstructor::new(&asm, &model, omega1, &cfg.rigid_velocity())?;
        let ratio = cfg.radii().ratio();
        let mut c = vec![0.0; model.dof_names.len()];
        c[recon.dof("theta5")?] = 1.0;
        c[recon.dof("theta0")?] = -1.0 / ratio;
        let dte_row = recon.elastic_row(&c)?;
        Ok(Prepared {
            cfg: cfg.clone(),
            opts: *opts,
            asm,
            model,
            sys,
            recon,
            omega1,
            dte_row,
        })
    }

    /// `ω_h` (rad/s): τ = ω_h t.
    pub fn omega_h(&self) -> f64 {
        self.model.omega_h
    }

    /// The right-hand side with the stiffness edges up to `t_end` (τ) as breakpoints.
    pub fn edge_aware(&self, t_end: f64) -> EdgeAware<'_, GearOde> {
        EdgeAware::new(&self.sys, &self.model, self.omega1, t_end)
    }

    /// Static operating point at t = 0 (state `[x̄, 0]`).
    pub fn static_start(&self) -> Result<Vec<f64>> {
        static_state(&self.model, &self.sys, 0.0)
    }

    /// Transmission error at the output `θ5 − θ0/R` (arcmin) of a state.
    pub fn dte_arcmin(&self, y: &[f64]) -> f64 {
        let b = self.model.length_ref;
        self.dte_row
            .iter()
            .zip(y)
            .map(|(r, x)| r * x * b)
            .sum::<f64>()
            * ARCMIN_PER_RAD
    }

    /// Undamped natural frequencies of the linearised model (all meshes in contact, mean
    /// stiffness), Hz.
    pub fn natural_frequencies_hz(&self) -> Vec<f64> {
        self.model
            .natural_frequencies()
            .iter()
            .map(|w| w * self.model.omega_h / std::f64::consts::TAU)
            .collect()
    }
}

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

// ---------------------------------------------------------------------------------------------
// Return difference
// ---------------------------------------------------------------------------------------------

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

// ---------------------------------------------------------------------------------------------
// Load drop
// ---------------------------------------------------------------------------------------------

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

/// Element names of Model B in state order (for labels).
pub fn element_names() -> [&'static str; 9] {
    ELEMENTS
}
