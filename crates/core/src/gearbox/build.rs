//! From a description to the generic assembly: physical values (given or defaulted), the
//! coordinates, the meshes, the shafts and the static load.
//!
//! # Coordinates and meshes
//! One rotation per rigid shaft (inertia: every gear on it plus the shaft's own `inertia`);
//! a shaft with a torsional stiffness gives each gear on it its own rotation, joined in stage
//! order by shaft elements. Each planet is a rotation; the carrier's rotation carries
//! `J_c + N m_p r_c²`. Meshes, with base radii `r` (m), coordinates in each member's own sense:
//!
//! | mesh | deflection |
//! | --- | --- |
//! | parallel, stage k | `x_k = r_a θ_a − r_b θ_b − e(t)` (a: the member nearer the input) |
//! | sun–planet n | `x_spn = r_s θ_s − r_p θ_pn − r_c θ_c − e(t)` |
//! | ring–planet n | `x_rpn = r_p θ_pn + r_r θ_r − r_c θ_c − e(t)` |
//!
//! (the fixed member's term is absent). With the ring fixed this is the first paper's form; the
//! ring term makes the rigid-body motion satisfy Willis' equation for the other two cases
//! (tested). The first mesh of stage 1 is the reference element (`Ω1`, `ω_h`, `F̄1`).
//!
//! # Defaults (each listed as assumed in the resolved gearbox)
//! - pressure angle 20°; module 2 mm when neither it nor a base radius is given; base radius
//!   `m z cos α / 2`; face width 10 × module (or the mating gear's);
//! - inertia of a solid disc of the pitch radius and face width, `J = ½ ρ π r⁴ b`, ρ = 7850
//!   kg/m³ (a rotating ring: the annulus from its pitch radius to 3 modules beyond); planet
//!   mass `ρ π r² b`; carrier radius `r_bs + r_bp`; carrier inertia a disc of the planet-centre
//!   radius and the planets' face width;
//! - mesh stiffness 20 N/(mm·µm) × face width (ISO 6336-1's c_γα); fluctuation ε = 0.2;
//!   damping ratio 0.07; half-clearance 0.05 × module; non-wear composite error 0.1 × the
//!   reference length; phase 0; shaft damping ratio 0.02;
//! - static load `F̄1 = 0.15` (the paper rig's calibrated value), reference length 5 µm.
//!
//! With `reference_frequency_hz` the reference mesh's stiffness is `ω_h² / A_00` instead, and
//! every other mesh whose stiffness is not given absolutely keeps its ratio to it.

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};

use serde::Serialize;

use super::description::{GearSpec, GearboxDescription, MeshSpec};
use super::kinematics::{Fixed, Stage, Topology};
use crate::error::GearboxError;
use crate::model::assembly::Assembly;
use crate::model::element::{Damping, Dof, Element, Load, LoadSchedule, StiffnessShape};

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

/// One resolved mesh (SI).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshValues {
    pub name: String,
    /// 1-based stage.
    pub stage: usize,
    /// Mesh frequency over the reference mesh frequency.
    pub freq_ratio: f64,
    pub stiffness_n_per_m: f64,
    pub shape: StiffnessShape,
    pub damping_ratio: f64,
    pub half_clearance_m: f64,
    /// Composite error when the mesh does not wear (m).
    pub baseline_error_m: f64,
    pub phase_rad: f64,
    /// True when the wear degree drives this mesh's error.
    pub wears: bool,
    /// True for the meshes of a planetary stage.
    pub planetary: bool,
    /// Row of `G`: (coordinate, coefficient in m).
    pub terms: Vec<(String, f64)>,
}

