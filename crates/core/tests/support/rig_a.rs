//! Model A: the first seed's multistage rig as a configuration of the generic assembly.
//!
//! Coordinates `q = [θ1, θB, θC, θp1..θp4, θc]` and the 10 meshes `x1, x2, xsp1..4, xrp1..4` of
//! `model.md`:
//!
//! | mesh | deflection |
//! | --- | --- |
//! | stage 1 | `x1 = r1 θ1 − r2 θB − e1(t)` |
//! | stage 2 | `x2 = r3 θB − r4 θC − e2(t)` |
//! | sun–planet n | `xspn = rs θC − rp θpn − rc θc − espn(t)` |
//! | ring–planet n | `xrpn = rp θpn − rc θc − erpn(t)` (ring fixed) |
//!
//! Wear is the fixed-axis composite-error amplitude `ea` (units of `b_ref`, the paper's
//! convention): `e1 = ea sin(Ω1 τ)`, `e2 = ea sin(Ω2 τ)`.
//!
//! The original hand-written configuration, kept as the test oracle that
//! `configs/gearboxes/wang2019.toml` must resolve to (included by `tests/paper_rig.rs` with
//! `#[path]`; it needs `kinematics_a` beside it as a sibling module).

use gearwear_core::error::{Error, Result};
use gearwear_core::model::{
    Assembly, Damping, Dof, Element, Load, LoadSchedule, StiffnessShape, Wear,
};
use serde::{Deserialize, Serialize};

use super::kinematics_a::ToothCounts;

/// The committed default configuration (`configs/model_a.toml`, four levels up from
/// `crates/core/tests/support/`).
pub const DEFAULT_CONFIG: &str = include_str!("../../../../configs/model_a.toml");

/// One gear of Table 1.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GearSpec {
    pub teeth: u32,
    pub base_radius_mm: f64,
    /// kg·m²
    pub inertia: f64,
}

/// The gears of the rig.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Gears {
    pub g1: GearSpec,
    pub g2: GearSpec,
    pub g3: GearSpec,
    pub g4: GearSpec,
    pub sun: GearSpec,
    pub planet: GearSpec,
    pub ring: GearSpec,
}

/// The planet carrier.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CarrierSpec {
    pub radius_mm: f64,
    pub inertia: f64,
}

/// Values the paper does not give (see the config file for each one's reason).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Assumed {
    pub planet_mass_kg: f64,
    pub stiffness_ratio_stage2: f64,
    pub stiffness_ratio_sun_planet: f64,
    pub stiffness_ratio_ring_planet: f64,
    pub fluctuation: f64,
    pub static_load: f64,
    pub planetary_error: f64,
    pub phase: f64,
    /// Optional contact-ratio square wave instead of the first harmonic:
    /// `{ contact_ratio, double_to_single, smoothing }`.
    #[serde(default)]
    pub square_wave: Option<SquareWaveSpec>,
}

/// Parameters of the contact-ratio square-wave stiffness.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct SquareWaveSpec {
    pub contact_ratio: f64,
    pub double_to_single: f64,
    pub smoothing: f64,
}

/// Model A configuration (the file format of `configs/model_a.toml`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelAConfig {
    pub name: String,
    pub description: String,
    pub length_ref_um: f64,
    pub half_clearance: f64,
    pub damping_ratio: f64,
    pub planets: u32,
    /// ω_h / 2π (Hz): the stage-1 mesh frequency at Ω1 = 1.
    pub reference_frequency_hz: f64,
    pub gears: Gears,
    pub carrier: CarrierSpec,
    pub assumed: Assumed,
}

impl ModelAConfig {
    /// The committed default rig.
    pub fn default_rig() -> Self {
        Self::from_toml(DEFAULT_CONFIG, "configs/model_a.toml")
            .expect("the committed Model A config parses")
    }

