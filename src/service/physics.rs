//! The machine's own model in the service: its physics fitted to its healthy records
//! ([`MachinePhysics::fit`]) and its own table, computed by a background job, read by its
//! records once ready.
//!
//! * **When** ([`super::physics_queue`]). A machine whose baseline has at least
//!   [`MIN_RECORDS`](crate::diagnosis::machine_physics::MIN_RECORDS) records carrying the
//!   table's line ratios at [`MIN_SPEEDS`](crate::diagnosis::machine_physics::MIN_SPEEDS)
//!   speeds or more, on one channel, while its gearbox's
//!   table is ready, gets a job queued for its machine row, gearbox description and
//!   `baseline_version` ([`PhysicsKey`]); a change of any of them queues it again (the result
//!   before is dropped). A job waits until its baseline has been still for [`SETTLE_MS`] (a
//!   baseline posted record by record would otherwise restart it with each one).
//! * **The job** ([`worker`], one per replica, beside the table worker): claimed in the store
//!   by compare-and-set with a lease renewed every second with its progress, like a table job;
//!   a killed replica's lease runs out and another replica takes it. The fit (0–50 %) is kept
//!   once done, so a restarted job only computes the table (50–100 %), resuming from its
//!   partial file on the same host. A fit the core refuses (no better than the empirical
//!   calibration, too few records or speeds) is stored `refused` with its message; any other
//!   error `failed`.
//! * **Use.** While none is ready, records are read as before (through the calibrated
//!   transfer path). Once ready, the machine's records are assessed with it
//!   ([`crate::assessment::Machine::own_model`]); each replica keeps the model it loaded
//!   ([`PhysicsCache`]) while the key stands.
//! * `GET /v1/machines/{id}/baseline` shows it as `physics` ([`physics_json`]).

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use serde_json::{Value, json};
use tokio::sync::watch;

use super::AppState;
use super::error::{ApiError, ApiResult};
use super::physics_queue::{fittable, healthy_ratios, key_of, queue_if_fittable};
use super::tables::jobs::{IDLE_POLL, LEASE_MS, LeaseOf, Ran, leased, partial, worker_id};
use crate::assessment::{OwnModel, TableDiagnoser};
use crate::diagnosis::DiagnoseOptions;
use crate::diagnosis::machine_path::LineRatios;
use crate::diagnosis::machine_physics::{MachinePhysics, PhysicsFitOptions};
use crate::gearbox::Gearbox;
use crate::signature::SignatureTable;
use crate::signature::precompute::precompute;
use crate::store::{MachineRow, PhysicsKey, PhysicsOutcome, PhysicsRow, now_ms};

/// How long a queued job waits for its machine's baseline to be still.
pub const SETTLE_MS: i64 = 3_000;
/// The own models this replica loaded, by machine, with the key they were made for.
#[derive(Default)]
pub struct PhysicsCache {
    loaded: Mutex<HashMap<String, (PhysicsKey, Arc<OwnModel>)>>,
}

impl PhysicsCache {
    fn get(&self, key: &PhysicsKey) -> Option<Arc<OwnModel>> {
        let m = self.loaded.lock().unwrap_or_else(|p| p.into_inner());
        m.get(&key.machine_id)
            .filter(|(k, _)| k == key)
            .map(|(_, o)| o.clone())
    }

    fn put(&self, key: PhysicsKey, o: Arc<OwnModel>) {
        let mut m = self.loaded.lock().unwrap_or_else(|p| p.into_inner());
        m.insert(key.machine_id.clone(), (key, o));
    }
}

