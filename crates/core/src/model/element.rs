//! The elements a gear train is assembled from.
//!
//! Every coupling element (gear mesh, torsional shaft, bearing support) has one *deflection*
//! coordinate that is a linear combination of the generalised coordinates minus a prescribed
//! error:
//!
//! ```text
//! d_j = Σ_i G_ji q_i − e_j(t)
//! ```
//!
//! and transmits the force `F_j = k_j(t) f_b(d_j) + c_j ḋ_j`, where `f_b` is the dead-zone
//! (backlash) function with half-clearance `b` (`b = 0`: a plain linear spring). The assembly
//! ([`crate::model::Assembly`]) stacks the rows `G_j` into `G` and writes the equations of motion
//! `M q̈ = −Gᵀ F + T` in the relative form `d̈ + A F = G M⁻¹ T − ë`, `A = G M⁻¹ Gᵀ`.
//!
//! Units: SI throughout (m, rad, kg, kg·m², N/m, N·s/m, N·m). A rotational coordinate's
//! "inertia" is in kg·m², a translational one's in kg; a mesh row uses base radii in m so that
//! its deflection is a length along the line of action.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// What a generalised coordinate is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DofKind {
    /// An angle (rad); its inertia is a moment of inertia (kg·m²).
    Rotation,
    /// A displacement (m); its inertia is a mass (kg).
    Translation,
}

/// A generalised coordinate with its inertia.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Dof {
    pub name: String,
    pub kind: DofKind,
    /// kg·m² for a rotation, kg for a translation. Must be positive and finite.
    pub inertia: f64,
}

impl Dof {
    /// A rotational coordinate with moment of inertia `j` (kg·m²).
    pub fn rotation(name: impl Into<String>, j: f64) -> Result<Self> {
        Self::new(name.into(), DofKind::Rotation, j)
    }
    /// A translational coordinate with mass `m` (kg).
    pub fn translation(name: impl Into<String>, m: f64) -> Result<Self> {
        Self::new(name.into(), DofKind::Translation, m)
    }
    fn new(name: String, kind: DofKind, inertia: f64) -> Result<Self> {
        if !(inertia.is_finite() && inertia > 0.0) {
            return Err(Error::param(
                format!("inertia of {name}"),
                inertia,
                "must be positive and finite",
            ));
        }
        Ok(Dof {
            name,
            kind,
            inertia,
        })
    }
}

/// One harmonic `a sin(ω τ + φ)` of a prescribed error (transmission error, eccentricity).
///
/// `freq_ratio` is the frequency over the reference (stage-1) mesh frequency, so in
/// dimensionless time `ω = freq_ratio · Ω1`. `amplitude` is in m in an [`Element`] and in units
/// of the reference length once resolved.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Harmonic {
    pub amplitude: f64,
    pub freq_ratio: f64,
    /// rad
    pub phase: f64,
}

/// Shape of the time-varying mesh stiffness over one mesh period, normalised to mean 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "shape")]
pub enum StiffnessShape {
    /// Constant stiffness (shafts, bearings).
    Constant,
    /// `1 + ε cos(ω τ + φ)`: the first harmonic (the first seed's form).
    FirstHarmonic { eps: f64 },
    /// The contact-ratio square wave (the second seed's correction): over one mesh period two
    /// tooth pairs carry load for a fraction `contact_ratio − 1` and one pair for the rest; the
    /// double-contact stiffness is `double_to_single` times the single-contact one. The edges
    /// are smoothed with `tanh` over `smoothing` (a fraction of the mesh period) and the whole
    /// wave is rescaled to mean 1.
    SquareWave {
        contact_ratio: f64,
        double_to_single: f64,
        smoothing: f64,
    },
}

