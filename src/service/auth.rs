//! `Authorization: Bearer gw_<id>_<secret>` → the key's scopes; per-key rate limit
//! (`governor`). The key is looked up by id, its secret hashed and compared in constant time
//! ([`crate::keys::verify`]); nothing about the presented token is logged but the id.

use std::num::NonZeroU32;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use axum::extract::FromRequestParts;
use axum::http::StatusCode;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use governor::Quota;
use governor::clock::{Clock, MonotonicClock};
use governor::middleware::NoOpMiddleware;
use governor::state::keyed::DashMapStateStore;

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

/// The per-key rate limit: `rate` requests per second, bursts of `burst`, by the `governor`
/// crate's keyed limiter (GCRA, which admits exactly what a token bucket of `burst` tokens
/// refilled at `rate` per second admits). `governor` counts whole requests: a fractional
/// `--rate-burst` is rounded down (at least 1).
///
/// The map of keys is bounded: a key whose state is indistinguishable from a new key's (its
/// bucket full again) is dropped by [`governor::RateLimiter::retain_recent`], which changes
/// nothing. Kept here, as `governor` has no policy of its own for when to sweep: whenever the
/// map grows past a threshold (at least [`SWEEP_AT`], then twice the number of keys left after
/// the last sweep, so sweeping costs O(1) per charge amortised).
pub struct RateLimiter<C: Clock = MonotonicClock> {
    rate: f64,
    burst: u32,
    keys: governor::RateLimiter<String, DashMapStateStore<String>, C, NoOpMiddleware<C::Instant>>,
    /// Sweep when the map holds this many keys.
    sweep_at: AtomicUsize,
    min_sweep_at: usize,
}

/// Keys before the first sweep.
pub const SWEEP_AT: usize = 1024;

impl RateLimiter {
    pub fn new(rate: f64, burst: f64) -> Self {
        Self::with_clock(rate, burst, SWEEP_AT, MonotonicClock)
    }
}

impl<C: Clock> RateLimiter<C> {
    /// As [`RateLimiter::new`] on `clock` (tests drive a fake one), sweeping idle keys once
    /// more than `sweep_at` exist.
    pub fn with_clock(rate: f64, burst: f64, sweep_at: usize, clock: C) -> Self {
        let sweep_at = sweep_at.max(1);
        let whole = burst.floor().clamp(1.0, u32::MAX as f64) as u32;
        // One request every 1/rate s, kept within what `governor`'s nanosecond arithmetic holds
        // (a rate over 1e9 per second is one per nanosecond; a rate so low that a burst's
        // refill would overflow is a refill in ~146 years).
        let max_ns = (u64::MAX / 4) as f64 / f64::from(whole);
        let period_ns = (1e9 / rate).clamp(1.0, max_ns);
        let quota = Quota::with_period(Duration::from_nanos(period_ns as u64))
            .expect("a period of at least 1 ns")
            .allow_burst(NonZeroU32::new(whole).expect("a burst of at least 1"));
        RateLimiter {
            rate,
            burst: whole,
            keys: governor::RateLimiter::dashmap_with_clock(quota, clock),
            sweep_at: AtomicUsize::new(sweep_at),
            min_sweep_at: sweep_at,
        }
    }

    /// Keys currently held (for tests and metrics).
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Take one request for `key`, or a 429 saying when the next one is allowed.
    pub fn charge(&self, key: &str) -> Result<(), ApiError> {
        if self.keys.len() >= self.sweep_at.load(Ordering::Relaxed) {
            self.keys.retain_recent();
            let left = self.keys.len();
            self.sweep_at
                .store((left * 2).max(self.min_sweep_at), Ordering::Relaxed);
        }
        let Err(not_until) = self.keys.check_key(&key.to_string()) else {
            return Ok(());
        };
        let now = self.keys.clock().now();
        let wait = not_until.wait_time_from(now).as_secs_f64().ceil().max(1.0) as u64;
        Err(ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            "rate-limited",
            "Too many requests",
            format!(
                "this key may send {} requests per second (bursts of {}); retry after {wait} s",
                self.rate, self.burst
            ),
        )
        .with("limit_per_second", self.rate)
        .retry_after(wait))
    }
}

