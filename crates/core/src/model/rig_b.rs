//! Model B: the second seed's 10-DOF bending–torsion two-stage spur drive as a configuration of
//! the generic assembly.
//!
//! Coordinates `q = [y1, y2, y3, y4, θ0, θ1, θ2, θ3, θ4, θ5]` (m and rad) and nine elements:
//!
//! | element | deflection | force |
//! | --- | --- | --- |
//! | `mesh1` (reference) | `δ1 = rb1 θ1 − rb2 θ2 − y1 + y2` (m) | `kt1(t) f_b1(δ1) + ct1 δ̇1` |
//! | `mesh2` | `δ2 = rb3 θ3 − rb4 θ4 − y3 + y4` (m) | `kt2(t) f_b2(δ2) + ct2 δ̇2` |
//! | `shaft1` | `θ0 − θ1` (rad) | `k1 (θ0 − θ1) + c1 (θ̇0 − θ̇1)` |
//! | `shaft2` | `θ2 − θ3` | `k2 …` |
//! | `shaft3` | `θ4 − θ5` | `k3 …` |
//! | `y1` … `y4` (bearings) | `y_i` | `ky y_i + cy ẏ_i` |
//!
//! `M q̈ = −Gᵀ F + T` with these rows is the paper's equations (1)–(8) with their typesetting
//! repaired (`model.md`). The bearing deflections are `y1..y4` themselves, so the transverse
//! accelerations are components of the relative form's right-hand side. One rigid-body mode
//! (the drive's rotation) remains; [`crate::model::reconstruct`] recovers angles and speeds.
//!
//! Loads: a motor torque `T_m = T_L / R` on θ0 and the load torque `−T_L` on θ5, with
//! `R = (rb2/rb1)(rb4/rb3)` (= 90 for the default tooth counts), so the mean speed is constant.

use std::f64::consts::{PI, TAU};
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::assembly::Assembly;
use super::element::{Damping, Dof, Element, Load, LoadSchedule, StiffnessShape};
use super::system::DimensionlessModel;
use crate::error::{Error, Result};

/// The committed default configuration (`configs/model_b.toml`).
pub const DEFAULT_CONFIG: &str = include_str!("../../../../configs/model_b.toml");

/// Radians to arc minutes.
pub const ARCMIN_PER_RAD: f64 = 180.0 * 60.0 / PI;

/// One gear.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GearB {
    pub teeth: u32,
    pub base_radius_mm: f64,
    /// kg·m²
    pub inertia: f64,
    /// Mass moving with the transverse coordinate `y_i`, kg.
    pub mass_kg: f64,
}

/// The four gears.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GearsB {
    pub g1: GearB,
    pub g2: GearB,
    pub g3: GearB,
    pub g4: GearB,
}

/// One mesh's parameters.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeshB {
    /// Mean mesh stiffness, N/m.
    pub stiffness: f64,
    pub damping_ratio: f64,
    /// Half-clearance along the line of action, µm.
    pub half_backlash_um: f64,
    pub contact_ratio: f64,
    pub double_to_single: f64,
    /// Edge width of the square wave, fraction of a mesh period.
    pub smoothing: f64,
    /// Position in the mesh period at t = 0 (fraction of a period).
    pub phase_fraction: f64,
    /// First-harmonic fluctuation ε for the alternative shape.
    pub eps: f64,
}

/// A torsional shaft.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShaftB {
    /// N·m/rad
    pub stiffness: f64,
    pub damping_ratio: f64,
}

/// The (equal) bearing supports.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BearingB {
    /// N/m
    pub stiffness: f64,
    pub damping_ratio: f64,
}

/// Model B configuration (the file format of `configs/model_b.toml`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelBConfig {
    pub name: String,
    pub description: String,
    pub length_ref_um: f64,
    /// Mean speed of gear 4 and the load, rad/s.
    pub output_speed_rad_s: f64,
    /// Load torque held at the output, N·m.
    pub load_torque_nm: f64,
    pub motor_inertia: f64,
    pub load_inertia: f64,
    pub gears: GearsB,
    pub mesh1: MeshB,
    pub mesh2: MeshB,
    pub shaft1: ShaftB,
    pub shaft2: ShaftB,
    pub shaft3: ShaftB,
    pub bearing: BearingB,
}

