//! MQTT ingest (`serve --mqtt-url … --mqtt-topic 'plant/+/vibration'`): records published to
//! a broker go through the same path as `POST /v1/machines/{id}/records`
//! ([`super::records::prepare`] and [`super::records::accept`]: one assessment, one store
//! transaction).
//!
//! * QoS 1, a persistent session (`clean_session = false`, a stable client id) and manual
//!   acknowledgements: a message is acknowledged only after its record is stored (or refused
//!   for good), so a record in flight when the service or the broker stops is redelivered;
//! * de-duplication: each record is stored under its record id ([`payload::record_id`]) as an
//!   idempotency key scoped to its machine (`mqtt:{machine}`), checked in the ingest
//!   transaction, so a redelivery is not stored twice;
//! * a payload that cannot be stored is logged and its problem (the HTTP endpoint's
//!   problem+json, with `topic`, `machine_id` and `record_id`) published to the error topic;
//!   the message is then acknowledged (a redelivery would fail the same way). A store that is
//!   unavailable is retried with back-off instead, and the message acknowledged once stored;
//! * the connection is retried with exponential back-off (0.1 s doubling to 10 s); `/metrics`
//!   shows its state (`gearwear_mqtt_connected`) and the messages by outcome.

pub mod metrics;
pub mod payload;
pub mod settings;
pub mod topic;

pub use self::metrics::MqttMetrics;
pub use self::settings::MqttSettings;

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use axum::http::StatusCode;
use backon::{BackoffBuilder, ExponentialBuilder};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, Publish, QoS};
use tokio::sync::{Semaphore, watch};
use tokio::task::JoinSet;

use super::AppState;
use super::error::{ApiError, ApiResult};
use super::http::check_machine_id;
use super::metrics::StageClock;
use super::records::{Accepted, Idempotency, accept, prepare};
use super::wire::parse_query;
pub use topic::TopicFilter;

/// First wait before reconnecting; doubled after each failure up to [`MAX_BACKOFF`].
pub const MIN_BACKOFF: Duration = Duration::from_millis(100);
/// Longest wait between connection attempts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(10);
/// The waits between connection attempts, and between attempts to store a record while the
/// store is unavailable: [`MIN_BACKOFF`] doubling to [`MAX_BACKOFF`], for as long as it takes.
///
/// `backon` gives the schedule; both loops that wait on it stay here, because their wait must
/// end when the service stops while the attempt it separates must not be cut: the connection's
/// event loop is polled, not retried as a future, and a record being stored is not dropped
/// mid-write — `backon`'s `Retryable` races nothing but its sleep.
pub const BACKOFF: ExponentialBuilder = ExponentialBuilder::new()
    .with_min_delay(MIN_BACKOFF)
    .with_max_delay(MAX_BACKOFF)
    .with_factor(2.0)
    .without_max_times();
/// Records assessed and stored at once. A broker may hand over its whole queue for the
/// session at once (mosquitto does after a restart); the rest wait for a slot (their payloads
/// held in memory) instead of all competing for the CPU and the store's connections, where
/// they ran into the pool's timeout and its back-off.
const CONCURRENT_RECORDS: usize = 8;
/// How long a stopping service keeps the connection for records in flight to be acknowledged.
const DRAIN: Duration = Duration::from_secs(10);

/// The client's options for `s`: a persistent session, manual acknowledgements, packets up to
/// the largest record (`max_payload`, bytes) plus headroom.
fn options(s: &MqttSettings, max_payload: usize) -> MqttOptions {
    let mut o = MqttOptions::new(&s.client_id, &s.host, s.port);
    o.set_keep_alive(Duration::from_secs(30))
        .set_clean_session(false)
        .set_manual_acks(true)
        // The largest record plus the header and the packet's own bytes.
        .set_max_packet_size(max_payload + (64 << 10), 64 << 10);
    if let Some(user) = &s.username {
        o.set_credentials(user, s.password.clone().unwrap_or_default());
    }
    o
}

