//! The meshes' values: stiffness shape, damping, clearance, baseline error and phase (given or
//! defaulted), then the mean stiffness, the reference mesh's first.
//!
//! With `reference_frequency_hz` the reference mesh's stiffness is `ω_h² / A_00` instead of its
//! estimate, and every other mesh whose stiffness is not given absolutely keeps its ratio to it.

use std::collections::{BTreeMap, BTreeSet};
use std::f64::consts::TAU;

use serde::Serialize;

use super::assumed::{
    BASELINE_ERROR, CLEARANCE_OVER_MODULE, Ctx, DAMPING_RATIO, FLUCTUATION, STIFFNESS_PER_WIDTH,
    non_negative, positive,
};
use super::description::{GearboxDescription, MeshSpec};
use super::gears::mesh_modules;
use crate::error::GearboxError;
use crate::model::element::StiffnessShape;

/// One resolved mesh (SI).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshValues {
    pub name: String,
    /// 1-based stage.
    pub stage: usize,
    /// Mesh frequency over the reference mesh frequency.
    pub freq_ratio: f64,
    pub stiffness_n_per_m: f64,
    pub shape: StiffnessShape,
    pub damping_ratio: f64,
    pub half_clearance_m: f64,
    /// Composite error when the mesh does not wear (m).
    pub baseline_error_m: f64,
    /// Factor on the mesh's composite error, whichever gives it (the wear degree, the
    /// baseline, a planetary override): a machine's own transmission error over the
    /// description's ([`super::factors::StageFactors::error`]); 1 without factors.
    pub error_scale: f64,
    pub phase_rad: f64,
    /// True when the wear degree drives this mesh's error.
    pub wears: bool,
    /// True for the meshes of a planetary stage.
    pub planetary: bool,
    /// Row of `G`: (coordinate, coefficient in m).
    pub terms: Vec<(String, f64)>,
}

/// A mesh's values before the stiffness is settled.
pub(super) struct MeshDraft {
    pub(super) values: MeshValues,
    pub(super) spec: MeshSpec,
    pub(super) width_m: f64,
    pub(super) label: String,
}

/// Every mesh's values other than its stiffness, from its spec or the defaults (`b_ref`: the
/// reference length in m, `length_ref_um` in µm).
pub(super) fn settle_values(
    d: &GearboxDescription,
    drafts: &mut [MeshDraft],
    length_ref_um: f64,
    b_ref: f64,
) -> Result<(), GearboxError> {
    // Module of each mesh for the clearance default: from its first gear's width over 10 is
    // not known here, so keep the module alongside: recompute from the terms' gears instead.
    let modules = mesh_modules(d);
    for dr in drafts.iter_mut() {
        let s = &dr.spec;
        let label = dr.label.clone();
        let v = &mut dr.values;
        let fl = match s.fluctuation {
            Some(e) if !(e.is_finite() && (0.0..1.0).contains(&e)) => {
                return Err(GearboxError::Value {
                    field: format!("{label} fluctuation"),
                    value: e,
                    reason: "must lie in [0, 1) so the stiffness stays positive",
                });
            }
            Some(e) => e,
            None => FLUCTUATION,
        };
        v.shape = match s.square_wave {
            Some(w) => StiffnessShape::SquareWave {
                contact_ratio: w.contact_ratio,
                double_to_single: w.double_to_single,
                smoothing: w.smoothing,
            },
            None => StiffnessShape::FirstHarmonic { eps: fl },
        };
        v.shape
            .validate(&label)
            .map_err(|e| GearboxError::Model(e.to_string()))?;
        v.damping_ratio = match non_negative(format!("{label} damping_ratio"), s.damping_ratio)? {
            Some(x) => x,
            None => DAMPING_RATIO,
        };
        let hc = non_negative(format!("{label} half_clearance_um"), s.half_clearance_um)?;
        v.half_clearance_m = match hc {
            Some(um) => (um / length_ref_um) * b_ref,
            None => CLEARANCE_OVER_MODULE * modules[v.stage - 1],
        };
        let err = non_negative(format!("{label} error_um"), s.error_um)?;
        v.baseline_error_m = match err {
            Some(um) => (um / length_ref_um) * b_ref,
            None => BASELINE_ERROR * b_ref,
        };
        v.phase_rad = match s.phase_rad {
            Some(p) if !p.is_finite() => {
                return Err(GearboxError::Value {
                    field: format!("{label} phase_rad"),
                    value: p,
                    reason: "must be finite",
                });
            }
            Some(p) => p,
            None => 0.0,
        };
    }
    Ok(())
}

