//! `Authorization: Bearer gw_<id>_<secret>` → the key's scopes; per-key token-bucket rate
//! limit. The key is looked up by id, its secret hashed and compared in constant time
//! ([`crate::keys::verify`]); nothing about the presented token is logged but the id.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

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
            tracing::debug!(presented_key_id = id, "API key refused: unknown id");
            return Ok(refuse(invalid));
        };
        if row.revoked_at.is_some() || !keys::verify(secret, &row.hash) {
            tracing::debug!(
                presented_key_id = id,
                revoked = row.revoked_at.is_some(),
                "API key refused: revoked or wrong secret"
            );
            return Ok(refuse(invalid));
        }
        // The request's span (mod.rs) carries the key's id from here on.
        tracing::Span::current().record("key_id", row.id.as_str());
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
///
/// The map of buckets is bounded: a bucket idle for `burst / rate` seconds has refilled to
/// `burst`, exactly what a new bucket holds, so dropping it changes nothing. Such buckets are
/// swept whenever the map grows past a threshold (at least [`SWEEP_AT`], then twice the number
/// of buckets left after the last sweep, so sweeping costs O(1) per charge amortised).
pub struct RateLimiter {
    rate: f64,
    burst: f64,
    buckets: Mutex<Buckets>,
}

/// Buckets before the first sweep.
pub const SWEEP_AT: usize = 1024;

struct Buckets {
    map: HashMap<String, (f64, Instant)>,
    /// Sweep when the map holds this many buckets and a new key arrives.
    sweep_at: usize,
    min_sweep_at: usize,
}

impl RateLimiter {
    pub fn new(rate: f64, burst: f64) -> Self {
        Self::with_sweep_at(rate, burst, SWEEP_AT)
    }

    /// As [`RateLimiter::new`], sweeping idle buckets once more than `sweep_at` exist.
    pub fn with_sweep_at(rate: f64, burst: f64, sweep_at: usize) -> Self {
        let sweep_at = sweep_at.max(1);
        RateLimiter {
            rate,
            burst: burst.max(1.0),
            buckets: Mutex::new(Buckets {
                map: HashMap::new(),
                sweep_at,
                min_sweep_at: sweep_at,
            }),
        }
    }

    /// Buckets currently held (for tests and metrics).
    pub fn len(&self) -> usize {
        self.lock().map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Buckets> {
        // A panic while holding the lock cannot leave a bucket half-updated in a way that
        // matters (two plain numbers), so a poisoned lock is used as is.
        self.buckets.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// How long a bucket must be idle to be full again.
    fn refill_time(&self) -> Duration {
        if self.rate > 0.0 && self.rate.is_finite() {
            Duration::try_from_secs_f64(self.burst / self.rate).unwrap_or(Duration::MAX)
        } else {
            Duration::MAX
        }
    }

    /// Take one token for `key`, or a 429 saying when the next one comes.
    pub fn charge(&self, key: &str) -> Result<(), ApiError> {
        self.charge_at(key, Instant::now())
    }

    /// [`RateLimiter::charge`] at a given instant (tests drive the clock).
    pub fn charge_at(&self, key: &str, now: Instant) -> Result<(), ApiError> {
        let mut b = self.lock();
        if b.map.len() >= b.sweep_at && !b.map.contains_key(key) {
            let full_after = self.refill_time();
            b.map
                .retain(|_, (_, last)| now.saturating_duration_since(*last) < full_after);
            b.sweep_at = (b.map.len() * 2).max(b.min_sweep_at);
        }
        let (tokens, last) = b.map.entry(key.to_string()).or_insert((self.burst, now));
        let idle = now.saturating_duration_since(*last).as_secs_f64();
        *tokens = (*tokens + idle * self.rate).min(self.burst);
        *last = now;
        if *tokens >= 1.0 {
            *tokens -= 1.0;
            Ok(())
        } else {
            let wait = ((1.0 - *tokens) / self.rate).ceil();
            let wait = if wait.is_finite() { wait as u64 } else { 3600 };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_gets_its_burst_then_429_and_refills() {
        let l = RateLimiter::new(2.0, 3.0);
        let t0 = Instant::now();
        for _ in 0..3 {
            assert!(l.charge_at("a", t0).is_ok());
        }
        let e = l.charge_at("a", t0).unwrap_err();
        assert_eq!(e.status, StatusCode::TOO_MANY_REQUESTS);
        // Another key is not limited by the first.
        assert!(l.charge_at("b", t0).is_ok());
        // Half a second later one token is back (2 per second).
        assert!(l.charge_at("a", t0 + Duration::from_millis(500)).is_ok());
        assert!(l.charge_at("a", t0 + Duration::from_millis(500)).is_err());
    }

    #[test]
    fn idle_buckets_are_evicted_and_the_map_stays_bounded() {
        // burst 4 at 2 per second: a bucket idle for 2 s is full again.
        let l = RateLimiter::with_sweep_at(2.0, 4.0, 8);
        let t0 = Instant::now();
        for i in 0..8 {
            l.charge_at(&format!("old-{i}"), t0).unwrap();
        }
        assert_eq!(l.len(), 8);
        // Two of them stay busy.
        let t1 = t0 + Duration::from_secs(1);
        for _ in 0..4 {
            // old-0 is full again (3 + 2 tokens, capped at 4) and spends all four.
            l.charge_at("old-0", t1).unwrap();
        }
        l.charge_at("old-1", t1).unwrap();
        // 2.5 s after the start: the six others have been idle long enough to be full again
        // and are swept when a new key arrives; the two busy ones are kept (idle 1.5 s).
        let t2 = t0 + Duration::from_millis(2500);
        l.charge_at("new", t2).unwrap();
        assert_eq!(l.len(), 3, "old-0, old-1 and new remain");
        // A kept bucket keeps its state: old-0 was empty at t1 and has refilled 3 tokens
        // (1.5 s × 2 per second), not the 4 of a new bucket.
        for _ in 0..3 {
            l.charge_at("old-0", t2).unwrap();
        }
        assert!(l.charge_at("old-0", t2).is_err());
        // An evicted key starts from a full bucket, the same as if it had been kept.
        for _ in 0..4 {
            l.charge_at("old-5", t2).unwrap();
        }
        assert!(l.charge_at("old-5", t2).is_err());

        // Many keys, each used once, 3 s apart in waves: the map never passes the threshold
        // by more than one wave.
        let l = RateLimiter::with_sweep_at(2.0, 4.0, 100);
        let mut max_len = 0;
        for wave in 0..50u64 {
            let t = t0 + Duration::from_secs(3 * wave);
            for i in 0..60 {
                l.charge_at(&format!("k-{wave}-{i}"), t).unwrap();
                max_len = max_len.max(l.len());
            }
        }
        assert!(max_len <= 100, "the map grew to {max_len} buckets");
    }
}
