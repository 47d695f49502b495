//! A machine's own physics over its description's: multipliers of each stage's mesh values,
//! the static load and the clearance (`[physics_factors]` in a description).
//!
//! A description written from tooth counts gets its stiffness, damping, stiffness fluctuation
//! and transmission error from rules of thumb (`build`'s defaults). A real machine differs from
//! them; [`crate::diagnosis::machine_physics`] fits these factors to the machine's healthy
//! records by simulating the description, and the machine's own model is then the description
//! with the fitted factors — a description like any other, so its table is precomputed, cached
//! and checked by hash as any table is. A description without factors hashes as before.
//!
//! Per stage `s` (every mesh of the stage, both meshes of a planetary one):
//!
//! | factor | acts on | note |
//! | --- | --- | --- |
//! | `stiffness` | mean mesh stiffness `k_m` | on stage 1 it moves `ω_h = √(k_1 A_11)` by `√factor`, so Ω1 of a given input rate moves too |
//! | `damping` | damping ratio `ξ` | |
//! | `fluctuation` | first-harmonic `ε` (a square wave's `double_to_single − 1`) | `ε · factor` must stay below 1 |
//! | `error` | composite transmission-error amplitude | a wear mesh's `ea · b_ref · factor`: the wear degree stays the machine's, its healthy error is the description's times the factor |
//!
//! and for the whole gearbox `load` (the input torque) and `clearance` (every mesh's
//! half-clearance). A factor of 1 changes nothing, bit for bit.

use serde::{Deserialize, Serialize};

use crate::error::GearboxError;

/// Smallest and largest factor a description may give.
pub const FACTOR_RANGE: (f64, f64) = (0.02, 50.0);

fn one() -> f64 {
    1.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

/// Multipliers of one stage's mesh values (1: the description's own).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageFactors {
    /// Mean mesh stiffness.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub stiffness: f64,
    /// Mesh damping ratio.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub damping: f64,
    /// Stiffness fluctuation ε.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub fluctuation: f64,
    /// Composite transmission-error amplitude.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub error: f64,
}

impl Default for StageFactors {
    fn default() -> Self {
        StageFactors {
            stiffness: 1.0,
            damping: 1.0,
            fluctuation: 1.0,
            error: 1.0,
        }
    }
}

impl StageFactors {
    /// The four factors in a fixed order: stiffness, damping, fluctuation, error.
    pub fn as_array(&self) -> [f64; 4] {
        [self.stiffness, self.damping, self.fluctuation, self.error]
    }

    /// From [`StageFactors::as_array`]'s order.
    pub fn from_array(v: [f64; 4]) -> Self {
        StageFactors {
            stiffness: v[0],
            damping: v[1],
            fluctuation: v[2],
            error: v[3],
        }
    }
}

/// The names of [`StageFactors::as_array`]'s entries.
pub const STAGE_FACTOR_NAMES: [&str; 4] = ["stiffness", "damping", "fluctuation", "error"];

/// A machine's physics as factors over its description's (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsFactors {
    /// One entry per stage, in the description's stage order; missing stages keep their
    /// values.
    #[serde(default, rename = "stage", alias = "stages")]
    pub stages: Vec<StageFactors>,
    /// The static load (input torque).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub load: f64,
    /// Every mesh's half-clearance.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub clearance: f64,
}

impl Default for PhysicsFactors {
    fn default() -> Self {
        PhysicsFactors {
            stages: Vec::new(),
            load: 1.0,
            clearance: 1.0,
        }
    }
}

impl PhysicsFactors {
    /// The factors of stage `k` (1-based); 1 for a stage not listed.
    pub fn stage(&self, k: usize) -> StageFactors {
        self.stages
            .get(k.wrapping_sub(1))
            .copied()
            .unwrap_or_default()
    }

    /// True when every factor is 1.
    pub fn is_identity(&self) -> bool {
        self.load == 1.0
            && self.clearance == 1.0
            && self
                .stages
                .iter()
                .all(|s| s.as_array().iter().all(|v| *v == 1.0))
    }

    /// Check every factor lies in [`FACTOR_RANGE`] and the stage list is not longer than the
    /// gearbox's `stages`.
    pub fn check(&self, stages: usize) -> Result<(), GearboxError> {
        if self.stages.len() > stages {
            return Err(GearboxError::StageIndex {
                field: "physics_factors.stage",
                stage: self.stages.len(),
                stages,
            });
        }
        let mut named: Vec<(String, f64)> = vec![
            ("physics_factors.load".into(), self.load),
            ("physics_factors.clearance".into(), self.clearance),
        ];
        for (i, s) in self.stages.iter().enumerate() {
            for (name, v) in STAGE_FACTOR_NAMES.iter().zip(s.as_array()) {
                named.push((format!("physics_factors.stage[{}].{name}", i + 1), v));
            }
        }
        for (field, value) in named {
            if !(value.is_finite() && value >= FACTOR_RANGE.0 && value <= FACTOR_RANGE.1) {
                return Err(GearboxError::Value {
                    field,
                    value,
                    reason: "a physics factor must lie in [0.02, 50]",
                });
            }
        }
        Ok(())
    }
}
