//! A machine's lifecycle: `DELETE /v1/machines/{id}`, and the strict fleet's rule
//! (`serve --require-registered-machines`) that only registered machines take records.
//!
//! * `DELETE /v1/machines/{id}` (admin) deletes — it does not archive — the machine and
//!   everything of it in one transaction ([`MachineStore::delete_machine`]): its records (raw
//!   samples, baseline marks), diagnoses, calibration, and the stored `Idempotency-Key` answers
//!   about it, so a key replayed afterwards is a new request (stored anew, or refused in a
//!   strict fleet) rather than an answer naming deleted rows. Webhooks subscribed to
//!   `machine.deleted` get that event; deliveries already queued about the machine still go out
//!   (they describe what happened while it existed). 204 when it was deleted; 404
//!   `unknown-machine` when there was no such machine — a repeated DELETE changes nothing and
//!   says so.
//! * A machine is *registered* once it was configured with `PUT /v1/machines/{id}` (or
//!   `gearwear machine set`): `registered_at` in the store. A machine that exists only because
//!   records were posted for it is not. With `--require-registered-machines` a record for a
//!   machine that is not registered is a 404 `unknown-machine` with the hint to PUT it first,
//!   and nothing is stored ([`check_registered`] before the diagnosis, and again inside the
//!   record's transaction: [`Ingest::registered_only`]).
//!
//! [`MachineStore::delete_machine`]: crate::store::MachineStore::delete_machine
//! [`Ingest::registered_only`]: crate::store::Ingest::registered_only

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult, unregistered_machine};
use super::http::check_machine_id;
use crate::keys::Scope;
use crate::store::{MachineRow, now_ms};

/// `DELETE /v1/machines/{id}`.
pub async fn delete(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    check_machine_id(&id)?;
    let Some(d) = app.store.delete_machine(&id, now_ms()).await? else {
        return Err(ApiError::not_found(
            "unknown-machine",
            format!(
                "no machine `{id}`: it was deleted already, or it never had a record, a \
                 configuration or a calibration (GET /v1/machines lists the machines)"
            ),
        )
        .with("machine_id", id.as_str()));
    };
    // The `machine.deleted` deliveries are queued: send them now rather than at the next poll.
    app.webhook_wake.notify_one();
    tracing::info!(
        machine = %id,
        records = d.records,
        diagnoses = d.diagnoses,
        calibration = d.calibration,
        idempotency_answers = d.idempotency_answers,
        "machine deleted"
    );
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// Does the service take a record for this machine? Always, unless it runs with
/// `--require-registered-machines`; then only for a machine registered with
/// `PUT /v1/machines/{id}` (`machine`: its row, `None` when it has none).
pub fn check_registered(
    app: &AppState,
    machine_id: &str,
    machine: Option<&MachineRow>,
) -> ApiResult<()> {
    let registered = machine.is_some_and(|m| m.registered_at.is_some());
    if app.settings.require_registered_machines && !registered {
        return Err(unregistered_machine(machine_id));
    }
    Ok(())
}
