//! A record's idempotency key and the replay of an earlier identical request's answer.

use std::sync::atomic::Ordering;

use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};

use crate::service::AppState;
use crate::service::auth::Caller;
use crate::service::error::{ApiError, ApiResult};
use crate::service::wire::BodyFormat;
use crate::store::IdemRow;

/// A record's idempotency key (HTTP: the `Idempotency-Key` header, scoped to the API key;
/// MQTT: the record id, scoped to the machine) and the hashes that identify the request.
pub struct Idempotency {
    pub(super) key: Option<String>,
    key_id: String,
    /// The body's SHA-256 (stored as the record's `sha256`).
    pub(super) body_sha256: String,
    /// Over machine, content type, query and the body hash.
    pub(super) request_hash: String,
}

impl Idempotency {
    pub(super) fn of(
        headers: &HeaderMap,
        caller: &Caller,
        machine_id: &str,
        format: BodyFormat,
        query: Option<&str>,
        bytes: &[u8],
    ) -> ApiResult<Idempotency> {
        let key = match headers.get("idempotency-key") {
            None => None,
            Some(v) => {
                let s = v.to_str().ok().filter(|s| !s.is_empty() && s.len() <= 255);
                Some(
                    s.ok_or_else(|| {
                        ApiError::bad_request(
                            "invalid-idempotency-key",
                            "Invalid Idempotency-Key",
                            "an Idempotency-Key is 1 to 255 visible ASCII characters (a UUID is a good choice)",
                        )
                    })?
                    .to_string(),
                )
            }
        };
        Ok(Idempotency::new(
            caller.key_id.clone().unwrap_or_default(),
            key,
            machine_id,
            format,
            query,
            bytes,
        ))
    }

    /// The key `key` in the scope `key_id` for a record of `machine_id` sent as `bytes` in
    /// `format` with the query (or MQTT header) `query`.
    pub fn new(
        key_id: String,
        key: Option<String>,
        machine_id: &str,
        format: BodyFormat,
        query: Option<&str>,
        bytes: &[u8],
    ) -> Idempotency {
        // The body is hashed once (it is stored as the record's `sha256`); the request hash
        // covers machine, content type, query and that body hash.
        let body_sha256 = hex::encode(Sha256::digest(bytes));
        let mut h = Sha256::new();
        for part in [
            machine_id.as_bytes(),
            format.mime().as_bytes(),
            query.unwrap_or("").as_bytes(),
            body_sha256.as_bytes(),
        ] {
            h.update(part);
            h.update([0u8]);
        }
        Idempotency {
            key,
            key_id,
            body_sha256,
            request_hash: hex::encode(h.finalize()),
        }
    }

    /// Whether `prev`, a stored answer to this key, answered this same request.
    pub fn same_request(&self, prev: &IdemRow) -> bool {
        prev.request_hash == self.request_hash
    }

    /// The stored answer to this key, if any.
    pub async fn stored(&self, app: &AppState) -> ApiResult<Option<IdemRow>> {
        match &self.key {
            Some(k) => Ok(app.store.get_idempotent(&self.key_id, k).await?),
            None => Ok(None),
        }
    }

    /// The answer of an earlier identical request, replayed.
    pub(super) async fn replay_stored(&self, app: &AppState) -> ApiResult<Option<Response>> {
        match self.stored(app).await? {
            Some(prev) => replay(app, &prev, &self.request_hash).map(Some),
            None => Ok(None),
        }
    }

    /// The row that keeps this request's answer.
    pub(super) fn row(&self, response_text: &str) -> Option<IdemRow> {
        self.key.as_ref().map(|k| IdemRow {
            key_id: self.key_id.clone(),
            idem_key: k.clone(),
            request_hash: self.request_hash.clone(),
            status: 201,
            response: response_text.to_string(),
        })
    }
}

pub(super) fn replay(app: &AppState, prev: &IdemRow, request_hash: &str) -> ApiResult<Response> {
    if prev.request_hash != request_hash {
        return Err(ApiError::unprocessable(
            "idempotency-key-reused",
            "Idempotency-Key reused with a different request",
            "this Idempotency-Key was already used for a different record; use a new key for a new record",
        ));
    }
    app.metrics.records_replayed.fetch_add(1, Ordering::Relaxed);
    let status = StatusCode::from_u16(prev.status as u16).unwrap_or(StatusCode::CREATED);
    let mut r = (status, prev.response.clone()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r.headers_mut()
        .insert("idempotent-replayed", HeaderValue::from_static("true"));
    Ok(r)
}
