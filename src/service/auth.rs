//! `Authorization: Bearer gw_<id>_<secret>` → the key's scopes; per-key token-bucket rate
//! limit. The key is looked up by id, its secret hashed and compared in constant time
//! ([`crate::keys::verify`]); nothing about the presented token is logged but the id.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use axum::extract::FromRequestParts;
use axum::http::StatusCode;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;

use super::AppState;
use super::error::ApiError;
use crate::keys::{self, Scope};

/// The caller: a verified key, or nobody.
#[derive(Debug, Clone)]
pub struct Caller {
    pub key_id: Option<String>,
    pub scopes: Vec<Scope>,
    /// Why a presented key was refused; reported by [`Caller::require`], so a handler can
    /// still drain the request body first (a client mid-upload then reads the 401 instead of
    /// a reset connection).
    pub refused: Option<String>,
}

impl FromRequestParts<AppState> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let Some(h) = parts.headers.get(AUTHORIZATION) else {
            return Ok(Caller {
                key_id: None,
                scopes: vec![],
                refused: None,
            });
        };
        let refuse = |why: &str| Caller {
            key_id: None,
            scopes: vec![],
            refused: Some(why.to_string()),
        };
        let Some(token) = h.to_str().ok().and_then(|h| {
            h.strip_prefix("Bearer ")
                .or_else(|| h.strip_prefix("bearer "))
        }) else {
            return Ok(refuse(
                "use `Authorization: Bearer <key>` with a key from `gearwear keys create`",
            ));
        };
        let invalid = "the API key is not valid (unknown, malformed or revoked)";
        let Some((id, secret)) = keys::split_token(token.trim()) else {
            return Ok(refuse(invalid));
        };
        let Some(row) = state.store.get_key(id).await? else {
            return Ok(refuse(invalid));
        };
        if row.revoked_at.is_some() || !keys::verify(secret, &row.hash) {
            return Ok(refuse(invalid));
        }
        Ok(Caller {
            key_id: Some(row.id),
            scopes: row.scopes,
            refused: None,
        })
    }
}

impl Caller {
    /// Demand a key with `scope`, then charge the key's rate limit.
    pub fn require(&self, state: &AppState, scope: Scope) -> Result<(), ApiError> {
        if let Some(why) = &self.refused {
            return Err(ApiError::unauthorized(why.clone()));
        }
        let Some(id) = &self.key_id else {
            return Err(ApiError::unauthorized(format!(
                "this request needs an API key with the `{}` scope in `Authorization: Bearer <key>`",
                scope.as_str()
            )));
        };
        if !keys::grants(&self.scopes, scope) {
            return Err(ApiError::forbidden(scope.as_str()));
        }
        state.limiter.charge(id)
    }

    /// Reads: a read key, unless the operator opened the dashboard and read endpoints.
    pub fn require_read(&self, state: &AppState) -> Result<(), ApiError> {
        if state.settings.open_dashboard && self.key_id.is_none() && self.refused.is_none() {
            return state.limiter.charge("anonymous");
        }
        self.require(state, Scope::Read)
    }
}

/// Token buckets per key: `rate` tokens per second, at most `burst`.
pub struct RateLimiter {
    rate: f64,
    burst: f64,
    buckets: Mutex<HashMap<String, (f64, Instant)>>,
}

impl RateLimiter {
    pub fn new(rate: f64, burst: f64) -> Self {
        RateLimiter {
            rate,
            burst: burst.max(1.0),
            buckets: Mutex::new(HashMap::new()),
        }
    }

    /// Take one token for `key`, or a 429 saying when the next one comes.
    pub fn charge(&self, key: &str) -> Result<(), ApiError> {
        let now = Instant::now();
        let mut b = self.buckets.lock().expect("rate limiter lock");
        let (tokens, last) = b.entry(key.to_string()).or_insert((self.burst, now));
        *tokens = (*tokens + now.duration_since(*last).as_secs_f64() * self.rate).min(self.burst);
        *last = now;
        if *tokens >= 1.0 {
            *tokens -= 1.0;
            Ok(())
        } else {
            let wait = ((1.0 - *tokens) / self.rate).ceil() as u64;
            Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "rate-limited",
                "Too many requests",
                format!(
                    "this key may send {} requests per second (bursts of {}); retry after {} s",
                    self.rate,
                    self.burst,
                    wait.max(1)
                ),
            )
            .with("limit_per_second", self.rate)
            .retry_after(wait))
        }
    }
}
