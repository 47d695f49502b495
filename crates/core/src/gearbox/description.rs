//! The gearbox description a user writes (format `gearwear-gearbox`, version 1): TOML or JSON.
//!
//! Only tooth counts and how the gears sit on shafts are required; every physical value is
//! optional and gets a documented default when the model is built ([`super::build`]). The field
//! names carry their units (`_mm`, `_um`, `_hz`, `_deg`, `_rad`, `_n_per_m`, `_kg`, kg·m² for
//! `inertia`). See `docs/gearbox.md` for the format with a worked example per kind.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::factors::PhysicsFactors;
use crate::error::GearboxError;

/// The format tag every description carries.
pub const FORMAT: &str = "gearwear-gearbox";
/// The one format version this build reads.
pub const VERSION: u32 = 1;
/// Largest description accepted (bytes): a real one is a few kilobytes.
pub const MAX_DESCRIPTION_BYTES: usize = 256 * 1024;
/// Most stages a description may have.
pub const MAX_STAGES: usize = 16;

/// A gearbox as its user describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GearboxDescription {
    /// Always `"gearwear-gearbox"`.
    pub format: String,
    /// Format version (1).
    pub version: u32,
    /// A short identifier (letters, digits, `-`, `_`, `.`).
    pub name: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The shaft whose rate is a record's `shaft_hz` (the driven input).
    pub input_shaft: String,
    /// The shaft that carries the load (default: the last stage's driven member).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub output_shaft: Option<String>,
    /// The stages, from the input towards the output.
    #[serde(rename = "stage", alias = "stages")]
    pub stages: Vec<StageSpec>,
    /// Optional per-shaft values (torsional stiffness, extra inertia such as a motor rotor).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shafts: BTreeMap<String, ShaftSpec>,
    /// Reference length that makes deflections dimensionless and is the unit of the wear
    /// degree `ea` (µm; default 5, the first paper's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_length_um: Option<f64>,
    /// Pin Ω1 = 1 to this stage-1 mesh frequency (Hz): the reference mesh's stiffness then
    /// follows from it (the first paper's convention) instead of from the geometry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_frequency_hz: Option<f64>,
    /// Static load as the dimensionless reference-mesh force `F̄1 = F1 / (k1 b_ref)` (default
    /// 0.15, the value calibrated on the first paper's rig); exclusive with `input_torque_nm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub static_load: Option<f64>,
    /// Static load as the torque on the input shaft (N·m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_torque_nm: Option<f64>,
    /// The input-shaft rate the machine usually runs at (Hz): the default signature grid spans
    /// ±15 % around it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_input_hz: Option<f64>,
    /// Where the simulated sensor sits (default: stage 1's mesh).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<SensorSpec>,
    /// Stages (1-based) whose composite error is the wear degree `ea` (default: every parallel
    /// stage, the first paper's convention; every stage when there is no parallel one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wear_stages: Option<Vec<usize>>,
    /// Mesh values that apply to every mesh unless the stage gives its own.
    #[serde(default, skip_serializing_if = "MeshSpec::is_empty")]
    pub mesh: MeshSpec,
    /// Material density for inertias estimated from geometry (kg/m³; default 7850, steel).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density_kg_m3: Option<f64>,
    /// Rolling-element bearings whose defect frequencies the findings look for (`[[bearing]]`;
    /// they do not enter the dynamic model).
    #[serde(
        rename = "bearing",
        alias = "bearings",
        default,
        skip_serializing_if = "Vec::is_empty"
    )]
    pub bearings: Vec<BearingSpec>,
    /// A machine's own physics over these values: per-stage factors of the meshes' stiffness,
    /// damping, fluctuation and transmission error, of the load and of the clearance
    /// ([`super::factors`]; fitted to a machine's healthy records by
    /// [`crate::diagnosis::machine_physics`]). Absent: the description's values.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physics_factors: Option<PhysicsFactors>,
}

