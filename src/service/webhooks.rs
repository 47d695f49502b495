//! Webhooks for maintenance systems: subscriptions over the API, a delivery queue in the
//! store, and a background worker that POSTs signed payloads with retries and back-off.
//!
//! At-least-once: every event is written to `deliveries` in the same transaction as the
//! diagnosis that raised it; the worker claims due deliveries with a lease (so replicas sharing
//! PostgreSQL do not double-send), and a delivery stays `pending` until a 2xx answer is
//! recorded — a restart in between only means it is sent again. Receivers deduplicate with
//! the `Gearwear-Delivery` header.
//!
//! Signature: `Gearwear-Signature: t=<unix seconds>,v1=<hex HMAC-SHA256(secret, "<t>.<body>")>`.

use std::time::{Duration, Instant};

use axum::Json;
use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};
use tokio::sync::watch;

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::read_body;
use crate::keys::{self, Scope};
use crate::store::{AttemptRow, DeliveryRow, Outcome, WebhookRow, new_id, now_ms};
use crate::time::rfc3339;

/// Events a subscription may ask for: a record's diagnosis was stored; a machine's alert opened
/// or escalated (`wear.threshold_crossed`, the older name, once per transition); a machine was
/// deleted (`DELETE /v1/machines/{id}`); an alert opened, was acknowledged, closed.
pub const EVENTS: [&str; 6] = [
    "diagnosis.created",
    "wear.threshold_crossed",
    "machine.deleted",
    "alert.opened",
    "alert.acknowledged",
    "alert.closed",
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NewWebhook {
    url: String,
    events: Vec<String>,
}

/// What webhook URLs may point at, for the messages.
const ALLOWED: &str = "webhooks may go to public, private (10.0.0.0/8, 172.16.0.0/12, \
                       192.168.0.0/16, fc00::/7) or loopback addresses, not to link-local, \
                       cloud-metadata or unspecified ones";

/// A webhook URL the service will POST to: absolute `http`/`https` with a host, at most 2048
/// characters, and not aimed at a link-local, cloud-metadata or unspecified address (the
/// worker must not become a way to read a cloud instance's credentials). Hosts given by name
/// are checked again when they are resolved, at each delivery ([`GuardedResolver`]).
/// `Err` is a message for the caller.
pub fn check_url(raw: &str) -> Result<reqwest::Url, String> {
    if raw.len() > 2048 {
        return Err(format!(
            "`url` is {} characters long; at most 2048 are accepted",
            raw.len()
        ));
    }
    let shown: String = raw.chars().take(200).collect();
    let u = reqwest::Url::parse(raw).map_err(|e| {
        format!("`url` must be an absolute http(s) URL such as https://cmms.example/hooks/wear, got `{shown}` ({e})")
    })?;
    if !matches!(u.scheme(), "http" | "https") {
        return Err(format!(
            "`url` must use http:// or https://, got the scheme `{}` in `{shown}`",
            u.scheme()
        ));
    }
    let Some(host) = u.host_str().filter(|h| !h.is_empty()) else {
        return Err(format!("`url` has no host: `{shown}`"));
    };
    // The URL parser has already normalised IPv4 spellings (decimal, hex, octal) to
    // dotted quads, and IPv6 literals come in brackets.
    let literal = host.trim_start_matches('[').trim_end_matches(']');
    if let Ok(ip) = literal.parse::<std::net::IpAddr>()
        && let Some(why) = refused_ip(ip)
    {
        return Err(format!("`url` points at {ip}, {why}; {ALLOWED}"));
    }
    Ok(u)
}

/// Why a webhook may not connect to `ip`, or `None` if it may. Link-local (169.254.0.0/16,
/// fe80::/10: where cloud metadata services answer), two metadata addresses outside it
/// (Alibaba's 100.100.100.200, AWS's IPv6 fd00:ec2::254), unspecified (0.0.0.0, ::) and the
/// IPv4 broadcast address; IPv4-mapped IPv6 addresses are judged as their IPv4 address.
/// Loopback and private addresses stay allowed (tests and plants use them).
pub fn refused_ip(ip: std::net::IpAddr) -> Option<&'static str> {
    use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};
    let ip = match ip {
        IpAddr::V6(v6) => v6.to_ipv4_mapped().map(IpAddr::V4).unwrap_or(ip),
        v4 => v4,
    };
    match ip {
        IpAddr::V4(a) if a.is_unspecified() => Some("the unspecified address"),
        IpAddr::V4(a) if a.is_broadcast() => Some("the broadcast address"),
        IpAddr::V4(a) if a.is_link_local() => {
            Some("a link-local address (169.254.0.0/16, where cloud instance metadata answers)")
        }
        IpAddr::V4(a) if a == Ipv4Addr::new(100, 100, 100, 200) => {
            Some("a cloud instance-metadata address")
        }
        IpAddr::V6(a) if a.is_unspecified() => Some("the unspecified address"),
        IpAddr::V6(a) if (a.segments()[0] & 0xffc0) == 0xfe80 => {
            Some("a link-local address (fe80::/10)")
        }
        IpAddr::V6(a) if a == Ipv6Addr::new(0xfd00, 0xec2, 0, 0, 0, 0, 0, 0x254) => {
            Some("a cloud instance-metadata address")
        }
        _ => None,
    }
}

