//! The library of candidate effects the closed loop can add to the model, and the augmented
//! model they make.
//!
//! | effect | physics | where it enters | fingerprint in the residual | parameters |
//! | --- | --- | --- | --- | --- |
//! | `shaft-modulation` | eccentricity / run-out of the input pinion: the stage-1 composite error is amplitude-modulated at the input-shaft rate `f_s = f1 / z1` | **element**: two error harmonics of amplitude `e` (units of b) on mesh `x1` at `(1 ± 1/z1) f1` | lines at `f1 ± f_s`, `2 f1 ± f_s` (and at the other model lines ± f_s), absent from the model | `e` |
//! | `path-resonance` | a housing / transfer-path / sensor-mount mode between gear mesh and accelerometer | **sensor stage**: `H(r) = 1 / (1 − (r/ρ)² + 2iζ r/ρ)` on the gear signal, before the (flat) measurement noise | a smooth trend in the residual at the model's lines: lines near `ρ f1` too strong, lines far above it too weak | `ρ = f_r/f1`, `ζ` |
//! | `planetary-wear` | a worn planetary stage: larger composite error of the sun–planet and ring–planet meshes | **element**: planetary error amplitude `p` (units of b) on every planetary mesh (baseline 0.1) | the f3 family `f3`, `2 f3`, `f1 ± f3` stronger than the model | `p` |

use std::collections::BTreeMap;

use serde::Serialize;

use crate::error::Result;
use crate::gearbox::Gearbox;
use crate::model::{DimensionlessModel, Wear};

/// Names of the library's effects.
pub const SHAFT_MODULATION: &str = "shaft-modulation";
/// See the module table.
pub const PATH_RESONANCE: &str = "path-resonance";
/// See the module table.
pub const PLANETARY_WEAR: &str = "planetary-wear";

/// An effect with its fitted parameters (the report's `effects` entries).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Effect {
    /// One of [`SHAFT_MODULATION`], [`PATH_RESONANCE`], [`PLANETARY_WEAR`].
    pub name: String,
    /// `element` or `sensor-stage`.
    pub kind: &'static str,
    /// Parameter name → value (units in the name).
    pub parameters: BTreeMap<String, f64>,
}

/// The physical (element) part of a model: wear, planetary error, eccentricity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ElementParams {
    /// Fixed-axis wear `ea` (units of b).
    pub ea: f64,
    /// Planetary composite-error amplitude (units of b).
    pub planetary: f64,
    /// Shaft-modulation sideband amplitude `e` on mesh x1 (units of b); 0: none.
    pub eccentricity: f64,
}

/// A second-order path resonance at `rho · f1` with damping ratio `zeta`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Resonance {
    /// Resonance frequency over f1.
    pub rho: f64,
    /// Damping ratio.
    pub zeta: f64,
}

impl Resonance {
    /// `20 log10 |H(r)|`, `H(r) = 1 / (1 − (r/ρ)² + 2iζ r/ρ)`.
    pub fn gain_db(&self, r: f64) -> f64 {
        let u = r / self.rho;
        let re = 1.0 - u * u;
        let im = 2.0 * self.zeta * u;
        -10.0 * (re * re + im * im).log10()
    }
}

/// The input-shaft rate over f1 (`1 / z1` for a pinion on the input shaft).
pub fn shaft_ratio(gb: &Gearbox) -> f64 {
    gb.input_shaft_ratio()
}

/// Resolve the gearbox's assembly for `p`, with the eccentricity harmonics (amplitude `e` b at
/// `(1 ± n_in/f1) f1`, phase 0) added to the reference mesh (`x1` of the paper's rig) when
/// `e > 0`.
pub fn build_model(gb: &Gearbox, p: &ElementParams) -> Result<DimensionlessModel> {
    let mut asm = gb.assembly(Wear {
        ea: p.ea,
        planetary: Some(p.planetary),
    })?;
    if p.eccentricity > 0.0 {
        let s = shaft_ratio(gb);
        let amp = p.eccentricity * asm.length_ref;
        if let Some(el) = asm.elements.first_mut() {
            *el = el
                .clone()
                .with_error(amp, 1.0 + s, 0.0)
                .with_error(amp, 1.0 - s, 0.0);
        }
    }
    asm.resolve()
}
