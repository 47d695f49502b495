//! What a record's diagnosis needs of its machine, shared by the record path, the re-reads
//! and the own-model job: the machine's context (its row, gearbox, table) and its baselines,
//! fitted from the stored features of its baseline records and cached per replica.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use super::AppState;
use super::error::{ApiError, ApiResult};
use super::gearboxes::BUILTIN_ID;
use crate::assessment::{Baselines, GearboxRef, StoredFeatures, TableDiagnoser};
use crate::gearbox::Gearbox;
use crate::novelty::RecordFeatures;
use crate::signature::TableStatus;
use crate::store::{GearboxRow, MachineRow};

/// What a record's diagnosis needs of its machine.
pub struct MachineContext {
    pub machine: Option<MachineRow>,
    pub gearbox_row: GearboxRow,
    pub gearbox: Arc<Gearbox>,
    /// The diagnoser of the gearbox's table; `None` while the table is not ready.
    pub diagnoser: Option<Arc<TableDiagnoser>>,
}

impl MachineContext {
    /// The note a diagnosis carries while the gearbox's table is not ready.
    pub fn table_note(&self) -> Option<String> {
        if self.diagnoser.is_some() {
            return None;
        }
        let g = &self.gearbox_row;
        Some(match g.status {
            TableStatus::Failed => format!(
                "the signature table of gearbox `{}` failed ({}): no wear degree; this diagnosis \
                 uses the machine's baseline and indicators only — PUT a corrected description",
                g.id,
                g.error.as_deref().unwrap_or("no reason stored")
            ),
            TableStatus::Queued | TableStatus::Running => format!(
                "the signature table of gearbox `{}` is being computed ({:.0} % done): no \
                 wear degree until it is ready",
                g.id,
                100.0 * g.progress
            ),
            s => format!(
                "the signature table of gearbox `{}` is {s}: no wear degree; this diagnosis \
                 uses the machine's baseline and indicators only",
                g.id
            ),
        })
    }

    /// The `gearbox` object of a diagnosis.
    pub fn gearbox_ref(&self) -> GearboxRef {
        GearboxRef {
            id: self.gearbox_row.id.clone(),
            name: self.gearbox_row.name.clone(),
            hash: self.gearbox_row.hash.clone(),
            table_status: self.gearbox_row.status,
            table_progress: self.gearbox_row.progress,
        }
    }

    pub fn input_shaft_hz(&self) -> Option<f64> {
        self.machine.as_ref().and_then(|m| m.input_shaft_hz)
    }
}

/// The machine (if it exists), its gearbox and that gearbox's diagnoser.
pub async fn context(app: &AppState, machine_id: &str) -> ApiResult<MachineContext> {
    let machine = app.store.get_machine(machine_id).await?;
    context_of(app, machine_id, machine).await
}

/// [`context`] of a machine row already read (`None`: a machine without a row yet).
pub async fn context_of(
    app: &AppState,
    machine_id: &str,
    machine: Option<MachineRow>,
) -> ApiResult<MachineContext> {
    let gid = machine
        .as_ref()
        .and_then(|m| m.gearbox_id.clone())
        .unwrap_or_else(|| BUILTIN_ID.to_string());
    let row = match app.store.get_gearbox(&gid).await? {
        Some(r) => r,
        None if gid == BUILTIN_ID => {
            super::gearboxes::ensure_builtin(app).await?;
            app.store
                .get_gearbox(BUILTIN_ID)
                .await?
                .ok_or_else(|| ApiError::internal("the built-in gearbox is missing"))?
        }
        None => {
            return Err(ApiError::internal(format!(
                "machine `{machine_id}` names gearbox `{gid}`, which is not stored"
            )));
        }
    };
    let gearbox = if row.builtin {
        app.builtin_gearbox.clone()
    } else {
        app.tables
            .gearbox(&row)
            .map_err(|e| ApiError::internal(format!("gearbox `{gid}`: {e}")))?
    };
    let diagnoser = app.tables.diagnoser(app, &row).await?;
    Ok(MachineContext {
        machine,
        gearbox_row: row,
        gearbox,
        diagnoser,
    })
}

