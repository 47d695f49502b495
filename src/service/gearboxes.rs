//! `/v1/gearboxes`: a user's gearbox descriptions (format `gearwear-gearbox` v1, TOML or JSON,
//! see `docs/gearbox.md`) and the background job that precomputes each one's signature table.
//!
//! * `PUT /v1/gearboxes/{id}` (admin): validate (a problem+json with the description's own
//!   error), store, queue the table job; 201 for a new id, 200 for a replaced or repeated one.
//! * `GET /v1/gearboxes`, `GET /v1/gearboxes/{id}` (read): status (`queued`, `running` with
//!   `progress` 0–1, `ready`, `failed` with the reason), the resolved kinematics, the assumed
//!   values.
//! * [`super::tables::jobs::worker`]: each replica claims queued jobs in the store
//!   (compare-and-set, with a lease it renews while the job runs), so two replicas never run
//!   the same job; the tables are laid over where the gearbox's machines run and extended when
//!   they run elsewhere ([`super::tables`]).
//! * [`Tables`]: resolved gearboxes (by description hash) and prepared diagnosers (by gearbox,
//!   for the table it has now: an extended table replaces the diagnoser of the one before).
//!
//! The paper's rig is the built-in gearbox [`BUILTIN_ID`], always `ready`: its table is the
//! signatures file the service was started with. A machine with no gearbox uses it.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::Response;
use serde_json::json;

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::{check_gearbox_id, json_response, json_with_etag, read_body};
use crate::assessment::TableDiagnoser;
use crate::diagnosis::DiagnoseOptions;
use crate::gearbox::description::{GearboxDescription, MAX_DESCRIPTION_BYTES, TextFormat};
use crate::gearbox::{Gearbox, PAPER_RIG};
use crate::keys::Scope;
use crate::signature::{SignatureTable, TableStatus};
use crate::store::{GearboxRow, PutOutcome, StoreError};
use crate::views::gearbox_json;

/// Id of the built-in gearbox: the first paper's rig.
pub const BUILTIN_ID: &str = crate::machine::BUILTIN_GEARBOX_ID;
pub use super::tables::jobs::LEASE_MS;

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

/// Resolved gearboxes (by description hash) and prepared diagnosers of stored tables (by
/// gearbox id, with the [`Tables::table_key`] of the table they were prepared from).
#[derive(Default)]
pub struct Tables {
    gearboxes: Mutex<HashMap<String, Arc<Gearbox>>>,
    diagnosers: Mutex<HashMap<String, (String, Arc<TableDiagnoser>)>>,
}

impl Tables {
    /// Which stored table a row has: its description's hash and its columns (an extension
    /// keeps the hash and changes the columns).
    pub fn table_key(row: &GearboxRow) -> String {
        format!("{}/{:?}", row.hash, row.table_columns)
    }

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
        let key = Self::table_key(row);
        if let Some((k, d)) = lock(&self.diagnosers).get(&row.id)
            && *k == key
        {
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
        lock(&self.diagnosers).insert(row.id.clone(), (key, d.clone()));
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
    let (mut row, gb) = GearboxRow::described(&id, text, format, "request body").map_err(|e| {
        ApiError::unprocessable(
            "invalid-gearbox",
            "Invalid gearbox description",
            format!("{e}; the format is described in docs/gearbox.md"),
        )
        .with("gearbox_id", id.as_str())
    })?;
    if gb.description.nominal_input_hz.is_none() {
        // Without a nominal rate the table has nowhere to go but its machines' speeds: its job
        // waits a moment for a machine to be configured (which makes it due at once).
        row.lease_until = crate::store::now_ms() + super::tables::WAIT_FOR_MACHINES_MS;
    }
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
    let gb = if row.builtin {
        Some(app.builtin_gearbox.clone())
    } else {
        app.tables.gearbox(&row).ok()
    };
    let mut body = gearbox_json(&row, gb.as_deref(), true);
    if let (true, Some(gb)) = (row.builtin, &gb) {
        body["covers"] = super::tables::covers_json(gb, &app.diagnoser.table().grid.omega1);
    }
    Ok(json_with_etag(&headers, &body))
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