#[cfg(test)]
mod tests {
    use governor::clock::FakeRelativeClock;

    use super::*;

    fn limiter(
        rate: f64,
        burst: f64,
        sweep_at: usize,
    ) -> (RateLimiter<FakeRelativeClock>, FakeRelativeClock) {
        let clock = FakeRelativeClock::default();
        (
            RateLimiter::with_clock(rate, burst, sweep_at, clock.clone()),
            clock,
        )
    }

    #[test]
    fn a_key_gets_its_burst_then_429_and_refills() {
        let (l, clock) = limiter(2.0, 3.0, SWEEP_AT);
        for _ in 0..3 {
            assert!(l.charge("a").is_ok());
        }
        let e = l.charge("a").unwrap_err();
        assert_eq!(e.status, StatusCode::TOO_MANY_REQUESTS);
        assert_eq!(e.slug, "rate-limited");
        // The next request is allowed in 0.5 s: Retry-After rounds up to whole seconds.
        assert_eq!(e.retry_after, Some(1));
        assert_eq!(e.extra["limit_per_second"], 2.0);
        assert_eq!(
            e.detail,
            "this key may send 2 requests per second (bursts of 3); retry after 1 s"
        );
        // Another key is not limited by the first.
        assert!(l.charge("b").is_ok());
        // Half a second later one request is allowed again (2 per second).
        clock.advance(Duration::from_millis(500));
        assert!(l.charge("a").is_ok());
        assert!(l.charge("a").is_err());
    }

    #[test]
    fn retry_after_is_the_wait_for_the_next_request_and_a_fractional_burst_rounds_down() {
        let (l, clock) = limiter(0.5, 2.7, SWEEP_AT);
        assert!(l.charge("a").is_ok() && l.charge("a").is_ok());
        assert_eq!(l.charge("a").unwrap_err().retry_after, Some(2));
        clock.advance(Duration::from_millis(1500));
        assert_eq!(l.charge("a").unwrap_err().retry_after, Some(1));
        clock.advance(Duration::from_millis(500));
        assert!(l.charge("a").is_ok());
    }

    #[test]
    fn idle_keys_are_evicted_and_the_map_stays_bounded() {
        // burst 4 at 2 per second; sweeping once 4 keys are held.
        let (l, clock) = limiter(2.0, 4.0, 4);
        for _ in 0..4 {
            l.charge("busy").unwrap();
        }
        for k in ["a", "b", "c"] {
            l.charge(k).unwrap();
        }
        assert_eq!(l.len(), 4);
        // 1.5 s later a, b and c are full again and swept when the next key comes; `busy`
        // has 3 of its 4 back and is kept.
        clock.advance(Duration::from_millis(1500));
        l.charge("new").unwrap();
        assert_eq!(l.len(), 2, "busy and new remain");
        // A kept key keeps its state: 3 requests, not the 4 of a new key.
        for _ in 0..3 {
            l.charge("busy").unwrap();
        }
        assert!(l.charge("busy").is_err());
        // An evicted key starts from a full burst, the same as if it had been kept.
        for _ in 0..4 {
            l.charge("a").unwrap();
        }
        assert!(l.charge("a").is_err());

        // Many keys, each used once, 3 s apart in waves: the map never passes the threshold.
        let (l, clock) = limiter(2.0, 4.0, 100);
        let mut max_len = 0;
        for wave in 0..50 {
            clock.advance(Duration::from_secs(3));
            for i in 0..60 {
                l.charge(&format!("k-{wave}-{i}")).unwrap();
                max_len = max_len.max(l.len());
            }
        }
        assert!(max_len <= 100, "the map grew to {max_len} keys");
        assert!(max_len > 60, "a sweep was needed: {max_len}");
    }
}
