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

use serde::Serialize;

pub use super::assumed::{
    AssumedValue, BASELINE_ERROR, CLEARANCE_OVER_MODULE, DAMPING_RATIO, DEFAULT_MODULE_MM,
    FLUCTUATION, PRESSURE_ANGLE_DEG, REFERENCE_LENGTH_UM, SHAFT_DAMPING_RATIO, STATIC_LOAD,
    STEEL_DENSITY, STIFFNESS_PER_WIDTH, WIDTH_OVER_MODULE,
};
use super::assumed::{Ctx, non_negative, positive};
use super::coordinates::{Dofs, Train};
use super::description::GearboxDescription;
use super::factors::PhysicsFactors;
pub use super::gears::GearValues;
use super::kinematics::{Stage, Topology};
use super::meshes;
pub use super::meshes::MeshValues;
use crate::error::GearboxError;
use crate::model::assembly::Assembly;
use crate::model::element::{Damping, Dof, Element, Load, LoadSchedule, StiffnessShape};

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

/// The description's values that are not a gear's or a mesh's, checked (or defaulted).
struct Settings {
    /// Reference length (µm): the unit of the wear degree.
    length_ref_um: f64,
    /// The same in m.
    b_ref: f64,
    /// `reference_frequency_hz`, which pins Ω1 when given.
    pinned: Option<f64>,
    static_load: Option<f64>,
    input_torque: Option<f64>,
    /// Stages (1-based) whose error is the wear degree.
    wear_stages: Vec<usize>,
    /// Stage (1-based) whose first mesh the sensor measures.
    sensor_stage: usize,
}

impl Settings {
    /// Check the description's top-level values and its shafts' (in this order, so the first
    /// error reported stays the same).
    fn new(cx: &mut Ctx, topo: &Topology) -> Result<Self, GearboxError> {
        let d = cx.d;
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
        for b in &d.bearings {
            let reason = if !topo.shafts.contains(&b.shaft) {
                Some(format!(
                    "shaft \"{}\" carries no gear (shafts: {})",
                    b.shaft,
                    topo.shafts.join(", ")
                ))
            } else {
                b.defect_orders().err()
            };
            if let Some(reason) = reason {
                return Err(GearboxError::Bearing {
                    name: b.name.clone(),
                    reason,
                });
            }
        }
        Ok(Settings {
            length_ref_um,
            b_ref,
            pinned,
            static_load,
            input_torque,
            wear_stages,
            sensor_stage,
        })
    }
}

/// Build the physics of a validated topology. Returns the physics and the assumed values.
///
/// In order: the top-level values, the coordinates and mesh rows stage by stage, the meshes'
/// values, their stiffness (the reference mesh first), the flexible shafts, and the static
/// load. The values assumed are listed in that order.
pub fn physics(
    d: &GearboxDescription,
    topo: &Topology,
) -> Result<(Physics, Vec<AssumedValue>), GearboxError> {
    let mut cx = Ctx::new(d);
    let s = Settings::new(&mut cx, topo)?;
    let ratios = mesh_ratios(topo);
    let train = Train::build(&mut cx, d, topo, &ratios, &s.wear_stages)?;
    let (rates, dofs, mut drafts, input_member) =
        (train.rates, train.dofs, train.drafts, train.input_member);
    meshes::settle_values(d, &mut drafts, s.length_ref_um, s.b_ref)?;
    meshes::log_stage_defaults(&mut cx, &drafts, topo.stages.len(), s.length_ref_um);
    let (k_ref, reference_frequency_hz) =
        meshes::settle_stiffness(&mut cx, &mut drafts, &dofs.list, s.pinned)?;
    let shafts = flexible_shafts(d, &dofs);
    let input_torque_nm = input_torque(
        &mut cx,
        &s,
        k_ref,
        input_member.expect("a gearbox has a stage"),
        rates[&topo.input_shaft].abs(),
    );
    let first_dof = |shaft: &str| dofs.shaft_dofs[shaft][0].clone();
    let input_dof = first_dof(&topo.input_shaft);
    let output_dof = dofs.shaft_dofs[&topo.output_shaft]
        .last()
        .cloned()
        .expect("a shaft has a coordinate");
    let sensor_element = drafts
        .iter()
        .position(|dr| dr.values.stage == s.sensor_stage)
        .expect("every stage has a mesh");
    let mut physics = Physics {
        length_ref_m: s.b_ref,
        dofs: dofs.list,
        meshes: drafts.into_iter().map(|d| d.values).collect(),
        shafts,
        input_torque_nm,
        input_dof,
        output_dof,
        reference_frequency_hz,
        sensor_element,
        dynamics_estimated: s.pinned.is_none() && cx.dynamic,
    };
    if let Some(f) = &d.physics_factors {
        apply_factors(&mut physics, f, topo.stages.len())?;
    }
    Ok((physics, cx.assumed))
}

/// A machine's factors over the settled physics ([`super::factors`]): each mesh's stiffness,
/// damping ratio, fluctuation and error scale by its stage's factors, every half-clearance by
/// `clearance`, the input torque by `load` (a torque, so a stiffer mesh deflects less under
/// it), and `ω_h` by the square root of the reference mesh's stiffness factor.
fn apply_factors(p: &mut Physics, f: &PhysicsFactors, stages: usize) -> Result<(), GearboxError> {
    f.check(stages)?;
    for m in p.meshes.iter_mut() {
        let s = f.stage(m.stage);
        m.stiffness_n_per_m *= s.stiffness;
        m.damping_ratio *= s.damping;
        m.error_scale *= s.error;
        m.half_clearance_m *= f.clearance;
        m.shape = match m.shape {
            StiffnessShape::FirstHarmonic { eps } => StiffnessShape::FirstHarmonic {
                eps: eps * s.fluctuation,
            },
            StiffnessShape::SquareWave {
                contact_ratio,
                double_to_single,
                smoothing,
            } => StiffnessShape::SquareWave {
                contact_ratio,
                double_to_single: 1.0 + (double_to_single - 1.0) * s.fluctuation,
                smoothing,
            },
            other => other,
        };
        m.shape
            .validate(&m.name)
            .map_err(|e| GearboxError::Model(format!("physics_factors: {e}")))?;
    }
    p.input_torque_nm *= f.load;
    if let Some(m0) = p.meshes.first() {
        p.reference_frequency_hz *= f.stage(m0.stage).stiffness.sqrt();
    }
    Ok(())
}

/// Flexible-shaft elements: each flexible shaft's coordinates chained in order, as (name,
/// coordinate a, coordinate b, N·m/rad, damping ratio).
fn flexible_shafts(d: &GearboxDescription, dofs: &Dofs) -> Vec<(String, String, String, f64, f64)> {
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
    shafts
}

/// Input torque (N·m): given, or from the static load `F̄1` on the member that drives the
/// reference mesh (`member`: its radius × load paths (m) and rate at input 1 Hz; `n_in`: the
/// input shaft's rate at input 1 Hz).
fn input_torque(cx: &mut Ctx, s: &Settings, k_ref: f64, member: (f64, f64), n_in: f64) -> f64 {
    let (r_in, n_member) = member;
    match s.input_torque {
        Some(t) => t,
        None => {
            let f = match s.static_load {
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
            f * k_ref * s.b_ref * r_in * (n_member / n_in)
        }
    }
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
        let amp = m.error_scale
            * if m.wears {
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
