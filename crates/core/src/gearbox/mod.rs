//! The gearbox as an input: a description a user writes from tooth counts (physics optional),
//! validated, with its exact kinematics and the dynamic model built from it.
//!
//! - [`description`]: the file format (`gearwear-gearbox`, version 1, TOML or JSON).
//! - [`kinematics`]: the validated topology, every shaft rate and mesh frequency.
//! - [`build`]: physical values (given or defaulted and listed as assumed) and the generic
//!   [`Assembly`](crate::model::Assembly) for a wear degree, from its parts: `assumed` (the
//!   defaults and the log of the values assumed), `gears` (geometry and inertia),
//!   `coordinates` (the coordinates and the meshes' rows, stage by stage) and `meshes` (the
//!   meshes' values and stiffness).
//! - [`export`]: the resolved model with its description as a self-contained JSON document.
//!
//! [`Gearbox`] ties them together; [`Gearbox::paper_rig`] is the first paper's test rig
//! (`configs/gearboxes/wang2019.toml`), which resolves to the same model as the original
//! hand-written configuration (tested to 1e-12).

mod assumed;
pub mod build;
mod coordinates;
pub mod description;
pub mod export;
pub mod factors;
mod gears;
pub mod kinematics;
mod meshes;

use std::path::Path;

use serde::Serialize;
use sha2::{Digest, Sha256};

pub use crate::error::GearboxError;
pub use build::{AssumedValue, MeshValues, Physics};
pub use description::{BearingSpec, DefectOrders, GearboxDescription, TextFormat};
pub use factors::{PhysicsFactors, StageFactors};
pub use kinematics::{Fixed, Kinematics, Stage, Topology};

use crate::model::{Assembly, Wear};
use crate::signal::tsa::ShaftTrain;

/// The first paper's rig as a description (committed as `configs/gearboxes/wang2019.toml`).
pub const PAPER_RIG: &str = include_str!("../../../../configs/gearboxes/wang2019.toml");

/// A validated, resolved gearbox: description, topology, kinematics ratios and physics.
#[derive(Debug, Clone, Serialize)]
pub struct Gearbox {
    pub description: GearboxDescription,
    /// SHA-256 (hex) of the description's canonical JSON.
    pub hash: String,
    #[serde(skip)]
    pub topology: Topology,
    /// Mesh frequency over the reference (stage-1) mesh frequency, per stage.
    pub mesh_ratios: Vec<f64>,
    pub physics: Physics,
    /// Every value the description did not give, with the rule that gave it.
    pub assumed: Vec<AssumedValue>,
    /// Non-fatal remarks (e.g. planets that cannot be equally spaced).
    pub warnings: Vec<String>,
    /// The reference mesh frequency at an input rate of 1 Hz (the pinion's teeth when it sits
    /// on the input shaft): kept so that the per-record conversions need no kinematics.
    pub f1_per_input_hz: f64,
}

impl Gearbox {
    /// Validate and resolve a description.
    pub fn new(description: GearboxDescription) -> Result<Self, GearboxError> {
        let name_ok = !description.name.is_empty()
            && description.name.len() <= 64
            && description
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
        if !name_ok {
            return Err(GearboxError::Name {
                name: description.name.clone(),
            });
        }
        let topology = Topology::new(&description)?;
        let (physics, assumed) = build::physics(&description, &topology)?;
        let mesh_ratios = build::mesh_ratios(&topology);
        let hash = Sha256::digest(description.canonical_json().as_bytes())
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        let f1_per_input_hz = topology.kinematics(1.0).meshes[0].hz;
        let gb = Gearbox {
            warnings: topology.warnings.clone(),
            description,
            hash,
            topology,
            mesh_ratios,
            physics,
            assumed,
            f1_per_input_hz,
        };
        // The model must assemble and resolve (one rigid-body mode for the balancing load).
        gb.assembly(Wear::fixed_axis(0.5))
            .and_then(|a| a.resolve())
            .map_err(|e| GearboxError::Model(e.to_string()))?;
        Ok(gb)
    }

    /// Parse (TOML or JSON, see [`GearboxDescription::parse`]) and resolve.
    pub fn parse(text: &str, origin: &str) -> Result<Self, GearboxError> {
        Self::new(GearboxDescription::parse(text, None, origin)?)
    }

