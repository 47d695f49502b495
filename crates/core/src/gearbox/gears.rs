//! A gear's geometry and inertia from what its description gives: module or base radius (or
//! its mate's), face width, inertia and mass, each defaulted and logged when absent.

use std::f64::consts::PI;

use serde::Serialize;

use super::assumed::{Ctx, DEFAULT_MODULE_MM, PRESSURE_ANGLE_DEG, WIDTH_OVER_MODULE, positive};
use super::description::{GearSpec, GearboxDescription, StageSpec};
use super::kinematics::Fixed;
use crate::error::GearboxError;

/// A gear's resolved geometry and inertia (SI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GearValues {
    pub teeth: u32,
    pub base_radius_m: f64,
    pub module_m: f64,
    pub face_width_m: f64,
    pub inertia: f64,
    pub mass_kg: f64,
}

/// Geometry a gear shares with its mate when it gives none of its own.
#[derive(Clone, Copy)]
pub(super) struct MateHint {
    pub(super) module_mm: Option<f64>,
    pub(super) face_width_mm: Option<f64>,
}

pub(super) fn hint(g: &GearSpec) -> MateHint {
    MateHint {
        module_mm: g.module_mm.or_else(|| {
            let alpha = g
                .pressure_angle_deg
                .unwrap_or(PRESSURE_ANGLE_DEG)
                .to_radians();
            g.base_radius_mm
                .map(|rb| 2.0 * rb / (g.teeth as f64 * alpha.cos()))
        }),
        face_width_mm: g.face_width_mm,
    }
}

/// Resolve one gear. `ring`: an internal gear (inertia of an annulus).
#[allow(clippy::too_many_arguments)]
pub(super) fn gear_values(
    cx: &mut Ctx,
    label: &str,
    teeth: u32,
    base_radius_mm: Option<f64>,
    module_mm: Option<f64>,
    pressure_angle_deg: Option<f64>,
    face_width_mm: Option<f64>,
    inertia: Option<f64>,
    mass_kg: Option<f64>,
    mate: MateHint,
    ring: bool,
) -> Result<GearValues, GearboxError> {
    let base_radius_mm = positive(format!("{label} base_radius_mm"), base_radius_mm)?;
    let module_mm = positive(format!("{label} module_mm"), module_mm)?;
    let face_width_mm = positive(format!("{label} face_width_mm"), face_width_mm)?;
    let inertia = positive(format!("{label} inertia"), inertia)?;
    let mass_kg = positive(format!("{label} mass_kg"), mass_kg)?;
    let pa = match pressure_angle_deg {
        Some(a) if !(a.is_finite() && a > 0.0 && a < 45.0) => {
            return Err(GearboxError::Value {
                field: format!("{label} pressure_angle_deg"),
                value: a,
                reason: "must lie between 0 and 45 degrees",
            });
        }
        Some(a) => a,
        None => PRESSURE_ANGLE_DEG,
    };
    let cos_a = pa.to_radians().cos();
    let z = teeth as f64;
    let module = match (module_mm, base_radius_mm) {
        (Some(m), _) => m,
        (None, Some(rb)) => 2.0 * rb / (z * cos_a),
        (None, None) => match mate.module_mm {
            Some(m) => m,
            None => cx.assume_dynamic(
                format!("{label} module"),
                DEFAULT_MODULE_MM,
                "mm",
                "no module or base radius given: a general-purpose value",
            ),
        },
    };
    let base_radius_mm = match base_radius_mm {
        Some(rb) => rb,
        None => {
            if pressure_angle_deg.is_none() {
                cx.assume(
                    format!("{label} pressure angle"),
                    PRESSURE_ANGLE_DEG,
                    "°",
                    "standard pressure angle (base radius = m z cos α / 2)",
                );
            }
            if module_mm.is_none() && mate.module_mm.is_some() {
                cx.assume_dynamic(
                    format!("{label} module"),
                    module,
                    "mm",
                    "the mating gear's module",
                );
            }
            module * z * cos_a / 2.0
        }
    };
    let width = match face_width_mm.or(mate.face_width_mm) {
        Some(b) => b,
        // Listed as assumed only where it is used: an inertia or mass from the geometry (the
        // stiffness estimate states the width it used).
        None if inertia.is_none() || (mass_kg.is_none() && label.contains("planet")) => cx.assume(
            format!("{label} face width"),
            WIDTH_OVER_MODULE * module,
            "mm",
            "10 × module",
        ),
        None => WIDTH_OVER_MODULE * module,
    };
    let (r, b) = (module * z / 2.0 * 1e-3, width * 1e-3);
    let rho = cx.density();
    let inertia = match inertia {
        Some(j) => j,
        None if ring => {
            let ro = r + 3.0 * module * 1e-3;
            cx.assume_dynamic(
                format!("{label} inertia"),
                0.5 * rho * PI * (ro.powi(4) - r.powi(4)) * b,
                "kg·m²",
                "steel annulus from the pitch radius to 3 modules beyond, face width thick",
            )
        }
        None => cx.assume_dynamic(
            format!("{label} inertia"),
            0.5 * rho * PI * r.powi(4) * b,
            "kg·m²",
            "solid steel disc of the pitch radius and face width, J = ½ ρ π r⁴ b",
        ),
    };
    let mass = mass_kg.unwrap_or(rho * PI * r * r * b);
    Ok(GearValues {
        teeth,
        base_radius_m: base_radius_mm * 1e-3,
        module_m: module * 1e-3,
        face_width_m: width * 1e-3,
        inertia,
        mass_kg: mass,
    })
}