/// A rolling-element bearing (`[[bearing]]`): its shaft and either its geometry or its
/// defect orders (defect frequency over the shaft's rate) directly.
///
/// From the geometry (rolling elements `n`, ball diameter `d`, pitch diameter `D`, contact
/// angle `β`, outer race fixed): `BPFO = n/2 (1 − d/D cos β)`, `BPFI = n/2 (1 + d/D cos β)`,
/// `BSF = D/(2d) (1 − (d/D cos β)²)`, `FTF = ½ (1 − d/D cos β)`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BearingSpec {
    /// A short name the findings use (e.g. `"in-output-side"`).
    pub name: String,
    /// The shaft it carries (a shaft of the stages).
    pub shaft: String,
    /// Number of rolling elements.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rolling_elements: Option<u32>,
    /// Ball (roller) diameter (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ball_diameter_mm: Option<f64>,
    /// Pitch diameter (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_diameter_mm: Option<f64>,
    /// Contact angle (degrees; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_angle_deg: Option<f64>,
    /// Ball-pass frequency of the outer race over the shaft rate (instead of the geometry).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bpfo: Option<f64>,
    /// Ball-pass frequency of the inner race over the shaft rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bpfi: Option<f64>,
    /// Ball spin frequency over the shaft rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bsf: Option<f64>,
    /// Fundamental train (cage) frequency over the shaft rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ftf: Option<f64>,
}

/// A bearing's defect orders: defect frequency over its shaft's rate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DefectOrders {
    pub bpfo: f64,
    pub bpfi: f64,
    pub bsf: f64,
    pub ftf: f64,
}

impl BearingSpec {
    /// The defect orders: those given, else from the geometry. `Err` names what is missing or
    /// out of range.
    pub fn defect_orders(&self) -> Result<DefectOrders, String> {
        let given = [self.bpfo, self.bpfi, self.bsf, self.ftf];
        if given.iter().all(Option::is_some) {
            let o = DefectOrders {
                bpfo: self.bpfo.unwrap_or_default(),
                bpfi: self.bpfi.unwrap_or_default(),
                bsf: self.bsf.unwrap_or_default(),
                ftf: self.ftf.unwrap_or_default(),
            };
            if [o.bpfo, o.bpfi, o.bsf, o.ftf]
                .iter()
                .all(|v| v.is_finite() && *v > 0.0)
            {
                return Ok(o);
            }
            return Err("its defect orders must be positive numbers".into());
        }
        if given.iter().any(Option::is_some) {
            return Err(
                "give all four defect orders (bpfo, bpfi, bsf, ftf) or the geometry \
                 (rolling_elements, ball_diameter_mm, pitch_diameter_mm)"
                    .into(),
            );
        }
        let (Some(n), Some(d), Some(p)) = (
            self.rolling_elements,
            self.ball_diameter_mm,
            self.pitch_diameter_mm,
        ) else {
            return Err(
                "give rolling_elements, ball_diameter_mm and pitch_diameter_mm (or \
                 the four defect orders bpfo, bpfi, bsf, ftf)"
                    .into(),
            );
        };
        let beta = self.contact_angle_deg.unwrap_or(0.0);
        if n == 0 || !(d > 0.0 && p > d && (0.0..90.0).contains(&beta)) {
            return Err(
                "needs at least one rolling element, 0 < ball diameter < pitch \
                 diameter and a contact angle in [0, 90) degrees"
                    .into(),
            );
        }
        let r = d / p * beta.to_radians().cos();
        let n = n as f64;
        Ok(DefectOrders {
            bpfo: 0.5 * n * (1.0 - r),
            bpfi: 0.5 * n * (1.0 + r),
            bsf: p / (2.0 * d) * (1.0 - r * r),
            ftf: 0.5 * (1.0 - r),
        })
    }
}

