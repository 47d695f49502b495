//! The library of candidate effects the closed loop can add to the model, and the augmented
//! model they make.
//!
//! | effect | physics | where it enters | fingerprint in the residual | parameters |
//! | --- | --- | --- | --- | --- |
//! | `shaft-modulation` | eccentricity / run-out of the input pinion: the stage-1 composite error is amplitude-modulated at the input-shaft rate `f_s = f1 / z1` | **element**: two error harmonics of amplitude `e` (units of b) on mesh `x1` at `(1 ± 1/z1) f1` | lines at `f1 ± f_s`, `2 f1 ± f_s` (and at the other model lines ± f_s), absent from the model | `e` |
//! | `path-resonance` | a housing / transfer-path / sensor-mount mode between gear mesh and accelerometer | **sensor stage**: `H(r) = 1 / (1 − (r/ρ)² + 2iζ r/ρ)` on the gear signal, before the (flat) measurement noise | a smooth trend in the residual at the model's lines: lines near `ρ f1` too strong, lines far above it too weak | `ρ = f_r/f1`, `ζ` |
//! | `planetary-wear` | a worn planetary stage: larger composite error of the sun–planet and ring–planet meshes | **element**: planetary error amplitude `p` (units of b) on every planetary mesh (baseline 0.1) | the f3 family `f3`, `2 f3`, `f1 ± f3` stronger than the model | `p` |
//! | `tooth-damage` | a cracked or broken tooth on one gear of the reference mesh | **element**: the mesh stiffness dips by `depth` for one tooth's time in mesh once per revolution of that gear's shaft ([`crate::model::ToothDamage`]) | a comb of shaft-order sidebands `k f1 ± n f_s` (n = 1, 2, 3, …) around every mesh harmonic; impulsive after TSA | `depth`, the gear (shaft, teeth) |
//!
//! Shaft modulation may sit on either shaft of the reference mesh (`shaft_ratio` = that
//! shaft's rate over f1). A path resonance has two forms: `low-pass` (the original, unit gain
//! below the mode and `(f_r/f)²` above: `H = 1/(1 − u² + 2iζu)`, `u = f/f_r`) and `peaking` (a
//! mode added to a flat path, unit gain away from it and `1 + g` at it:
//! `H = 1 + g · 2iζu / (1 − u² + 2iζu)`).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::error::Result;
use crate::gearbox::{Gearbox, Stage};
use crate::model::{DimensionlessModel, ToothDamage, Wear};

/// Names of the library's effects.
pub const SHAFT_MODULATION: &str = "shaft-modulation";
/// See the module table.
pub const PATH_RESONANCE: &str = "path-resonance";
/// See the module table.
pub const PLANETARY_WEAR: &str = "planetary-wear";
/// See the module table.
pub const TOOTH_DAMAGE: &str = "tooth-damage";

/// An effect with its fitted parameters (the report's `effects` entries).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Effect {
    /// One of [`SHAFT_MODULATION`], [`PATH_RESONANCE`], [`PLANETARY_WEAR`], [`TOOTH_DAMAGE`].
    pub name: String,
    /// `element` or `sensor-stage`.
    pub kind: &'static str,
    /// Parameter name → value (units in the name).
    pub parameters: BTreeMap<String, f64>,
    /// Words that go with the numbers (the damaged gear, the modulated shaft, the resonance
    /// form); empty when there are none.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub labels: BTreeMap<String, String>,
}

/// A gear of the reference mesh, as the element effects name it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshGear {
    /// `pinion` or `gear` (of stage 1).
    pub member: &'static str,
    pub shaft: String,
    pub teeth: u32,
    /// Its shaft's rate over f1 (`1 / teeth`).
    pub shaft_ratio: f64,
}

/// The two gears of the reference (stage-1) mesh when it is a parallel stage; empty for a
/// planetary first stage (tooth damage and output-side shaft modulation are then not tried).
pub fn reference_gears(gb: &Gearbox) -> Vec<MeshGear> {
    match gb.topology.stages.first() {
        Some(Stage::Parallel {
            pinion_shaft,
            pinion_teeth,
            gear_shaft,
            gear_teeth,
        }) => vec![
            MeshGear {
                member: "pinion",
                shaft: pinion_shaft.clone(),
                teeth: *pinion_teeth,
                shaft_ratio: 1.0 / *pinion_teeth as f64,
            },
            MeshGear {
                member: "gear",
                shaft: gear_shaft.clone(),
                teeth: *gear_teeth,
                shaft_ratio: 1.0 / *gear_teeth as f64,
            },
        ],
        _ => Vec::new(),
    }
}

/// The physical (element) part of a model: wear, planetary error, shaft modulation, a damaged
/// tooth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ElementParams {
    /// Fixed-axis wear `ea` (units of b).
    pub ea: f64,
    /// Planetary composite-error amplitude (units of b).
    pub planetary: f64,
    /// Shaft-modulation sideband amplitude `e` on mesh x1 (units of b); 0: none.
    pub eccentricity: f64,
    /// Rate of the modulating shaft over f1; 0: the input shaft.
    pub ecc_shaft: f64,
    /// Tooth-damage stiffness depth (0: none) and the damaged gear's shaft rate over f1.
    pub tooth_depth: f64,
    pub tooth_shaft: f64,
}

