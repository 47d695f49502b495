//! The queue of the machine's own model: which machines' baselines are enough for a fit, the
//! key a fit is made for, and queueing it (the fit itself runs in [`super::physics`]).

use std::collections::BTreeMap;

use super::AppState;
use super::gearboxes::BUILTIN_ID;
use crate::diagnosis::machine_path::LineRatios;
use crate::diagnosis::machine_physics::{MIN_RECORDS, MIN_SPEEDS};
use crate::novelty::RecordFeatures;
use crate::store::{MachineRow, PhysicsKey, now_ms};

/// Healthy records within this relative f1 of each other are one speed (the fit's own rule).
const SAME_SPEED: f64 = 0.03;

/// The key of machine `m`'s own model on gearbox `gearbox_id` with description `hash`.
pub fn key_of(m: &MachineRow, hash: &str) -> PhysicsKey {
    PhysicsKey {
        machine_id: m.id.clone(),
        machine_created_at: m.created_at,
        gearbox_id: m
            .gearbox_id
            .clone()
            .unwrap_or_else(|| BUILTIN_ID.to_string()),
        gearbox_hash: hash.to_string(),
        baseline_version: m.baseline_version,
    }
}

/// The line ratios per channel of baseline records' features ([`crate::novelty::line_ratios`]), channels
/// without any left out.
pub fn healthy_ratios(
    per: &BTreeMap<String, Vec<RecordFeatures>>,
) -> BTreeMap<String, Vec<LineRatios>> {
    crate::novelty::line_ratios(per)
        .into_iter()
        .filter(|(_, r)| !r.is_empty())
        .collect()
}

/// Whether some channel has enough records and speeds for a fit.
pub fn fittable(healthy: &BTreeMap<String, Vec<LineRatios>>) -> bool {
    healthy.values().any(|rs| {
        let mut f: Vec<f64> = rs.iter().map(|r| r.f1_hz).collect();
        f.sort_by(f64::total_cmp);
        let mut groups: Vec<f64> = Vec::new();
        for x in f {
            if groups.last().is_none_or(|&c| x / c - 1.0 > SAME_SPEED) {
                groups.push(x);
            }
        }
        rs.len() >= MIN_RECORDS && groups.len() >= MIN_SPEEDS
    })
}

/// After machine `m`'s baselines were fitted from `per` (its baseline changed, or this replica
/// had not fitted them): queue its own model when its baseline is fittable and its gearbox's
/// table is ready (`table_ready`). Errors are logged: the next fit tries again.
pub async fn queue_if_fittable(
    app: &AppState,
    m: &MachineRow,
    hash: &str,
    per: &BTreeMap<String, Vec<RecordFeatures>>,
    table_ready: bool,
) {
    if !table_ready || !fittable(&healthy_ratios(per)) {
        return;
    }
    match app
        .store
        .queue_machine_physics(&key_of(m, hash), now_ms())
        .await
    {
        Ok(true) => {
            tracing::info!(machine = %m.id, version = m.baseline_version, "the machine's own model is queued");
            app.physics_wake.notify_one();
        }
        Ok(false) => {}
        Err(e) => {
            tracing::warn!(machine = %m.id, error = %e, "the machine's own model was not queued")
        }
    }
}
