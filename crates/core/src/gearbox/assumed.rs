//! The values a description may leave out: their defaults, the checks of the values it gives,
//! and the log of every value assumed (each listed in the resolved gearbox).

use serde::Serialize;

use super::description::GearboxDescription;
use crate::error::GearboxError;

/// Steel (kg/m³).
pub const STEEL_DENSITY: f64 = 7850.0;
/// Default pressure angle (degrees).
pub const PRESSURE_ANGLE_DEG: f64 = 20.0;
/// Module assumed when a gear gives neither module nor base radius (mm).
pub const DEFAULT_MODULE_MM: f64 = 2.0;
/// Face width over module when no width is given.
pub const WIDTH_OVER_MODULE: f64 = 10.0;
/// Mean mesh stiffness per face width, N/(mm·µm) (ISO 6336-1 c_γα for steel spur gears).
pub const STIFFNESS_PER_WIDTH: f64 = 20.0;
/// Default first-harmonic stiffness fluctuation.
pub const FLUCTUATION: f64 = 0.2;
/// Default mesh damping ratio (the first paper's).
pub const DAMPING_RATIO: f64 = 0.07;
/// Default half-clearance over module.
pub const CLEARANCE_OVER_MODULE: f64 = 0.05;
/// Default non-wear composite error, in reference lengths (the first paper's planetary value).
pub const BASELINE_ERROR: f64 = 0.1;
/// Default dimensionless static load (calibrated on the first paper's rig).
pub const STATIC_LOAD: f64 = 0.15;
/// Default reference length (µm).
pub const REFERENCE_LENGTH_UM: f64 = 5.0;
/// Default torsional damping ratio of a flexible shaft.
pub const SHAFT_DAMPING_RATIO: f64 = 0.02;

/// A value the description did not give, with what was used and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AssumedValue {
    /// Where it belongs, e.g. `stage 1 pinion inertia`.
    pub what: String,
    pub value: f64,
    pub unit: &'static str,
    /// The rule that gave it.
    pub basis: &'static str,
}

/// The description being built and the values assumed so far, in the order they were assumed.
pub(super) struct Ctx<'a> {
    pub(super) d: &'a GearboxDescription,
    pub(super) assumed: Vec<AssumedValue>,
    /// Set when a value the dynamics rest on was assumed.
    pub(super) dynamic: bool,
}

impl<'a> Ctx<'a> {
    pub(super) fn new(d: &'a GearboxDescription) -> Self {
        Ctx {
            d,
            assumed: Vec::new(),
            dynamic: false,
        }
    }

    pub(super) fn assume(
        &mut self,
        what: String,
        value: f64,
        unit: &'static str,
        basis: &'static str,
    ) -> f64 {
        self.assumed.push(AssumedValue {
            what,
            value,
            unit,
            basis,
        });
        value
    }

    /// [`Ctx::assume`] for a value the dynamics rest on (an inertia, a module, a stiffness).
    pub(super) fn assume_dynamic(
        &mut self,
        what: String,
        value: f64,
        unit: &'static str,
        basis: &'static str,
    ) -> f64 {
        self.dynamic = true;
        self.assume(what, value, unit, basis)
    }

    pub(super) fn density(&self) -> f64 {
        self.d.density_kg_m3.unwrap_or(STEEL_DENSITY)
    }
}

pub(super) fn positive(field: String, v: Option<f64>) -> Result<Option<f64>, GearboxError> {
    match v {
        Some(x) if !(x.is_finite() && x > 0.0) => Err(GearboxError::Value {
            field,
            value: x,
            reason: "must be a positive finite number",
        }),
        other => Ok(other),
    }
}

pub(super) fn non_negative(field: String, v: Option<f64>) -> Result<Option<f64>, GearboxError> {
    match v {
        Some(x) if !(x.is_finite() && x >= 0.0) => Err(GearboxError::Value {
            field,
            value: x,
            reason: "must be a finite number ≥ 0",
        }),
        other => Ok(other),
    }
}
