//! Storage of the service: one [`Store`] trait, one implementation per backend.
//!
//! * [`sqlite::SqliteStore`] — the default, a single file (`gearwear.db`), no set-up. WAL
//!   journal with `synchronous = FULL`: a committed transaction survives a crash and a power
//!   cut.
//! * [`postgres::PgStore`] — chosen when the database URL starts with `postgres://` (or
//!   `postgresql://`), so several service replicas can share one store.
//!
//! Both run the same SQL text (`$1`-style parameters work on both) from one macro,
//! [`impl_store!`], with per-backend migrations under `migrations/{sqlite,postgres}`; the
//! integration tests run the same API tests against both. The only differences live in the
//! migrations (`BLOB`/`BYTEA`, `AUTOINCREMENT`/`BIGSERIAL`) and the connection options.
//!
//! Times are unix milliseconds. A record is acknowledged only after [`Store::ingest`]'s
//! transaction — machine, record, diagnosis, webhook deliveries, idempotency entry — commits.

use std::sync::Arc;

use async_trait::async_trait;
use serde::Serialize;

use crate::keys::Scope;

pub mod postgres;
pub mod queue;
pub mod sqlite;

/// Storage errors.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A unique constraint was hit (an idempotency key used concurrently, a duplicate id).
    #[error("conflict: {0}")]
    Conflict(String),
    /// The database could not be reached or answered with an error.
    #[error("database: {0}")]
    Db(#[from] sqlx::Error),
    /// Migrations failed at start-up.
    #[error("migration: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// One error shared by every record of a failed group commit.
    #[error("{0}")]
    Shared(Arc<StoreError>),
}

impl StoreError {
    /// Is this the database being unreachable or too busy to answer (→ 503 + Retry-After)
    /// rather than a bug (→ 500)?
    ///
    /// * the connection: pool timed out or closed, I/O, TLS, protocol, worker gone;
    /// * SQLite: `SQLITE_BUSY` / `SQLITE_LOCKED` with any extended code (sqlx reports the
    ///   extended one, e.g. 517 `SQLITE_BUSY_SNAPSHOT`, so the primary code is `code & 0xff`);
    /// * PostgreSQL: class 08 (connection exception), 57P01 `admin_shutdown`, 57P02
    ///   `crash_shutdown`, 57P03 `cannot_connect_now`, 53300 `too_many_connections`, and a
    ///   transaction that lost to a concurrent one: 40P01 `deadlock_detected`, 40001
    ///   `serialization_failure` (two replicas' group commits touching the same machines in
    ///   opposite orders).
    pub fn is_unavailable(&self) -> bool {
        match self {
            StoreError::Shared(e) => e.is_unavailable(),
            StoreError::Db(
                sqlx::Error::PoolTimedOut
                | sqlx::Error::PoolClosed
                | sqlx::Error::Io(_)
                | sqlx::Error::Tls(_)
                | sqlx::Error::Protocol(_)
                | sqlx::Error::WorkerCrashed,
            ) => true,
            StoreError::Db(sqlx::Error::Database(e)) => {
                let code = e.code().unwrap_or_default();
                if e.try_downcast_ref::<sqlx::sqlite::SqliteError>().is_some() {
                    code.parse::<i32>().is_ok_and(|c| matches!(c & 0xff, 5 | 6))
                } else {
                    // 40P01, 40001: rolled back after losing to a concurrent transaction;
                    // like SQLite's BUSY/LOCKED, a retry succeeds.
                    code.starts_with("08")
                        || matches!(
                            &*code,
                            "57P01" | "57P02" | "57P03" | "53300" | "40P01" | "40001"
                        )
                }
            }
            _ => false,
        }
    }
}

pub type StoreResult<T> = Result<T, StoreError>;

/// An API key as stored (hash only).
#[derive(Debug, Clone, Serialize)]
pub struct KeyRow {
    pub id: String,
    #[serde(skip)]
    pub hash: String,
    pub scopes: Vec<Scope>,
    pub label: String,
    pub created_at: i64,
    pub revoked_at: Option<i64>,
}

/// A machine and its latest state.
#[derive(Debug, Clone)]
pub struct MachineRow {
    pub id: String,
    pub created_at: i64,
    pub updated_at: i64,
    pub record_count: i64,
    pub last_diagnosis_id: Option<String>,
    pub alert_level: String,
    /// Its gearbox (`gearboxes.id`); `None`: the paper's rig.
    pub gearbox_id: Option<String>,
    /// Nominal input-shaft rate (Hz), a hint for finding the mesh lines.
    pub input_shaft_hz: Option<f64>,
    /// The channel names it records; `None`: whatever a record brings.
    pub channels: Option<Vec<String>>,
}

/// What `PUT /v1/machines/{id}` sets.
#[derive(Debug, Clone)]
pub struct MachineConfig {
    pub id: String,
    pub gearbox_id: Option<String>,
    pub input_shaft_hz: Option<f64>,
    pub channels: Option<Vec<String>>,
}

/// A stored gearbox and the state of its signature-table job (without the table itself).
#[derive(Debug, Clone)]
pub struct GearboxRow {
    pub id: String,
    pub name: String,
    /// The description as submitted.
    pub source: String,
    /// `toml` or `json`.
    pub source_format: String,
    /// Canonical JSON of the description.
    pub description: String,
    pub hash: String,
    /// The paper's rig: its table is the served signatures file.
    pub builtin: bool,
    /// `queued`, `running`, `ready`, `failed`.
    pub status: String,
    /// 0–1 while running.
    pub progress: f64,
    pub error: Option<String>,
    pub claimed_by: Option<String>,
    pub lease_until: i64,
    pub attempts: i64,
    pub created_at: i64,
    pub updated_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
}

/// What a `put_gearbox` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PutOutcome {
    Created,
    /// Another description under the same id: its table is recomputed.
    Replaced,
    /// The same description again: nothing changes.
    Unchanged,
}

/// A baseline record's stored features.
#[derive(Debug, Clone)]
pub struct BaselineRecord {
    pub id: String,
    pub received_at: i64,
    pub baseline_at: Option<i64>,
    /// The record's features JSON (as stored with it).
    pub features: String,
}

/// A diagnosis; `body`/`spectrum` are JSON texts, empty in summaries.
#[derive(Debug, Clone)]
pub struct DiagnosisRow {
    pub seq: i64,
    pub id: String,
    pub record_id: String,
    pub machine_id: String,
    pub created_at: i64,
    pub ea_estimate: f64,
    pub ea_lower: f64,
    pub ea_upper: f64,
    pub alert_level: String,
    pub motion_state: String,
    pub body: String,
    pub spectrum: String,
    /// False when the diagnosis has no wear degree (its gearbox's table was not ready).
    pub has_wear: bool,
    /// Novelty against the machine's baseline (deciding channel), when it has one.
    pub novelty_score: Option<f64>,
    pub novelty_threshold: Option<f64>,
    /// The channel that decides the alert.
    pub channel: Option<String>,
}