/// Machine `m`'s own model when it is ready for its current baseline and gearbox description
/// `hash` (loaded once per replica), `None` otherwise.
pub async fn own_model(
    app: &AppState,
    m: Option<&MachineRow>,
    hash: &str,
) -> ApiResult<Option<Arc<OwnModel>>> {
    let Some(m) = m else {
        return Ok(None);
    };
    let key = key_of(m, hash);
    if let Some(o) = app.physics.get(&key) {
        return Ok(Some(o));
    }
    let Some(row) = app.store.get_machine_physics(&m.id).await? else {
        return Ok(None);
    };
    if row.key != key || row.status != "ready" {
        return Ok(None);
    }
    let (Some(report), Some(table)) = (row.report, app.store.machine_own_table(&key).await?) else {
        return Ok(None);
    };
    let o = tokio::task::spawn_blocking(move || -> crate::Result<OwnModel> {
        let physics: MachinePhysics =
            serde_json::from_str(&report).map_err(|e| crate::Error::Stored {
                what: "the machine's physics".into(),
                reason: e.to_string(),
            })?;
        let table = SignatureTable::from_json(&table, "the machine's own table")?;
        // Its gears' fault signatures are simulated here, once per replica (a few seconds).
        Ok(OwnModel::new(
            physics,
            TableDiagnoser::new(table, DiagnoseOptions::default())?,
        ))
    })
    .await
    .map_err(|e| ApiError::internal(format!("loading the machine's own model failed: {e}")))?;
    match o {
        Ok(o) => {
            let o = Arc::new(o);
            app.physics.put(key, o.clone());
            Ok(Some(o))
        }
        Err(e) => {
            // Read as before, and say so in the log: the stored model does not load.
            tracing::warn!(machine = %m.id, error = %e, "the machine's own model does not load");
            Ok(None)
        }
    }
}

/// The `physics` member of a machine's baseline: its own model's job — `status` (`queued`,
/// `running`, `ready`, `refused`, `failed`), `progress`, `phase`, the `error` of a refused or
/// failed one, the `report` (the fitted physics), and whether it was made for the machine's
/// current baseline and gearbox (`current`); null when none was ever queued.
pub fn physics_json(row: Option<&PhysicsRow>, current: &PhysicsKey) -> Value {
    let Some(r) = row else {
        return Value::Null;
    };
    let report: Value = r
        .report
        .as_deref()
        .and_then(|t| serde_json::from_str(t).ok())
        .unwrap_or(Value::Null);
    let phase = match (r.status.as_str(), r.report.is_some()) {
        ("queued" | "running", false) => Value::from("fit"),
        ("queued" | "running", true) => Value::from("table"),
        _ => Value::Null,
    };
    json!({
        "status": r.status,
        "progress": r.progress,
        "phase": phase,
        "error": r.error,
        "attempts": r.attempts,
        "baseline_version": r.key.baseline_version,
        "current": r.key == *current,
        "updated_at": crate::time::rfc3339(r.updated_at),
        "finished_at": r.finished_at.map(crate::time::rfc3339),
        "report": report,
    })
}

/// The background worker of the machines' own models: one job at a time.
pub async fn worker(app: AppState, mut stop: watch::Receiver<bool>) {
    let me = worker_id();
    loop {
        if *stop.borrow() {
            break;
        }
        let now = now_ms();
        match app
            .store
            .claim_machine_physics(now, LEASE_MS, now - SETTLE_MS, &me)
            .await
        {
            Ok(Some(job)) => {
                if run(&app, &me, job, &mut stop).await {
                    break;
                }
                continue;
            }
            Ok(None) => {}
            Err(e) => tracing::warn!(error = %e, "own models: store unavailable"),
        }
        tokio::select! {
            _ = tokio::time::sleep(IDLE_POLL) => {}
            _ = app.physics_wake.notified() => {}
            _ = stop.changed() => break,
        }
    }
}

/// What a job needs: the gearbox, the description's table and the healthy records' ratios.
struct Inputs {
    gearbox: Arc<Gearbox>,
    table: Arc<TableDiagnoser>,
    healthy: BTreeMap<String, Vec<LineRatios>>,
}

/// Why a claimed job does not run.
enum NotRun {
    /// It ends as failed, with the reason.
    Fails(String),
    /// The machine's baseline or gearbox changed since it was queued: the job was queued again
    /// for the machine as it is now (or dropped, when that is not fittable any more).
    Superseded,
}

