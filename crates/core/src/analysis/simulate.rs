//! One run of a model at one operating point, sampled on an exact grid.
//!
//! Time is dimensionless (`τ = ω_h t`); the stage-1 mesh period is `T1 = 2π/Ω1`. After a
//! transient the response is sampled `samples_per_period` times per `T1` over `periods`
//! periods; the Poincaré section is every `samples_per_period`-th sample (phase 0 of the
//! stage-1 mesh).

use std::f64::consts::TAU;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::DimensionlessModel;
use crate::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Stats, advance_to, sample_uniform,
};

/// How long to wait before sampling: `max(tau, periods · T1)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transient {
    /// Minimum transient in dimensionless time.
    pub tau: f64,
    /// Minimum transient in stage-1 mesh periods.
    pub periods: f64,
}

impl Default for Transient {
    /// 400 τ (the slowest mode, Ω ≈ 0.28 with ≈ 7 % damping, decays by e⁻⁸ over it) and at least
    /// 20 mesh periods.
    fn default() -> Self {
        Transient {
            tau: 400.0,
            periods: 20.0,
        }
    }
}

impl Transient {
    /// Transient length in τ at `Ω1`.
    pub fn length(&self, omega1: f64) -> f64 {
        self.tau.max(self.periods * TAU / omega1)
    }
}

/// What to simulate at one operating point.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunSpec {
    pub omega1: f64,
    /// Retained stage-1 mesh periods.
    pub periods: usize,
    pub samples_per_period: usize,
    pub transient: Transient,
    /// Initial state `[x̄, x̄']` (empty: zero, the paper's choice).
    #[serde(default)]
    pub initial: Vec<f64>,
    pub solver: Dopri5Options,
    /// Also estimate the largest Lyapunov exponent over the retained periods (a twin
    /// trajectory, renormalised once per stage-1 mesh period; doubles the cost).
    #[serde(default)]
    pub lyapunov: bool,
}

impl RunSpec {
    /// The paper's sampling (80 periods, 256 samples each) at `Ω1`, zero initial state.
    pub fn paper(omega1: f64) -> Self {
        RunSpec {
            omega1,
            periods: 80,
            samples_per_period: 256,
            transient: Transient::default(),
            initial: Vec::new(),
            solver: Dopri5Options::default(),
            lyapunov: false,
        }
    }

    fn check(&self) -> Result<()> {
        if !(self.omega1.is_finite() && self.omega1 > 0.0) {
            return Err(Error::param("Ω1", self.omega1, "must be positive"));
        }
        if self.periods == 0 || self.samples_per_period < 2 {
            return Err(Error::param(
                "periods / samples per period",
                self.periods as f64,
                "need at least 1 period and 2 samples a period",
            ));
        }
        Ok(())
    }
}

/// A sampled response.
#[derive(Debug, Clone, Serialize)]
pub struct Trajectory {
    pub omega1: f64,
    pub samples_per_period: usize,
    /// State dimension (`2n`).
    pub dim: usize,
    /// Sample times τ.
    pub tau: Vec<f64>,
    /// Row-major samples, `dim` per time.
    pub states: Vec<f64>,
    pub stats: Stats,
    /// Largest Lyapunov exponent per stage-1 mesh period, when requested.
    pub lyapunov_per_period: Option<f64>,
}

impl Trajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.tau.len()
    }
    /// True if no sample was taken.
    pub fn is_empty(&self) -> bool {
        self.tau.is_empty()
    }
    /// Component `i` of the state over time.
    pub fn series(&self, i: usize) -> Vec<f64> {
        self.states
            .iter()
            .skip(i)
            .step_by(self.dim)
            .copied()
            .collect()
    }
    /// Poincaré points `(x̄_j, x̄'_j)` of element `j`, once per stage-1 mesh period.
    pub fn poincare(&self, j: usize) -> Vec<(f64, f64)> {
        let n = self.dim / 2;
        (0..self.len())
            .step_by(self.samples_per_period)
            .map(|k| {
                (
                    self.states[k * self.dim + j],
                    self.states[k * self.dim + n + j],
                )
            })
            .collect()
    }
    /// Sample rate in samples per stage-1 mesh period (so frequency is in units of f1).
    pub fn sample_rate_per_f1(&self) -> f64 {
        self.samples_per_period as f64
    }
}

/// Simulate a model: transient, then sampled periods.
pub fn run(model: &DimensionlessModel, spec: &RunSpec) -> Result<Trajectory> {
    spec.check()?;
    let sys = model.system(spec.omega1)?;
    run_inner(&sys, Some(model), spec)
}

/// Simulate any system whose time unit makes the stage-1 mesh period `2π/Ω1`.
pub fn run_system<S: OdeSystem>(sys: &S, spec: &RunSpec) -> Result<Trajectory> {
    run_inner(sys, None, spec)
}

fn run_inner<S: OdeSystem>(
    sys: &S,
    model: Option<&DimensionlessModel>,
    spec: &RunSpec,
) -> Result<Trajectory> {
    let dim = sys.dim();
    let n_samples = spec.periods * spec.samples_per_period;
    let mut tau = Vec::with_capacity(n_samples);
    let mut states = Vec::with_capacity(n_samples * dim);
    let obs = observe(sys, model, spec, |_, t, y| {
        tau.push(t);
        states.extend_from_slice(y);
    })?;
    Ok(Trajectory {
        omega1: spec.omega1,
        samples_per_period: spec.samples_per_period,
        dim,
        tau,
        states,
        stats: obs.stats,
        lyapunov_per_period: obs.lyapunov_per_period,
    })
}