/// An accepted record's metadata, features and (optionally) raw samples.
#[derive(Debug, Clone)]
pub struct NewRecord {
    pub id: String,
    pub machine_id: String,
    pub received_at: i64,
    pub recorded_at: Option<String>,
    pub sensor: Option<String>,
    pub content_type: String,
    pub sample_rate_hz: f64,
    pub shaft_hz: Option<f64>,
    pub sample_count: i64,
    pub sha256: String,
    /// JSON: lines and condition indicators.
    pub features: String,
    /// Little-endian f32 samples, `None` when retention is zero (several channels: one after
    /// another, in the order of `channels`).
    pub samples: Option<Vec<u8>>,
    /// Marked healthy: part of the machine's baseline.
    pub baseline: bool,
    /// Channel names of a multichannel record.
    pub channels: Option<Vec<String>>,
}

/// The stored response to an `Idempotency-Key`.
#[derive(Debug, Clone)]
pub struct IdemRow {
    pub key_id: String,
    pub idem_key: String,
    /// SHA-256 of the request (machine, content type, query, body).
    pub request_hash: String,
    pub status: i64,
    pub response: String,
}

/// Everything one accepted record writes, in one transaction.
#[derive(Debug, Clone)]
pub struct Ingest {
    pub record: NewRecord,
    pub diagnosis: DiagnosisRow,
    pub idempotency: Option<IdemRow>,
}

/// A machine's current calibration (`calibrations` table).
#[derive(Debug, Clone)]
pub struct CalibrationRow {
    pub machine_id: String,
    pub id: String,
    pub created_at: i64,
    /// JSON list of the accepted effects `{name, kind, parameters}`.
    pub effects: String,
    /// The calibration report JSON.
    pub report: String,
}

/// A webhook subscription.
#[derive(Debug, Clone)]
pub struct WebhookRow {
    pub id: String,
    pub url: String,
    pub secret: String,
    pub events: Vec<String>,
    pub created_at: i64,
}

/// One event to one webhook.
#[derive(Debug, Clone)]
pub struct DeliveryRow {
    pub id: String,
    pub webhook_id: String,
    pub event: String,
    pub payload: String,
    /// `pending`, `delivered`, `failed`.
    pub status: String,
    pub attempts: i64,
    pub next_attempt_at: i64,
    pub created_at: i64,
    pub delivered_at: Option<i64>,
}

/// One HTTP attempt of a delivery.
#[derive(Debug, Clone, Serialize)]
pub struct AttemptRow {
    #[serde(skip)]
    pub delivery_id: String,
    pub attempt: i64,
    pub attempted_at: i64,
    pub status_code: Option<i64>,
    pub error: Option<String>,
    pub duration_ms: i64,
}

/// What happened to a delivery after an attempt.
#[derive(Debug, Clone, Copy)]
pub enum Outcome {
    Delivered,
    Retry { next_attempt_at: i64 },
    Failed,
}

/// Alert levels in increasing severity.
pub const LEVELS: [&str; 4] = ["unknown", "ok", "warning", "alarm"];

pub fn level_rank(level: &str) -> usize {
    LEVELS.iter().position(|l| *l == level).unwrap_or(0)
}

/// `{estimate, lower, upper}`, or null for a diagnosis without a wear degree.
pub fn wear_json(d: &DiagnosisRow) -> serde_json::Value {
    if d.has_wear {
        serde_json::json!({"estimate": d.ea_estimate, "lower": d.ea_lower, "upper": d.ea_upper})
    } else {
        serde_json::Value::Null
    }
}

/// `{score, threshold, anomalous}`, or null without a baseline.
pub fn novelty_json(d: &DiagnosisRow) -> serde_json::Value {
    match (d.novelty_score, d.novelty_threshold) {
        (Some(s), Some(t)) => {
            serde_json::json!({"score": s, "threshold": t, "anomalous": s > t})
        }
        _ => serde_json::Value::Null,
    }
}

/// The webhook events an ingest raises, given the machine's previous alert level:
/// `diagnosis.created` always, `wear.threshold_crossed` when the level rises to warning or
/// alarm. Payloads are JSON texts.
pub fn ingest_events(prev_level: &str, ing: &Ingest, event_id: &str) -> Vec<(String, String)> {
    let d = &ing.diagnosis;
    let base = serde_json::json!({
        "event_id": event_id,
        "machine_id": d.machine_id,
        "diagnosis_id": d.id,
        "record_id": d.record_id,
        "created_at": crate::time::rfc3339(d.created_at),
        "wear_degree": wear_json(d),
        "alert_level": d.alert_level,
        "motion_state": d.motion_state,
        "novelty": novelty_json(d),
        "channel": d.channel,
    });
    let mut out = Vec::new();
    let mut created = base.clone();
    created["event"] = "diagnosis.created".into();
    out.push(("diagnosis.created".to_string(), created.to_string()));
    if level_rank(&d.alert_level) > level_rank(prev_level) && level_rank(&d.alert_level) >= 2 {
        let mut crossed = base;
        crossed["event"] = "wear.threshold_crossed".into();
        crossed["previous_alert_level"] = prev_level.into();
        out.push(("wear.threshold_crossed".to_string(), crossed.to_string()));
    }
    out
}