impl ElementParams {
    /// Wear `ea` and planetary error `p`, nothing else.
    pub fn plain(ea: f64, planetary: f64) -> Self {
        ElementParams {
            ea,
            planetary,
            eccentricity: 0.0,
            ecc_shaft: 0.0,
            tooth_depth: 0.0,
            tooth_shaft: 0.0,
        }
    }

    /// Bit pattern of every field (a cache key).
    pub fn key(&self) -> [u64; 6] {
        [
            self.ea.to_bits(),
            self.planetary.to_bits(),
            self.eccentricity.to_bits(),
            self.ecc_shaft.to_bits(),
            self.tooth_depth.to_bits(),
            self.tooth_shaft.to_bits(),
        ]
    }
}

/// A second-order path resonance at `rho · f1` with damping ratio `zeta`: low-pass form when
/// `peak_gain` is `None`, peaking form `1 + g · 2iζu/(1 − u² + 2iζu)` with `g = peak_gain`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Resonance {
    /// Resonance frequency over f1.
    pub rho: f64,
    /// Damping ratio.
    pub zeta: f64,
    /// Peak gain over the flat path (peaking form); `None`: low-pass form.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_gain: Option<f64>,
}

impl Resonance {
    /// The low-pass form `H(r) = 1 / (1 − (r/ρ)² + 2iζ r/ρ)`.
    pub fn low_pass(rho: f64, zeta: f64) -> Self {
        Resonance {
            rho,
            zeta,
            peak_gain: None,
        }
    }

    /// `20 log10 |H(r)|`.
    pub fn gain_db(&self, r: f64) -> f64 {
        let u = r / self.rho;
        let re = 1.0 - u * u;
        let im = 2.0 * self.zeta * u;
        let d = re * re + im * im;
        match self.peak_gain {
            None => -10.0 * d.log10(),
            Some(g) => {
                // 1 + g·(iy)/(re + iy), y = im: (re + iy + g·iy)/(re + iy)
                let nre = re;
                let nim = im * (1.0 + g);
                10.0 * ((nre * nre + nim * nim) / d).log10()
            }
        }
    }

    /// `low-pass` or `peaking`.
    pub fn form(&self) -> &'static str {
        if self.peak_gain.is_some() {
            "peaking"
        } else {
            "low-pass"
        }
    }
}

/// The input-shaft rate over f1 (`1 / z1` for a pinion on the input shaft).
pub fn shaft_ratio(gb: &Gearbox) -> f64 {
    gb.input_shaft_ratio()
}

/// Every shaft's rate over f1, named, positive (a fixed shaft left out), fastest first: what
/// the residual's guesses and the level trace's impacts are read against.
pub fn shaft_rates(gb: &Gearbox) -> Vec<(String, f64)> {
    let mut shafts: Vec<(String, f64)> = gb
        .shaft_ratios()
        .into_iter()
        .map(|(n, v)| (n, v.abs()))
        .filter(|(_, v)| *v > 0.0)
        .collect();
    shafts.sort_by(|a, b| b.1.total_cmp(&a.1));
    shafts
}

/// Resolve the gearbox's assembly for `p`: the eccentricity harmonics (amplitude `e` b at
/// `(1 ± s) f1`, `s` the modulating shaft's rate over f1, phase 0) added to the reference mesh
/// when `e > 0`, and a damaged tooth on it (pulse one mesh period long, `1/z` of a revolution)
/// when `tooth_depth > 0`.
pub fn build_model(gb: &Gearbox, p: &ElementParams) -> Result<DimensionlessModel> {
    let mut asm = gb.assembly(Wear {
        ea: p.ea,
        planetary: Some(p.planetary),
    })?;
    if p.eccentricity > 0.0 {
        let s = if p.ecc_shaft > 0.0 {
            p.ecc_shaft
        } else {
            shaft_ratio(gb)
        };
        let amp = p.eccentricity * asm.length_ref;
        if let Some(el) = asm.elements.first_mut() {
            *el = el
                .clone()
                .with_error(amp, 1.0 + s, 0.0)
                .with_error(amp, 1.0 - s, 0.0);
        }
    }
    if p.tooth_depth > 0.0
        && p.tooth_shaft > 0.0
        && let Some(el) = asm.elements.first_mut()
    {
        *el = el.clone().with_tooth_damage(ToothDamage {
            depth: p.tooth_depth.min(0.95),
            shaft_ratio: p.tooth_shaft,
            width: p.tooth_shaft.min(0.5),
            phase: 0.0,
        });
    }
    asm.resolve()
}

/// A shaft modulation of sideband amplitude `e` (units of b) on `shaft`.
fn effect_shaft(e: f64, shaft: &MeshGear) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("sideband_amplitude_b".into(), e);
    p.insert("shaft_ratio".into(), shaft.shaft_ratio);
    let mut l = BTreeMap::new();
    l.insert("shaft".into(), shaft.shaft.clone());
    Effect {
        name: SHAFT_MODULATION.into(),
        kind: "element",
        parameters: p,
        labels: l,
    }
}

