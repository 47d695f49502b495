//! What the condition modules' tests share.

use super::machine_model::{LineKind, LineLevel};
use super::parts::Parts;
use super::state::{Load, OperatingState, SpeedSource};
use crate::gearbox::Gearbox;

/// The PHM 2009 spur train's kinematics: 32T → 96T, 48T → 80T (shafts `in`, `idler` at 1/3,
/// `out` at 1/5), nothing else described.
pub fn spur_train() -> Gearbox {
    Gearbox::parse(
        "format = \"gearwear-gearbox\"\nversion = 1\nname = \"s\"\ninput_shaft = \"in\"\n\
         [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"in\", teeth = 32 }\n\
         gear = { shaft = \"idler\", teeth = 96 }\n\
         [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"idler\", teeth = 48 }\n\
         gear = { shaft = \"out\", teeth = 80 }\n",
        "test",
    )
    .expect("the spur train parses")
}

/// [`spur_train`]'s parts.
pub fn spur() -> Parts {
    Parts::of(&spur_train())
}

/// A state measured by a tachometer at `f` Hz and load `load`.
pub fn state(f: f64, load: &str) -> OperatingState {
    OperatingState {
        shaft_hz: f,
        source: SpeedSource::Tachometer,
        hint_hz: None,
        speed_variation: 0.0,
        load: Load::parse(load),
    }
}

/// A housing mode at 1.2 kHz (Q ≈ 7) in dB.
pub fn path_db(hz: f64) -> f64 {
    let r = hz / 1200.0;
    -20.0 * ((1.0 - r * r).powi(2) + (0.14 * r).powi(2)).sqrt().log10()
}

/// Deterministic "noise" in ±`amp` dB.
fn jitter(i: usize, j: usize, amp: f64) -> f64 {
    amp * ((i * 7919 + j * 104_729) as f64 * 0.618).sin()
}

/// Mesh harmonics of order 16 and their ±1, ±2 sidebands at 1/3 order, each with its own
/// source, through [`path_db`] and the load's offset, plus ±`noise` dB.
pub fn lines(f: f64, load: &str, rec: usize, noise: f64, with_sources: bool) -> Vec<LineLevel> {
    let mut v = Vec::new();
    for h in 1..=4 {
        let c = 16.0 * h as f64;
        for (j, k) in [0, -2, -1, 1, 2].into_iter().enumerate() {
            let o = c + k as f64 / 3.0;
            let kind = if k == 0 {
                LineKind::Mesh
            } else {
                LineKind::Sideband
            };
            let source = if with_sources {
                -10.0 * h as f64 - if k == 0 { 0.0 } else { 15.0 + 3.0 * j as f64 }
            } else {
                0.0
            };
            let load_db = if load == "High" { 4.0 } else { 0.0 };
            v.push(LineLevel {
                order: o,
                kind,
                feature: format!("lines.{}.m{}", kind.name(), 16 * h),
                level_db: source + path_db(o * f) + load_db + jitter(rec, h * 5 + j, noise),
            });
        }
    }
    v
}