/// The storage interface of the service.
#[async_trait]
pub trait Store: Send + Sync + 'static {
    /// `"sqlite"` or `"postgres"`.
    fn kind(&self) -> &'static str;
    /// A trivial query: is the database reachable?
    async fn ping(&self) -> StoreResult<()>;
    /// Close the pool (after the server stopped).
    async fn close(&self);

    async fn insert_key(&self, key: &KeyRow) -> StoreResult<()>;
    async fn get_key(&self, id: &str) -> StoreResult<Option<KeyRow>>;
    async fn list_keys(&self) -> StoreResult<Vec<KeyRow>>;
    /// Revoke; `false` if no such (unrevoked) key.
    async fn revoke_key(&self, id: &str, now: i64) -> StoreResult<bool>;
    async fn active_key_count(&self) -> StoreResult<i64>;

    async fn get_idempotent(&self, key_id: &str, idem_key: &str) -> StoreResult<Option<IdemRow>>;
    /// Write an accepted record in one transaction. `StoreError::Conflict` when the
    /// idempotency key was stored meanwhile by a concurrent request.
    async fn ingest(&self, ing: &Ingest) -> StoreResult<()>;
    /// Write several accepted records in ONE transaction (one commit, one fsync — group
    /// commit), each in its own savepoint: the result of each, in order. When the commit
    /// fails, every record gets that error and none is stored.
    async fn ingest_batch(&self, ings: &[Ingest]) -> Vec<StoreResult<()>>;

    async fn list_machines(&self) -> StoreResult<Vec<MachineRow>>;
    async fn get_machine(&self, id: &str) -> StoreResult<Option<MachineRow>>;
    /// Diagnosis summaries (no body) of one machine with `seq > after` and
    /// `created_at > since`, oldest first.
    async fn list_diagnoses(
        &self,
        machine_id: &str,
        after: i64,
        since: i64,
        limit: i64,
    ) -> StoreResult<Vec<DiagnosisRow>>;
    /// The latest `limit` diagnosis summaries of one machine, oldest first.
    async fn recent_diagnoses(
        &self,
        machine_id: &str,
        limit: i64,
    ) -> StoreResult<Vec<DiagnosisRow>>;
    async fn get_diagnosis(&self, id: &str) -> StoreResult<Option<DiagnosisRow>>;

    async fn insert_webhook(&self, w: &WebhookRow) -> StoreResult<()>;
    async fn list_webhooks(&self) -> StoreResult<Vec<WebhookRow>>;
    async fn get_webhook(&self, id: &str) -> StoreResult<Option<WebhookRow>>;
    async fn delete_webhook(&self, id: &str, now: i64) -> StoreResult<bool>;
    /// Claim up to `limit` due deliveries (pending, `next_attempt_at <= now`) by pushing their
    /// `next_attempt_at` to `now + lease_ms`, so another replica does not send them meanwhile.
    async fn claim_deliveries(
        &self,
        now: i64,
        lease_ms: i64,
        limit: i64,
    ) -> StoreResult<Vec<(DeliveryRow, WebhookRow)>>;
    async fn record_attempt(&self, attempt: &AttemptRow, outcome: Outcome) -> StoreResult<()>;
    async fn list_deliveries(&self, webhook_id: &str, limit: i64) -> StoreResult<Vec<DeliveryRow>>;
    async fn list_attempts(&self, delivery_id: &str) -> StoreResult<Vec<AttemptRow>>;
    /// Drop raw samples of records received before `before`; returns how many.
    async fn purge_samples(&self, before: i64) -> StoreResult<u64>;
    /// Forget the stored answers to idempotency keys created before `before`; returns how many.
    async fn purge_idempotency(&self, before: i64) -> StoreResult<u64>;

    /// Store a machine's calibration, replacing the one it had.
    async fn put_calibration(&self, c: &CalibrationRow) -> StoreResult<()>;
    async fn get_calibration(&self, machine_id: &str) -> StoreResult<Option<CalibrationRow>>;
    /// Clear it; `false` if the machine had none.
    async fn delete_calibration(&self, machine_id: &str) -> StoreResult<bool>;

    /// Store a gearbox description. A new id is queued for its table; the same id with another
    /// description is replaced and queued again (its table dropped); the same description again
    /// changes nothing.
    async fn put_gearbox(&self, g: &GearboxRow) -> StoreResult<PutOutcome>;
    /// Insert or refresh the built-in gearbox (status `ready`, its table served from a file).
    async fn ensure_builtin_gearbox(&self, g: &GearboxRow) -> StoreResult<()>;
    async fn get_gearbox(&self, id: &str) -> StoreResult<Option<GearboxRow>>;
    async fn list_gearboxes(&self) -> StoreResult<Vec<GearboxRow>>;
    /// The signature table JSON of a `ready` gearbox whose description hash is `hash`.
    async fn gearbox_table(&self, id: &str, hash: &str) -> StoreResult<Option<String>>;
    /// Claim one table job for `worker` until `now + lease_ms`: a queued one, or a running one
    /// whose lease ran out (its replica stopped). Compare-and-set: one replica wins each job.
    async fn claim_gearbox_job(
        &self,
        now: i64,
        lease_ms: i64,
        worker: &str,
    ) -> StoreResult<Option<GearboxRow>>;
    /// Progress of a claimed job, renewing its lease; `false` when `worker` no longer holds
    /// it (the lease ran out and another replica took it, or the description was replaced).
    async fn gearbox_progress(
        &self,
        id: &str,
        hash: &str,
        worker: &str,
        progress: f64,
        lease_until: i64,
        now: i64,
    ) -> StoreResult<bool>;
    /// Finish a claimed job: `Ok(table JSON)` → `ready`, `Err(reason)` → `failed`. `false`
    /// when `worker` no longer holds it (nothing is written).
    async fn finish_gearbox_job(
        &self,
        id: &str,
        hash: &str,
        worker: &str,
        result: Result<String, String>,
        now: i64,
    ) -> StoreResult<bool>;

    /// Give a claimed job back (the replica is stopping): queued again at once, for any
    /// replica, instead of after its lease.
    async fn release_gearbox_job(&self, id: &str, hash: &str, worker: &str) -> StoreResult<bool>;

    /// Create or update a machine's configuration; `true` when the machine is new.
    async fn put_machine(&self, m: &MachineConfig, now: i64) -> StoreResult<bool>;
    /// Mark (or unmark) records of one machine as baseline; how many changed. Ids of other
    /// machines' records are ignored.
    async fn set_baseline(
        &self,
        machine_id: &str,
        record_ids: &[String],
        baseline: bool,
        now: i64,
    ) -> StoreResult<u64>;
    /// Unmark every baseline record of a machine; how many.
    async fn clear_baseline(&self, machine_id: &str) -> StoreResult<u64>;
    /// The machine's baseline records with their features, oldest first.
    async fn baseline_records(&self, machine_id: &str) -> StoreResult<Vec<BaselineRecord>>;
    /// Which of these record ids belong to the machine.
    async fn machine_record_ids(
        &self,
        machine_id: &str,
        record_ids: &[String],
    ) -> StoreResult<Vec<String>>;
}

/// Open the store a URL names: `postgres://…` / `postgresql://…` → PostgreSQL, anything else
/// is a SQLite file path (or `sqlite://path`). Runs the migrations.
pub async fn connect(url: &str) -> StoreResult<Arc<dyn Store>> {
    if url.starts_with("postgres://") || url.starts_with("postgresql://") {
        Ok(Arc::new(postgres::PgStore::connect(url).await?))
    } else {
        let path = url
            .strip_prefix("sqlite://")
            .or_else(|| url.strip_prefix("sqlite:"))
            .unwrap_or(url);
        Ok(Arc::new(sqlite::SqliteStore::connect(path).await?))
    }
}

/// A new unique id: 26-character ULID (sortable by creation time).
pub fn new_id() -> String {
    ulid::Ulid::generate().to_string().to_ascii_lowercase()
}