/// Module (m) per stage for the clearance default: the first gear's given or derived module.
pub(super) fn mesh_modules(d: &GearboxDescription) -> Vec<f64> {
    d.stages
        .iter()
        .map(|s| {
            let g = s
                .pinion
                .as_ref()
                .or(s.sun.as_ref())
                .cloned()
                .unwrap_or_default();
            let other = s.gear.as_ref().map(hint);
            let m = hint(&g)
                .module_mm
                .or(other.and_then(|h| h.module_mm))
                .or_else(|| {
                    s.planets.as_ref().and_then(|p| {
                        p.module_mm.or_else(|| {
                            let a = p
                                .pressure_angle_deg
                                .unwrap_or(PRESSURE_ANGLE_DEG)
                                .to_radians();
                            p.base_radius_mm
                                .map(|rb| 2.0 * rb / (p.teeth as f64 * a.cos()))
                        })
                    })
                });
            m.unwrap_or(DEFAULT_MODULE_MM) * 1e-3
        })
        .collect()
}

/// The two gears of parallel stage `k`: (pinion, gear), each its mate's hint.
pub(super) fn parallel_pair(
    cx: &mut Ctx,
    k: usize,
    spec: &StageSpec,
    pinion_teeth: u32,
    gear_teeth: u32,
) -> Result<(GearValues, GearValues), GearboxError> {
    let (ps, gs) = (spec.pinion.as_ref().unwrap(), spec.gear.as_ref().unwrap());
    let p = gear_values(
        cx,
        &format!("stage {k} pinion"),
        pinion_teeth,
        ps.base_radius_mm,
        ps.module_mm,
        ps.pressure_angle_deg,
        ps.face_width_mm,
        ps.inertia,
        ps.mass_kg,
        hint(gs),
        false,
    )?;
    let g = gear_values(
        cx,
        &format!("stage {k} gear"),
        gear_teeth,
        gs.base_radius_mm,
        gs.module_mm,
        gs.pressure_angle_deg,
        gs.face_width_mm,
        gs.inertia,
        gs.mass_kg,
        hint(ps),
        false,
    )?;
    Ok((p, g))
}

/// The resolved members of a planetary stage (SI).
#[derive(Clone, Copy)]
pub(super) struct PlanetaryGears {
    pub(super) sun: GearValues,
    pub(super) planet: GearValues,
    pub(super) ring: GearValues,
    /// Planet-centre radius projected on the line of action (m).
    pub(super) carrier_radius_m: f64,
}

/// The sun, planets, ring and carrier radius of planetary stage `k`, one module for the stage.
pub(super) fn planetary_gears(
    cx: &mut Ctx,
    k: usize,
    spec: &StageSpec,
    (sun_teeth, planet_teeth, ring_teeth): (u32, u32, u32),
    fixed: Fixed,
) -> Result<PlanetaryGears, GearboxError> {
    let (ss, pl, rs_spec) = (
        spec.sun.as_ref().unwrap(),
        spec.planets.as_ref().unwrap(),
        spec.ring.as_ref().unwrap(),
    );
    let planet_spec = GearSpec {
        shaft: None,
        teeth: pl.teeth,
        base_radius_mm: pl.base_radius_mm,
        module_mm: pl.module_mm,
        pressure_angle_deg: pl.pressure_angle_deg,
        face_width_mm: pl.face_width_mm,
        inertia: pl.inertia,
        mass_kg: pl.mass_kg,
    };
    // One module for the stage: the first that any member gives or implies.
    let stage_hint = MateHint {
        module_mm: hint(ss)
            .module_mm
            .or(hint(&planet_spec).module_mm)
            .or(hint(rs_spec).module_mm),
        face_width_mm: ss
            .face_width_mm
            .or(planet_spec.face_width_mm)
            .or(rs_spec.face_width_mm),
    };
    let sun_hint = stage_hint;
    let sun = gear_values(
        cx,
        &format!("stage {k} sun"),
        sun_teeth,
        ss.base_radius_mm,
        ss.module_mm,
        ss.pressure_angle_deg,
        ss.face_width_mm,
        ss.inertia,
        ss.mass_kg,
        stage_hint,
        false,
    )?;
    let planet = gear_values(
        cx,
        &format!("stage {k} planet"),
        planet_teeth,
        pl.base_radius_mm,
        pl.module_mm,
        pl.pressure_angle_deg,
        pl.face_width_mm,
        pl.inertia,
        pl.mass_kg,
        sun_hint,
        false,
    )?;
    if pl.mass_kg.is_none() {
        cx.assume_dynamic(
            format!("stage {k} planet mass"),
            planet.mass_kg,
            "kg",
            "solid steel disc of the pitch radius and face width, m = ρ π r² b",
        );
    }
    let ring = gear_values(
        cx,
        &format!("stage {k} ring"),
        ring_teeth,
        rs_spec.base_radius_mm,
        rs_spec.module_mm,
        rs_spec.pressure_angle_deg,
        rs_spec.face_width_mm,
        // A fixed ring is no coordinate: its inertia is never used, so a
        // placeholder keeps it off the list of assumed values.
        rs_spec.inertia.or(if fixed == Fixed::Ring {
            Some(1.0)
        } else {
            None
        }),
        rs_spec.mass_kg,
        stage_hint,
        true,
    )?;
    let carrier = spec.carrier.clone().unwrap_or_default();
    let rc = match positive(format!("stage {k} carrier radius_mm"), carrier.radius_mm)? {
        Some(r) => r * 1e-3,
        None => {
            cx.assume(
                format!("stage {k} carrier radius"),
                (sun.base_radius_m + planet.base_radius_m) * 1e3,
                "mm",
                "sun + planet base radii (planet centre projected on the line of action)",
            ) * 1e-3
        }
    };
    Ok(PlanetaryGears {
        sun,
        planet,
        ring,
        carrier_radius_m: rc,
    })
}