/// Which mesh's relative acceleration the simulated sensor measures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// 1-based stage index (default 1).
    #[serde(default = "one")]
    pub stage: usize,
}

fn one() -> usize {
    1
}

/// One stage as written: a flat table whose `kind` says which members it must have.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageSpec {
    /// `parallel` (external spur or helical pair, treated as spur) or `planetary`.
    pub kind: String,
    /// Parallel: the first gear of the pair (on the side of the input as a rule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pinion: Option<GearSpec>,
    /// Parallel: the second gear of the pair.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gear: Option<GearSpec>,
    /// Planetary: the sun.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sun: Option<GearSpec>,
    /// Planetary: the planets (all alike).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub planets: Option<PlanetsSpec>,
    /// Planetary: the ring (internal gear).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ring: Option<GearSpec>,
    /// Planetary: the carrier.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub carrier: Option<CarrierSpec>,
    /// Planetary: the member held by the housing, `ring`, `carrier` or `sun`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed: Option<String>,
    /// Planetary: the teeth do not satisfy `ring = sun + 2 planet` on purpose (profile-shifted
    /// set); skips the coaxial check.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub profile_shifted: bool,
    /// Parallel: the mesh's values; planetary: the sun–planet meshes' values.
    #[serde(default, skip_serializing_if = "MeshSpec::is_empty")]
    pub mesh: MeshSpec,
    /// Planetary: the ring–planet meshes' values (default: those of `mesh`).
    #[serde(default, skip_serializing_if = "MeshSpec::is_empty")]
    pub ring_mesh: MeshSpec,
}

/// A gear: its shaft, its teeth and optional geometry and inertia.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GearSpec {
    /// The shaft the gear sits on (two gears on one shaft turn together).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shaft: Option<String>,
    /// Number of teeth (a positive integer).
    pub teeth: i64,
    /// Base-circle radius (mm); else from `module_mm` and `pressure_angle_deg`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_radius_mm: Option<f64>,
    /// Module (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub module_mm: Option<f64>,
    /// Pressure angle (degrees; default 20).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pressure_angle_deg: Option<f64>,
    /// Face width (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face_width_mm: Option<f64>,
    /// Moment of inertia about its axis (kg·m²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertia: Option<f64>,
    /// Mass (kg); used for planets (they add `m rc²` to the carrier).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
}

/// The planets of a planetary stage.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanetsSpec {
    /// How many planets (1 … 32).
    pub count: i64,
    /// Teeth of each planet.
    pub teeth: i64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_radius_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub module_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pressure_angle_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face_width_mm: Option<f64>,
    /// Each planet's moment of inertia about its own axis (kg·m²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertia: Option<f64>,
    /// Each planet's mass (kg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
}

/// The planet carrier.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CarrierSpec {
    /// The shaft the carrier drives or is driven by (none when the carrier is fixed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shaft: Option<String>,
    /// Planet-centre radius projected on the line of action (mm; default: sun + planet base
    /// radii).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_mm: Option<f64>,
    /// Moment of inertia without the planets (kg·m²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertia: Option<f64>,
}

/// Values of a mesh (or of every mesh, at the top level). All optional.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// Mean mesh stiffness along the line of action (N/m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_n_per_m: Option<f64>,
    /// Mean mesh stiffness per face width, N/(mm·µm) (ISO 6336-1's c_γα, about 20 for steel).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_per_width_n_per_mm_um: Option<f64>,
    /// Mean stiffness over the reference (stage-1) mesh's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_ratio: Option<f64>,
    /// First-harmonic stiffness fluctuation ε (default 0.2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fluctuation: Option<f64>,
    /// Contact-ratio square wave instead of the first harmonic.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub square_wave: Option<SquareWave>,
    /// Damping ratio ξ (default 0.07).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub damping_ratio: Option<f64>,
    /// Half-clearance (backlash) along the line of action (µm; default 0.05 × module).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_clearance_um: Option<f64>,
    /// Composite transmission-error amplitude when the mesh is not a wear mesh (µm; default
    /// 0.1 × the reference length, the first paper's planetary value).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_um: Option<f64>,
    /// Phase of the stiffness variation and the error (rad; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_rad: Option<f64>,
}

