//! `/v1/gearboxes`: a user's gearbox descriptions (format `gearwear-gearbox` v1, TOML or JSON,
//! see `docs/gearbox.md`) and the background job that precomputes each one's signature table.
//!
//! * `PUT /v1/gearboxes/{id}` (admin): validate (a problem+json with the description's own
//!   error), store, queue the table job; 201 for a new id, 200 for a replaced or repeated one.
//! * `GET /v1/gearboxes`, `GET /v1/gearboxes/{id}` (read): status (`queued`, `running` with
//!   `progress` 0–1, `ready`, `failed` with the reason), the resolved kinematics, the assumed
//!   values.
//! * [`worker`]: each replica claims queued jobs in the store (compare-and-set, with a lease it
//!   renews while the job runs), so two replicas never run the same job; a job whose replica
//!   died is claimed again when its lease runs out; a replica that stops gives its job back at
//!   once. The precompute writes its finished grid points to a partial file under the
//!   temporary directory, so the same host resumes an interrupted job where it stopped;
//!   another host starts it again.
//! * [`Tables`]: resolved gearboxes and prepared diagnosers, cached by description hash.
//!
//! The paper's rig is the built-in gearbox [`BUILTIN_ID`], always `ready`: its table is the
//! signatures file the service was started with. A machine with no gearbox uses it.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::Response;
use serde_json::json;
use tokio::sync::watch;

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::{check_gearbox_id, json_response, json_with_etag, read_body};
use crate::assessment::TableDiagnoser;
use crate::diagnosis::DiagnoseOptions;
use crate::gearbox::description::{GearboxDescription, MAX_DESCRIPTION_BYTES, TextFormat};
use crate::gearbox::{Gearbox, PAPER_RIG};
use crate::keys::Scope;
use crate::signature::precompute::{PrecomputeSpec, default_grid, partial_path, precompute};
use crate::signature::{SignatureTable, SimulationSettings, TableStatus};
use crate::store::{GearboxRow, PutOutcome, StoreError, new_id, now_ms};
use crate::views::gearbox_json;

/// Id of the built-in gearbox: the first paper's rig.
pub const BUILTIN_ID: &str = crate::machine::BUILTIN_GEARBOX_ID;
/// A claimed job's lease; renewed every [`PROGRESS_EVERY`] while it runs.
pub const LEASE_MS: i64 = 30_000;
const PROGRESS_EVERY: Duration = Duration::from_secs(1);
/// How often an idle worker looks for a job (a PUT on this replica wakes it at once).
const IDLE_POLL: Duration = Duration::from_secs(2);

/// Insert or refresh the built-in gearbox row (at start-up).
pub async fn ensure_builtin(app: &AppState) -> Result<(), StoreError> {
    let (mut row, _) = GearboxRow::described(
        BUILTIN_ID,
        PAPER_RIG,
        Some(TextFormat::Toml),
        "configs/gearboxes/wang2019.toml",
    )
    .map_err(|e| StoreError::Conflict(format!("the built-in description: {e}")))?;
    row.builtin = true;
    app.store.ensure_builtin_gearbox(&row).await
}

/// Resolved gearboxes and prepared diagnosers of stored tables, by description hash.
#[derive(Default)]
pub struct Tables {
    gearboxes: Mutex<HashMap<String, Arc<Gearbox>>>,
    diagnosers: Mutex<HashMap<String, Arc<TableDiagnoser>>>,
}

impl Tables {
    /// The resolved gearbox of a stored row.
    pub fn gearbox(&self, row: &GearboxRow) -> crate::Result<Arc<Gearbox>> {
        if let Some(g) = lock(&self.gearboxes).get(&row.hash) {
            return Ok(g.clone());
        }
        let d: GearboxDescription =
            serde_json::from_str(&row.description).map_err(|e| crate::Error::Stored {
                what: format!("gearbox `{}`", row.id),
                reason: e.to_string(),
            })?;
        let g = Arc::new(Gearbox::new(d)?);
        lock(&self.gearboxes).insert(row.hash.clone(), g.clone());
        Ok(g)
    }