impl StiffnessShape {
    /// Check the parameters.
    pub fn validate(&self, name: &str) -> Result<()> {
        match *self {
            StiffnessShape::Constant => Ok(()),
            StiffnessShape::FirstHarmonic { eps } => {
                if !(eps.is_finite() && (0.0..1.0).contains(&eps)) {
                    return Err(Error::param(
                        format!("{name}: stiffness fluctuation ε"),
                        eps,
                        "must lie in [0, 1) so the stiffness stays positive",
                    ));
                }
                Ok(())
            }
            StiffnessShape::SquareWave {
                contact_ratio,
                double_to_single,
                smoothing,
            } => {
                if !(contact_ratio > 1.0 && contact_ratio < 2.0) {
                    return Err(Error::param(
                        format!("{name}: contact ratio"),
                        contact_ratio,
                        "the square-wave form needs 1 < contact ratio < 2",
                    ));
                }
                if !(double_to_single.is_finite() && double_to_single >= 1.0) {
                    return Err(Error::param(
                        format!("{name}: double-to-single stiffness ratio"),
                        double_to_single,
                        "must be ≥ 1",
                    ));
                }
                if !(smoothing > 0.0 && smoothing < 0.25) {
                    return Err(Error::param(
                        format!("{name}: smoothing"),
                        smoothing,
                        "must lie in (0, 0.25) of a mesh period",
                    ));
                }
                Ok(())
            }
        }
    }
}

/// How an element's viscous damping is given.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind", content = "value")]
pub enum Damping {
    /// Damping ratio ξ of the element's own equivalent oscillator:
    /// `c = 2 ξ sqrt(k_m m_e)`, `m_e = 1 / A_jj`.
    Ratio(f64),
    /// Viscous coefficient in N·s/m (or N·m·s/rad for a shaft written in angles).
    Coefficient(f64),
}

/// A coupling element: a gear mesh, a shaft, or a bearing support.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Element {
    pub name: String,
    /// "mesh", "shaft", "bearing" or an effect's name: descriptive only.
    pub kind: String,
    /// The row of `G`: (coordinate name, coefficient). For a mesh the coefficients are base
    /// radii (m) with signs; for a shaft ±1; for a bearing 1.
    pub terms: Vec<(String, f64)>,
    /// Mean stiffness (N/m along the line of action, or N·m/rad for a shaft in angles).
    pub stiffness: f64,
    pub shape: StiffnessShape,
    /// Mesh frequency over the reference mesh frequency (0 for elements with no mesh cycle).
    pub freq_ratio: f64,
    /// Phase of the stiffness variation, rad.
    pub phase: f64,
    pub damping: Damping,
    /// Half-clearance `b` (same unit as the deflection); 0 for no backlash.
    pub backlash: f64,
    /// Prescribed error `e_j(t) = Σ a sin(ω τ + φ)` (amplitudes in the deflection's unit).
    pub error: Vec<Harmonic>,
    /// Contact-only damping: the viscous term acts only while the clearance is closed,
    /// `F = k f_b(d) + c ḋ` for `|d| > b` and `F = 0` inside the clearance (free flight). This is
    /// the usual contact-damping choice of backlash/impact models (the damping models the
    /// losses of the loaded tooth contact, which are absent while the flanks are apart).
    /// `false` (the default, and the first seed's form): `c ḋ` acts everywhere. Has no effect
    /// when `backlash` is 0.
    #[serde(default)]
    pub damping_in_contact_only: bool,
    /// A locally damaged tooth (crack, broken tooth) on one gear of this mesh: the mesh
    /// stiffness dips once per revolution of that gear's shaft ([`ToothDamage`]). `None`: healthy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tooth_damage: Option<ToothDamage>,
}