/// Current unix time in milliseconds.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// The shared implementation: the same SQL on both backends. `$db` is the sqlx database type.
macro_rules! impl_store {
    ($ty:ty, $db:ty, $kind:literal) => {
        use sqlx::Row;
        use $crate::keys::Scope;
        use $crate::store::*;

        fn key_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<KeyRow> {
            let scopes: String = r.try_get("scopes")?;
            Ok(KeyRow {
                id: r.try_get("id")?,
                hash: r.try_get("hash")?,
                scopes: Scope::parse_list(&scopes).unwrap_or_default(),
                label: r.try_get("label")?,
                created_at: r.try_get("created_at")?,
                revoked_at: r.try_get("revoked_at")?,
            })
        }

        fn machine_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<MachineRow> {
            Ok(MachineRow {
                id: r.try_get("id")?,
                created_at: r.try_get("created_at")?,
                updated_at: r.try_get("updated_at")?,
                record_count: r.try_get("record_count")?,
                last_diagnosis_id: r.try_get("last_diagnosis_id")?,
                alert_level: r.try_get("alert_level")?,
                gearbox_id: r.try_get("gearbox_id")?,
                input_shaft_hz: r.try_get("input_shaft_hz")?,
                channels: r
                    .try_get::<Option<String>, _>("channels")?
                    .and_then(|c| serde_json::from_str(&c).ok()),
            })
        }

        fn gearbox_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<GearboxRow> {
            Ok(GearboxRow {
                id: r.try_get("id")?,
                name: r.try_get("name")?,
                source: r.try_get("source")?,
                source_format: r.try_get("source_format")?,
                description: r.try_get("description")?,
                hash: r.try_get("hash")?,
                builtin: r.try_get::<i64, _>("builtin")? != 0,
                status: r.try_get("status")?,
                progress: r.try_get("progress")?,
                error: r.try_get("error")?,
                claimed_by: r.try_get("claimed_by")?,
                lease_until: r.try_get("lease_until")?,
                attempts: r.try_get("attempts")?,
                created_at: r.try_get("created_at")?,
                updated_at: r.try_get("updated_at")?,
                started_at: r.try_get("started_at")?,
                finished_at: r.try_get("finished_at")?,
            })
        }

        const GEARBOX_COLS: &str = "id, name, source, source_format, description, hash, builtin, \
            status, progress, error, claimed_by, lease_until, attempts, created_at, updated_at, \
            started_at, finished_at";

        fn diagnosis_row(r: &<$db as sqlx::Database>::Row, full: bool) -> StoreResult<DiagnosisRow> {
            Ok(DiagnosisRow {
                seq: r.try_get("seq")?,
                id: r.try_get("id")?,
                record_id: r.try_get("record_id")?,
                machine_id: r.try_get("machine_id")?,
                created_at: r.try_get("created_at")?,
                ea_estimate: r.try_get("ea_estimate")?,
                ea_lower: r.try_get("ea_lower")?,
                ea_upper: r.try_get("ea_upper")?,
                alert_level: r.try_get("alert_level")?,
                motion_state: r.try_get("motion_state")?,
                body: if full { r.try_get("body")? } else { String::new() },
                spectrum: if full { r.try_get("spectrum")? } else { String::new() },
                has_wear: r.try_get::<i64, _>("has_wear")? != 0,
                novelty_score: r.try_get("novelty_score")?,
                novelty_threshold: r.try_get("novelty_threshold")?,
                channel: r.try_get("channel")?,
            })
        }

        fn webhook_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<WebhookRow> {
            let events: String = r.try_get("events")?;
            Ok(WebhookRow {
                id: r.try_get("id")?,
                url: r.try_get("url")?,
                secret: r.try_get("secret")?,
                events: events.split(',').filter(|s| !s.is_empty()).map(String::from).collect(),
                created_at: r.try_get("created_at")?,
            })
        }

        fn delivery_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<DeliveryRow> {
            Ok(DeliveryRow {
                id: r.try_get("id")?,
                webhook_id: r.try_get("webhook_id")?,
                event: r.try_get("event")?,
                payload: r.try_get("payload")?,
                status: r.try_get("status")?,
                attempts: r.try_get("attempts")?,
                next_attempt_at: r.try_get("next_attempt_at")?,
                created_at: r.try_get("created_at")?,
                delivered_at: r.try_get("delivered_at")?,
            })
        }

        const SUMMARY_COLS: &str = "seq, id, record_id, machine_id, created_at, ea_estimate, \
            ea_lower, ea_upper, alert_level, motion_state, has_wear, novelty_score, \
            novelty_threshold, channel";

        fn is_unique_violation(e: &sqlx::Error) -> bool {
            matches!(e, sqlx::Error::Database(d) if d.is_unique_violation())
        }

        /// Every write of one accepted record, inside the caller's transaction.
        async fn ingest_in(tx: &mut sqlx::Transaction<'_, $db>, ing: &Ingest) -> StoreResult<()> {
                let (rec, d) = (&ing.record, &ing.diagnosis);
                // A write first: SQLite then takes its write lock at once (waiting on the busy
                // timeout) instead of failing to upgrade a read lock later. The same statement
                // hands back the machine's alert level before this record (the no-op update
                // returns the stored row; a new machine's is the column default): one round trip
                // instead of an insert and a select, and on PostgreSQL the row stays locked
                // until the commit, so a concurrent record cannot read the same previous level.
                let prev: String = sqlx::query(
                    "INSERT INTO machines (id, created_at, updated_at) VALUES ($1, $2, $2) \
                     ON CONFLICT (id) DO UPDATE SET updated_at = machines.updated_at \
                     RETURNING alert_level",
                )
                .bind(&rec.machine_id)
                .bind(rec.received_at)
                .fetch_one(&mut **tx)
                .await?
                .try_get("alert_level")?;
                if let Some(i) = &ing.idempotency {
                    let r = sqlx::query(
                        "INSERT INTO idempotency_keys \
                         (key_id, idem_key, request_hash, status, response, created_at) \
                         VALUES ($1, $2, $3, $4, $5, $6)",
                    )
                    .bind(&i.key_id)
                    .bind(&i.idem_key)
                    .bind(&i.request_hash)
                    .bind(i.status)
                    .bind(&i.response)
                    .bind(rec.received_at)
                    .execute(&mut **tx)
                    .await;
                    if let Err(e) = r {
                        return Err(if is_unique_violation(&e) {
                            StoreError::Conflict("idempotency key".into())
                        } else {
                            e.into()
                        });
                    }
                }
                sqlx::query(
                    "INSERT INTO records (id, machine_id, received_at, recorded_at, sensor, \
                     content_type, sample_rate_hz, shaft_hz, sample_count, sha256, features, \
                     samples, baseline, baseline_at, channels) \
                     VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15)",
                )
                .bind(&rec.id)
                .bind(&rec.machine_id)
                .bind(rec.received_at)
                .bind(&rec.recorded_at)
                .bind(&rec.sensor)
                .bind(&rec.content_type)
                .bind(rec.sample_rate_hz)
                .bind(rec.shaft_hz)
                .bind(rec.sample_count)
                .bind(&rec.sha256)
                .bind(&rec.features)
                .bind(&rec.samples)
                .bind(rec.baseline as i64)
                .bind(rec.baseline.then_some(rec.received_at))
                .bind(rec.channels.as_ref().map(|c| serde_json::to_string(c).unwrap_or_default()))
                .execute(&mut **tx)
                .await?;
                sqlx::query(
                    "INSERT INTO diagnoses (id, record_id, machine_id, created_at, ea_estimate, \
                     ea_lower, ea_upper, alert_level, motion_state, body, spectrum, has_wear, \
                     novelty_score, novelty_threshold, channel) \
                     VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15)",
                )
                .bind(&d.id)
                .bind(&d.record_id)
                .bind(&d.machine_id)
                .bind(d.created_at)
                .bind(d.ea_estimate)
                .bind(d.ea_lower)
                .bind(d.ea_upper)
                .bind(&d.alert_level)
                .bind(&d.motion_state)
                .bind(&d.body)
                .bind(&d.spectrum)
                .bind(d.has_wear as i64)
                .bind(d.novelty_score)
                .bind(d.novelty_threshold)
                .bind(&d.channel)
                .execute(&mut **tx)
                .await?;
                sqlx::query(
                    "UPDATE machines SET updated_at = $2, record_count = record_count + 1, \
                     last_diagnosis_id = $3, alert_level = $4 WHERE id = $1",
                )
                .bind(&rec.machine_id)
                .bind(rec.received_at)
                .bind(&d.id)
                .bind(&d.alert_level)
                .execute(&mut **tx)
                .await?;
                let hooks = sqlx::query("SELECT * FROM webhooks WHERE deleted_at IS NULL")
                    .fetch_all(&mut **tx)
                    .await?;
                let event_id = new_id();
                let events = ingest_events(&prev, ing, &event_id);
                for h in &hooks {
                    let h = webhook_row(h)?;
                    for (event, payload) in &events {
                        if !h.events.iter().any(|e| e == event || e == "*") {
                            continue;
                        }
                        sqlx::query(
                            "INSERT INTO deliveries (id, webhook_id, event, payload, status, \
                             attempts, next_attempt_at, created_at) \
                             VALUES ($1, $2, $3, $4, 'pending', 0, $5, $5)",
                        )
                        .bind(new_id())
                        .bind(&h.id)
                        .bind(event)
                        .bind(payload)
                        .bind(rec.received_at)
                        .execute(&mut **tx)
                        .await?;
                    }
                }
                Ok(())
            }

        #[async_trait::async_trait]
        impl Store for $ty {
            fn kind(&self) -> &'static str {
                $kind
            }

            async fn ping(&self) -> StoreResult<()> {
                sqlx::query("SELECT 1").execute(&self.pool).await?;
                Ok(())
            }

            async fn close(&self) {
                self.pool.close().await;
            }

            async fn insert_key(&self, k: &KeyRow) -> StoreResult<()> {
                sqlx::query(
                    "INSERT INTO api_keys (id, hash, scopes, label, created_at, revoked_at) \
                     VALUES ($1, $2, $3, $4, $5, $6)",
                )
                .bind(&k.id)
                .bind(&k.hash)
                .bind(Scope::join(&k.scopes))
                .bind(&k.label)
                .bind(k.created_at)
                .bind(k.revoked_at)
                .execute(&self.pool)
                .await?;
                Ok(())
            }

            async fn get_key(&self, id: &str) -> StoreResult<Option<KeyRow>> {
                let r = sqlx::query("SELECT * FROM api_keys WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(key_row).transpose()
            }

            async fn list_keys(&self) -> StoreResult<Vec<KeyRow>> {
                let rows = sqlx::query("SELECT * FROM api_keys ORDER BY created_at, id")
                    .fetch_all(&self.pool)
                    .await?;
                rows.iter().map(key_row).collect()
            }

            async fn revoke_key(&self, id: &str, now: i64) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE api_keys SET revoked_at = $2 WHERE id = $1 AND revoked_at IS NULL",
                )
                .bind(id)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn active_key_count(&self) -> StoreResult<i64> {
                let r = sqlx::query("SELECT COUNT(*) AS n FROM api_keys WHERE revoked_at IS NULL")
                    .fetch_one(&self.pool)
                    .await?;
                Ok(r.try_get("n")?)
            }

            async fn get_idempotent(
                &self,
                key_id: &str,
                idem_key: &str,
            ) -> StoreResult<Option<IdemRow>> {
                let r = sqlx::query(
                    "SELECT * FROM idempotency_keys WHERE key_id = $1 AND idem_key = $2",
                )
                .bind(key_id)
                .bind(idem_key)
                .fetch_optional(&self.pool)
                .await?;
                r.map(|r| -> StoreResult<IdemRow> {
                    Ok(IdemRow {
                        key_id: r.try_get("key_id")?,
                        idem_key: r.try_get("idem_key")?,
                        request_hash: r.try_get("request_hash")?,
                        status: r.try_get("status")?,
                        response: r.try_get("response")?,
                    })
                })
                .transpose()
            }

            async fn ingest(&self, ing: &Ingest) -> StoreResult<()> {
                let mut tx = self.pool.begin().await?;
                ingest_in(&mut tx, ing).await?;
                tx.commit().await.map_err(|e| {
                    if is_unique_violation(&e) {
                        StoreError::Conflict("idempotency key".into())
                    } else {
                        e.into()
                    }
                })?;
                Ok(())
            }

            async fn ingest_batch(&self, ings: &[Ingest]) -> Vec<StoreResult<()>> {
                if ings.len() == 1 {
                    return vec![self.ingest(&ings[0]).await];
                }
                let mut tx = match self.pool.begin().await {
                    Ok(tx) => tx,
                    Err(e) => {
                        let e = Arc::new(StoreError::from(e));
                        return ings.iter().map(|_| Err(StoreError::Shared(e.clone()))).collect();
                    }
                };
                let mut out = Vec::with_capacity(ings.len());
                for ing in ings {
                    // Each record in its own savepoint: one that fails (a duplicate idempotency
                    // key) is rolled back alone and answered with its own error.
                    let r = async {
                        let mut sp = sqlx::Acquire::begin(&mut *tx).await?;
                        ingest_in(&mut sp, ing).await?;
                        sp.commit().await?;
                        Ok::<(), StoreError>(())
                    }
                    .await;
                    out.push(r);
                }
                if let Err(e) = tx.commit().await {
                    let e = Arc::new(StoreError::from(e));
                    return ings.iter().map(|_| Err(StoreError::Shared(e.clone()))).collect();
                }
                out
            }

            async fn list_machines(&self) -> StoreResult<Vec<MachineRow>> {
                let rows = sqlx::query("SELECT * FROM machines ORDER BY id")
                    .fetch_all(&self.pool)
                    .await?;
                rows.iter().map(machine_row).collect()
            }

            async fn get_machine(&self, id: &str) -> StoreResult<Option<MachineRow>> {
                let r = sqlx::query("SELECT * FROM machines WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(machine_row).transpose()
            }

            async fn list_diagnoses(
                &self,
                machine_id: &str,
                after: i64,
                since: i64,
                limit: i64,
            ) -> StoreResult<Vec<DiagnosisRow>> {
                let rows = sqlx::query(sqlx::AssertSqlSafe(format!(
                    "SELECT {SUMMARY_COLS} FROM diagnoses WHERE machine_id = $1 AND seq > $2 \
                     AND created_at > $3 ORDER BY seq LIMIT $4"
                )))
                .bind(machine_id)
                .bind(after)
                .bind(since)
                .bind(limit)
                .fetch_all(&self.pool)
                .await?;
                rows.iter().map(|r| diagnosis_row(r, false)).collect()
            }

            async fn recent_diagnoses(
                &self,
                machine_id: &str,
                limit: i64,
            ) -> StoreResult<Vec<DiagnosisRow>> {
                let rows = sqlx::query(sqlx::AssertSqlSafe(format!(
                    "SELECT {SUMMARY_COLS} FROM diagnoses WHERE machine_id = $1 \
                     ORDER BY seq DESC LIMIT $2"
                )))
                .bind(machine_id)
                .bind(limit)
                .fetch_all(&self.pool)
                .await?;
                let mut v: Vec<DiagnosisRow> = rows
                    .iter()
                    .map(|r| diagnosis_row(r, false))
                    .collect::<StoreResult<_>>()?;
                v.reverse();
                Ok(v)
            }

            async fn get_diagnosis(&self, id: &str) -> StoreResult<Option<DiagnosisRow>> {
                let r = sqlx::query("SELECT * FROM diagnoses WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(|r| diagnosis_row(r, true)).transpose()
            }

            async fn insert_webhook(&self, w: &WebhookRow) -> StoreResult<()> {
                sqlx::query(
                    "INSERT INTO webhooks (id, url, secret, events, created_at) \
                     VALUES ($1, $2, $3, $4, $5)",
                )
                .bind(&w.id)
                .bind(&w.url)
                .bind(&w.secret)
                .bind(w.events.join(","))
                .bind(w.created_at)
                .execute(&self.pool)
                .await?;
                Ok(())
            }

            async fn list_webhooks(&self) -> StoreResult<Vec<WebhookRow>> {
                let rows = sqlx::query(
                    "SELECT * FROM webhooks WHERE deleted_at IS NULL ORDER BY created_at, id",
                )
                .fetch_all(&self.pool)
                .await?;
                rows.iter().map(webhook_row).collect()
            }

            async fn get_webhook(&self, id: &str) -> StoreResult<Option<WebhookRow>> {
                let r = sqlx::query("SELECT * FROM webhooks WHERE id = $1 AND deleted_at IS NULL")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(webhook_row).transpose()
            }

            async fn delete_webhook(&self, id: &str, now: i64) -> StoreResult<bool> {
                let mut tx = self.pool.begin().await?;
                let r = sqlx::query(
                    "UPDATE webhooks SET deleted_at = $2 WHERE id = $1 AND deleted_at IS NULL",
                )
                .bind(id)
                .bind(now)
                .execute(&mut *tx)
                .await?;
                // Nothing more goes to a deleted subscription.
                sqlx::query(
                    "UPDATE deliveries SET status = 'cancelled' \
                     WHERE webhook_id = $1 AND status = 'pending'",
                )
                .bind(id)
                .execute(&mut *tx)
                .await?;
                tx.commit().await?;
                Ok(r.rows_affected() == 1)
            }

            async fn claim_deliveries(
                &self,
                now: i64,
                lease_ms: i64,
                limit: i64,
            ) -> StoreResult<Vec<(DeliveryRow, WebhookRow)>> {
                let due = sqlx::query(
                    "SELECT id FROM deliveries WHERE status = 'pending' AND next_attempt_at <= $1 \
                     ORDER BY next_attempt_at LIMIT $2",
                )
                .bind(now)
                .bind(limit)
                .fetch_all(&self.pool)
                .await?;
                let mut out = Vec::new();
                for r in due {
                    let id: String = r.try_get("id")?;
                    // Compare-and-set: only one replica wins each delivery.
                    let c = sqlx::query(
                        "UPDATE deliveries SET next_attempt_at = $3 \
                         WHERE id = $1 AND status = 'pending' AND next_attempt_at <= $2",
                    )
                    .bind(&id)
                    .bind(now)
                    .bind(now + lease_ms)
                    .execute(&self.pool)
                    .await?;
                    if c.rows_affected() != 1 {
                        continue;
                    }
                    let d = sqlx::query("SELECT * FROM deliveries WHERE id = $1")
                        .bind(&id)
                        .fetch_one(&self.pool)
                        .await?;
                    let d = delivery_row(&d)?;
                    let w = sqlx::query("SELECT * FROM webhooks WHERE id = $1")
                        .bind(&d.webhook_id)
                        .fetch_one(&self.pool)
                        .await?;
                    out.push((d, webhook_row(&w)?));
                }
                Ok(out)
            }

            async fn record_attempt(&self, a: &AttemptRow, outcome: Outcome) -> StoreResult<()> {
                let mut tx = self.pool.begin().await?;
                let (status, next, delivered) = match outcome {
                    Outcome::Delivered => ("delivered", a.attempted_at, Some(a.attempted_at)),
                    Outcome::Retry { next_attempt_at } => ("pending", next_attempt_at, None),
                    Outcome::Failed => ("failed", a.attempted_at, None),
                };
                sqlx::query(
                    "UPDATE deliveries SET status = $2, attempts = $3, next_attempt_at = $4, \
                     delivered_at = $5 WHERE id = $1",
                )
                .bind(&a.delivery_id)
                .bind(status)
                .bind(a.attempt)
                .bind(next)
                .bind(delivered)
                .execute(&mut *tx)
                .await?;
                sqlx::query(
                    "INSERT INTO delivery_attempts (delivery_id, attempt, attempted_at, \
                     status_code, error, duration_ms) VALUES ($1, $2, $3, $4, $5, $6) \
                     ON CONFLICT (delivery_id, attempt) DO NOTHING",
                )
                .bind(&a.delivery_id)
                .bind(a.attempt)
                .bind(a.attempted_at)
                .bind(a.status_code)
                .bind(&a.error)
                .bind(a.duration_ms)
                .execute(&mut *tx)
                .await?;
                tx.commit().await?;
                Ok(())
            }

            async fn list_deliveries(
                &self,
                webhook_id: &str,
                limit: i64,
            ) -> StoreResult<Vec<DeliveryRow>> {
                let rows = sqlx::query(
                    "SELECT * FROM deliveries WHERE webhook_id = $1 \
                     ORDER BY created_at DESC, id DESC LIMIT $2",
                )
                .bind(webhook_id)
                .bind(limit)
                .fetch_all(&self.pool)
                .await?;
                rows.iter().map(delivery_row).collect()
            }

            async fn list_attempts(&self, delivery_id: &str) -> StoreResult<Vec<AttemptRow>> {
                let rows = sqlx::query(
                    "SELECT * FROM delivery_attempts WHERE delivery_id = $1 ORDER BY attempt",
                )
                .bind(delivery_id)
                .fetch_all(&self.pool)
                .await?;
                rows.iter()
                    .map(|r| -> StoreResult<AttemptRow> {
                        Ok(AttemptRow {
                            delivery_id: r.try_get("delivery_id")?,
                            attempt: r.try_get("attempt")?,
                            attempted_at: r.try_get("attempted_at")?,
                            status_code: r.try_get("status_code")?,
                            error: r.try_get("error")?,
                            duration_ms: r.try_get("duration_ms")?,
                        })
                    })
                    .collect()
            }

            async fn purge_samples(&self, before: i64) -> StoreResult<u64> {
                let r = sqlx::query(
                    "UPDATE records SET samples = NULL \
                     WHERE received_at < $1 AND samples IS NOT NULL",
                )
                .bind(before)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected())
            }

            async fn purge_idempotency(&self, before: i64) -> StoreResult<u64> {
                let r = sqlx::query("DELETE FROM idempotency_keys WHERE created_at < $1")
                    .bind(before)
                    .execute(&self.pool)
                    .await?;
                Ok(r.rows_affected())
            }

            async fn put_calibration(&self, c: &CalibrationRow) -> StoreResult<()> {
                sqlx::query(
                    "INSERT INTO calibrations (machine_id, id, created_at, effects, report) \
                     VALUES ($1, $2, $3, $4, $5) \
                     ON CONFLICT (machine_id) DO UPDATE SET id = excluded.id, \
                     created_at = excluded.created_at, effects = excluded.effects, \
                     report = excluded.report",
                )
                .bind(&c.machine_id)
                .bind(&c.id)
                .bind(c.created_at)
                .bind(&c.effects)
                .bind(&c.report)
                .execute(&self.pool)
                .await?;
                Ok(())
            }

            async fn get_calibration(
                &self,
                machine_id: &str,
            ) -> StoreResult<Option<CalibrationRow>> {
                let r = sqlx::query("SELECT * FROM calibrations WHERE machine_id = $1")
                    .bind(machine_id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.map(|r| -> StoreResult<CalibrationRow> {
                    Ok(CalibrationRow {
                        machine_id: r.try_get("machine_id")?,
                        id: r.try_get("id")?,
                        created_at: r.try_get("created_at")?,
                        effects: r.try_get("effects")?,
                        report: r.try_get("report")?,
                    })
                })
                .transpose()
            }

            async fn delete_calibration(&self, machine_id: &str) -> StoreResult<bool> {
                let r = sqlx::query("DELETE FROM calibrations WHERE machine_id = $1")
                    .bind(machine_id)
                    .execute(&self.pool)
                    .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn put_gearbox(&self, g: &GearboxRow) -> StoreResult<PutOutcome> {
                let mut tx = self.pool.begin().await?;
                // A write first (SQLite takes its write lock at once).
                let ins = sqlx::query(
                    "INSERT INTO gearboxes (id, name, source, source_format, description, hash, \
                     builtin, status, progress, created_at, updated_at) \
                     VALUES ($1, $2, $3, $4, $5, $6, 0, 'queued', 0, $7, $7) \
                     ON CONFLICT (id) DO NOTHING",
                )
                .bind(&g.id)
                .bind(&g.name)
                .bind(&g.source)
                .bind(&g.source_format)
                .bind(&g.description)
                .bind(&g.hash)
                .bind(g.created_at)
                .execute(&mut *tx)
                .await?;
                let outcome = if ins.rows_affected() == 1 {
                    PutOutcome::Created
                } else {
                    let upd = sqlx::query(
                        "UPDATE gearboxes SET name = $2, source = $3, source_format = $4, \
                         description = $5, hash = $6, status = 'queued', progress = 0, \
                         error = NULL, claimed_by = NULL, lease_until = 0, attempts = 0, \
                         signature_table = NULL, updated_at = $7, started_at = NULL, \
                         finished_at = NULL WHERE id = $1 AND hash <> $6 AND builtin = 0",
                    )
                    .bind(&g.id)
                    .bind(&g.name)
                    .bind(&g.source)
                    .bind(&g.source_format)
                    .bind(&g.description)
                    .bind(&g.hash)
                    .bind(g.created_at)
                    .execute(&mut *tx)
                    .await?;
                    if upd.rows_affected() == 1 {
                        PutOutcome::Replaced
                    } else {
                        let builtin: i64 =
                            sqlx::query("SELECT builtin FROM gearboxes WHERE id = $1")
                                .bind(&g.id)
                                .fetch_one(&mut *tx)
                                .await?
                                .try_get("builtin")?;
                        let same: i64 = sqlx::query(
                            "SELECT COUNT(*) AS n FROM gearboxes WHERE id = $1 AND hash = $2",
                        )
                        .bind(&g.id)
                        .bind(&g.hash)
                        .fetch_one(&mut *tx)
                        .await?
                        .try_get("n")?;
                        if builtin != 0 && same == 0 {
                            return Err(StoreError::Conflict(format!(
                                "gearbox `{}` is built in and cannot be replaced",
                                g.id
                            )));
                        }
                        PutOutcome::Unchanged
                    }
                };
                tx.commit().await?;
                Ok(outcome)
            }

            async fn ensure_builtin_gearbox(&self, g: &GearboxRow) -> StoreResult<()> {
                sqlx::query(
                    "INSERT INTO gearboxes (id, name, source, source_format, description, hash, \
                     builtin, status, progress, created_at, updated_at, finished_at) \
                     VALUES ($1, $2, $3, $4, $5, $6, 1, 'ready', 1, $7, $7, $7) \
                     ON CONFLICT (id) DO UPDATE SET name = excluded.name, \
                     source = excluded.source, source_format = excluded.source_format, \
                     description = excluded.description, hash = excluded.hash, builtin = 1, \
                     status = 'ready', progress = 1, error = NULL, signature_table = NULL, \
                     updated_at = excluded.updated_at \
                     WHERE gearboxes.hash <> excluded.hash OR gearboxes.builtin = 0",
                )
                .bind(&g.id)
                .bind(&g.name)
                .bind(&g.source)
                .bind(&g.source_format)
                .bind(&g.description)
                .bind(&g.hash)
                .bind(g.created_at)
                .execute(&self.pool)
                .await?;
                Ok(())
            }

            async fn get_gearbox(&self, id: &str) -> StoreResult<Option<GearboxRow>> {
                let r = sqlx::query(sqlx::AssertSqlSafe(format!(
                    "SELECT {GEARBOX_COLS} FROM gearboxes WHERE id = $1"
                )))
                .bind(id)
                .fetch_optional(&self.pool)
                .await?;
                r.as_ref().map(gearbox_row).transpose()
            }

            async fn list_gearboxes(&self) -> StoreResult<Vec<GearboxRow>> {
                let rows = sqlx::query(sqlx::AssertSqlSafe(format!(
                    "SELECT {GEARBOX_COLS} FROM gearboxes ORDER BY id"
                )))
                .fetch_all(&self.pool)
                .await?;
                rows.iter().map(gearbox_row).collect()
            }

            async fn gearbox_table(&self, id: &str, hash: &str) -> StoreResult<Option<String>> {
                let r = sqlx::query(
                    "SELECT signature_table FROM gearboxes \
                     WHERE id = $1 AND hash = $2 AND status = 'ready'",
                )
                .bind(id)
                .bind(hash)
                .fetch_optional(&self.pool)
                .await?;
                Ok(match r {
                    Some(r) => r.try_get("signature_table")?,
                    None => None,
                })
            }

            async fn claim_gearbox_job(
                &self,
                now: i64,
                lease_ms: i64,
                worker: &str,
            ) -> StoreResult<Option<GearboxRow>> {
                let due = sqlx::query(
                    "SELECT id, hash FROM gearboxes WHERE builtin = 0 AND (status = 'queued' \
                     OR (status = 'running' AND lease_until < $1)) \
                     ORDER BY updated_at, id LIMIT 4",
                )
                .bind(now)
                .fetch_all(&self.pool)
                .await?;
                for r in due {
                    let id: String = r.try_get("id")?;
                    let hash: String = r.try_get("hash")?;
                    // Compare-and-set: only one replica wins each job.
                    let c = sqlx::query(
                        "UPDATE gearboxes SET status = 'running', claimed_by = $3, \
                         lease_until = $4, attempts = attempts + 1, updated_at = $2, \
                         started_at = COALESCE(started_at, $2) \
                         WHERE id = $1 AND hash = $5 AND builtin = 0 AND (status = 'queued' \
                         OR (status = 'running' AND lease_until < $2))",
                    )
                    .bind(&id)
                    .bind(now)
                    .bind(worker)
                    .bind(now + lease_ms)
                    .bind(&hash)
                    .execute(&self.pool)
                    .await?;
                    if c.rows_affected() == 1 {
                        return self.get_gearbox(&id).await;
                    }
                }
                Ok(None)
            }

            async fn gearbox_progress(
                &self,
                id: &str,
                hash: &str,
                worker: &str,
                progress: f64,
                lease_until: i64,
                now: i64,
            ) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE gearboxes SET progress = $4, lease_until = $5, updated_at = $6 \
                     WHERE id = $1 AND hash = $2 AND claimed_by = $3 AND status = 'running'",
                )
                .bind(id)
                .bind(hash)
                .bind(worker)
                .bind(progress)
                .bind(lease_until)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn finish_gearbox_job(
                &self,
                id: &str,
                hash: &str,
                worker: &str,
                result: Result<String, String>,
                now: i64,
            ) -> StoreResult<bool> {
                let (status, table, error, progress) = match result {
                    Ok(t) => ("ready", Some(t), None, 1.0),
                    Err(e) => ("failed", None, Some(e), 0.0),
                };
                let r = sqlx::query(
                    "UPDATE gearboxes SET status = $4, signature_table = $5, error = $6, \
                     progress = $7, finished_at = $8, updated_at = $8, lease_until = 0 \
                     WHERE id = $1 AND hash = $2 AND claimed_by = $3 AND status = 'running'",
                )
                .bind(id)
                .bind(hash)
                .bind(worker)
                .bind(status)
                .bind(table)
                .bind(error)
                .bind(progress)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn release_gearbox_job(
                &self,
                id: &str,
                hash: &str,
                worker: &str,
            ) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE gearboxes SET status = 'queued', claimed_by = NULL, lease_until = 0 \
                     WHERE id = $1 AND hash = $2 AND claimed_by = $3 AND status = 'running'",
                )
                .bind(id)
                .bind(hash)
                .bind(worker)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn put_machine(&self, m: &MachineConfig, now: i64) -> StoreResult<bool> {
                let channels = m
                    .channels
                    .as_ref()
                    .map(|c| serde_json::to_string(c).unwrap_or_default());
                let mut tx = self.pool.begin().await?;
                let ins = sqlx::query(
                    "INSERT INTO machines (id, created_at, updated_at, gearbox_id, \
                     input_shaft_hz, channels) VALUES ($1, $2, $2, $3, $4, $5) \
                     ON CONFLICT (id) DO NOTHING",
                )
                .bind(&m.id)
                .bind(now)
                .bind(&m.gearbox_id)
                .bind(m.input_shaft_hz)
                .bind(&channels)
                .execute(&mut *tx)
                .await?;
                let created = ins.rows_affected() == 1;
                if !created {
                    sqlx::query(
                        "UPDATE machines SET gearbox_id = $2, input_shaft_hz = $3, \
                         channels = $4, updated_at = $5 WHERE id = $1",
                    )
                    .bind(&m.id)
                    .bind(&m.gearbox_id)
                    .bind(m.input_shaft_hz)
                    .bind(&channels)
                    .bind(now)
                    .execute(&mut *tx)
                    .await?;
                }
                tx.commit().await?;
                Ok(created)
            }

            async fn set_baseline(
                &self,
                machine_id: &str,
                record_ids: &[String],
                baseline: bool,
                now: i64,
            ) -> StoreResult<u64> {
                let mut tx = self.pool.begin().await?;
                let mut n = 0;
                for id in record_ids {
                    let r = sqlx::query(
                        "UPDATE records SET baseline = $3, baseline_at = $4 \
                         WHERE id = $1 AND machine_id = $2 AND baseline <> $3",
                    )
                    .bind(id)
                    .bind(machine_id)
                    .bind(baseline as i64)
                    .bind(baseline.then_some(now))
                    .execute(&mut *tx)
                    .await?;
                    n += r.rows_affected();
                }
                tx.commit().await?;
                Ok(n)
            }

            async fn clear_baseline(&self, machine_id: &str) -> StoreResult<u64> {
                let r = sqlx::query(
                    "UPDATE records SET baseline = 0, baseline_at = NULL \
                     WHERE machine_id = $1 AND baseline = 1",
                )
                .bind(machine_id)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected())
            }

            async fn baseline_records(&self, machine_id: &str) -> StoreResult<Vec<BaselineRecord>> {
                let rows = sqlx::query(
                    "SELECT id, received_at, baseline_at, features FROM records \
                     WHERE machine_id = $1 AND baseline = 1 ORDER BY received_at, id",
                )
                .bind(machine_id)
                .fetch_all(&self.pool)
                .await?;
                rows.iter()
                    .map(|r| -> StoreResult<BaselineRecord> {
                        Ok(BaselineRecord {
                            id: r.try_get("id")?,
                            received_at: r.try_get("received_at")?,
                            baseline_at: r.try_get("baseline_at")?,
                            features: r.try_get("features")?,
                        })
                    })
                    .collect()
            }

            async fn machine_record_ids(
                &self,
                machine_id: &str,
                record_ids: &[String],
            ) -> StoreResult<Vec<String>> {
                let mut out = Vec::new();
                for id in record_ids {
                    let r = sqlx::query("SELECT id FROM records WHERE id = $1 AND machine_id = $2")
                        .bind(id)
                        .bind(machine_id)
                        .fetch_optional(&self.pool)
                        .await?;
                    if let Some(r) = r {
                        out.push(r.try_get("id")?);
                    }
                }
                Ok(out)
            }
        }
    };
}
pub(crate) use impl_store;