/// A path resonance as the report names it (`res.rho` over f1; `f1` in Hz).
pub(crate) fn effect_resonance(res: &Resonance, f1: f64) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("frequency_ratio".into(), res.rho);
    p.insert("frequency_hz".into(), res.rho * f1);
    p.insert("damping_ratio".into(), res.zeta);
    if let Some(g) = res.peak_gain {
        p.insert("peak_gain".into(), g);
    }
    let mut l = BTreeMap::new();
    l.insert("form".into(), res.form().to_string());
    Effect {
        name: PATH_RESONANCE.into(),
        kind: "sensor-stage",
        parameters: p,
        labels: l,
    }
}

/// Planetary wear of composite-error amplitude `pl` (units of b).
fn effect_planetary(pl: f64) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("planetary_error_b".into(), pl);
    Effect {
        name: PLANETARY_WEAR.into(),
        kind: "element",
        parameters: p,
        labels: BTreeMap::new(),
    }
}

/// A damaged tooth of stiffness loss `depth` on `gear`.
fn effect_tooth(depth: f64, gear: &MeshGear) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("stiffness_loss".into(), depth);
    p.insert("shaft_ratio".into(), gear.shaft_ratio);
    p.insert("teeth".into(), gear.teeth as f64);
    let mut l = BTreeMap::new();
    l.insert("gear".into(), format!("stage-1 {}", gear.member));
    l.insert("shaft".into(), gear.shaft.clone());
    Effect {
        name: TOOTH_DAMAGE.into(),
        kind: "element",
        parameters: p,
        labels: l,
    }
}

/// The effects of an element parameter set (given the gears and shafts they name).
pub(crate) fn element_effects(
    p: &ElementParams,
    baseline: f64,
    gears: &[MeshGear],
    input: &MeshGear,
) -> Vec<Effect> {
    let mut v = Vec::new();
    if p.eccentricity > 0.0 {
        let sh = gears
            .iter()
            .find(|g| p.ecc_shaft > 0.0 && (g.shaft_ratio - p.ecc_shaft).abs() < 1e-12)
            .unwrap_or(input);
        v.push(effect_shaft(p.eccentricity, sh));
    }
    if p.planetary > baseline + 1e-12 {
        v.push(effect_planetary(p.planetary));
    }
    if p.tooth_depth > 0.0
        && let Some(g) = gears
            .iter()
            .find(|g| (g.shaft_ratio - p.tooth_shaft).abs() < 1e-12)
    {
        v.push(effect_tooth(p.tooth_depth, g));
    }
    v
}

/// The shafts and gears the element effects may sit on.
pub(super) struct Mesh {
    /// The reference mesh's two gears ([`reference_gears`]).
    pub gears: Vec<MeshGear>,
    /// The input shaft's pinion: where a shaft modulation of no other shaft sits.
    pub input: MeshGear,
    /// The input shaft, then the reference mesh's shafts other than it.
    pub shafts: Vec<MeshGear>,
}

impl Mesh {
    pub(super) fn new(gb: &Gearbox) -> Mesh {
        let gears = reference_gears(gb);
        let input = MeshGear {
            member: "pinion",
            shaft: gb.description.input_shaft.clone(),
            teeth: (1.0 / shaft_ratio(gb)).round() as u32,
            shaft_ratio: shaft_ratio(gb),
        };
        let mut shafts: Vec<MeshGear> = vec![input.clone()];
        for g in &gears {
            if (g.shaft_ratio - input.shaft_ratio).abs() > 1e-9 {
                shafts.push(g.clone());
            }
        }
        Mesh {
            gears,
            input,
            shafts,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tooth_damage_enters_the_reference_mesh_once_per_revolution() {
        let gb = Gearbox::paper_rig();
        let gears = reference_gears(&gb);
        assert_eq!(gears.len(), 2);
        let pinion = &gears[0];
        let p = ElementParams {
            tooth_depth: 0.5,
            tooth_shaft: pinion.shaft_ratio,
            ..ElementParams::plain(0.3, 0.1)
        };
        let m = build_model(&gb, &p).unwrap();
        let d = m.tooth_damage[0].expect("damage on the reference mesh");
        assert!(m.tooth_damage[1..].iter().all(Option::is_none));
        assert_eq!(d.shaft_ratio, pinion.shaft_ratio);
        // The stiffness factor: 1 − depth at the pulse centre, 1 outside one mesh period.
        assert!((d.factor(d.width / 2.0) - 0.5).abs() < 1e-12);
        assert_eq!(d.factor(d.width * 1.01), 1.0);
        assert_eq!(d.factor(0.5), 1.0);
        // Without damage the model is the plain one.
        let plain = build_model(&gb, &ElementParams::plain(0.3, 0.1)).unwrap();
        assert!(plain.tooth_damage.iter().all(Option::is_none));
    }
}