/// Subscribe and ingest until `stop` turns true; then let the records in flight finish (and
/// be acknowledged) for up to [`DRAIN`], and disconnect.
pub async fn run(app: AppState, s: MqttSettings, mut stop: watch::Receiver<bool>) {
    let metrics = &app.metrics.mqtt;
    metrics.enabled.store(true, Ordering::Relaxed);
    let max_payload = app.settings.limits.max_body_bytes;
    let (client, mut events) = AsyncClient::new(options(&s, max_payload), 64);
    let mut tasks = JoinSet::new();
    let ingesting = Arc::new(Semaphore::new(CONCURRENT_RECORDS));
    let mut backoff = BACKOFF.build();
    tracing::info!(host = %s.host, port = s.port, topic = %s.filter.subscription, "MQTT ingest");
    loop {
        while tasks.try_join_next().is_some() {}
        let ev = tokio::select! {
            _ = stop.changed() => break,
            ev = events.poll() => ev,
        };
        match ev {
            Ok(Event::Incoming(Packet::ConnAck(c))) => {
                backoff = BACKOFF.build();
                metrics.connections.fetch_add(1, Ordering::Relaxed);
                tracing::info!(session_present = c.session_present, "MQTT connected");
                // Subscribe after every connection (a broker without persistence forgets
                // the session), from a task of its own: this loop drives the event loop that
                // drains the request channel, and that channel can be full of the
                // acknowledgements of records finishing — `try_subscribe` then failed and
                // left the service connected but deaf.
                let (client, filter) = (client.clone(), s.filter.subscription.clone());
                tasks.spawn(async move {
                    if let Err(e) = client.subscribe(&filter, QoS::AtLeastOnce).await {
                        tracing::error!(error = %e, "MQTT subscribe could not be queued");
                    }
                });
            }
            Ok(Event::Incoming(Packet::SubAck(a))) => {
                let ok = a
                    .return_codes
                    .iter()
                    .all(|c| !matches!(c, rumqttc::SubscribeReasonCode::Failure));
                metrics.set_connected(ok);
                if !ok {
                    tracing::error!(topic = %s.filter.subscription, "the broker refused the MQTT subscription");
                }
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let job = Message {
                    app: app.clone(),
                    ingesting: ingesting.clone(),
                    client: client.clone(),
                    settings: s.clone(),
                    stop: stop.clone(),
                };
                tasks.spawn(job.handle(p));
            }
            Ok(_) => {}
            Err(e) => {
                metrics.set_connected(false);
                let wait = backoff.next().unwrap_or(MAX_BACKOFF);
                tracing::warn!(error = %e, retry_in_ms = wait.as_millis() as u64, "MQTT connection lost");
                tokio::select! {
                    _ = stop.changed() => break,
                    _ = tokio::time::sleep(wait) => {}
                }
            }
        }
    }
    drain(&client, &mut events, &mut tasks).await;
    metrics.set_connected(false);
}

/// Keep the connection while the records in flight finish and their acknowledgements go out,
/// then disconnect.
async fn drain(client: &AsyncClient, events: &mut rumqttc::EventLoop, tasks: &mut JoinSet<()>) {
    let deadline = tokio::time::Instant::now() + DRAIN;
    while !tasks.is_empty() {
        tokio::select! {
            _ = tasks.join_next() => {}
            ev = events.poll() => if ev.is_err() { break },
            _ = tokio::time::sleep_until(deadline) => break,
        }
    }
    tasks.abort_all();
    if client.try_disconnect().is_ok() {
        let until = tokio::time::Instant::now() + Duration::from_secs(1);
        while let Ok(Ok(ev)) = tokio::time::timeout_at(until, events.poll()).await {
            if matches!(ev, Event::Outgoing(rumqttc::Outgoing::Disconnect)) {
                break;
            }
        }
    }
}

/// What became of a message.
enum Outcome {
    Stored,
    /// Stored before (a redelivery, or the same record published twice).
    Duplicate,
}

/// One message's handling.
struct Message {
    app: AppState,
    /// A slot of [`CONCURRENT_RECORDS`].
    ingesting: Arc<Semaphore>,
    client: AsyncClient,
    settings: MqttSettings,
    stop: watch::Receiver<bool>,
}

impl Message {
    /// Ingest, retrying while the store is unavailable; on a refusal publish the problem;
    /// acknowledge (not when the service stops first: the broker redelivers it).
    async fn handle(mut self, p: Publish) {
        let metrics = &self.app.metrics.mqtt;
        let mut backoff = BACKOFF.build();
        let _slot = tokio::select! {
            _ = self.stop.changed() => return,
            slot = self.ingesting.clone().acquire_owned() => slot,
        };
        let result = loop {
            match ingest(&self.app, &self.settings.filter, &p).await {
                Err((e, _)) if e.status == StatusCode::SERVICE_UNAVAILABLE => {
                    tracing::warn!(topic = %p.topic, error = %e.detail, "MQTT record: store unavailable, retrying");
                    let wait = backoff.next().unwrap_or(MAX_BACKOFF);
                    tokio::select! {
                        _ = self.stop.changed() => return,
                        _ = tokio::time::sleep(wait) => {}
                    }
                }
                r => break r,
            }
        };
        match result {
            Ok(Outcome::Stored) => metrics.message("stored"),
            Ok(Outcome::Duplicate) => metrics.message("duplicate"),
            Err((e, record_id)) => {
                metrics.message("refused");
                self.publish_problem(&p, e, record_id).await;
            }
        }
        if let Err(e) = self.client.ack(&p).await {
            tracing::warn!(error = %e, "MQTT acknowledgement not sent (the broker redelivers)");
        }
    }