    /// The diagnoser of a gearbox whose table is ready (`None` otherwise). The built-in one is
    /// the service's own.
    pub async fn diagnoser(
        &self,
        app: &AppState,
        row: &GearboxRow,
    ) -> ApiResult<Option<Arc<TableDiagnoser>>> {
        if row.builtin {
            return Ok(Some(app.diagnoser.clone()));
        }
        if row.status != TableStatus::Ready {
            return Ok(None);
        }
        if let Some(d) = lock(&self.diagnosers).get(&row.hash) {
            return Ok(Some(d.clone()));
        }
        let Some(text) = app.store.gearbox_table(&row.id, &row.hash).await? else {
            return Ok(None);
        };
        let origin = format!("the stored table of gearbox `{}`", row.id);
        let d = tokio::task::spawn_blocking(move || -> crate::Result<Arc<TableDiagnoser>> {
            let table = SignatureTable::from_json(&text, &origin)?;
            Ok(Arc::new(TableDiagnoser::new(
                table,
                DiagnoseOptions::default(),
            )?))
        })
        .await
        .map_err(|e| ApiError::internal(format!("loading a table failed: {e}")))?
        .map_err(|e| ApiError::internal(format!("the stored table is unusable: {e}")))?;
        lock(&self.diagnosers).insert(row.hash.clone(), d.clone());
        Ok(Some(d))
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn unknown_gearbox(id: &str) -> ApiError {
    ApiError::not_found(
        "unknown-gearbox",
        format!("no gearbox `{id}`; PUT its description to /v1/gearboxes/{id} first"),
    )
    .with("gearbox_id", id)
}

/// `PUT /v1/gearboxes/{id}`.
pub async fn put(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Body,
) -> ApiResult<Response> {
    if let Err(e) = caller.require(&app, Scope::Admin) {
        let _ = read_body(&headers, body, MAX_DESCRIPTION_BYTES).await;
        return Err(e);
    }
    check_gearbox_id(&id)?;
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    let format = match ct.as_str() {
        "application/json" => Some(TextFormat::Json),
        "application/toml" | "text/toml" | "text/x-toml" => Some(TextFormat::Toml),
        "text/plain" | "" => None,
        other => {
            return Err(ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported-media-type",
                "Unsupported content type",
                format!(
                    "content type `{other}` is not a gearbox description; send application/toml \
                     or application/json (format: docs/gearbox.md)"
                ),
            )
            .with("accepted", json!(["application/toml", "application/json"])));
        }
    };
    let bytes = read_body(&headers, body, MAX_DESCRIPTION_BYTES).await?;
    let text = std::str::from_utf8(&bytes).map_err(|_| {
        ApiError::bad_request(
            "invalid-gearbox",
            "Invalid gearbox description",
            "the description is not UTF-8 text",
        )
    })?;
    if id == BUILTIN_ID {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "builtin-gearbox",
            "Built-in gearbox",
            format!(
                "`{BUILTIN_ID}` is the built-in paper rig and cannot be replaced; choose another id"
            ),
        ));
    }
    let (row, gb) = GearboxRow::described(&id, text, format, "request body").map_err(|e| {
        ApiError::unprocessable(
            "invalid-gearbox",
            "Invalid gearbox description",
            format!("{e}; the format is described in docs/gearbox.md"),
        )
        .with("gearbox_id", id.as_str())
    })?;
    let outcome = app.store.put_gearbox(&row).await.map_err(|e| match e {
        StoreError::Conflict(m) => ApiError::new(
            StatusCode::CONFLICT,
            "builtin-gearbox",
            "Built-in gearbox",
            m,
        ),
        other => other.into(),
    })?;
    app.job_wake.notify_one();
    tracing::info!(gearbox = %id, ?outcome, "gearbox stored");
    let stored = app
        .store
        .get_gearbox(&id)
        .await?
        .ok_or_else(|| ApiError::internal("the stored gearbox vanished"))?;
    let status = if outcome == PutOutcome::Created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    let mut r = json_response(status, &gearbox_json(&stored, Some(&gb), true));
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/gearboxes/{id}")) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    Ok(r)
}

/// `GET /v1/gearboxes/{id}`.
pub async fn get(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    check_gearbox_id(&id)?;
    let row = app
        .store
        .get_gearbox(&id)
        .await?
        .ok_or_else(|| unknown_gearbox(&id))?;
    let gb = app.tables.gearbox(&row).ok();
    Ok(json_with_etag(
        &headers,
        &gearbox_json(&row, gb.as_deref(), true),
    ))
}

/// `GET /v1/gearboxes`.
pub async fn list(
    State(app): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    let rows = app.store.list_gearboxes().await?;
    let body =
        json!({"gearboxes": rows.iter().map(|r| gearbox_json(r, None, false)).collect::<Vec<_>>()});
    Ok(json_with_etag(&headers, &body))
}

/// Where a job keeps its finished grid points (resumed after a restart on this host).
fn job_partial(row: &GearboxRow) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join("gearwear-table-jobs");
    partial_path(&dir.join(format!(
        "{}-{}.json",
        row.id,
        &row.hash[..16.min(row.hash.len())]
    )))
}

