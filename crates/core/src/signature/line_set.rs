//! The measured lines of a described gearbox, from its kinematics.
//!
//! Frequencies are ratios to the reference (stage-1) mesh frequency f1. Candidates, in
//! priority order:
//!
//! 1. `f1`, the period-2 subharmonic `f1/2` and its odd multiple `3f1/2`, and `2f1`;
//! 2. for every other stage k (stage order) with mesh ratio `r_k`, named `fk`: `fk`, `2fk`,
//!    `f1−fk` and `f1+fk` (the modulation sidebands the backlash nonlinearity makes); for a
//!    stage the wear acts on, also `f1−2fk` and `2f1−fk` (the paper's Figure 17 shows these
//!    grow with wear).
//!
//! A candidate is kept when it lies in `(MIN_RATIO, BAND_HI]` and at least [`MIN_SPACING`] (4
//! resolution bins, `4 / SEGMENT_PERIODS`) from every line kept before it; otherwise it is
//! dropped (the stronger, earlier line stands for both). Lines of stages the wear does not act
//! on are flagged `planetary` (kept out of the wear likelihood; in the first paper's rig those
//! are its planetary stage's lines). For the first paper's rig this gives exactly the 14 lines
//! of the original hand-written set (tested).

use super::LineDef;
use crate::signal::lines::{BAND_HI, SEGMENT_PERIODS};

/// Smallest distance between two kept lines, in units of f1 (4 resolution bins).
pub const MIN_SPACING: f64 = 4.0 / SEGMENT_PERIODS;
/// Lines at or below this ratio are too close to DC to be measured (4 bins).
pub const MIN_RATIO: f64 = 4.0 / SEGMENT_PERIODS;

/// One mesh of the gearbox as the line set sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshLine {
    /// 1-based stage.
    pub stage: usize,
    /// Mesh frequency over f1.
    pub ratio: f64,
    /// The wear degree acts on this stage.
    pub wears: bool,
}

/// The line set of meshes `meshes` (the first is the reference, ratio 1), ascending frequency.
pub fn kinematic_line_set(meshes: &[MeshLine]) -> Vec<LineDef> {
    let mut kept: Vec<LineDef> = Vec::new();
    let mut offer = |name: String, ratio: f64, planetary: bool| {
        let ok = ratio.is_finite()
            && ratio > MIN_RATIO
            && ratio <= BAND_HI
            && kept
                .iter()
                .all(|l| (l.ratio - ratio).abs() >= MIN_SPACING - 1e-12);
        if ok {
            kept.push(LineDef {
                name,
                ratio,
                planetary,
            });
        }
    };
    offer("f1".into(), 1.0, false);
    offer("f1/2".into(), 0.5, false);
    offer("3f1/2".into(), 1.5, false);
    offer("2f1".into(), 2.0, false);
    for m in meshes.iter().skip(1) {
        let f = format!("f{}", m.stage);
        let r = m.ratio;
        let side = !m.wears;
        offer(f.clone(), r, side);
        offer(format!("2{f}"), 2.0 * r, side);
        if r < 1.0 {
            offer(format!("f1-{f}"), 1.0 - r, side);
        } else {
            offer(format!("{f}-f1"), r - 1.0, side);
        }
        offer(format!("f1+{f}"), 1.0 + r, side);
        if m.wears {
            offer(format!("f1-2{f}"), 1.0 - 2.0 * r, side);
            offer(format!("2f1-{f}"), 2.0 - r, side);
        }
    }
    kept.sort_by(|a, b| a.ratio.total_cmp(&b.ratio));
    kept
}

/// The meshes of a gearbox for [`kinematic_line_set`]: one per stage.
pub fn mesh_lines(gb: &crate::gearbox::Gearbox) -> Vec<MeshLine> {
    let wear = gb.wear_stages();
    gb.mesh_ratios
        .iter()
        .enumerate()
        .map(|(i, &ratio)| MeshLine {
            stage: i + 1,
            ratio,
            wears: wear.contains(&(i + 1)),
        })
        .collect()
}

/// The line set of a described gearbox.
pub fn gearbox_line_set(gb: &crate::gearbox::Gearbox) -> Vec<LineDef> {
    kinematic_line_set(&mesh_lines(gb))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(r2: f64, wears: bool) -> Vec<LineDef> {
        kinematic_line_set(&[
            MeshLine {
                stage: 1,
                ratio: 1.0,
                wears: true,
            },
            MeshLine {
                stage: 2,
                ratio: r2,
                wears,
            },
        ])
    }

    #[test]
    fn close_lines_are_dropped_and_far_ones_kept() {
        // A non-wear stage at 0.3: 0.3, 0.6, 0.7, 1.3 are all ≥ 4 bins from the f1 family.
        let lines = names(0.3, false);
        let n: Vec<&str> = lines.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(
            n,
            ["f2", "f1/2", "2f2", "f1-f2", "f1", "f1+f2", "3f1/2", "2f1"]
        );
        assert!(
            lines
                .iter()
                .filter(|l| l.name.contains("f2"))
                .all(|l| l.planetary)
        );
        // At 0.52 every f2 line falls within 4 bins of an f1-family line: all dropped.
        let lines = names(0.52, true);
        assert!(lines.iter().all(|l| !l.name.contains("f2")), "{lines:?}");
        // A wear stage adds f1−2f2 and 2f1−f2, not flagged.
        let lines = names(0.3, true);
        assert!(lines.iter().any(|l| l.name == "f1-2f2" && !l.planetary));
        assert!(lines.iter().any(|l| l.name == "2f1-f2"));
        for w in lines.windows(2) {
            assert!(w[1].ratio - w[0].ratio >= MIN_SPACING - 1e-12);
        }
    }

    #[test]
    fn single_stage_box_has_the_f1_family_only() {
        let lines = kinematic_line_set(&[MeshLine {
            stage: 1,
            ratio: 1.0,
            wears: true,
        }]);
        let names: Vec<&str> = lines.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(names, ["f1/2", "f1", "3f1/2", "2f1"]);
    }
}