/// Which mesh-stiffness form to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StiffnessForm {
    /// The paper's correction: the smoothed contact-ratio square wave (default for Model B).
    SquareWave,
    /// `1 + ε cos(Ω τ + φ)` (Model A's form).
    FirstHarmonic,
    /// The mean stiffness only (what the static return-difference formula assumes).
    Mean,
}

/// How the loads vary in time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum LoadCase {
    /// Motor torque `T_L/R` and load torque `−T_L`, constant.
    Steady,
    /// At `at_s` the load torque, and with it the motor's holding torque, step to zero (so no
    /// net torque acts on the rotation and the mean speed stays the configured one).
    LoadDrop { at_s: f64 },
    /// At `at_s` both torques reverse sign (`T_L → −T_L`): the drive is loaded on the other
    /// tooth flanks.
    Reversal { at_s: f64 },
}

/// Where the mesh damping acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeshDamping {
    /// `kt f(δ) + ct δ̇` everywhere, also inside the clearance (the paper's equations as
    /// written, and the first seed's form).
    #[default]
    Viscous,
    /// `kt f(δ) + ct δ̇` only while the teeth are in contact (`|δ| > b`), no force inside the
    /// clearance: the usual contact-damping choice of backlash models.
    ContactOnly,
}

/// Variant of the configured rig for one run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelBOptions {
    pub stiffness: StiffnessForm,
    /// Keep the configured backlash (`false`: both half-clearances 0, i.e. no return difference
    /// from clearance).
    pub backlash: bool,
    pub loads: LoadCase,
    /// Output torque (N·m); `None`: the configured `load_torque_nm`.
    pub load_torque_nm: Option<f64>,
    /// Where the two meshes' damping acts.
    #[serde(default)]
    pub mesh_damping: MeshDamping,
}

impl Default for ModelBOptions {
    fn default() -> Self {
        ModelBOptions {
            stiffness: StiffnessForm::SquareWave,
            backlash: true,
            loads: LoadCase::Steady,
            load_torque_nm: None,
            mesh_damping: MeshDamping::Viscous,
        }
    }
}

/// Base radii in m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BaseRadii {
    pub rb1: f64,
    pub rb2: f64,
    pub rb3: f64,
    pub rb4: f64,
}

impl BaseRadii {
    /// Stage-1 ratio `i1 = rb2/rb1`.
    pub fn i1(&self) -> f64 {
        self.rb2 / self.rb1
    }
    /// Stage-2 ratio `i2 = rb4/rb3`.
    pub fn i2(&self) -> f64 {
        self.rb4 / self.rb3
    }
    /// Total ratio `R = i1 i2` (motor angle over output angle).
    pub fn ratio(&self) -> f64 {
        self.i1() * self.i2()
    }
}

/// Element order of the assembly (and of the resolved model's deflections).
pub const ELEMENTS: [&str; 9] = [
    "mesh1", "mesh2", "shaft1", "shaft2", "shaft3", "y1", "y2", "y3", "y4",
];
/// Coordinate order.
pub const DOFS: [&str; 10] = [
    "y1", "y2", "y3", "y4", "theta0", "theta1", "theta2", "theta3", "theta4", "theta5",
];

impl ModelBConfig {
    /// The committed default rig.
    pub fn default_rig() -> Self {
        Self::from_toml(DEFAULT_CONFIG, "configs/model_b.toml")
            .expect("the committed Model B config parses")
    }