/// DNS for webhook deliveries: the system resolver, minus the addresses [`refused_ip`]
/// refuses, so a name that resolves to a metadata address (now or after a DNS change) is not
/// connected to either. A name that resolves only to refused addresses fails the attempt
/// with a message saying so.
pub struct GuardedResolver;

impl reqwest::dns::Resolve for GuardedResolver {
    fn resolve(&self, name: reqwest::dns::Name) -> reqwest::dns::Resolving {
        Box::pin(resolve_guarded(name.as_str().to_string()))
    }
}

async fn resolve_guarded(
    host: String,
) -> Result<reqwest::dns::Addrs, Box<dyn std::error::Error + Send + Sync>> {
    let all: Vec<std::net::SocketAddr> =
        tokio::net::lookup_host((host.as_str(), 0)).await?.collect();
    let ok: Vec<std::net::SocketAddr> = all
        .iter()
        .copied()
        .filter(|a| refused_ip(a.ip()).is_none())
        .collect();
    if ok.is_empty()
        && let Some(first) = all.first()
    {
        let why = refused_ip(first.ip()).unwrap_or("refused");
        return Err(format!("`{host}` resolves to {}, {why}; {ALLOWED}", first.ip()).into());
    }
    Ok(Box::new(ok.into_iter()))
}

fn webhook_json(w: &WebhookRow) -> Value {
    json!({"id": w.id, "url": w.url, "events": w.events, "created_at": rfc3339(w.created_at)})
}

pub async fn create(
    State(app): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
    body: Body,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    let bytes = read_body(&headers, body, 64 * 1024).await?;
    let n: NewWebhook = serde_json::from_slice(&bytes).map_err(|e| {
        ApiError::bad_request(
            "invalid-json",
            "Malformed webhook",
            format!("{e}; expected {{\"url\": \"https://…\", \"events\": [\"diagnosis.created\", \"wear.threshold_crossed\"]}}"),
        )
    })?;
    if let Err(why) = check_url(&n.url) {
        return Err(ApiError::unprocessable(
            "invalid-webhook",
            "Invalid webhook",
            why,
        ));
    }
    if n.events.is_empty() || n.events.iter().any(|e| !EVENTS.contains(&e.as_str())) {
        return Err(ApiError::unprocessable(
            "invalid-webhook",
            "Invalid webhook",
            format!(
                "`events` must be a non-empty list of {EVENTS:?}, got {:?}",
                n.events
            ),
        ));
    }
    let mut events = n.events.clone();
    events.sort();
    events.dedup();
    let w = WebhookRow {
        id: new_id(),
        url: n.url,
        secret: keys::webhook_secret(),
        events,
        created_at: now_ms(),
    };
    app.store.insert_webhook(&w).await?;
    let mut body = webhook_json(&w);
    // The signing secret is shown once, here.
    body["secret"] = w.secret.clone().into();
    Ok((StatusCode::CREATED, Json(body)).into_response())
}

pub async fn list(State(app): State<AppState>, caller: Caller) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    let ws = app.store.list_webhooks().await?;
    Ok(Json(json!({"webhooks": ws.iter().map(webhook_json).collect::<Vec<_>>()})).into_response())
}