/// What [`observe`] reports besides the samples.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Observed {
    pub stats: Stats,
    /// Largest Lyapunov exponent per stage-1 mesh period (`λ T1`), when requested.
    pub lyapunov_per_period: Option<f64>,
}

/// Initial separation of the twin trajectory (dimensionless state norm, the attractors are
/// O(1)). It must stay well above the integration error per period (≈ rtol ≈ 1e-6), or the
/// twin measures the solver's noise instead of the dynamics; 1e-3 keeps a factor 1000 and is
/// still small enough for the linearised growth on these attractors.
const TWIN_SEPARATION: f64 = 1e-3;

/// Integrate a run and hand every retained sample `(k, τ_k, y(τ_k))` to `on_sample` without
/// storing the trajectory (what a sweep needs). `model`, when given, makes the initial state
/// kinematically consistent ([`DimensionlessModel::project_consistent`]).
///
/// With `spec.lyapunov`, a twin trajectory starts `10⁻³` away at the end of the transient and
/// is pulled back to that distance once per stage-1 mesh period (Benettin's method); the mean
/// log growth per period is `λ T1`: > 0 for chaos, < 0 for a motion locked to the forcing
/// (periodic, or quasi-periodic through the incommensurate mesh frequencies), ≈ 0 on a torus
/// born of a Hopf bifurcation.
pub fn observe<S: OdeSystem>(
    sys: &S,
    model: Option<&DimensionlessModel>,
    spec: &RunSpec,
    mut on_sample: impl FnMut(usize, f64, &[f64]),
) -> Result<Observed> {
    spec.check()?;
    let dim = sys.dim();
    let mut y0 = if spec.initial.is_empty() {
        vec![0.0; dim]
    } else if spec.initial.len() == dim {
        spec.initial.clone()
    } else {
        return Err(Error::InvalidConfig(format!(
            "initial state has {} components, the model needs {dim}",
            spec.initial.len()
        )));
    };
    if let Some(m) = model {
        m.project_consistent(spec.omega1, 0.0, &mut y0);
    }
    let period = TAU / spec.omega1;
    let t0 = spec.transient.length(spec.omega1);
    let spp = spec.samples_per_period;
    let dt = period / spp as f64;
    let n_samples = spec.periods * spp;
    let t_end = t0 + (n_samples - 1) as f64 * dt;
    let mut integ = Dopri5::new(sys, 0.0, &y0, spec.solver)?;
    advance_to(&mut integ, t0)?;
    let mut finite = true;
    let mut twin = if spec.lyapunov {
        Some(Twin::start(sys, t0, integ.y(), spec.solver)?)
    } else {
        None
    };
    let mut twin_err: Option<Error> = None;
    sample_uniform(&mut integ, t0, dt, t_end, |k, t, y| {
        finite &= y.iter().all(|v| v.is_finite());
        if k > 0
            && k % spp == 0
            && twin_err.is_none()
            && let Some(tw) = twin.as_mut()
            && let Err(e) = tw.renormalise(t, y)
        {
            twin_err = Some(e);
        }
        on_sample(k, t, y);
    })?;
    if let Some(e) = twin_err {
        return Err(e);
    }
    if !finite {
        return Err(Error::NonFinite { t: integ.t() });
    }
    Ok(Observed {
        stats: integ.stats(),
        lyapunov_per_period: twin.and_then(|tw| tw.exponent_per_renormalisation()),
    })
}

/// The twin trajectory of Benettin's method.
struct Twin<'a, S: OdeSystem> {
    sys: &'a S,
    opts: Dopri5Options,
    integ: Dopri5<'a, S>,
    log_growth: f64,
    count: usize,
}

impl<'a, S: OdeSystem> Twin<'a, S> {
    /// Start `TWIN_SEPARATION` away from `y` (along the diagonal direction).
    fn start(sys: &'a S, t: f64, y: &[f64], opts: Dopri5Options) -> Result<Self> {
        let step = TWIN_SEPARATION / (y.len() as f64).sqrt();
        let y2: Vec<f64> = y.iter().map(|v| v + step).collect();
        Ok(Twin {
            sys,
            opts,
            integ: Dopri5::new(sys, t, &y2, opts)?,
            log_growth: 0.0,
            count: 0,
        })
    }

    /// Advance to `t`, record the growth of the separation from `y` and pull the twin back to
    /// `TWIN_SEPARATION` along the same direction.
    fn renormalise(&mut self, t: f64, y: &[f64]) -> Result<()> {
        advance_to(&mut self.integ, t)?;
        let mut z = self.integ.y().to_vec();
        let d = z
            .iter()
            .zip(y)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        if d > 0.0 && d.is_finite() {
            self.log_growth += (d / TWIN_SEPARATION).ln();
            self.count += 1;
            for (zi, yi) in z.iter_mut().zip(y) {
                *zi = yi + (*zi - yi) * TWIN_SEPARATION / d;
            }
        }
        // Restart from the pulled-back state, keeping the step size the controller had reached.
        let opts = Dopri5Options {
            h_init: self.integ.proposed_step(),
            ..self.opts
        };
        self.integ = Dopri5::new(self.sys, t, &z, opts)?;
        Ok(())
    }

    /// Mean log growth per renormalisation interval.
    fn exponent_per_renormalisation(&self) -> Option<f64> {
        (self.count > 0).then(|| self.log_growth / self.count as f64)
    }
}