/// A local tooth fault on one gear of a mesh: while the damaged tooth is in mesh the mesh
/// stiffness is reduced,
///
/// `k(τ) → k(τ) (1 − depth · w(u))`, `u = frac(Ω_s τ / 2π + phase / 2π)`,
///
/// with `Ω_s = shaft_ratio · Ω1` the rate of the damaged gear's shaft and `w` a raised-cosine
/// (Hann) pulse of length `width` revolutions (`w(u) = ½ (1 − cos 2π u / width)` for
/// `u < width`, else 0). With `width = contact_ratio / z` the pulse spans the damaged tooth's
/// time in mesh. Once per shaft revolution: the fault's signature is shaft-order sidebands
/// around every mesh harmonic and an impulsive residual after time-synchronous averaging.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ToothDamage {
    /// Fraction of the mesh stiffness lost at the centre of the pulse, in [0, 1).
    pub depth: f64,
    /// The damaged gear's shaft rate over the reference mesh frequency (`1 / z` of that gear
    /// for a gear of the reference mesh).
    pub shaft_ratio: f64,
    /// Pulse length in revolutions of that shaft, in (0, 0.5].
    pub width: f64,
    /// rad.
    pub phase: f64,
}

impl ToothDamage {
    /// The stiffness factor `1 − depth · w(u)` at shaft phase fraction `u ∈ [0, 1)`.
    #[inline]
    pub fn factor(&self, u: f64) -> f64 {
        if u < self.width {
            1.0 - self.depth * 0.5 * (1.0 - (std::f64::consts::TAU * u / self.width).cos())
        } else {
            1.0
        }
    }

    fn validate(&self, name: &str) -> Result<()> {
        if !(self.depth.is_finite() && (0.0..1.0).contains(&self.depth)) {
            return Err(Error::param(
                format!("{name}: tooth-damage depth"),
                self.depth,
                "must lie in [0, 1) so the stiffness stays positive",
            ));
        }
        if !(self.shaft_ratio.is_finite() && self.shaft_ratio > 0.0) {
            return Err(Error::param(
                format!("{name}: tooth-damage shaft ratio"),
                self.shaft_ratio,
                "must be positive",
            ));
        }
        if !(self.width > 0.0 && self.width <= 0.5 && self.phase.is_finite()) {
            return Err(Error::param(
                format!("{name}: tooth-damage pulse width"),
                self.width,
                "must lie in (0, 0.5] revolutions (and the phase be finite)",
            ));
        }
        Ok(())
    }
}

impl Element {
    /// A gear mesh between two rotations with base radii `r_a`, `r_b` (m):
    /// `d = r_a θ_a − r_b θ_b − e(t)`. Extra terms (transverse motion, a fixed ring) can be
    /// added with [`Element::with_term`].
    #[allow(clippy::too_many_arguments)]
    pub fn mesh(
        name: impl Into<String>,
        a: (&str, f64),
        b: (&str, f64),
        stiffness: f64,
        shape: StiffnessShape,
        freq_ratio: f64,
        damping: Damping,
        backlash: f64,
    ) -> Self {
        let mut terms = vec![(a.0.to_string(), a.1)];
        if b.1 != 0.0 {
            terms.push((b.0.to_string(), -b.1));
        }
        Element {
            name: name.into(),
            kind: "mesh".into(),
            terms,
            stiffness,
            shape,
            freq_ratio,
            phase: 0.0,
            damping,
            backlash,
            error: Vec::new(),
            damping_in_contact_only: false,
            tooth_damage: None,
        }
    }

    /// A torsional shaft between two rotations: `d = θ_a − θ_b`, stiffness in N·m/rad.
    pub fn shaft(
        name: impl Into<String>,
        a: &str,
        b: &str,
        stiffness: f64,
        damping: Damping,
    ) -> Self {
        Element {
            name: name.into(),
            kind: "shaft".into(),
            terms: vec![(a.to_string(), 1.0), (b.to_string(), -1.0)],
            stiffness,
            shape: StiffnessShape::Constant,
            freq_ratio: 0.0,
            phase: 0.0,
            damping,
            backlash: 0.0,
            error: Vec::new(),
            damping_in_contact_only: false,
            tooth_damage: None,
        }
    }

