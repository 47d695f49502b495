//! Storage of the service: one [`Store`] trait, one implementation per backend.
//!
//! * [`sqlite::SqliteStore`] — the default, a single file, no set-up. WAL journal with
//!   `synchronous = FULL`: a committed transaction survives a crash and a power cut.
//! * [`postgres::PgStore`] — chosen when the database URL starts with `postgres://` (or
//!   `postgresql://`), so several service replicas can share one store.
//!
//! [`Store`] is the sum of one trait per resource, each in its own module with its row types and
//! its SQL: [`keys`], [`ingest`] (the record path's writes and idempotent answers),
//! [`diagnoses`], [`machines`], [`webhooks`] (subscriptions and deliveries), [`retention`]
//! (purges), [`calibration`], [`gearboxes`] (descriptions and their table jobs),
//! [`extensions`] (what a table must cover and its extensions), [`physics`] (machines' own
//! models), [`baselines`] and [`alerts`] (alert episodes and their audit trail). Both backends run the same SQL text (`$1`-style parameters work on both): each
//! resource module has one small macro (`keys_sql!`, …) that the backend modules instantiate
//! with their own pool type, with per-backend migrations under `migrations/{sqlite,postgres}`;
//! the integration tests run the same API tests against both. The only differences live in the
//! migrations (`BLOB`/`BYTEA`, `AUTOINCREMENT`/`BIGSERIAL`) and the connection options.
//!
//! Times are unix milliseconds. A record is acknowledged only after [`IngestStore::ingest`]'s
//! transaction — machine, record, diagnosis, webhook deliveries, idempotency entry — commits.
//! [`MachineStore::delete_machine`] takes all of a machine's rows away in one transaction.

use std::sync::Arc;

use async_trait::async_trait;

/// What each backend module (`sqlite.rs`, `postgres.rs`) declares after its connection code:
/// the [`Store`] impl (`kind`, `ping`, `close`) for `$store`, and one module per resource
/// holding that resource's SQL instantiated for the sqlx database `$db`.
macro_rules! backend {
    ($store:ident, $db:ty, $kind:literal) => {
        #[async_trait::async_trait]
        impl $crate::Store for $store {
            fn kind(&self) -> &'static str {
                $kind
            }

            async fn ping(&self) -> $crate::StoreResult<()> {
                sqlx::query("SELECT 1").execute(&self.pool).await?;
                Ok(())
            }

            async fn close(&self) {
                self.pool.close().await;
            }
        }

        mod keys {
            $crate::keys::keys_sql!($store, $db);
        }
        mod alerts {
            $crate::alerts::alerts_sql!($store, $db);
        }
        mod ingest {
            $crate::ingest::ingest_sql!($store, $db);
        }
        mod diagnoses {
            $crate::diagnoses::diagnoses_sql!($store, $db);
        }
        mod machines {
            $crate::machines::machines_sql!($store, $db);
        }
        mod webhooks {
            $crate::webhooks::webhooks_sql!($store, $db);
        }
        mod retention {
            $crate::retention::retention_sql!($store, $db);
        }
        mod calibration {
            $crate::calibration::calibration_sql!($store, $db);
        }
        mod gearboxes {
            $crate::gearboxes::gearboxes_sql!($store, $db);
        }
        mod baselines {
            $crate::baselines::baselines_sql!($store, $db);
        }
        mod extensions {
            $crate::extensions::extensions_sql!($store, $db);
        }
        mod physics {
            $crate::physics::physics_sql!($store, $db);
        }
    };
}
pub(crate) use backend;

pub mod alert_rows;
pub mod alerts;
pub mod baselines;
pub mod calibration;
pub mod diagnoses;
pub mod events;
pub mod extensions;
pub mod gearboxes;
pub mod ingest;
pub mod keys;
pub mod machines;
pub mod physics;
pub mod postgres;
pub mod queue;
pub mod retention;
pub mod sqlite;
pub mod time;
pub mod webhooks;

pub use alerts::{
    Acknowledged, AlertEventRow, AlertFilter, AlertInput, AlertRow, AlertStore, transition_events,
};
pub use baselines::{BaselineRecord, BaselineStore};
pub use calibration::{CalibrationRow, CalibrationStore};
pub use diagnoses::{DiagnosisRow, DiagnosisStore, PendingReread};
pub use events::{DiagnosisEvent, Event, QueuedEvent};
pub use extensions::{ConfiguredSpeeds, TableExtensionStore, TableSpeed};
pub use gearboxes::{Extension, GearboxRow, GearboxStore, PutOutcome, TableText};
pub use ingest::{IdemRow, Ingest, IngestStore, NewRecord, Reread};
pub use keys::{KeyRow, KeyStore};
pub use machines::{MachineConfig, MachineDeletion, MachineRow, MachineStore};
pub use physics::{PhysicsKey, PhysicsOutcome, PhysicsRow, PhysicsStore};
pub use retention::RetentionStore;
pub use webhooks::{AttemptRow, DeliveryRow, Outcome, WebhookRow, WebhookStore};

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
    /// A record for a machine that was not registered (`PUT /v1/machines/{id}`), written with
    /// [`Ingest::registered_only`]: nothing of it is stored.
    #[error("machine `{0}` is not registered")]
    UnregisteredMachine(String),
    /// A stored value that does not read back as its type (a row written by another program).
    #[error("stored value unreadable: {0}")]
    Decode(String),
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

/// A unique constraint was hit (e.g. an idempotency key stored meanwhile by a concurrent request).
pub(crate) fn is_unique_violation(e: &sqlx::Error) -> bool {
    matches!(e, sqlx::Error::Database(d) if d.is_unique_violation())
}

/// The storage interface of the service: every resource's trait, and the connection itself.
#[async_trait]
pub trait Store:
    KeyStore
    + AlertStore
    + IngestStore
    + DiagnosisStore
    + MachineStore
    + WebhookStore
    + RetentionStore
    + CalibrationStore
    + GearboxStore
    + BaselineStore
    + TableExtensionStore
    + PhysicsStore
    + Send
    + Sync
    + 'static
{
    /// `"sqlite"` or `"postgres"`.
    fn kind(&self) -> &'static str;
    /// A trivial query: is the database reachable?
    async fn ping(&self) -> StoreResult<()>;
    /// Close the pool (after the server stopped).
    async fn close(&self);
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
