//! The background worker of the tables: each replica claims, in the store, a gearbox's first
//! table job or a ready table's extension (compare-and-set, with a lease it renews every second
//! with the progress), so that two replicas never run the same one; a job whose replica died is
//! claimed again when its lease runs out, and a replica that stops gives its job back at once.
//! The precompute writes its finished grid points to a partial file under the temporary
//! directory, so the same host resumes an interrupted job where it stopped.
//!
//! A first table is laid over the gearbox's demand ([`super::demand`]; the default grid
//! without one); an extension computes the columns the demand needs beyond the stored table's
//! ([`crate::signature::coverage::extend`]), the stored table ready and in use meanwhile. After
//! either, the replica that finished it checks the demand again (it may have grown while the
//! job ran) and wakes the re-read worker for the records that waited for the table ([`crate::service::records::reread`]). Idle,
//! the worker also reads again the records a stopped replica left waiting.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use tokio::sync::watch;

use super::{covers_all, demand, plan};
use crate::service::AppState;
use crate::signature::coverage::{described_spans, extend, grid_for};
use crate::signature::precompute::{PrecomputeSpec, default_grid, partial_path, precompute};
use crate::signature::table::Grid;
use crate::signature::{SignatureTable, SimulationSettings};
use crate::store::{GearboxRow, StoreResult, TableText, new_id, now_ms};

/// A claimed job's lease; renewed every [`PROGRESS_EVERY`] while it runs.
pub const LEASE_MS: i64 = 30_000;
pub(crate) const PROGRESS_EVERY: Duration = Duration::from_secs(1);
/// How often an idle worker looks for a job (a PUT on this replica wakes it at once).
pub(crate) const IDLE_POLL: Duration = Duration::from_secs(2);

/// The worker's id: the process id in it lets an operator (and scripts/cluster_test.sh) tell
/// which replica holds a job.
pub(crate) fn worker_id() -> String {
    format!("pid{}-{}", std::process::id(), new_id())
}

/// Which lease a running job holds.
pub(crate) enum LeaseOf {
    Table { id: String, hash: String },
    Extension { id: String, hash: String },
    Physics { machine_id: String },
}

impl LeaseOf {
    /// Renew with the progress; `false` when `me` no longer holds it.
    async fn renew(&self, app: &AppState, me: &str, progress: f64) -> StoreResult<bool> {
        let now = now_ms();
        let until = now + LEASE_MS;
        match self {
            LeaseOf::Table { id, hash } => {
                app.store
                    .gearbox_progress(id, hash, me, progress, until, now)
                    .await
            }
            LeaseOf::Extension { id, hash } => {
                app.store
                    .extension_progress(id, hash, me, progress, None, until, now)
                    .await
            }
            LeaseOf::Physics { machine_id } => {
                app.store
                    .machine_physics_progress(machine_id, me, progress, None, until, now)
                    .await
            }
        }
    }

    /// Give the job back for any replica (this one is stopping).
    async fn release(&self, app: &AppState, me: &str) {
        let _ = match self {
            LeaseOf::Table { id, hash } => app.store.release_gearbox_job(id, hash, me).await,
            LeaseOf::Extension { id, hash } => app.store.release_extension(id, hash, me).await,
            LeaseOf::Physics { machine_id } => {
                app.store.release_machine_physics(machine_id, me).await
            }
        };
    }
}

/// How a leased run ended.
pub(crate) enum Ran<T> {
    /// The computation's result (or the task's panic, as text).
    Done(Result<T, String>),
    /// Another replica holds the job now (or it was queued again): this run is dropped.
    Lost,
    /// The service is stopping: the job was given back.
    Stopping,
}

/// Wait for the blocking `task`, renewing `lease` every [`PROGRESS_EVERY`] with `progress()`.
pub(crate) async fn leased<T: Send + 'static>(
    app: &AppState,
    me: &str,
    lease: &LeaseOf,
    mut task: tokio::task::JoinHandle<T>,
    progress: &(dyn Fn() -> f64 + Send + Sync),
    stop: &mut watch::Receiver<bool>,
) -> Ran<T> {
    loop {
        tokio::select! {
            r = &mut task => {
                return Ran::Done(r.map_err(|e| format!("the computation failed: {e}")));
            }
            _ = tokio::time::sleep(PROGRESS_EVERY) => {
                match lease.renew(app, me, progress().min(0.999)).await {
                    Ok(true) => {}
                    // Another replica holds it now (or it was replaced): its answer is the one
                    // kept; this one is dropped when it ends (a computation cannot be
                    // cancelled: waited for, so that a worker runs one at a time).
                    Ok(false) => {
                        let _ = task.await;
                        return Ran::Lost;
                    }
                    Err(e) => tracing::warn!(error = %e, "job: progress not stored"),
                }
            }
            _ = stop.changed() => {
                // Given back for any replica (this one's restart resumes it from its partial
                // file). A replica killed without stopping gives nothing back: its lease runs
                // out.
                lease.release(app, me).await;
                return Ran::Stopping;
            }
        }
    }
}