/// The inputs of job `k`, or why it does not run.
async fn inputs(app: &AppState, k: &PhysicsKey) -> ApiResult<Result<Inputs, NotRun>> {
    let Some(m) = app.store.get_machine(&k.machine_id).await? else {
        return Ok(Err(NotRun::Fails("the machine is gone".into())));
    };
    let ctx = super::context::context_of(app, &k.machine_id, Some(m.clone())).await?;
    let hash = ctx.gearbox_row.hash.clone();
    let per = super::context::baseline_features(app, &k.machine_id, &hash).await?;
    if key_of(&m, &hash) != *k {
        // (A baseline posted record by record ends with a job one version behind: the last
        // record's own mark comes after the fit it triggered.)
        if fittable(&healthy_ratios(&per)) && ctx.diagnoser.is_some() {
            queue_if_fittable(app, &m, &hash, &per, true).await;
            return Ok(Err(NotRun::Superseded));
        }
        return Ok(Err(NotRun::Fails(
            "the machine's baseline or gearbox changed since this fit was queued, and is no \
             longer enough for a fit"
                .into(),
        )));
    }
    let Some(table) = ctx.diagnoser.clone() else {
        return Ok(Err(NotRun::Fails(
            "the gearbox's table is not ready".into(),
        )));
    };
    Ok(Ok(Inputs {
        gearbox: ctx.gearbox.clone(),
        table,
        healthy: healthy_ratios(&per),
    }))
}

/// Run one claimed job; `true` when the service is stopping.
async fn run(app: &AppState, me: &str, job: PhysicsRow, stop: &mut watch::Receiver<bool>) -> bool {
    let id = job.key.machine_id.clone();
    let finish = async |outcome: PhysicsOutcome| {
        let what = match &outcome {
            PhysicsOutcome::Ready { .. } => "ready",
            PhysicsOutcome::Refused(_) => "refused",
            PhysicsOutcome::Failed(_) => "failed",
        };
        match app
            .store
            .finish_machine_physics(&id, me, outcome, now_ms())
            .await
        {
            Ok(true) => {
                tracing::info!(machine = %id, status = what, "the machine's own model finished")
            }
            Ok(false) => {
                tracing::warn!(machine = %id, "the machine's own model finished after losing its lease; dropped")
            }
            Err(e) => {
                tracing::warn!(machine = %id, error = %e, "the machine's own model was not stored; it will run again")
            }
        }
    };
    let inputs = match inputs(app, &job.key).await {
        Ok(Ok(i)) => i,
        Ok(Err(NotRun::Fails(why))) => {
            finish(PhysicsOutcome::Failed(why)).await;
            return false;
        }
        Ok(Err(NotRun::Superseded)) => return false,
        Err(e) => {
            tracing::warn!(machine = %id, error = %e.detail, "own model: inputs not read");
            let _ = app.store.release_machine_physics(&id, me).await;
            return false;
        }
    };
    tracing::info!(machine = %id, attempt = job.attempts, fitted = job.report.is_some(), "the machine's own model started");
    let lease = LeaseOf::Physics {
        machine_id: id.clone(),
    };
    // The fit, unless a run before this one stored it.
    let stored: Option<MachinePhysics> = job
        .report
        .as_deref()
        .and_then(|t| serde_json::from_str(t).ok());
    let physics = match stored {
        Some(p) => p,
        None => match fit(app, me, &lease, &inputs, stop).await {
            Phase::Done(p) => p,
            Phase::Over(outcome) => {
                finish(outcome).await;
                return false;
            }
            Phase::Lost => return false,
            Phase::Stopping => return true,
        },
    };
    match own_table(app, me, &lease, &inputs, &physics, &job.key, stop).await {
        Phase::Done(table) => {
            let report = serde_json::to_string(&physics).unwrap_or_default();
            finish(PhysicsOutcome::Ready { report, table }).await;
            false
        }
        Phase::Over(outcome) => {
            finish(outcome).await;
            false
        }
        Phase::Lost => false,
        Phase::Stopping => true,
    }
}