    /// A bearing support of a translational coordinate to the ground: `d = y`, N/m.
    pub fn bearing(name: impl Into<String>, y: &str, stiffness: f64, damping: Damping) -> Self {
        Element {
            name: name.into(),
            kind: "bearing".into(),
            terms: vec![(y.to_string(), 1.0)],
            stiffness,
            shape: StiffnessShape::Constant,
            freq_ratio: 0.0,
            phase: 0.0,
            damping,
            backlash: 0.0,
            error: Vec::new(),
            damping_in_contact_only: false,
            tooth_damage: None,
        }
    }

    /// Add a term `coeff · q` to the deflection.
    pub fn with_term(mut self, dof: &str, coeff: f64) -> Self {
        self.terms.push((dof.to_string(), coeff));
        self
    }

    /// Add an error harmonic (amplitude in m or rad, frequency over the reference mesh
    /// frequency, phase in rad).
    pub fn with_error(mut self, amplitude: f64, freq_ratio: f64, phase: f64) -> Self {
        self.error.push(Harmonic {
            amplitude,
            freq_ratio,
            phase,
        });
        self
    }

    /// Let the viscous damping act only while the clearance is closed (see
    /// [`Element::damping_in_contact_only`]).
    pub fn with_contact_only_damping(mut self, on: bool) -> Self {
        self.damping_in_contact_only = on;
        self
    }

    /// Give one gear of this mesh a damaged tooth ([`ToothDamage`]).
    pub fn with_tooth_damage(mut self, damage: ToothDamage) -> Self {
        self.tooth_damage = Some(damage);
        self
    }

    /// Set the mesh phase (stiffness variation; error harmonics carry their own phase).
    pub fn with_phase(mut self, phase: f64) -> Self {
        self.phase = phase;
        self
    }

    /// Check the element's parameters (refuses zero stiffness, negative damping, …).
    pub fn validate(&self) -> Result<()> {
        let n = &self.name;
        if self.terms.is_empty() {
            return Err(Error::InvalidConfig(format!(
                "element {n} couples no coordinate"
            )));
        }
        if !(self.stiffness.is_finite() && self.stiffness > 0.0) {
            return Err(Error::param(
                format!("{n}: stiffness"),
                self.stiffness,
                "must be positive",
            ));
        }
        match self.damping {
            Damping::Ratio(x) | Damping::Coefficient(x) if !(x.is_finite() && x >= 0.0) => {
                return Err(Error::param(format!("{n}: damping"), x, "must be ≥ 0"));
            }
            _ => {}
        }
        if !(self.backlash.is_finite() && self.backlash >= 0.0) {
            return Err(Error::param(
                format!("{n}: backlash"),
                self.backlash,
                "must be ≥ 0",
            ));
        }
        if !(self.freq_ratio.is_finite() && self.freq_ratio >= 0.0) {
            return Err(Error::param(
                format!("{n}: frequency ratio"),
                self.freq_ratio,
                "must be ≥ 0",
            ));
        }
        if self.freq_ratio == 0.0 && !matches!(self.shape, StiffnessShape::Constant) {
            return Err(Error::InvalidConfig(format!(
                "element {n} has a varying stiffness but no mesh frequency"
            )));
        }
        for h in &self.error {
            if !(h.amplitude.is_finite() && h.freq_ratio.is_finite() && h.phase.is_finite()) {
                return Err(Error::param(
                    format!("{n}: error harmonic"),
                    h.amplitude,
                    "must be finite",
                ));
            }
        }
        if let Some(t) = &self.tooth_damage {
            t.validate(n)?;
        }
        self.shape.validate(n)
    }
}

/// A generalised force on a coordinate (N·m on a rotation, N on a translation).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Load {
    pub dof: String,
    pub schedule: LoadSchedule,
}

/// How a load varies in time (times in s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum LoadSchedule {
    /// A constant value.
    Constant { value: f64 },
    /// The value that balances every other constant load on the rigid-body mode (so the mean
    /// speed does not drift): the output torque of a drive running at constant speed.
    Balancing,
    /// `before` until `at` (s), then `after`.
    Step { before: f64, after: f64, at: f64 },
}