    /// Parse a TOML configuration (`origin` names it in errors).
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        let cfg: ModelAConfig = toml::from_str(text).map_err(|e| Error::Parse {
            path: origin.to_string(),
            reason: e.to_string(),
        })?;
        cfg.tooth_counts().validate()?;
        Ok(cfg)
    }

    /// Tooth counts for the kinematic frequencies.
    pub fn tooth_counts(&self) -> ToothCounts {
        let g = &self.gears;
        ToothCounts {
            z1: g.g1.teeth,
            z2: g.g2.teeth,
            z3: g.g3.teeth,
            z4: g.g4.teeth,
            zs: g.sun.teeth,
            zp: g.planet.teeth,
            zr: g.ring.teeth,
            planets: self.planets,
        }
    }

    /// The stage-1 mesh frequency (Hz) when the motor turns at `shaft_hz`.
    pub fn f1_hz(&self, shaft_hz: f64) -> f64 {
        self.gears.g1.teeth as f64 * shaft_hz
    }

    fn shape(&self) -> StiffnessShape {
        match self.assumed.square_wave {
            Some(s) => StiffnessShape::SquareWave {
                contact_ratio: s.contact_ratio,
                double_to_single: s.double_to_single,
                smoothing: s.smoothing,
            },
            None => StiffnessShape::FirstHarmonic {
                eps: self.assumed.fluctuation,
            },
        }
    }

    /// Build the generic assembly for a wear state.
    pub fn assembly(&self, wear: Wear) -> Result<Assembly> {
        if !(wear.ea.is_finite() && wear.ea >= 0.0) {
            return Err(Error::param("ea", wear.ea, "the wear degree must be ≥ 0"));
        }
        let planetary = wear.planetary.unwrap_or(self.assumed.planetary_error);
        if !(planetary.is_finite() && planetary >= 0.0) {
            return Err(Error::param("planetary error", planetary, "must be ≥ 0"));
        }
        let mm = 1e-3;
        let g = &self.gears;
        let (r1, r2, r3, r4) = (
            g.g1.base_radius_mm * mm,
            g.g2.base_radius_mm * mm,
            g.g3.base_radius_mm * mm,
            g.g4.base_radius_mm * mm,
        );
        let (rs, rp, rc) = (
            g.sun.base_radius_mm * mm,
            g.planet.base_radius_mm * mm,
            self.carrier.radius_mm * mm,
        );
        let a = &self.assumed;
        let b_ref = self.length_ref_um * 1e-6;
        let b = self.half_clearance * b_ref;
        let np = self.planets as usize;
        let mut dofs = vec![
            Dof::rotation("theta1", g.g1.inertia)?,
            Dof::rotation("thetaB", g.g2.inertia + g.g3.inertia)?,
            Dof::rotation("thetaC", g.g4.inertia + g.sun.inertia)?,
        ];
        for n in 1..=np {
            dofs.push(Dof::rotation(format!("thetap{n}"), g.planet.inertia)?);
        }
        dofs.push(Dof::rotation(
            "thetac",
            self.carrier.inertia + np as f64 * a.planet_mass_kg * rc * rc,
        )?);
        let fr = self.tooth_counts().frequencies();
        // ω_h² = k1m A11 fixes the stage-1 mean stiffness.
        let a11 = r1 * r1 / g.g1.inertia + r2 * r2 / (g.g2.inertia + g.g3.inertia);
        let wh = std::f64::consts::TAU * self.reference_frequency_hz;
        if !(wh.is_finite() && wh > 0.0) {
            return Err(Error::param(
                "reference_frequency_hz",
                self.reference_frequency_hz,
                "must be positive",
            ));
        }
        let k1 = wh * wh / a11;
        let shape = self.shape();
        let damp = Damping::Ratio(self.damping_ratio);
        let ph = a.phase;
        let mut elements = vec![
            Element::mesh(
                "x1",
                ("theta1", r1),
                ("thetaB", r2),
                k1,
                shape,
                1.0,
                damp,
                b,
            )
            .with_error(wear.ea * b_ref, 1.0, ph)
            .with_phase(ph),
            Element::mesh(
                "x2",
                ("thetaB", r3),
                ("thetaC", r4),
                k1 * a.stiffness_ratio_stage2,
                shape,
                fr.f2,
                damp,
                b,
            )
            .with_error(wear.ea * b_ref, fr.f2, ph)
            .with_phase(ph),
        ];
        for n in 1..=np {
            let p = format!("thetap{n}");
            elements.push(
                Element::mesh(
                    format!("xsp{n}"),
                    ("thetaC", rs),
                    (&p, rp),
                    k1 * a.stiffness_ratio_sun_planet,
                    shape,
                    fr.f3,
                    damp,
                    b,
                )
                .with_term("thetac", -rc)
                .with_error(planetary * b_ref, fr.f3, ph)
                .with_phase(ph),
            );
        }
        for n in 1..=np {
            let p = format!("thetap{n}");
            elements.push(
                Element::mesh(
                    format!("xrp{n}"),
                    (&p, rp),
                    ("thetac", rc),
                    k1 * a.stiffness_ratio_ring_planet,
                    shape,
                    fr.f3,
                    damp,
                    b,
                )
                .with_error(planetary * b_ref, fr.f3, ph)
                .with_phase(ph),
            );
        }
        // Static load: input torque from the dimensionless stage-1 force F̄1 = F1/(k1 b_ref),
        // output torque balancing it (constant mean speed).
        let t_in = a.static_load * k1 * b_ref * r1;
        let loads = vec![
            Load {
                dof: "theta1".into(),
                schedule: LoadSchedule::Constant { value: t_in },
            },
            Load {
                dof: "thetac".into(),
                schedule: LoadSchedule::Balancing,
            },
        ];
        let asm = Assembly {
            name: self.name.clone(),
            dofs,
            elements,
            loads,
            length_ref: b_ref,
            sensor: 0,
        };
        asm.validate()?;
        Ok(asm)
    }
}
