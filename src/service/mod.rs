//! The wear-diagnosis HTTP service (`gearwear serve`).
//!
//! * [`router`] — every route, as a plain function (tests can call it with `oneshot`);
//! * [`serve`] — run the router on a bound listener until `shutdown` resolves, finishing
//!   in-flight requests, with the webhook worker and the retention task beside it;
//! * [`AppState`] — settings, the [`Store`], the [`Diagnoser`], metrics, rate limiter.
//!
//! Errors are [`ApiError`]s rendered as `application/problem+json`.

use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{MatchedPath, Request, State};
use axum::http::StatusCode;
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use tokio::net::TcpListener;
use tokio::sync::{Notify, watch};
use tower_http::timeout::TimeoutLayer;
use tower_http::trace::TraceLayer;

pub mod alerts;
pub mod auth;
pub mod calibration;
pub mod cli;
pub mod context;
pub mod dashboard;
pub mod error;
pub mod evidence;
pub mod gearboxes;
pub mod health;
pub mod http;
pub mod lifecycle;
pub mod machines;
pub mod metrics;
pub mod mqtt;
pub mod physics;
pub mod physics_queue;
pub mod read;
pub mod records;
pub mod routes;
pub mod signatures;
pub mod spectrum;
pub mod tables;
pub mod trend;
pub mod units;
pub mod webhooks;
pub mod wire;

pub use crate::assessment::TableDiagnoser;
use crate::configuration::Settings;
use crate::store::Store;
pub use error::ApiError;

/// Shared state of every handler (cheap to clone).
#[derive(Clone)]
pub struct AppState(Arc<Inner>);

pub struct Inner {
    pub settings: Settings,
    pub store: Arc<dyn Store>,
    /// Group commit of accepted records (one writer, one transaction per batch).
    pub ingest_queue: crate::store::queue::IngestQueue,
    pub diagnoser: Arc<TableDiagnoser>,
    pub metrics: metrics::Metrics,
    pub limiter: auth::RateLimiter,
    pub webhook_wake: Notify,
    pub http: reqwest::Client,
    /// Wakes the table-job worker (a gearbox was stored).
    pub job_wake: Notify,
    /// Resolved gearboxes and diagnosers of stored tables.
    pub tables: gearboxes::Tables,
    /// The built-in gearbox (the paper's rig), resolved once.
    pub builtin_gearbox: Arc<crate::gearbox::Gearbox>,
    /// The machines' fitted baselines, refitted when a baseline changes.
    pub baselines: context::BaselineCache,
    /// The machines' own models this replica loaded.
    pub physics: physics::PhysicsCache,
    /// Wakes the own-model worker (a job was queued).
    pub physics_wake: Notify,
    /// Wakes the re-read worker (a table was stored: records may wait for it).
    pub reread_wake: Notify,
}

impl std::ops::Deref for AppState {
    type Target = Inner;
    fn deref(&self) -> &Inner {
        &self.0
    }
}

/// Most records one group commit writes.
const INGEST_BATCH: usize = 32;

impl AppState {
    pub fn new(settings: Settings, store: Arc<dyn Store>, diagnoser: Arc<TableDiagnoser>) -> Self {
        let limiter =
            auth::RateLimiter::new(settings.limits.rate_per_second, settings.limits.rate_burst);
        let http = reqwest::Client::builder()
            .redirect(reqwest::redirect::Policy::none())
            // Webhook hosts given by name must not resolve to metadata/link-local addresses.
            .dns_resolver(webhooks::GuardedResolver)
            .build()
            .expect("HTTP client");
        let ingest_queue = crate::store::queue::IngestQueue::start(store.clone(), INGEST_BATCH);
        AppState(Arc::new(Inner {
            settings,
            ingest_queue,
            store,
            diagnoser,
            metrics: metrics::Metrics::default(),
            limiter,
            webhook_wake: Notify::new(),
            http,
            job_wake: Notify::new(),
            tables: gearboxes::Tables::default(),
            builtin_gearbox: Arc::new(crate::gearbox::Gearbox::paper_rig()),
            baselines: context::BaselineCache::default(),
            physics: physics::PhysicsCache::default(),
            physics_wake: Notify::new(),
            reread_wake: Notify::new(),
        }))
    }
}

/// The service: every route of [`routes::routes`] (one method router per path), its fallbacks
/// and layers.
pub fn router(state: AppState) -> Router {
    let mut by_path: std::collections::BTreeMap<&str, axum::routing::MethodRouter<AppState>> =
        std::collections::BTreeMap::new();
    for r in routes::routes() {
        let merged = match by_path.remove(r.path) {
            Some(m) => m.merge(r.handler),
            None => r.handler,
        };
        by_path.insert(r.path, merged);
    }
    let api = by_path
        .into_iter()
        .fold(Router::new(), |api, (path, m)| api.route(path, m));
    api.fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(TimeoutLayer::with_status_code(
            TIMED_OUT,
            state.settings.limits.request_timeout,
        ))
        .layer(middleware::from_fn_with_state(state.clone(), observe))
        .layer(TraceLayer::new_for_http().make_span_with(|req: &Request| {
            // Method and path only: never headers (they carry keys). `key_id` is filled in
            // once a key is verified (auth.rs): the id names the caller, the secret never
            // leaves the request.
            tracing::info_span!(
                "http",
                method = %req.method(),
                path = %req.uri().path(),
                key_id = tracing::field::Empty
            )
        }))
        .with_state(state)
}

