//! `/healthz` (the process answers), `/readyz` (table loaded, store reachable), `/metrics`.

use std::time::Duration;

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::json;

use super::AppState;

pub async fn healthz() -> Response {
    Json(json!({"status": "ok"})).into_response()
}

/// The longest `/readyz` waits for the store's answer. Without a bound it would wait for the
/// pool's acquire timeout (5 s on PostgreSQL) while the database is unreachable — longer
/// than a readiness probe's own timeout usually is.
pub const READY_STORE_TIMEOUT: Duration = Duration::from_secs(2);

pub async fn readyz(State(app): State<AppState>) -> Response {
    let store_ok = match tokio::time::timeout(READY_STORE_TIMEOUT, app.store.ping()).await {
        Ok(Ok(())) => true,
        Ok(Err(e)) => {
            tracing::debug!(error = %e, "readyz: store unavailable");
            false
        }
        Err(_) => {
            tracing::debug!("readyz: the store did not answer within {READY_STORE_TIMEOUT:?}");
            false
        }
    };
    let table = app.diagnoser.table_id();
    let ready = store_ok && !table.is_empty();
    let body = json!({
        "status": if ready { "ready" } else { "not_ready" },
        "checks": {
            "signature_table": {"ok": !table.is_empty(), "model_hash": table},
            "store": {"ok": store_ok, "kind": app.store.kind()},
        }
    });
    let code = if ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    let mut r = (code, Json(body)).into_response();
    if !ready {
        r.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
    }
    r
}

pub async fn metrics(State(app): State<AppState>) -> Response {
    let text = app
        .metrics
        .render(!app.diagnoser.table_id().is_empty(), app.store.kind());
    let mut r = text.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
    );
    r
}