/// The baselines this replica fitted, one entry per machine, kept by what they were fitted
/// from: the machine's row (its creation time: a machine deleted and made again starts over),
/// the gearbox description's hash and the machine's `baseline_version`, which the store raises
/// with every change of the machine's baseline records. A record's ingest reads the machine's
/// row anyway, so a baseline changed through another replica is seen at the next record.
#[derive(Default)]
pub struct BaselineCache {
    fitted: std::sync::Mutex<HashMap<String, (BaselineKey, Arc<Baselines>)>>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct BaselineKey {
    created_at: i64,
    hash: String,
    version: i64,
    /// The table the transfer paths were calibrated through (`None`: not ready, no paths).
    table: Option<String>,
}

impl BaselineCache {
    fn get(&self, machine_id: &str, key: &BaselineKey) -> Option<Arc<Baselines>> {
        let fitted = self.fitted.lock().unwrap_or_else(|p| p.into_inner());
        fitted
            .get(machine_id)
            .filter(|(k, _)| k == key)
            .map(|(_, b)| b.clone())
    }

    fn put(&self, machine_id: &str, key: BaselineKey, b: Arc<Baselines>) {
        let mut fitted = self.fitted.lock().unwrap_or_else(|p| p.into_inner());
        fitted.insert(machine_id.to_string(), (key, b));
    }
}

/// The stored features of the machine's baseline records computed with gearbox description
/// `hash`, per channel.
pub async fn baseline_features(
    app: &AppState,
    machine_id: &str,
    hash: &str,
) -> ApiResult<BTreeMap<String, Vec<RecordFeatures>>> {
    let rows = app.store.baseline_records(machine_id).await?;
    let mut per: BTreeMap<String, Vec<RecordFeatures>> = BTreeMap::new();
    for r in rows {
        let f = stored_features(&r)?;
        if f.gearbox_hash != hash {
            continue;
        }
        for (name, c) in f.channels {
            per.entry(name).or_default().push(c.novelty_features);
        }
    }
    Ok(per)
}

/// A baseline record's stored features; a row that does not read is an error that names it
/// (the service wrote every row itself: a row it cannot read is not skipped unseen).
pub(super) fn stored_features(r: &crate::store::BaselineRecord) -> ApiResult<StoredFeatures> {
    serde_json::from_str(&r.features).map_err(|e| {
        ApiError::internal(format!(
            "the stored features of baseline record `{}` do not read ({e}); unmark it \
             (DELETE /v1/machines/{{machine_id}}/baseline/{})",
            r.id, r.id
        ))
    })
}

/// The machine's baselines per channel, fitted (by the core's one fitter, [`Baselines::fit`])
/// from the stored features of its baseline records computed with gearbox description `hash`;
/// refitted only when the machine's baseline or gearbox changed since the last fit
/// ([`BaselineCache`]). `None`: a machine without a row, which has no records yet.
pub async fn baselines(
    app: &AppState,
    machine: Option<&MachineRow>,
    hash: &str,
    diagnoser: Option<Arc<TableDiagnoser>>,
) -> ApiResult<Arc<Baselines>> {
    let Some(m) = machine else {
        return Ok(Arc::new(Baselines::default()));
    };
    let key = BaselineKey {
        created_at: m.created_at,
        hash: hash.to_string(),
        version: m.baseline_version,
        // (Its columns too: an extended table keeps its description's hash.)
        table: diagnoser
            .as_ref()
            .map(|d| format!("{}/{:?}", d.table_id(), d.table().grid.omega1)),
    };
    if let Some(b) = app.baselines.get(&m.id, &key) {
        return Ok(b);
    }
    let per = baseline_features(app, &m.id, hash).await?;
    let table_ready = diagnoser.is_some();
    let (fitted, per) = tokio::task::spawn_blocking(move || {
        let b = Baselines::fit(&per).with_paths(&per, diagnoser.as_deref());
        (b, per)
    })
    .await
    .map_err(|e| ApiError::internal(format!("fitting the baseline failed: {e}")))?;
    // A baseline that changed may now be enough for the machine's own model.
    super::physics_queue::queue_if_fittable(app, m, hash, &per, table_ready).await;
    for (channel, e) in &fitted.unfitted {
        tracing::warn!(machine = %m.id, channel = %channel, error = %e, "a baseline could not be fitted");
    }
    let fitted = Arc::new(fitted);
    app.baselines.put(&m.id, key, fitted.clone());
    Ok(fitted)
}