async fn not_found(req: Request) -> ApiError {
    ApiError::not_found(
        "not-found",
        format!(
            "no route {} {}; see openapi.yaml for the API",
            req.method(),
            req.uri().path()
        ),
    )
}

async fn method_not_allowed(req: Request) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method-not-allowed",
        "Method not allowed",
        format!(
            "{} is not allowed on {}; see openapi.yaml",
            req.method(),
            req.uri().path()
        ),
    )
}

/// What tower-http's timeout layer answers a request it cut off with (an empty body); no
/// handler answers it, and [`observe`] turns it into the `request-timeout` problem.
const TIMED_OUT: StatusCode = StatusCode::GATEWAY_TIMEOUT;

/// Metrics around every request, and the problem of a request the timeout layer cut off.
async fn observe(State(app): State<AppState>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|m| m.as_str().to_string())
        .unwrap_or_else(|| "unmatched".into());
    let method = req.method().to_string();
    let started = Instant::now();
    let limit = app.settings.limits.request_timeout;
    let resp = next.run(req).await;
    let cut_off = resp.status() == TIMED_OUT
        && !resp
            .headers()
            .contains_key(axum::http::header::CONTENT_TYPE);
    let resp = match cut_off {
        false => resp,
        true => ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "request-timeout",
            "Request timed out",
            format!(
                "the request took longer than {} s; if it was a record with an Idempotency-Key, \
                 retry with the same key",
                limit.as_secs_f64()
            ),
        )
        .retry_after(1)
        .into_response(),
    };
    app.metrics
        .observe(&method, &route, resp.status().as_u16(), started.elapsed());
    resp
}

/// Is this address allowed with this many active keys? A non-loopback address needs a key,
/// or anyone on the network could write.
pub fn check_exposure(addr: &std::net::SocketAddr, active_keys: i64) -> Result<(), String> {
    if !addr.ip().is_loopback() && active_keys == 0 {
        Err(format!(
            "refusing to listen on {addr}, which is not a loopback address, while no API key \
             exists: create one first with `gearwear keys create --scope ingest,read`"
        ))
    } else {
        Ok(())
    }
}

/// Serve until `shutdown` resolves; in-flight requests finish, then the background tasks stop.
pub async fn serve(
    state: AppState,
    listener: TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    if let Err(e) = gearboxes::ensure_builtin(&state).await {
        tracing::warn!(error = %e, "the built-in gearbox could not be stored (database unavailable?)");
    }
    let (stop_tx, stop_rx) = watch::channel(false);
    let worker = tokio::spawn(webhooks::worker(state.clone(), stop_rx.clone()));
    let jobs = tokio::spawn(tables::jobs::worker(state.clone(), stop_rx.clone()));
    let own_models = tokio::spawn(physics::worker(state.clone(), stop_rx.clone()));
    let rereads = tokio::spawn(records::reread::worker(state.clone(), stop_rx.clone()));
    let mqtt = state
        .settings
        .mqtt
        .clone()
        .map(|m| tokio::spawn(mqtt::run(state.clone(), m, stop_rx.clone())));
    let retention = tokio::spawn(retention_task(state.clone(), stop_rx));
    let app = router(state.clone());
    let res = axum::serve(listener, app)
        .with_graceful_shutdown(shutdown)
        .await;
    let _ = stop_tx.send(true);
    let _ = worker.await;
    let _ = jobs.await;
    let _ = own_models.await;
    let _ = rereads.await;
    let _ = retention.await;
    if let Some(m) = mqtt {
        let _ = m.await;
    }
    res
}

/// Drops raw samples and idempotency answers past their retention, hourly.
async fn retention_task(app: AppState, mut stop: watch::Receiver<bool>) {
    let keep = app.settings.raw_retention;
    loop {
        if !keep.is_zero() {
            let before = crate::store::now_ms() - keep.as_millis() as i64;
            // The plots not drawn yet are drawn from the samples while they are there; the
            // samples are kept until they are.
            match evidence::draw_before_purge(&app, before).await {
                Ok(n) => {
                    if n > 0 {
                        tracing::info!(records = n, "evidence plots drawn before retention");
                    }
                    match app.store.purge_samples(before).await {
                        Ok(n) if n > 0 => {
                            tracing::info!(records = n, "raw samples past retention dropped")
                        }
                        Ok(_) => {}
                        Err(e) => tracing::warn!(error = %e, "retention: store unavailable"),
                    }
                }
                Err(e) => {
                    tracing::warn!(error = %e.detail, "retention: evidence plots not drawn, samples kept")
                }
            }
        }
        let before = crate::store::now_ms() - app.settings.idempotency_retention.as_millis() as i64;
        match app.store.purge_idempotency(before).await {
            Ok(n) if n > 0 => {
                tracing::info!(keys = n, "idempotency answers past retention dropped")
            }
            Ok(_) => {}
            Err(e) => tracing::warn!(error = %e, "retention: store unavailable"),
        }
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_secs(3600)) => {}
            _ = stop.changed() => break,
        }
    }
}
