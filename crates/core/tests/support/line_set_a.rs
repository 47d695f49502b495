//! The original hand-written line set of the first paper's rig, kept as the test oracle the
//! generic line set must reproduce for that rig (included by `tests/paper_rig.rs` with
//! `#[path]`; it needs `kinematics_a` beside it as a sibling module).

use gearwear_core::signature::LineDef;

use super::kinematics_a::Frequencies;

/// The original hand-written line set of the first paper's rig (kept as the reference that
/// `line_set::gearbox_line_set` must reproduce for that rig): the mesh frequencies, their
/// harmonics and combination tones, and the subharmonics of period-2 motion. Lines closer than 4
/// resolution bins (`4 / SEGMENT_PERIODS` f1) to another are left out (e.g. `3f2 = 1.08` next
/// to `f1 + f3 = 1.0875`; `f2 + f3 = 0.4475` next to `f1/2`).
pub fn legacy_line_set(fr: &Frequencies) -> Vec<LineDef> {
    let (f2, f3) = (fr.f2, fr.f3);
    let l = |name: &str, ratio: f64, planetary: bool| LineDef {
        name: name.into(),
        ratio,
        planetary,
    };
    let mut v = vec![
        l("f3", f3, true),
        l("2f3", 2.0 * f3, true),
        l("f1-2f2", 1.0 - 2.0 * f2, false),
        l("f2", f2, false),
        l("f1/2", 0.5, false),
        l("f1-f2", 1.0 - f2, false),
        l("2f2", 2.0 * f2, false),
        l("f1-f3", 1.0 - f3, true),
        l("f1", 1.0, false),
        l("f1+f3", 1.0 + f3, true),
        l("f1+f2", 1.0 + f2, false),
        l("3f1/2", 1.5, false),
        l("2f1-f2", 2.0 - f2, false),
        l("2f1", 2.0, false),
    ];
    v.sort_by(|a, b| a.ratio.total_cmp(&b.ratio));
    v
}