/// How a phase of a job ended.
enum Phase<T> {
    Done(T),
    /// The job ends here: refused or failed.
    Over(PhysicsOutcome),
    /// Another replica holds it now, or it was queued again.
    Lost,
    Stopping,
}

/// The fit (progress 0 while it runs), stored once done; a refusal or a failure as the job's
/// outcome.
async fn fit(
    app: &AppState,
    me: &str,
    lease: &LeaseOf,
    i: &Inputs,
    stop: &mut watch::Receiver<bool>,
) -> Phase<MachinePhysics> {
    let task = tokio::task::spawn_blocking({
        let (gb, table, healthy) = (i.gearbox.clone(), i.table.clone(), i.healthy.clone());
        move || {
            MachinePhysics::fit(
                &gb,
                table.table(),
                &table.options(None),
                &healthy,
                &PhysicsFitOptions::default(),
            )
        }
    });
    let fitted = match leased(app, me, lease, task, &|| 0.0, stop).await {
        Ran::Done(Ok(Ok(p))) => p,
        Ran::Done(Ok(Err(
            e @ (crate::Error::PhysicsNoBetter { .. } | crate::Error::BaselineTooSmall { .. }),
        ))) => return Phase::Over(PhysicsOutcome::Refused(e.to_string())),
        Ran::Done(Ok(Err(e))) => return Phase::Over(PhysicsOutcome::Failed(e.to_string())),
        Ran::Done(Err(e)) => return Phase::Over(PhysicsOutcome::Failed(e)),
        Ran::Lost => return Phase::Lost,
        Ran::Stopping => return Phase::Stopping,
    };
    let LeaseOf::Physics { machine_id } = lease else {
        unreachable!("a physics job holds a physics lease")
    };
    let report = serde_json::to_string(&fitted).unwrap_or_default();
    let now = now_ms();
    match app
        .store
        .machine_physics_progress(machine_id, me, 0.5, Some(&report), now + LEASE_MS, now)
        .await
    {
        Ok(false) => return Phase::Lost,
        Err(e) => tracing::warn!(machine = %machine_id, error = %e, "the fit was not stored"),
        Ok(true) => {}
    }
    tracing::info!(machine = %machine_id, seconds = fitted.seconds, left_out_db = fitted.left_out_db, "the machine's physics are fitted");
    Phase::Done(fitted)
}

/// The machine's own table (progress 50–100 %), as JSON.
async fn own_table(
    app: &AppState,
    me: &str,
    lease: &LeaseOf,
    i: &Inputs,
    physics: &MachinePhysics,
    key: &PhysicsKey,
    stop: &mut watch::Receiver<bool>,
) -> Phase<String> {
    let spec = match physics.table_spec(&i.gearbox, i.table.table()) {
        Ok(s) => s,
        Err(e) => return Phase::Over(PhysicsOutcome::Failed(e.to_string())),
    };
    let total = (spec.grid.ea.len() * spec.grid.omega1.len()).max(1);
    let done = Arc::new(AtomicUsize::new(0));
    let path = partial(
        "own-",
        &key.machine_id,
        &format!("{}-{}", key.baseline_version, key.gearbox_hash),
    );
    let task = tokio::task::spawn_blocking({
        let done = done.clone();
        move || -> crate::Result<String> {
            let t = precompute(&spec, Some(&path), &|| {
                done.fetch_add(1, Ordering::Relaxed);
            })?;
            let _ = std::fs::remove_file(&path);
            t.to_json()
        }
    });
    let progress = move || 0.5 + 0.5 * done.load(Ordering::Relaxed) as f64 / total as f64;
    match leased(app, me, lease, task, &progress, stop).await {
        Ran::Done(Ok(Ok(t))) => Phase::Done(t),
        Ran::Done(Ok(Err(e))) => Phase::Over(PhysicsOutcome::Failed(e.to_string())),
        Ran::Done(Err(e)) => Phase::Over(PhysicsOutcome::Failed(e)),
        Ran::Lost => Phase::Lost,
        Ran::Stopping => Phase::Stopping,
    }
}