/// Where a job keeps its finished grid points (resumed after a restart on this host).
pub(crate) fn partial(kind: &str, id: &str, hash: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join("gearwear-table-jobs");
    partial_path(&dir.join(format!("{kind}{id}-{}.json", &hash[..16.min(hash.len())])))
}

/// What one pass of the worker did.
enum Step {
    Ran,
    Idle,
    Stopping,
}

/// The background worker: claims table jobs and extensions and runs them one at a time.
pub async fn worker(app: AppState, mut stop: watch::Receiver<bool>) {
    let me = worker_id();
    loop {
        if *stop.borrow() {
            break;
        }
        match step(&app, &me, &mut stop).await {
            Ok(Step::Ran) => continue,
            Ok(Step::Stopping) => break,
            Ok(Step::Idle) => {}
            Err(e) => tracing::warn!(error = %e, "table jobs: store unavailable"),
        }
        tokio::select! {
            _ = tokio::time::sleep(IDLE_POLL) => {}
            _ = app.job_wake.notified() => {}
            _ = stop.changed() => break,
        }
    }
}

async fn step(app: &AppState, me: &str, stop: &mut watch::Receiver<bool>) -> StoreResult<Step> {
    if let Some(job) = app.store.claim_gearbox_job(now_ms(), LEASE_MS, me).await? {
        return Ok(run_table(app, me, job, stop).await);
    }
    if let Some(job) = app.store.claim_extension(now_ms(), LEASE_MS, me).await? {
        return Ok(run_extension(app, me, job, stop).await);
    }
    Ok(Step::Idle)
}

/// The grid of a gearbox's first table: over its demand, else the default grid. A demand
/// whose plan is refused (machines checked one by one that together need too large a table)
/// falls back to the description's own span, then to the default grid.
async fn first_grid(app: &AppState, job: &GearboxRow, gb: &crate::gearbox::Gearbox) -> Grid {
    let spans = match demand(app, job, gb, None).await {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!(gearbox = %job.id, error = %e.detail, "table demand not read");
            described_spans(gb)
        }
    };
    match grid_for(gb, &spans) {
        Ok(Some(g)) => return g,
        Ok(None) => return default_grid(gb),
        Err(e) => tracing::warn!(gearbox = %job.id, error = %e, "the demand's table is refused"),
    }
    grid_for(gb, &described_spans(gb))
        .ok()
        .flatten()
        .unwrap_or_else(|| default_grid(gb))
}

/// Run one claimed first-table job.
async fn run_table(
    app: &AppState,
    me: &str,
    job: GearboxRow,
    stop: &mut watch::Receiver<bool>,
) -> Step {
    tracing::info!(gearbox = %job.id, attempt = job.attempts, "table job started");
    let gb = match app.tables.gearbox(&job) {
        Ok(g) => g,
        Err(e) => {
            let _ = app
                .store
                .finish_gearbox_job(&job.id, &job.hash, me, Err(e.to_string()), now_ms())
                .await;
            return Step::Ran;
        }
    };
    let grid = first_grid(app, &job, &gb).await;
    let total = (grid.ea.len() * grid.omega1.len()).max(1);
    let done = Arc::new(AtomicUsize::new(0));
    let task = tokio::task::spawn_blocking({
        let (done, path) = (done.clone(), partial("", &job.id, &job.hash));
        let spec = PrecomputeSpec {
            grid,
            sensor: crate::signature::SensorQuantity::default(),
            gearbox: gb.clone(),
            settings: SimulationSettings::default(),
            created_by: "gearwear serve (table job)".into(),
        };
        move || -> crate::Result<TableText> {
            let table = precompute(&spec, Some(&path), &|| {
                done.fetch_add(1, Ordering::Relaxed);
            })?;
            let _ = std::fs::remove_file(&path);
            table_text(&table)
        }
    });
    let lease = LeaseOf::Table {
        id: job.id.clone(),
        hash: job.hash.clone(),
    };
    let progress = move || done.load(Ordering::Relaxed) as f64 / total as f64;
    let result = match leased(app, me, &lease, task, &progress, stop).await {
        Ran::Done(r) => r.and_then(|r| r.map_err(|e| e.to_string())),
        Ran::Lost => {
            tracing::warn!(gearbox = %job.id, "table job lost its lease; abandoned");
            return Step::Ran;
        }
        Ran::Stopping => {
            tracing::info!(gearbox = %job.id, "stopping: the table job is queued again");
            return Step::Stopping;
        }
    };
    let ok = result.is_ok();
    match app
        .store
        .finish_gearbox_job(&job.id, &job.hash, me, result, now_ms())
        .await
    {
        Ok(true) => {
            tracing::info!(gearbox = %job.id, ready = ok, "table job finished");
            if ok {
                follow_up(app, &job.id).await;
            }
        }
        Ok(false) => {
            tracing::warn!(gearbox = %job.id, "table job finished after losing its lease; dropped")
        }
        Err(e) => {
            tracing::warn!(gearbox = %job.id, error = %e, "table job result not stored; it will run again")
        }
    }
    Step::Ran
}