fn unknown_webhook(id: &str) -> ApiError {
    ApiError::not_found("unknown-webhook", format!("no webhook `{id}`")).with("webhook_id", id)
}

pub async fn delete(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    if app.store.delete_webhook(&id, now_ms()).await? {
        Ok(StatusCode::NO_CONTENT.into_response())
    } else {
        Err(unknown_webhook(&id))
    }
}

fn delivery_json(d: &DeliveryRow, attempts: Vec<AttemptRow>) -> Value {
    json!({
        "id": d.id,
        "event": d.event,
        "status": d.status,
        "attempt_count": d.attempts,
        "created_at": rfc3339(d.created_at),
        "next_attempt_at": (d.status == "pending").then(|| rfc3339(d.next_attempt_at)),
        "delivered_at": d.delivered_at.map(rfc3339),
        "payload": serde_json::from_str::<Value>(&crate::views::delivery_payload(&d.payload))
            .unwrap_or(Value::Null),
        "attempts": attempts.iter().map(|a| json!({
            "attempt": a.attempt,
            "attempted_at": rfc3339(a.attempted_at),
            "status_code": a.status_code,
            "error": a.error,
            "duration_ms": a.duration_ms,
        })).collect::<Vec<_>>(),
    })
}

pub async fn deliveries(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    caller.require(&app, Scope::Admin)?;
    if app.store.get_webhook(&id).await?.is_none() {
        return Err(unknown_webhook(&id));
    }
    let ds = app.store.list_deliveries(&id, 100).await?;
    let mut out = Vec::with_capacity(ds.len());
    for d in &ds {
        let a = app.store.list_attempts(&d.id).await?;
        out.push(delivery_json(d, a));
    }
    Ok(Json(json!({"deliveries": out})).into_response())
}

/// Back-off before attempt `attempt + 1`: `base · 2^(attempt − 1)`, capped.
///
/// Hand-written, not `backon`'s: a delivery's attempts are spread over worker runs, replicas
/// and restarts, so the schedule's position (the attempt count) and the next attempt's time
/// live in the database, where `backon`'s in-process retry cannot keep them; and `backon`'s
/// exponential schedule multiplies in `f32`, so a 700 ms base's second wait is 1.399999976 s,
/// stored as 1399 ms, where this gives 1400 ms.
pub fn backoff(base: Duration, max: Duration, attempt: i64) -> Duration {
    let f = 2f64.powi((attempt - 1).clamp(0, 30) as i32);
    base.mul_f64(f).min(max)
}

/// An error with its causes (`reqwest` alone says "error sending request for url (…)"; the
/// cause — connection refused, timed out, DNS — is in the source chain).
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let c_text = c.to_string();
        if !s.contains(&c_text) {
            s.push_str(": ");
            s.push_str(&c_text);
        }
        cause = c.source();
    }
    s
}

/// The delivery worker: runs until `stop` turns true.
pub async fn worker(app: AppState, mut stop: watch::Receiver<bool>) {
    let ws = app.settings.webhooks.clone();
    let lease_ms = (ws.timeout.as_millis() as i64) * 2 + 1000;
    loop {
        if *stop.borrow() {
            break;
        }
        match app.store.claim_deliveries(now_ms(), lease_ms, 32).await {
            Ok(batch) => {
                let busy = !batch.is_empty();
                for (d, w) in batch {
                    deliver(&app, &d, &w).await;
                }
                if busy {
                    continue;
                }
            }
            Err(e) => tracing::warn!(error = %e, "webhook worker: store unavailable"),
        }
        tokio::select! {
            _ = app.webhook_wake.notified() => {}
            _ = tokio::time::sleep(ws.poll_interval) => {}
            _ = stop.changed() => {}
        }
    }
}