    /// Read a description file (`.json`: JSON, anything else: TOML unless it starts with `{`).
    pub fn from_file(path: &Path) -> crate::error::Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| crate::error::Error::Io {
            path: path.display().to_string(),
            source,
        })?;
        let fmt = match path.extension().and_then(|e| e.to_str()) {
            Some("json") => Some(TextFormat::Json),
            Some("toml") => Some(TextFormat::Toml),
            _ => None,
        };
        let d = GearboxDescription::parse(&text, fmt, &path.display().to_string())?;
        Ok(Self::new(d)?)
    }

    /// This gearbox with a machine's own physics ([`factors`]) in place of any it had: the
    /// same description with `physics_factors` set (so another hash, and its own table).
    pub fn with_factors(&self, f: &PhysicsFactors) -> Result<Self, GearboxError> {
        let mut d = self.description.clone();
        d.physics_factors = (!f.is_identity()).then(|| f.clone());
        Self::new(d)
    }

    /// The description's own physics factors (none: every factor 1).
    pub fn factors(&self) -> PhysicsFactors {
        self.description.physics_factors.clone().unwrap_or_default()
    }

    /// The first paper's test rig.
    pub fn paper_rig() -> Self {
        Self::parse(PAPER_RIG, "configs/gearboxes/wang2019.toml")
            .expect("the committed paper rig description resolves")
    }

    /// True when the dynamics rest on estimates ([`Physics::dynamics_estimated`]).
    pub fn dynamics_estimated(&self) -> bool {
        self.physics.dynamics_estimated
    }

    /// The name of the gearbox.
    pub fn name(&self) -> &str {
        &self.description.name
    }

    /// The reference length (µm): the unit of the wear degree `ea` — the description's
    /// `reference_length_um`, else 5 µm (the first paper's `b`), as the model is built with.
    pub fn reference_length_um(&self) -> f64 {
        self.description
            .reference_length_um
            .unwrap_or(assumed::REFERENCE_LENGTH_UM)
    }

    /// Exact kinematics at an input-shaft rate (Hz).
    pub fn kinematics(&self, input_hz: f64) -> Kinematics {
        self.topology.kinematics(input_hz)
    }

    /// The shafts and meshes for order analysis ([`crate::signal::tsa::order_analysis`]): the
    /// input shaft, the stage-1 mesh order on it, and every shaft and mesh rate per unit
    /// input-shaft rate.
    pub fn shaft_train(&self) -> ShaftTrain {
        let kin = self.kinematics(1.0);
        ShaftTrain {
            mesh_order: self.f1_hz(1.0),
            meshes: kin.meshes.iter().map(|m| m.hz).collect(),
            input_shaft: kin.input_shaft,
            shafts: kin.shafts,
        }
    }

    /// The reference (stage-1) mesh frequency (Hz) at an input-shaft rate (Hz).
    pub fn f1_hz(&self, input_hz: f64) -> f64 {
        self.f1_per_input_hz * input_hz
    }

    /// Input-shaft rates over the reference mesh frequency, per shaft (signed: +1 with the
    /// input). With these, a shaft's rate is `ratio × f1`.
    pub fn shaft_ratios(&self) -> std::collections::BTreeMap<String, f64> {
        self.topology.signed_rates(1.0 / self.f1_per_input_hz)
    }

    /// Input-shaft rate over the reference mesh frequency (`1 / z` for a pinion on the input).
    pub fn input_shaft_ratio(&self) -> f64 {
        1.0 / self.f1_per_input_hz
    }

    /// `ω_h / 2π` (Hz): the reference mesh frequency at Ω1 = 1.
    pub fn reference_frequency_hz(&self) -> f64 {
        self.physics.reference_frequency_hz
    }

    /// Stages (1-based) whose error is the wear degree.
    pub fn wear_stages(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self
            .physics
            .meshes
            .iter()
            .filter(|m| m.wears)
            .map(|m| m.stage)
            .collect();
        v.dedup();
        v
    }

    /// The baseline composite error of the first planetary stage's meshes in reference lengths
    /// (the first paper's `ea_sp = ea_rp = 0.1`), `None` without a planetary stage.
    pub fn planetary_baseline(&self) -> Option<f64> {
        self.physics
            .meshes
            .iter()
            .find(|m| m.planetary && !m.wears)
            .map(|m| m.baseline_error_m / self.physics.length_ref_m)
    }

    /// The lines a single run reports and the wear-lines figure draws, `(name, ratio to f1)`:
    /// `f1`, every other stage's `fk` (and `2fk` for a wear stage), `f1/2`, and `f1−fk` for a
    /// wear stage. For the first paper's rig: f1, f2, 2f2, f3, f1/2, f1−f2 (its Figure 17).
    pub fn report_lines(&self) -> Vec<(String, f64)> {
        let wear = self.wear_stages();
        let mut v = vec![("f1".to_string(), 1.0)];
        let others: Vec<(usize, f64)> = self
            .mesh_ratios
            .iter()
            .enumerate()
            .skip(1)
            .map(|(i, r)| (i + 1, *r))
            .collect();
        for &(k, r) in &others {
            v.push((format!("f{k}"), r));
            if wear.contains(&k) {
                v.push((format!("2f{k}"), 2.0 * r));
            }
        }
        v.push(("f1/2".into(), 0.5));
        for &(k, r) in &others {
            if wear.contains(&k) && r < 1.0 {
                v.push((format!("f1-f{k}"), 1.0 - r));
            }
        }
        v
    }

    /// The ratio to f1 of the first planetary stage's mesh frequency, if there is one that the
    /// wear does not act on (the first paper's f3).
    pub fn planetary_ratio(&self) -> Option<f64> {
        self.physics
            .meshes
            .iter()
            .find(|m| m.planetary && !m.wears)
            .map(|m| m.freq_ratio)
    }

    /// The generic assembly for a wear state.
    pub fn assembly(&self, wear: Wear) -> crate::error::Result<Assembly> {
        build::assembly(self.name(), &self.physics, wear.ea, wear.planetary)
    }
}

#[cfg(test)]
mod tests;
