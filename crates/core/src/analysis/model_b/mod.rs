//! Model B experiments: the time response (transverse accelerations, transmission error, output
//! speed), the return difference against backlash, and the load drop.
//!
//! Everything runs on the generic relative form of [`crate::model::rig_b`] and reports physical
//! quantities through [`Reconstructor`]: `ÿ_i` (m/s²), the mesh deflections `δ1, δ2` (µm along
//! the lines of action), the transmission error at the output `θ5 − θ0/R` (arcmin) and the
//! speeds `θ̇4, θ̇5` (rad/s).

mod load_drop;
mod response;
mod return_difference;
mod solve;

use crate::error::Result;
use crate::model::rig_b::{ARCMIN_PER_RAD, ELEMENTS};
use crate::model::{
    Assembly, DimensionlessModel, GearOde, ModelBConfig, ModelBOptions, Reconstructor, static_state,
};

pub use self::load_drop::{
    DecayMeasures, LoadDropComparison, LoadDropReport, LoadDropRun, decay_measures, load_drop,
    load_drop_comparison, load_drop_run,
};
pub use self::response::{
    Record, SeriesSummary, SimSpec, SimulateReport, shock_times, simulate, simulate_report,
};
pub use self::return_difference::{
    ReturnDifferenceTerms, ReversalResult, return_difference_formula, simulate_reversal,
};
pub use self::solve::{EdgeAware, SolverKind, SolverSettings, integrate};

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

/// Element names of Model B in state order (for labels).
pub fn element_names() -> [&'static str; 9] {
    ELEMENTS
}