async fn deliver(app: &AppState, d: &DeliveryRow, w: &WebhookRow) {
    let ws = &app.settings.webhooks;
    let t = now_ms() / 1000;
    let payload = crate::views::delivery_payload(&d.payload);
    let sig = keys::sign_webhook(&w.secret, t, payload.as_bytes());
    let started = Instant::now();
    // A subscription made before the URL rules (or written to the store by hand) is checked
    // again here; a refused URL fails at once, retrying cannot help.
    let refused = check_url(&w.url).err();
    let (code, error) = match &refused {
        Some(why) => (None, Some(why.clone())),
        None => {
            let res = app
                .http
                .post(&w.url)
                .timeout(ws.timeout)
                .header("content-type", "application/json")
                .header(
                    "user-agent",
                    concat!("gearwear/", env!("CARGO_PKG_VERSION")),
                )
                .header("gearwear-event", &d.event)
                .header("gearwear-delivery", &d.id)
                .header("gearwear-signature", sig)
                .body(payload)
                .send()
                .await;
            match &res {
                Ok(r) => (Some(r.status().as_u16() as i64), None),
                Err(e) => (None, Some(error_chain(e))),
            }
        }
    };
    let attempt = d.attempts + 1;
    let ok = code.is_some_and(|c| (200..300).contains(&c));
    let now = now_ms();
    let outcome = if ok {
        Outcome::Delivered
    } else if attempt >= ws.max_attempts || refused.is_some() {
        Outcome::Failed
    } else {
        Outcome::Retry {
            next_attempt_at: now
                + backoff(ws.base_backoff, ws.max_backoff, attempt).as_millis() as i64,
        }
    };
    let a = AttemptRow {
        delivery_id: d.id.clone(),
        attempt,
        attempted_at: now,
        status_code: code,
        error: error.or_else(|| (!ok).then(|| format!("HTTP {}", code.unwrap_or(0)))),
        duration_ms: started.elapsed().as_millis() as i64,
    };
    app.metrics.delivery(match outcome {
        Outcome::Delivered => "delivered",
        Outcome::Retry { .. } => "retry",
        Outcome::Failed => "failed",
    });
    tracing::info!(delivery = %d.id, webhook = %w.id, event = %d.event, attempt, status = ?code, ok, "webhook attempt");
    if let Err(e) = app.store.record_attempt(&a, outcome).await {
        // The lease expires and the delivery is retried: at least once.
        tracing::warn!(error = %e, delivery = %d.id, "could not record a webhook attempt");
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn webhook_urls_refuse_metadata_and_link_local_only() {
        use super::check_url;
        for ok in [
            "http://127.0.0.1:8081/hook",
            "http://[::1]:9/hook",
            "http://localhost:9/hook",
            "http://10.1.2.3/hook",
            "http://172.16.0.1/hook",
            "http://192.168.0.10:8080/hook",
            "http://[fd12:3456::1]/hook",
            "https://cmms.example.com/hooks/wear?x=1",
            "http://169.255.0.1/",
        ] {
            assert!(check_url(ok).is_ok(), "{ok}: {:?}", check_url(ok));
        }
        for (bad, says) in [
            ("ftp://x/y", "http:// or https://"),
            ("file:///etc/passwd", "http:// or https://"),
            ("hook", "absolute"),
            ("http://169.254.169.254/latest/meta-data/", "link-local"),
            ("http://169.254.0.1:8080/", "link-local"),
            // The same address spelt as one decimal number and in hex.
            ("http://2852039166/", "link-local"),
            ("http://0xa9fea9fe/", "link-local"),
            ("http://[::ffff:169.254.169.254]/", "link-local"),
            ("http://[fe80::1]/hook", "link-local"),
            ("http://[febf::1]/hook", "link-local"),
            ("http://0.0.0.0:8080/", "unspecified"),
            ("http://[::]:8080/", "unspecified"),
            ("http://255.255.255.255/", "broadcast"),
            ("http://100.100.100.200/", "metadata"),
            ("http://[fd00:ec2::254]/", "metadata"),
        ] {
            let e = check_url(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
        assert!(check_url(&format!("https://x.example/{}", "a".repeat(2100))).is_err());
    }

    #[test]
    fn backoff_doubles_and_caps() {
        use std::time::Duration;
        let b = |n| super::backoff(Duration::from_secs(2), Duration::from_secs(60), n);
        assert_eq!(b(1), Duration::from_secs(2));
        assert_eq!(b(2), Duration::from_secs(4));
        assert_eq!(b(4), Duration::from_secs(16));
        assert_eq!(b(10), Duration::from_secs(60));
    }
}