    /// Parse a TOML configuration (`origin` names it in errors).
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        let cfg: ModelBConfig = toml::from_str(text).map_err(|e| Error::Parse {
            path: origin.to_string(),
            reason: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Read a configuration file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }

    fn validate(&self) -> Result<()> {
        let g = &self.gears;
        for (name, gear) in [("g1", &g.g1), ("g2", &g.g2), ("g3", &g.g3), ("g4", &g.g4)] {
            if gear.teeth == 0 {
                return Err(Error::param(format!("{name}.teeth"), 0.0, "must be ≥ 1"));
            }
            if !(gear.base_radius_mm.is_finite() && gear.base_radius_mm > 0.0) {
                return Err(Error::param(
                    format!("{name}.base_radius_mm"),
                    gear.base_radius_mm,
                    "must be positive",
                ));
            }
        }
        for (name, v) in [
            ("output_speed_rad_s", self.output_speed_rad_s),
            ("length_ref_um", self.length_ref_um),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::param(name, v, "must be positive"));
            }
        }
        if !(self.load_torque_nm.is_finite()) {
            return Err(Error::param(
                "load_torque_nm",
                self.load_torque_nm,
                "must be finite",
            ));
        }
        for m in [&self.mesh1, &self.mesh2] {
            if !(m.half_backlash_um.is_finite() && m.half_backlash_um >= 0.0) {
                return Err(Error::param(
                    "half_backlash_um",
                    m.half_backlash_um,
                    "must be ≥ 0",
                ));
            }
        }
        // Each value above can be finite while the speeds they make are not (radii of 1e-300
        // and 1e308 mm give an infinite ratio, so zero mesh periods).
        let w1 = self.mesh1_rad_s();
        for (name, w) in [
            ("stage-1 mesh frequency", w1),
            ("stage-2 mesh frequency", w1 * self.mesh2_ratio()),
        ] {
            if !(w.is_finite() && w > 0.0) {
                return Err(Error::param(
                    name,
                    w,
                    "must be positive and finite: check the base radii and output_speed_rad_s",
                ));
            }
        }
        Ok(())
    }

    /// Base radii in m.
    pub fn radii(&self) -> BaseRadii {
        let g = &self.gears;
        BaseRadii {
            rb1: g.g1.base_radius_mm * 1e-3,
            rb2: g.g2.base_radius_mm * 1e-3,
            rb3: g.g3.base_radius_mm * 1e-3,
            rb4: g.g4.base_radius_mm * 1e-3,
        }
    }

    /// Mean motor speed (rad/s) for the configured output speed: `ω0 = R ω_out`.
    pub fn motor_speed(&self) -> f64 {
        self.output_speed_rad_s * self.radii().ratio()
    }

    /// Stage-1 mesh frequency in rad/s: `z1 ω1` (= `z2 ω2`).
    pub fn mesh1_rad_s(&self) -> f64 {
        self.gears.g1.teeth as f64 * self.motor_speed()
    }

    /// Stage-2 mesh frequency over the stage-1 one: `z3 ω3 / (z1 ω1) = z3 z1 / (z2 z1) = z3/z2`.
    pub fn mesh2_ratio(&self) -> f64 {
        self.gears.g3.teeth as f64 / self.gears.g2.teeth as f64
    }

    /// Stage-1 and stage-2 mesh periods, s.
    pub fn mesh_periods_s(&self) -> (f64, f64) {
        let w1 = self.mesh1_rad_s();
        (TAU / w1, TAU / (w1 * self.mesh2_ratio()))
    }

    /// The rigid-body velocity `q̇0` at the mean speed (y: 0; θ0, θ1: `ω0`; θ2, θ3: `ω0/i1`;
    /// θ4, θ5: `ω0/R`), for [`crate::model::Reconstructor::new`].
    pub fn rigid_velocity(&self) -> Vec<f64> {
        let r = self.radii();
        let w0 = self.motor_speed();
        let (w2, w4) = (w0 / r.i1(), w0 / r.ratio());
        vec![0.0, 0.0, 0.0, 0.0, w0, w0, w2, w2, w4, w4]
    }

    /// The dimensionless operating frequency `Ω1 = ω_mesh1 / ω_h` of a resolved model.
    pub fn omega1(&self, model: &DimensionlessModel) -> f64 {
        self.mesh1_rad_s() / model.omega_h
    }

    fn shape(m: &MeshB, form: StiffnessForm) -> StiffnessShape {
        match form {
            StiffnessForm::SquareWave => StiffnessShape::SquareWave {
                contact_ratio: m.contact_ratio,
                double_to_single: m.double_to_single,
                smoothing: m.smoothing,
            },
            StiffnessForm::FirstHarmonic => StiffnessShape::FirstHarmonic { eps: m.eps },
            StiffnessForm::Mean => StiffnessShape::FirstHarmonic { eps: 0.0 },
        }
    }

    /// Output torque used by a run.
    pub fn torque(&self, opts: &ModelBOptions) -> f64 {
        opts.load_torque_nm.unwrap_or(self.load_torque_nm)
    }

    /// Build the generic assembly.
    pub fn assembly(&self, opts: &ModelBOptions) -> Result<Assembly> {
        self.validate()?;
        let g = &self.gears;
        let r = self.radii();
        let dofs = vec![
            Dof::translation("y1", g.g1.mass_kg)?,
            Dof::translation("y2", g.g2.mass_kg)?,
            Dof::translation("y3", g.g3.mass_kg)?,
            Dof::translation("y4", g.g4.mass_kg)?,
            Dof::rotation("theta0", self.motor_inertia)?,
            Dof::rotation("theta1", g.g1.inertia)?,
            Dof::rotation("theta2", g.g2.inertia)?,
            Dof::rotation("theta3", g.g3.inertia)?,
            Dof::rotation("theta4", g.g4.inertia)?,
            Dof::rotation("theta5", self.load_inertia)?,
        ];
        let um = 1e-6;
        let bl = |m: &MeshB| {
            if opts.backlash {
                m.half_backlash_um * um
            } else {
                0.0
            }
        };
        let (m1, m2) = (&self.mesh1, &self.mesh2);
        let contact_only = opts.mesh_damping == MeshDamping::ContactOnly;
        let bearing = |name: &str| {
            Element::bearing(
                name,
                name,
                self.bearing.stiffness,
                Damping::Ratio(self.bearing.damping_ratio),
            )
        };
        let elements = vec![
            Element::mesh(
                "mesh1",
                ("theta1", r.rb1),
                ("theta2", r.rb2),
                m1.stiffness,
                Self::shape(m1, opts.stiffness),
                1.0,
                Damping::Ratio(m1.damping_ratio),
                bl(m1),
            )
            .with_term("y1", -1.0)
            .with_term("y2", 1.0)
            .with_phase(TAU * m1.phase_fraction)
            .with_contact_only_damping(contact_only),
            Element::mesh(
                "mesh2",
                ("theta3", r.rb3),
                ("theta4", r.rb4),
                m2.stiffness,
                Self::shape(m2, opts.stiffness),
                self.mesh2_ratio(),
                Damping::Ratio(m2.damping_ratio),
                bl(m2),
            )
            .with_term("y3", -1.0)
            .with_term("y4", 1.0)
            .with_phase(TAU * m2.phase_fraction)
            .with_contact_only_damping(contact_only),
            Element::shaft(
                "shaft1",
                "theta0",
                "theta1",
                self.shaft1.stiffness,
                Damping::Ratio(self.shaft1.damping_ratio),
            ),
            Element::shaft(
                "shaft2",
                "theta2",
                "theta3",
                self.shaft2.stiffness,
                Damping::Ratio(self.shaft2.damping_ratio),
            ),
            Element::shaft(
                "shaft3",
                "theta4",
                "theta5",
                self.shaft3.stiffness,
                Damping::Ratio(self.shaft3.damping_ratio),
            ),
            bearing("y1"),
            bearing("y2"),
            bearing("y3"),
            bearing("y4"),
        ];
        let t_l = self.torque(opts);
        let t_m = t_l / r.ratio();
        let (motor, load) = match opts.loads {
            LoadCase::Steady => (
                LoadSchedule::Constant { value: t_m },
                LoadSchedule::Constant { value: -t_l },
            ),
            LoadCase::LoadDrop { at_s } => (
                LoadSchedule::Step {
                    before: t_m,
                    after: 0.0,
                    at: at_s,
                },
                LoadSchedule::Step {
                    before: -t_l,
                    after: 0.0,
                    at: at_s,
                },
            ),
            LoadCase::Reversal { at_s } => (
                LoadSchedule::Step {
                    before: t_m,
                    after: -t_m,
                    at: at_s,
                },
                LoadSchedule::Step {
                    before: -t_l,
                    after: t_l,
                    at: at_s,
                },
            ),
        };
        let asm = Assembly {
            name: self.name.clone(),
            dofs,
            elements,
            loads: vec![
                Load {
                    dof: "theta0".into(),
                    schedule: motor,
                },
                Load {
                    dof: "theta5".into(),
                    schedule: load,
                },
            ],
            length_ref: self.length_ref_um * um,
            sensor: 0,
        };
        asm.validate()?;
        Ok(asm)
    }
}