fn table_text(t: &SignatureTable) -> crate::Result<TableText> {
    Ok(TableText {
        json: t.to_json()?,
        columns: t.grid.omega1.clone(),
    })
}

/// Run one claimed extension: the columns the demand needs, the new ones computed.
async fn run_extension(
    app: &AppState,
    me: &str,
    job: GearboxRow,
    stop: &mut watch::Receiver<bool>,
) -> Step {
    let finish = async |result: Result<Option<TableText>, String>| {
        let ok = result.is_ok();
        match app
            .store
            .finish_extension(&job.id, &job.hash, me, result, now_ms())
            .await
        {
            Ok(true) => {
                tracing::info!(gearbox = %job.id, ready = ok, "table extension finished");
                true
            }
            Ok(false) => {
                tracing::warn!(gearbox = %job.id, "table extension finished after losing its lease; dropped");
                false
            }
            Err(e) => {
                tracing::warn!(gearbox = %job.id, error = %e, "table extension not stored; it will run again");
                false
            }
        }
    };
    let prepared = prepare_extension(app, &job).await;
    let (table, columns) = match prepared {
        Ok(Some(p)) => p,
        Ok(None) => {
            // The stored table covers the demand already (an earlier extension did).
            if finish(Ok(None)).await {
                follow_up(app, &job.id).await;
            }
            return Step::Ran;
        }
        Err(why) => {
            finish(Err(why)).await;
            return Step::Ran;
        }
    };
    let lease = LeaseOf::Extension {
        id: job.id.clone(),
        hash: job.hash.clone(),
    };
    let new = columns
        .iter()
        .filter(|c| !table.grid.omega1.contains(c))
        .count();
    tracing::info!(gearbox = %job.id, attempt = job.attempts, columns = columns.len(), new, "table extension started");
    let now = now_ms();
    let _ = app
        .store
        .extension_progress(
            &job.id,
            &job.hash,
            me,
            0.0,
            Some(&columns),
            now + LEASE_MS,
            now,
        )
        .await;
    let total = (table.grid.ea.len() * new).max(1);
    let done = Arc::new(AtomicUsize::new(0));
    let task = tokio::task::spawn_blocking({
        let (done, path) = (done.clone(), partial("extension-", &job.id, &job.hash));
        move || -> crate::Result<TableText> {
            let t = extend(&table, &columns, Some(&path), &|| {
                done.fetch_add(1, Ordering::Relaxed);
            })?;
            let _ = std::fs::remove_file(&path);
            table_text(&t)
        }
    });
    let progress = move || done.load(Ordering::Relaxed) as f64 / total as f64;
    let result = match leased(app, me, &lease, task, &progress, stop).await {
        Ran::Done(r) => r.and_then(|r| r.map_err(|e| e.to_string())),
        Ran::Lost => {
            tracing::warn!(gearbox = %job.id, "table extension lost its lease; abandoned");
            return Step::Ran;
        }
        Ran::Stopping => return Step::Stopping,
    };
    if finish(result.map(Some)).await {
        follow_up(app, &job.id).await;
    }
    Step::Ran
}

/// The stored table and the columns an extension computes towards; `None` when the table
/// covers its demand already; `Err` (the extension fails with it) when the plan is refused or
/// the table cannot be read.
async fn prepare_extension(
    app: &AppState,
    job: &GearboxRow,
) -> Result<Option<(SignatureTable, Vec<f64>)>, String> {
    let gb = app.tables.gearbox(job).map_err(|e| e.to_string())?;
    let spans = demand(app, job, &gb, None).await.map_err(|e| e.detail)?;
    let d = app
        .tables
        .diagnoser(app, job)
        .await
        .map_err(|e| e.detail)?
        .ok_or("the stored table is not ready")?;
    let have = &d.table().grid.omega1;
    if covers_all(&gb, have, &spans) {
        return Ok(None);
    }
    let columns = plan(&gb, have, &spans).map_err(|e| e.to_string())?;
    if columns.iter().all(|c| have.contains(c)) {
        return Ok(None);
    }
    Ok(Some((d.table().clone(), columns)))
}

/// After a table of gearbox `id` was stored: queue another extension when the demand grew
/// while the job ran, and read again the records that waited for it.
async fn follow_up(app: &AppState, id: &str) {
    match app.store.get_gearbox(id).await {
        Ok(Some(row)) => {
            if let Err(e) = super::extend_if_needed(app, &row).await {
                tracing::warn!(gearbox = %id, error = %e.detail, "table demand not checked");
            }
        }
        Ok(None) => return,
        Err(e) => tracing::warn!(gearbox = %id, error = %e, "table demand not checked"),
    }
    // The re-read worker reads again the records that waited for this table.
    app.reread_wake.notify_one();
}