    async fn publish_problem(&self, p: &Publish, e: ApiError, record_id: Option<String>) {
        let machine = self.settings.filter.machine_id(&p.topic);
        tracing::warn!(topic = %p.topic, problem = e.slug, detail = %e.detail, "MQTT record refused");
        let mut body = e.body();
        body["topic"] = p.topic.clone().into();
        body["machine_id"] = machine.into();
        body["record_id"] = record_id.into();
        let r = self
            .client
            .publish(
                &self.settings.error_topic,
                QoS::AtLeastOnce,
                false,
                body.to_string(),
            )
            .await;
        if let Err(e) = r {
            tracing::warn!(error = %e, "the MQTT error message could not be queued");
        }
    }
}

/// A message through the record path: machine id from the topic, payload split and decoded,
/// its record id checked against the stored ones, assessed and stored. An error carries the
/// record id when it was known.
async fn ingest(
    app: &AppState,
    filter: &TopicFilter,
    p: &Publish,
) -> Result<Outcome, (ApiError, Option<String>)> {
    let no_id = |e: ApiError| (e, None);
    let machine_id = filter.machine_id(&p.topic).ok_or_else(|| {
        no_id(ApiError::bad_request(
            "invalid-machine-id",
            "Invalid machine id",
            format!("the topic `{}` has no machine id level", p.topic),
        ))
    })?;
    check_machine_id(machine_id).map_err(no_id)?;
    let payload = payload::split(&p.payload).map_err(no_id)?;
    let q = parse_query(payload.query).map_err(no_id)?;
    let mut clock = StageClock::new();
    let prepared = prepare(app, machine_id, payload.format, q, payload.body, &mut clock)
        .await
        .map_err(no_id)?;
    let carried = payload.record_id.or_else(|| prepared.dec.record_id.clone());
    let record_id = payload::record_id(carried, &p.payload).map_err(no_id)?;
    let with_id = |e: ApiError| (e, Some(record_id.clone()));
    let idem = Idempotency::new(
        format!("mqtt:{machine_id}"),
        Some(record_id.clone()),
        machine_id,
        payload.format,
        payload.query,
        payload.body,
    );
    if let Some(prev) = idem.stored(app).await.map_err(with_id)? {
        return duplicate(&idem, &prev, &record_id).map_err(with_id);
    }
    match accept(app, machine_id, payload.format, prepared, &idem, clock).await {
        Ok(Accepted::Created { .. }) => Ok(Outcome::Stored),
        Ok(Accepted::Replayed(prev)) => duplicate(&idem, &prev, &record_id).map_err(with_id),
        Err(e) => Err(with_id(e)),
    }
}

/// A record id stored before: a duplicate when it named the same payload, else a refusal.
fn duplicate(idem: &Idempotency, prev: &crate::store::IdemRow, id: &str) -> ApiResult<Outcome> {
    if idem.same_request(prev) {
        Ok(Outcome::Duplicate)
    } else {
        Err(ApiError::unprocessable(
            "idempotency-key-reused",
            "Record id reused with a different record",
            format!(
                "record id `{id}` was already stored for this machine with a different \
                 payload; give each record its own `record_id`"
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_back_off_starts_at_100_ms_doubles_and_stays_at_10_s() {
        let got: Vec<Duration> = BACKOFF.build().take(12).collect();
        let want = [
            0.1, 0.2, 0.4, 0.8, 1.6, 3.2, 6.4, 10.0, 10.0, 10.0, 10.0, 10.0,
        ];
        assert_eq!(got.len(), want.len(), "the schedule does not end");
        for (g, w) in got.iter().zip(want) {
            // `backon` multiplies in f32: within a microsecond of the doubling.
            assert!((g.as_secs_f64() - w).abs() < 1e-6, "{got:?}");
        }
        assert_eq!(got[0], MIN_BACKOFF);
        assert_eq!(got[11], MAX_BACKOFF);
    }
}