/// One "assumed" line per stage for the defaults shared by its meshes.
pub(super) fn log_stage_defaults(
    cx: &mut Ctx,
    drafts: &[MeshDraft],
    n_stages: usize,
    length_ref_um: f64,
) {
    for k in 1..=n_stages {
        let Some(dr) = drafts.iter().find(|dr| dr.values.stage == k) else {
            continue;
        };
        if dr.spec.fluctuation.is_none() && dr.spec.square_wave.is_none() {
            cx.assume(
                format!("stage {k} mesh stiffness fluctuation ε"),
                FLUCTUATION,
                "",
                "first harmonic of a spur mesh's stiffness variation (contact ratio ≈ 1.6)",
            );
        }
        if dr.spec.damping_ratio.is_none() {
            cx.assume(
                format!("stage {k} mesh damping ratio"),
                DAMPING_RATIO,
                "",
                "the first paper's mesh damping ratio",
            );
        }
        if dr.spec.half_clearance_um.is_none() {
            cx.assume(
                format!("stage {k} half-clearance"),
                dr.values.half_clearance_m * 1e6,
                "µm",
                "0.05 × module (general-purpose backlash)",
            );
        }
        if dr.spec.error_um.is_none() && !dr.values.wears {
            cx.assume(
                format!("stage {k} composite error (not a wear stage)"),
                BASELINE_ERROR * length_ref_um,
                "µm",
                "0.1 × reference length (the first paper's planetary error)",
            );
        }
    }
}

/// Settle every mesh's mean stiffness (N/m), the reference mesh's first; returns the reference
/// stiffness and `ω_h / 2π` (Hz). `dofs`: the coordinates' (name, inertia); `pinned`: the
/// description's reference frequency.
pub(super) fn settle_stiffness(
    cx: &mut Ctx,
    drafts: &mut [MeshDraft],
    dofs: &[(String, f64)],
    pinned: Option<f64>,
) -> Result<(f64, f64), GearboxError> {
    let a00: f64 = {
        let inertia: BTreeMap<&str, f64> = dofs.iter().map(|(n, j)| (n.as_str(), *j)).collect();
        let terms = &drafts[0].values.terms;
        let mut s = 0.0;
        for (n, c) in terms {
            s += c * c / inertia[n.as_str()];
        }
        s
    };
    let estimate = |dr: &MeshDraft| -> Result<(Option<f64>, f64), GearboxError> {
        // (absolute stiffness if given, estimate from width otherwise)
        let s = &dr.spec;
        let abs = positive(
            format!("{} stiffness_n_per_m", dr.label),
            s.stiffness_n_per_m,
        )?;
        let per = positive(
            format!("{} stiffness_per_width_n_per_mm_um", dr.label),
            s.stiffness_per_width_n_per_mm_um,
        )?;
        positive(format!("{} stiffness_ratio", dr.label), s.stiffness_ratio)?;
        let width_based = per.unwrap_or(STIFFNESS_PER_WIDTH) * 1e9 * dr.width_m;
        Ok((abs.or(per.map(|_| width_based)), width_based))
    };
    let (ref_abs, ref_est) = estimate(&drafts[0])?;
    let k_ref = match pinned {
        Some(f) => {
            let wh = TAU * f;
            wh * wh / a00
        }
        None => match ref_abs {
            Some(k) => k,
            None => cx.assume_dynamic(
                format!("{} stiffness", drafts[0].label),
                ref_est,
                "N/m",
                "20 N/(mm·µm) × the narrower face width of the pair (ISO 6336-1 c_γα, steel spur gears)",
            ),
        },
    };
    let mut logged = BTreeSet::new();
    for i in 0..drafts.len() {
        let k = if i == 0 {
            k_ref
        } else {
            let (abs, est) = estimate(&drafts[i])?;
            match (drafts[i].spec.stiffness_ratio, abs) {
                (Some(r), _) => k_ref * r,
                (None, Some(k)) => k,
                (None, None) => {
                    let k = if pinned.is_some() {
                        k_ref * (est / ref_est)
                    } else {
                        est
                    };
                    let key = (drafts[i].values.stage, drafts[i].label.clone());
                    if logged.insert(key) {
                        cx.assume_dynamic(
                            format!("{} stiffness", drafts[i].label),
                            k,
                            "N/m",
                            if pinned.is_some() {
                                "reference stiffness × face-width ratio to the reference mesh"
                            } else {
                                "20 N/(mm·µm) × the narrower face width of the pair (ISO 6336-1 c_γα, steel spur gears)"
                            },
                        );
                    }
                    k
                }
            }
        };
        drafts[i].values.stiffness_n_per_m = k;
    }
    let reference_frequency_hz = match pinned {
        Some(f) => f,
        None => (k_ref * a00).sqrt() / TAU,
    };
    Ok((k_ref, reference_frequency_hz))
}