/// The contact-ratio square-wave stiffness (see `model::StiffnessShape::SquareWave`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SquareWave {
    pub contact_ratio: f64,
    pub double_to_single: f64,
    pub smoothing: f64,
}

impl MeshSpec {
    /// True when nothing is set.
    pub fn is_empty(&self) -> bool {
        *self == MeshSpec::default()
    }

    /// `self`'s values where set, else `fallback`'s.
    pub fn or(&self, fallback: &MeshSpec) -> MeshSpec {
        MeshSpec {
            stiffness_n_per_m: self.stiffness_n_per_m.or(fallback.stiffness_n_per_m),
            stiffness_per_width_n_per_mm_um: self
                .stiffness_per_width_n_per_mm_um
                .or(fallback.stiffness_per_width_n_per_mm_um),
            stiffness_ratio: self.stiffness_ratio.or(fallback.stiffness_ratio),
            fluctuation: self.fluctuation.or(fallback.fluctuation),
            square_wave: self.square_wave.or(fallback.square_wave),
            damping_ratio: self.damping_ratio.or(fallback.damping_ratio),
            half_clearance_um: self.half_clearance_um.or(fallback.half_clearance_um),
            error_um: self.error_um.or(fallback.error_um),
            phase_rad: self.phase_rad.or(fallback.phase_rad),
        }
    }
}

/// Optional values of a shaft.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShaftSpec {
    /// Torsional stiffness between the gears on the shaft (N·m/rad); absent: rigid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub torsional_stiffness_nm_per_rad: Option<f64>,
    /// Extra inertia on the shaft besides its gears (a motor rotor, a coupling, a load; kg·m²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertia: Option<f64>,
    /// Damping ratio of the shaft's torsion (default 0.02).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub damping_ratio: Option<f64>,
}

/// Text formats a description may come in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TextFormat {
    Toml,
    Json,
}

impl GearboxDescription {
    /// Parse a description. `format` `None`: JSON if the text starts with `{`, else TOML.
    /// `origin` names the source in errors (a path, "request body").
    pub fn parse(
        text: &str,
        format: Option<TextFormat>,
        origin: &str,
    ) -> Result<Self, GearboxError> {
        if text.len() > MAX_DESCRIPTION_BYTES {
            return Err(GearboxError::TooLarge {
                bytes: text.len(),
                max: MAX_DESCRIPTION_BYTES,
            });
        }
        if text.trim().is_empty() {
            return Err(GearboxError::Syntax {
                origin: origin.into(),
                reason: "the description is empty; see docs/gearbox.md for the format".into(),
            });
        }
        let fmt = format.unwrap_or_else(|| {
            if text.trim_start().starts_with('{') {
                TextFormat::Json
            } else {
                TextFormat::Toml
            }
        });
        let d: GearboxDescription = match fmt {
            TextFormat::Json => serde_json::from_str(text).map_err(|e| GearboxError::Syntax {
                origin: origin.into(),
                reason: e.to_string(),
            })?,
            TextFormat::Toml => toml::from_str(text).map_err(|e| GearboxError::Syntax {
                origin: origin.into(),
                reason: e.to_string().trim_end().to_string(),
            })?,
        };
        if d.format != FORMAT {
            return Err(GearboxError::Format {
                found: d.format.clone(),
            });
        }
        if d.version != VERSION {
            return Err(GearboxError::Version { found: d.version });
        }
        Ok(d)
    }

    /// Canonical JSON (fields in declaration order, no whitespace): what the hash covers.
    pub fn canonical_json(&self) -> String {
        serde_json::to_string(self).expect("a description serialises")
    }
}