/// The physical model of a gearbox: every value it needs, given or assumed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Physics {
    pub length_ref_m: f64,
    pub dofs: Vec<(String, f64)>,
    pub meshes: Vec<MeshValues>,
    /// Flexible-shaft elements: (name, coordinate a, coordinate b, N·m/rad, damping ratio).
    pub shafts: Vec<(String, String, String, f64, f64)>,
    /// Input torque (N·m) on `input_dof`; the output coordinate balances it.
    pub input_torque_nm: f64,
    pub input_dof: String,
    pub output_dof: String,
    /// `ω_h / 2π` (Hz): the reference mesh frequency at Ω1 = 1.
    pub reference_frequency_hz: f64,
    /// Element index of the simulated sensor.
    pub sensor_element: usize,
    /// True when no reference frequency pins Ω1 and an inertia, a module or a mesh stiffness
    /// was assumed: the model's resonances, and so Ω1, are estimates.
    pub dynamics_estimated: bool,
}

struct Ctx<'a> {
    d: &'a GearboxDescription,
    assumed: Vec<AssumedValue>,
    /// Set when a value the dynamics rest on was assumed.
    dynamic: bool,
}

impl Ctx<'_> {
    fn assume(&mut self, what: String, value: f64, unit: &'static str, basis: &'static str) -> f64 {
        self.assumed.push(AssumedValue {
            what,
            value,
            unit,
            basis,
        });
        value
    }

    /// [`Ctx::assume`] for a value the dynamics rest on (an inertia, a module, a stiffness).
    fn assume_dynamic(
        &mut self,
        what: String,
        value: f64,
        unit: &'static str,
        basis: &'static str,
    ) -> f64 {
        self.dynamic = true;
        self.assume(what, value, unit, basis)
    }

    fn density(&self) -> f64 {
        self.d.density_kg_m3.unwrap_or(STEEL_DENSITY)
    }
}

fn positive(field: String, v: Option<f64>) -> Result<Option<f64>, GearboxError> {
    match v {
        Some(x) if !(x.is_finite() && x > 0.0) => Err(GearboxError::Value {
            field,
            value: x,
            reason: "must be a positive finite number",
        }),
        other => Ok(other),
    }
}

fn non_negative(field: String, v: Option<f64>) -> Result<Option<f64>, GearboxError> {
    match v {
        Some(x) if !(x.is_finite() && x >= 0.0) => Err(GearboxError::Value {
            field,
            value: x,
            reason: "must be a finite number ≥ 0",
        }),
        other => Ok(other),
    }
}

/// Geometry a gear shares with its mate when it gives none of its own.
#[derive(Clone, Copy)]
struct MateHint {
    module_mm: Option<f64>,
    face_width_mm: Option<f64>,
}

