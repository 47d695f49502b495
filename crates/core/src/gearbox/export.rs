//! A gearbox's resolved dimensionless model as a self-contained JSON document, so that anyone
//! can re-integrate it independently (`gearwear model --export json`).

use serde::Serialize;

use super::{AssumedValue, Gearbox, GearboxDescription};
use crate::model::{DimensionlessModel, StiffnessShape};

/// Export format (version 1). Vectors follow `order`.
#[derive(Debug, Clone, Serialize)]
pub struct ModelExport {
    pub format: &'static str,
    pub model: String,
    /// The equation the arrays parameterise.
    pub equation: &'static str,
    /// Element (coordinate) order: x1, x2, xsp1..4, xrp1..4 for Model A.
    pub order: Vec<String>,
    /// Ā (row-major, n × n).
    #[serde(rename = "A")]
    pub a: Vec<Vec<f64>>,
    pub k_ratio: Vec<f64>,
    /// First-harmonic stiffness fluctuation ε (0 for other shapes, see `stiffness_shape`).
    pub eps: Vec<f64>,
    pub c: Vec<f64>,
    #[serde(rename = "F")]
    pub f: Vec<f64>,
    pub omega_ratio: Vec<f64>,
    /// Phase φ_j (rad) of both the stiffness variation and the composite error.
    pub phase: Vec<f64>,
    /// Half-clearance b̄_j (units of `length_ref_m`).
    pub backlash: Vec<f64>,
    /// Composite-error amplitude ē_j at the mesh frequency (units of `length_ref_m`).
    pub error_amplitude: Vec<f64>,
    pub stiffness_shape: Vec<StiffnessShape>,
    pub omega_h_rad_s: f64,
    pub length_ref_m: f64,
    /// Ω1 = 1 corresponds to this input-shaft rate (Hz).
    pub shaft_hz_at_omega1_1: f64,
    /// The reference (stage-1) mesh frequency at Ω1 = 1 (Hz), `ω_h / 2π`.
    pub reference_frequency_hz: f64,
    /// Element the simulated sensor measures.
    pub sensor_element: String,
    /// The gearbox description the model was built from.
    pub config: GearboxDescription,
    /// Its SHA-256 (the signature tables' `model_hash`).
    pub gearbox_hash: String,
    /// Every value the description did not give, with the rule that gave it.
    pub assumed: Vec<AssumedValue>,
    /// True when the dynamics rest on estimates (no stiffness, inertia or reference frequency
    /// given): the model's resonances and so Ω1 are then uncertain.
    pub dynamics_estimated: bool,
}

const EQUATION: &str = "x'' + A (k(tau) * f(x) + c * x') = F + e * (omega_ratio*Omega1)^2 * sin(omega_ratio*Omega1*tau + phase); \
k_j(tau) = k_ratio_j (1 + eps_j cos(omega_ratio_j*Omega1*tau + phase_j)); \
f(x) = x - b (x > b), 0 (|x| <= b), x + b (x < -b); tau = omega_h t; x = deflection / length_ref";

impl ModelExport {
    /// Export the resolved model of a gearbox.
    pub fn new(m: &DimensionlessModel, gb: &Gearbox) -> Self {
        let n = m.n();
        ModelExport {
            format: "gearwear-model/1",
            model: m.name.clone(),
            equation: EQUATION,
            order: m.names.clone(),
            a: (0..n)
                .map(|i| (0..n).map(|j| m.a[(i, j)]).collect())
                .collect(),
            k_ratio: m.k_ratio.clone(),
            eps: m
                .shape
                .iter()
                .map(|s| match s {
                    StiffnessShape::FirstHarmonic { eps } => *eps,
                    _ => 0.0,
                })
                .collect(),
            c: m.c.clone(),
            f: m.f.clone(),
            omega_ratio: m.omega_ratio.clone(),
            phase: m.phase.clone(),
            backlash: m.backlash.clone(),
            error_amplitude: m
                .error
                .iter()
                .zip(&m.omega_ratio)
                .map(|(hs, r)| {
                    hs.iter()
                        .filter(|h| h.freq_ratio == *r)
                        .map(|h| h.amplitude)
                        .sum()
                })
                .collect(),
            stiffness_shape: m.shape.clone(),
            omega_h_rad_s: m.omega_h,
            length_ref_m: m.length_ref,
            shaft_hz_at_omega1_1: gb.reference_frequency_hz() * gb.input_shaft_ratio(),
            reference_frequency_hz: gb.reference_frequency_hz(),
            sensor_element: m.names[m.sensor].clone(),
            config: gb.description.clone(),
            gearbox_hash: gb.hash.clone(),
            assumed: gb.assumed.clone(),
            dynamics_estimated: gb.dynamics_estimated(),
        }
    }
}