/// The table job of one gearbox, as a blocking computation.
fn run_precompute(
    gb: Arc<Gearbox>,
    partial: std::path::PathBuf,
    done: Arc<AtomicUsize>,
) -> crate::Result<String> {
    let spec = PrecomputeSpec {
        grid: default_grid(&gb),
        sensor: crate::signature::SensorQuantity::default(),
        gearbox: gb,
        settings: SimulationSettings::default(),
        created_by: "gearwear serve (table job)".into(),
    };
    let table = precompute(&spec, Some(&partial), &|| {
        done.fetch_add(1, Ordering::Relaxed);
    })?;
    let _ = std::fs::remove_file(&partial);
    table.to_json()
}

/// The background worker: claims table jobs and runs them one at a time.
pub async fn worker(app: AppState, mut stop: watch::Receiver<bool>) {
    // The process id in the worker's name lets an operator (and scripts/cluster_test.sh) tell
    // which replica holds a job.
    let me = format!("pid{}-{}", std::process::id(), new_id());
    loop {
        if *stop.borrow() {
            break;
        }
        match app.store.claim_gearbox_job(now_ms(), LEASE_MS, &me).await {
            Ok(Some(job)) => {
                if run_job(&app, &me, job, &mut stop).await.is_break() {
                    break;
                }
                continue;
            }
            Ok(None) => {}
            Err(e) => tracing::warn!(error = %e, "table jobs: store unavailable"),
        }
        tokio::select! {
            _ = tokio::time::sleep(IDLE_POLL) => {}
            _ = app.job_wake.notified() => {}
            _ = stop.changed() => break,
        }
    }
}

/// Run one claimed job; `Break` when the service is stopping (the job's lease then runs out
/// and it is claimed again, resuming from its partial file on this host).
async fn run_job(
    app: &AppState,
    me: &str,
    job: GearboxRow,
    stop: &mut watch::Receiver<bool>,
) -> std::ops::ControlFlow<()> {
    use std::ops::ControlFlow::{Break, Continue};
    tracing::info!(gearbox = %job.id, attempt = job.attempts, "table job started");
    let gb = match app.tables.gearbox(&job) {
        Ok(g) => g,
        Err(e) => {
            let _ = app
                .store
                .finish_gearbox_job(&job.id, &job.hash, me, Err(e.to_string()), now_ms())
                .await;
            return Continue(());
        }
    };
    let total = {
        let g = default_grid(&gb);
        (g.ea.len() * g.omega1.len()).max(1)
    };
    let done = Arc::new(AtomicUsize::new(0));
    let mut task = tokio::task::spawn_blocking({
        let (gb, done, partial) = (gb.clone(), done.clone(), job_partial(&job));
        move || run_precompute(gb, partial, done)
    });
    let result = loop {
        tokio::select! {
            r = &mut task => break r,
            _ = tokio::time::sleep(PROGRESS_EVERY) => {
                let p = done.load(Ordering::Relaxed) as f64 / total as f64;
                let now = now_ms();
                match app.store.gearbox_progress(&job.id, &job.hash, me, p.min(0.999), now + LEASE_MS, now).await {
                    Ok(true) => {}
                    Ok(false) => {
                        // Another replica holds it now (or the description was replaced):
                        // its answer is the one kept; this one is dropped when it ends.
                        tracing::warn!(gearbox = %job.id, "table job lost its lease; abandoned");
                        return Continue(());
                    }
                    Err(e) => tracing::warn!(error = %e, "table job: progress not stored"),
                }
            }
            _ = stop.changed() => {
                // Given back for any replica (this one's restart resumes it from its partial
                // file). A replica killed without stopping gives nothing back: its lease runs out.
                let _ = app.store.release_gearbox_job(&job.id, &job.hash, me).await;
                tracing::info!(gearbox = %job.id, "stopping: the table job is queued again");
                return Break(());
            }
        }
    };
    let result = match result {
        Ok(Ok(json)) => Ok(json),
        Ok(Err(e)) => Err(e.to_string()),
        Err(e) => Err(format!("the precompute task failed: {e}")),
    };
    let ok = result.is_ok();
    match app
        .store
        .finish_gearbox_job(&job.id, &job.hash, me, result, now_ms())
        .await
    {
        Ok(true) => tracing::info!(gearbox = %job.id, ready = ok, "table job finished"),
        Ok(false) => {
            tracing::warn!(gearbox = %job.id, "table job finished after losing its lease; dropped")
        }
        Err(e) => {
            tracing::warn!(gearbox = %job.id, error = %e, "table job result not stored; it will run again")
        }
    }
    Continue(())
}