fn hint(g: &GearSpec) -> MateHint {
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
fn gear_values(
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

/// A mesh's values before the stiffness is settled.
struct MeshDraft {
    values: MeshValues,
    spec: MeshSpec,
    width_m: f64,
    label: String,
}

/// Where each member's rotation lives: shaft → coordinates of the gears on it.
#[derive(Default)]
struct Dofs {
    list: Vec<(String, f64)>,
    /// (stage, member) → coordinate.
    member: BTreeMap<(usize, String), String>,
    /// shaft → coordinates in order (one for a rigid shaft).
    shaft_dofs: BTreeMap<String, Vec<String>>,
    flexible: BTreeMap<String, f64>,
}

impl Dofs {
    fn dof_name(shaft: &str) -> String {
        format!("theta_{shaft}")
    }

    /// Put a member's inertia on its shaft; returns its coordinate.
    fn place(&mut self, stage: usize, member: &str, shaft: &str, inertia: f64) -> String {
        let name = if self.flexible.contains_key(shaft) {
            let name = format!("theta_{shaft}_{member}{stage}");
            self.list.push((name.clone(), inertia));
            self.shaft_dofs
                .entry(shaft.to_string())
                .or_default()
                .push(name.clone());
            name
        } else {
            let name = Self::dof_name(shaft);
            match self.list.iter_mut().find(|(n, _)| *n == name) {
                Some((_, j)) => *j += inertia,
                None => {
                    self.list.push((name.clone(), inertia));
                    self.shaft_dofs
                        .entry(shaft.to_string())
                        .or_default()
                        .push(name.clone());
                }
            }
            name
        };
        self.member
            .insert((stage, member.to_string()), name.clone());
        name
    }

    fn add_own(&mut self, name: String, inertia: f64) {
        self.list.push((name, inertia));
    }
}

/// Build the physics of a validated topology. Returns the physics and the assumed values.
pub fn physics(
    d: &GearboxDescription,
    topo: &Topology,
) -> Result<(Physics, Vec<AssumedValue>), GearboxError> {
    let mut cx = Ctx {
        d,
        assumed: Vec::new(),
        dynamic: false,
    };
    positive("density_kg_m3".into(), d.density_kg_m3)?;
    positive("nominal_input_hz".into(), d.nominal_input_hz)?;
    let length_ref_um = match positive("reference_length_um".into(), d.reference_length_um)? {
        Some(l) => l,
        None => cx.assume(
            "reference length (unit of the wear degree ea)".into(),
            REFERENCE_LENGTH_UM,
            "µm",
            "the first paper's b = 5 µm",
        ),
    };
    let b_ref = length_ref_um * 1e-6;
    let pinned = positive("reference_frequency_hz".into(), d.reference_frequency_hz)?;
    if d.static_load.is_some() && d.input_torque_nm.is_some() {
        return Err(GearboxError::TwoLoads);
    }
    let static_load = non_negative("static_load".into(), d.static_load)?;
    let input_torque = non_negative("input_torque_nm".into(), d.input_torque_nm)?;
    let n_stages = topo.stages.len();
    let wear_stages: Vec<usize> = match &d.wear_stages {
        Some(v) => {
            for &s in v {
                if s == 0 || s > n_stages {
                    return Err(GearboxError::StageIndex {
                        field: "wear_stages",
                        stage: s,
                        stages: n_stages,
                    });
                }
            }
            v.clone()
        }
        None => {
            let par: Vec<usize> = (1..=n_stages)
                .filter(|&k| matches!(topo.stages[k - 1], Stage::Parallel { .. }))
                .collect();
            if par.is_empty() {
                (1..=n_stages).collect()
            } else {
                par
            }
        }
    };
    let sensor_stage = d.sensor.as_ref().map_or(1, |s| s.stage);
    if sensor_stage == 0 || sensor_stage > n_stages {
        return Err(GearboxError::StageIndex {
            field: "sensor.stage",
            stage: sensor_stage,
            stages: n_stages,
        });
    }
    for (name, s) in &d.shafts {
        positive(
            format!("[shafts.{name}] torsional_stiffness_nm_per_rad"),
            s.torsional_stiffness_nm_per_rad,
        )?;
        positive(format!("[shafts.{name}] inertia"), s.inertia)?;
        non_negative(format!("[shafts.{name}] damping_ratio"), s.damping_ratio)?;
    }

    // Which stage set each shaft's rate: the member nearer the input comes first in a mesh.
    let rates = topo.signed_rates(1.0);
    let ratios = mesh_ratios(topo);
    let set_by = topo.set_by();
    // True when `shaft` turns before `stage` is reached (it is the stage's input side).
    let reached_before = |shaft: &str, stage: usize| -> bool { set_by[shaft] != stage };

    let mut dofs = Dofs::default();
    for (name, s) in &d.shafts {
        if let Some(k) = s.torsional_stiffness_nm_per_rad {
            dofs.flexible.insert(name.clone(), k);
        }
    }
    // A flexible shaft's own inertia is its first coordinate; a rigid one's joins its gears'.
    let mut extra_inertia: BTreeMap<String, f64> = d
        .shafts
        .iter()
        .filter_map(|(n, s)| s.inertia.map(|j| (n.clone(), j)))
        .collect();

    let mut drafts: Vec<MeshDraft> = Vec::new();
    let planetary_stages = topo
        .stages
        .iter()
        .filter(|s| matches!(s, Stage::Planetary { .. }))
        .count();
    // The member driving the first stage: (radius × load paths (m), its rate at input 1 Hz).
    let mut input_member: Option<(f64, f64)> = None;
    for (k0, (st, spec)) in topo.stages.iter().zip(&d.stages).enumerate() {
        let k = k0 + 1;
        let wears = wear_stages.contains(&k);
        let stage_mesh = spec.mesh.or(&d.mesh);
        let mut place = |dofs: &mut Dofs, member: &str, shaft: &str, j: f64| -> String {
            if dofs.flexible.contains_key(shaft)
                && !dofs.shaft_dofs.contains_key(shaft)
                && let Some(own) = extra_inertia.remove(shaft)
            {
                let name = Dofs::dof_name(shaft);
                dofs.add_own(name.clone(), own);
                dofs.shaft_dofs.insert(shaft.to_string(), vec![name]);
            }
            dofs.place(k, member, shaft, j)
        };
        match st {
            Stage::Parallel {
                pinion_shaft,
                pinion_teeth,
                gear_shaft,
                gear_teeth,
            } => {
                let (ps, gs) = (spec.pinion.as_ref().unwrap(), spec.gear.as_ref().unwrap());
                let p = gear_values(
                    &mut cx,
                    &format!("stage {k} pinion"),
                    *pinion_teeth,
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
                    &mut cx,
                    &format!("stage {k} gear"),
                    *gear_teeth,
                    gs.base_radius_mm,
                    gs.module_mm,
                    gs.pressure_angle_deg,
                    gs.face_width_mm,
                    gs.inertia,
                    gs.mass_kg,
                    hint(ps),
                    false,
                )?;
                let pd = place(&mut dofs, "pinion", pinion_shaft, p.inertia);
                let gd = place(&mut dofs, "gear", gear_shaft, g.inertia);
                // The member nearer the input first.
                let pinion_first = reached_before(pinion_shaft, k);
                let (a, b, ga, gb, shaft_a) = if pinion_first {
                    (pd, gd, p, g, pinion_shaft)
                } else {
                    (gd, pd, g, p, gear_shaft)
                };
                if input_member.is_none() {
                    input_member = Some((ga.base_radius_m, rates[shaft_a].abs()));
                }
                drafts.push(MeshDraft {
                    values: MeshValues {
                        name: format!("x{k}"),
                        stage: k,
                        freq_ratio: ratios[k0],
                        stiffness_n_per_m: 0.0,
                        shape: StiffnessShape::Constant,
                        damping_ratio: 0.0,
                        half_clearance_m: 0.0,
                        baseline_error_m: 0.0,
                        phase_rad: 0.0,
                        wears,
                        planetary: false,
                        terms: vec![(a, ga.base_radius_m), (b, -gb.base_radius_m)],
                    },
                    spec: stage_mesh.clone(),
                    width_m: ga.face_width_m.min(gb.face_width_m),
                    label: format!("stage {k} mesh"),
                });
            }
            Stage::Planetary {
                sun_shaft,
                sun_teeth,
                planet_teeth,
                planets,
                ring_shaft,
                ring_teeth,
                carrier_shaft,
                fixed,
            } => {
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
                    &mut cx,
                    &format!("stage {k} sun"),
                    *sun_teeth,
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
                    &mut cx,
                    &format!("stage {k} planet"),
                    *planet_teeth,
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
                    &mut cx,
                    &format!("stage {k} ring"),
                    *ring_teeth,
                    rs_spec.base_radius_mm,
                    rs_spec.module_mm,
                    rs_spec.pressure_angle_deg,
                    rs_spec.face_width_mm,
                    // A fixed ring is no coordinate: its inertia is never used, so a
                    // placeholder keeps it off the list of assumed values.
                    rs_spec.inertia.or(if *fixed == Fixed::Ring {
                        Some(1.0)
                    } else {
                        None
                    }),
                    rs_spec.mass_kg,
                    stage_hint,
                    true,
                )?;
                let carrier = spec.carrier.clone().unwrap_or_default();
                let rc = match positive(format!("stage {k} carrier radius_mm"), carrier.radius_mm)?
                {
                    Some(r) => r * 1e-3,
                    None => cx.assume(
                        format!("stage {k} carrier radius"),
                        (sun.base_radius_m + planet.base_radius_m) * 1e3,
                        "mm",
                        "sun + planet base radii (planet centre projected on the line of action)",
                    ) * 1e-3,
                };
                let np = *planets as usize;
                let sd = sun_shaft
                    .as_ref()
                    .map(|s| place(&mut dofs, "sun", s, sun.inertia));
                let mut pds = Vec::new();
                for n in 1..=np {
                    let name = if planetary_stages > 1 {
                        format!("theta_s{k}p{n}")
                    } else {
                        format!("theta_p{n}")
                    };
                    dofs.add_own(name.clone(), planet.inertia);
                    pds.push(name);
                }
                let rd = ring_shaft
                    .as_ref()
                    .map(|s| place(&mut dofs, "ring", s, ring.inertia));
                let cd = match carrier_shaft {
                    Some(s) => {
                        let jc = match positive(
                            format!("stage {k} carrier inertia"),
                            carrier.inertia,
                        )? {
                            Some(j) => j,
                            None => {
                                let r = (sun.module_m * *sun_teeth as f64
                                    + planet.module_m * *planet_teeth as f64)
                                    / 2.0;
                                cx.assume_dynamic(
                                    format!("stage {k} carrier inertia"),
                                    0.5 * cx.density() * PI * r.powi(4) * planet.face_width_m,
                                    "kg·m²",
                                    "steel disc of the planet-centre radius, planet face width thick",
                                )
                            }
                        };
                        Some(place(
                            &mut dofs,
                            "carrier",
                            s,
                            jc + np as f64 * planet.mass_kg * rc * rc,
                        ))
                    }
                    None => None,
                };
                if input_member.is_none() {
                    // Torque on the member through which power enters the stage.
                    let first =
                        |sh: &Option<String>| sh.as_ref().is_some_and(|s| reached_before(s, k));
                    let (r, shaft) = if first(sun_shaft) {
                        (sun.base_radius_m, sun_shaft)
                    } else if first(ring_shaft) {
                        (ring.base_radius_m, ring_shaft)
                    } else {
                        (2.0 * rc, carrier_shaft)
                    };
                    let n = shaft.as_ref().map_or(0.0, |s| rates[s].abs());
                    input_member = Some((r * np as f64, n));
                }
                let name = |m: &str, n: usize| {
                    if planetary_stages > 1 {
                        format!("x{k}{m}{n}")
                    } else {
                        format!("x{m}{n}")
                    }
                };
                let ring_mesh = spec.ring_mesh.or(&spec.mesh).or(&d.mesh);
                let width = sun.face_width_m.min(planet.face_width_m);
                let ring_width = ring.face_width_m.min(planet.face_width_m);
                let mut sp = Vec::new();
                let mut rp = Vec::new();
                for (n, pd) in pds.iter().enumerate() {
                    let mut terms = Vec::new();
                    if let Some(s) = &sd {
                        terms.push((s.clone(), sun.base_radius_m));
                    }
                    terms.push((pd.clone(), -planet.base_radius_m));
                    if let Some(c) = &cd {
                        terms.push((c.clone(), -rc));
                    }
                    sp.push((name("sp", n + 1), terms));
                    let mut terms = vec![(pd.clone(), planet.base_radius_m)];
                    if let Some(c) = &cd {
                        terms.push((c.clone(), -rc));
                    }
                    if let Some(r) = &rd {
                        terms.push((r.clone(), ring.base_radius_m));
                    }
                    rp.push((name("rp", n + 1), terms));
                }
                for ((nm, terms), (spec, w, what)) in sp
                    .into_iter()
                    .map(|t| (t, (stage_mesh.clone(), width, "sun–planet")))
                    .chain(
                        rp.into_iter()
                            .map(|t| (t, (ring_mesh.clone(), ring_width, "ring–planet"))),
                    )
                {
                    drafts.push(MeshDraft {
                        values: MeshValues {
                            name: nm,
                            stage: k,
                            freq_ratio: ratios[k0],
                            stiffness_n_per_m: 0.0,
                            shape: StiffnessShape::Constant,
                            damping_ratio: 0.0,
                            half_clearance_m: 0.0,
                            baseline_error_m: 0.0,
                            phase_rad: 0.0,
                            wears,
                            planetary: true,
                            terms,
                        },
                        spec,
                        width_m: w,
                        label: format!("stage {k} {what} mesh"),
                    });
                }
            }
        }
    }
    // Shafts whose only inertia was declared on the shaft (rigid): add it now.
    for (shaft, j) in extra_inertia {
        if let Some(dofs_of) = dofs.shaft_dofs.get(&shaft) {
            let first = dofs_of[0].clone();
            if let Some((_, jj)) = dofs.list.iter_mut().find(|(n, _)| *n == first) {
                *jj += j;
            }
        }
    }

    // Module of each mesh for the clearance default: from its first gear's width over 10 is
    // not known here, so keep the module alongside: recompute from the terms' gears instead.
    let modules = mesh_modules(d);
    // Mesh values other than stiffness.
    for dr in drafts.iter_mut() {
        let s = &dr.spec;
        let label = dr.label.clone();
        let v = &mut dr.values;
        let fl = match s.fluctuation {
            Some(e) if !(e.is_finite() && (0.0..1.0).contains(&e)) => {
                return Err(GearboxError::Value {
                    field: format!("{label} fluctuation"),
                    value: e,
                    reason: "must lie in [0, 1) so the stiffness stays positive",
                });
            }
            Some(e) => e,
            None => FLUCTUATION,
        };
        v.shape = match s.square_wave {
            Some(w) => StiffnessShape::SquareWave {
                contact_ratio: w.contact_ratio,
                double_to_single: w.double_to_single,
                smoothing: w.smoothing,
            },
            None => StiffnessShape::FirstHarmonic { eps: fl },
        };
        v.shape
            .validate(&label)
            .map_err(|e| GearboxError::Model(e.to_string()))?;
        v.damping_ratio = match non_negative(format!("{label} damping_ratio"), s.damping_ratio)? {
            Some(x) => x,
            None => DAMPING_RATIO,
        };
        let hc = non_negative(format!("{label} half_clearance_um"), s.half_clearance_um)?;
        v.half_clearance_m = match hc {
            Some(um) => (um / length_ref_um) * b_ref,
            None => CLEARANCE_OVER_MODULE * modules[v.stage - 1],
        };
        let err = non_negative(format!("{label} error_um"), s.error_um)?;
        v.baseline_error_m = match err {
            Some(um) => (um / length_ref_um) * b_ref,
            None => BASELINE_ERROR * b_ref,
        };
        v.phase_rad = match s.phase_rad {
            Some(p) if !p.is_finite() => {
                return Err(GearboxError::Value {
                    field: format!("{label} phase_rad"),
                    value: p,
                    reason: "must be finite",
                });
            }
            Some(p) => p,
            None => 0.0,
        };
    }
    // One "assumed" line per stage for the defaults shared by its meshes.
    for k in 1..=n_stages {
        let Some(dr) = drafts.iter().find(|dr| dr.values.stage == k) else {
            continue;
        };
        if dr.spec.fluctuation.is_none() && dr.spec.square_wave.is_none() {
            cx.assume(
                format!("stage {k} mesh stiffness fluctuation ε"),
                FLUCTUATION,
                "",
                "first harmonic of a spur mesh's stiffness variation (contact ratio ≈ 1.6)",
            );
        }
        if dr.spec.damping_ratio.is_none() {
            cx.assume(
                format!("stage {k} mesh damping ratio"),
                DAMPING_RATIO,
                "",
                "the first paper's mesh damping ratio",
            );
        }
        if dr.spec.half_clearance_um.is_none() {
            cx.assume(
                format!("stage {k} half-clearance"),
                dr.values.half_clearance_m * 1e6,
                "µm",
                "0.05 × module (general-purpose backlash)",
            );
        }
        if dr.spec.error_um.is_none() && !dr.values.wears {
            cx.assume(
                format!("stage {k} composite error (not a wear stage)"),
                BASELINE_ERROR * length_ref_um,
                "µm",
                "0.1 × reference length (the first paper's planetary error)",
            );
        }
    }

    // Stiffness: the reference mesh first.
    let a00: f64 = {
        let inertia: BTreeMap<&str, f64> =
            dofs.list.iter().map(|(n, j)| (n.as_str(), *j)).collect();
        let terms = &drafts[0].values.terms;
        let mut s = 0.0;
        for (n, c) in terms {
            s += c * c / inertia[n.as_str()];
        }
        s
    };
    let estimate = |dr: &MeshDraft| -> Result<(Option<f64>, f64), GearboxError> {
        // (absolute stiffness if given, estimate from width otherwise)
        let s = &dr.spec;
        let abs = positive(
            format!("{} stiffness_n_per_m", dr.label),
            s.stiffness_n_per_m,
        )?;
        let per = positive(
            format!("{} stiffness_per_width_n_per_mm_um", dr.label),
            s.stiffness_per_width_n_per_mm_um,
        )?;
        positive(format!("{} stiffness_ratio", dr.label), s.stiffness_ratio)?;
        let width_based = per.unwrap_or(STIFFNESS_PER_WIDTH) * 1e9 * dr.width_m;
        Ok((abs.or(per.map(|_| width_based)), width_based))
    };
    let (ref_abs, ref_est) = estimate(&drafts[0])?;
    let k_ref = match pinned {
        Some(f) => {
            let wh = TAU * f;
            wh * wh / a00
        }
        None => match ref_abs {
            Some(k) => k,
            None => cx.assume_dynamic(
                format!("{} stiffness", drafts[0].label),
                ref_est,
                "N/m",
                "20 N/(mm·µm) × the narrower face width of the pair (ISO 6336-1 c_γα, steel spur gears)",
            ),
        },
    };
    let mut logged = std::collections::BTreeSet::new();
    for i in 0..drafts.len() {
        let k = if i == 0 {
            k_ref
        } else {
            let (abs, est) = estimate(&drafts[i])?;
            match (drafts[i].spec.stiffness_ratio, abs) {
                (Some(r), _) => k_ref * r,
                (None, Some(k)) => k,
                (None, None) => {
                    let k = if pinned.is_some() {
                        k_ref * (est / ref_est)
                    } else {
                        est
                    };
                    let key = (drafts[i].values.stage, drafts[i].label.clone());
                    if logged.insert(key) {
                        cx.assume_dynamic(
                            format!("{} stiffness", drafts[i].label),
                            k,
                            "N/m",
                            if pinned.is_some() {
                                "reference stiffness × face-width ratio to the reference mesh"
                            } else {
                                "20 N/(mm·µm) × the narrower face width of the pair (ISO 6336-1 c_γα, steel spur gears)"
                            },
                        );
                    }
                    k
                }
            }
        };
        drafts[i].values.stiffness_n_per_m = k;
    }
    let reference_frequency_hz = match pinned {
        Some(f) => f,
        None => (k_ref * a00).sqrt() / TAU,
    };

    // Flexible shafts: chain each shaft's coordinates in order.
    let mut shafts = Vec::new();
    for (name, k) in &dofs.flexible {
        let damping = d.shafts[name].damping_ratio.unwrap_or(SHAFT_DAMPING_RATIO);
        if let Some(list) = dofs.shaft_dofs.get(name) {
            for w in list.windows(2) {
                shafts.push((
                    format!("shaft_{name}_{}", shafts.len() + 1),
                    w[0].clone(),
                    w[1].clone(),
                    *k,
                    damping,
                ));
            }
        }
    }

    // Static load.
    let (r_in, n_member) = input_member.expect("a gearbox has a stage");
    let input_torque_nm = match input_torque {
        Some(t) => t,
        None => {
            let f = match static_load {
                Some(f) => f,
                None => cx.assume(
                    "static load F̄1".into(),
                    STATIC_LOAD,
                    "",
                    "dimensionless reference-mesh force calibrated on the first paper's rig",
                ),
            };
            // Torque on the member that drives the reference mesh, carried to the input by
            // power conservation (lossless): T_in = T_member · n_member / n_in.
            f * k_ref * b_ref * r_in * (n_member / rates[&topo.input_shaft].abs())
        }
    };
    let first_dof = |shaft: &str| dofs.shaft_dofs[shaft][0].clone();
    let input_dof = first_dof(&topo.input_shaft);
    let output_dof = dofs.shaft_dofs[&topo.output_shaft]
        .last()
        .cloned()
        .expect("a shaft has a coordinate");
    let sensor_element = drafts
        .iter()
        .position(|dr| dr.values.stage == sensor_stage)
        .expect("every stage has a mesh");
    Ok((
        Physics {
            length_ref_m: b_ref,
            dofs: dofs.list,
            meshes: drafts.into_iter().map(|d| d.values).collect(),
            shafts,
            input_torque_nm,
            input_dof,
            output_dof,
            reference_frequency_hz,
            sensor_element,
            dynamics_estimated: pinned.is_none() && cx.dynamic,
        },
        cx.assumed,
    ))
}

/// Module (m) per stage for the clearance default: the first gear's given or derived module.
fn mesh_modules(d: &GearboxDescription) -> Vec<f64> {
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

/// Mesh frequencies over the reference (stage-1) mesh frequency, per stage; stage 1's is 1
/// exactly. Computed at the input rate that makes the reference mesh frequency 1, with the
/// operations of the first paper's Table 2 (so the paper's rig gets its ratios bit for bit).
pub fn mesh_ratios(topo: &Topology) -> Vec<f64> {
    let unit = topo.kinematics(1.0).meshes[0].hz;
    let k = topo.kinematics(1.0 / unit);
    k.meshes
        .iter()
        .enumerate()
        .map(|(i, m)| if i == 0 { 1.0 } else { m.hz })
        .collect()
}

/// The generic assembly for a wear degree: wear meshes carry `ea · b_ref`, the others their
/// baseline error (planetary meshes `planetary · b_ref` when given).
pub fn assembly(
    name: &str,
    p: &Physics,
    ea: f64,
    planetary: Option<f64>,
) -> crate::error::Result<Assembly> {
    use crate::error::Error;
    if !(ea.is_finite() && ea >= 0.0) {
        return Err(Error::param("ea", ea, "the wear degree must be ≥ 0"));
    }
    if let Some(pe) = planetary
        && !(pe.is_finite() && pe >= 0.0)
    {
        return Err(Error::param("planetary error", pe, "must be ≥ 0"));
    }
    let b_ref = p.length_ref_m;
    let mut dofs = Vec::with_capacity(p.dofs.len());
    for (n, j) in &p.dofs {
        dofs.push(Dof::rotation(n.clone(), *j)?);
    }
    let mut elements = Vec::with_capacity(p.meshes.len() + p.shafts.len());
    for m in &p.meshes {
        let amp = if m.wears {
            ea * b_ref
        } else if let (true, Some(pe)) = (m.planetary, planetary) {
            pe * b_ref
        } else {
            m.baseline_error_m
        };
        let (a, b) = (&m.terms[0], &m.terms[1]);
        let mut el = Element::mesh(
            m.name.clone(),
            (&a.0, a.1),
            (&b.0, -b.1),
            m.stiffness_n_per_m,
            m.shape,
            m.freq_ratio,
            Damping::Ratio(m.damping_ratio),
            m.half_clearance_m,
        );
        for (dof, c) in &m.terms[2..] {
            el = el.with_term(dof, *c);
        }
        elements.push(
            el.with_error(amp, m.freq_ratio, m.phase_rad)
                .with_phase(m.phase_rad),
        );
    }
    for (n, a, b, k, xi) in &p.shafts {
        elements.push(Element::shaft(n.clone(), a, b, *k, Damping::Ratio(*xi)));
    }
    let loads = vec![
        Load {
            dof: p.input_dof.clone(),
            schedule: LoadSchedule::Constant {
                value: p.input_torque_nm,
            },
        },
        Load {
            dof: p.output_dof.clone(),
            schedule: LoadSchedule::Balancing,
        },
    ];
    let asm = Assembly {
        name: name.to_string(),
        dofs,
        elements,
        loads,
        length_ref: b_ref,
        sensor: p.sensor_element,
    };
    asm.validate()?;
    Ok(asm)
}
