//! Settings of the service: one struct with documented defaults, filled from the command line
//! (and the environment variables clap reads for it, e.g. `GEARWEAR_ADDRESS`; the database is
//! resolved by [`crate::database`]).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Everything `serve` needs.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Where to listen (default `127.0.0.1:8080`).
    pub address: SocketAddr,
    /// `postgres://…` → PostgreSQL; anything else is a SQLite file. `serve` fills it with
    /// [`crate::database::DatabaseArg::resolve`]; this struct's default, `gearwear.db` in the
    /// current directory, is for tests and embedders that set it.
    pub database_url: String,
    /// The signature table (default: the committed one under `signatures/`).
    pub signatures: PathBuf,
    /// Serve the dashboard and the read endpoints without a key.
    pub open_dashboard: bool,
    /// Take records only for machines registered with `PUT /v1/machines/{id}` (a record for
    /// any other id is a 404 `unknown-machine` and stores nothing); off: a record for a new
    /// id creates the machine.
    pub require_registered_machines: bool,
    /// Logs as JSON lines instead of human-readable text.
    pub log_json: bool,
    pub limits: Limits,
    pub thresholds: Thresholds,
    /// Alert episodes: open after N records at warning, close after M below (defaults 2, 3).
    pub alerts: EpisodePolicy,
    pub webhooks: WebhookSettings,
    /// Raw samples are kept this long (0: never stored); metadata, features and diagnoses
    /// are kept forever.
    pub raw_retention: Duration,
    /// Stored answers to `Idempotency-Key`s are kept this long (default 7 days): a client
    /// retrying within it gets the original answer, later the key is forgotten.
    pub idempotency_retention: Duration,
    /// MQTT ingest (`--mqtt-url`): off when `None`.
    pub mqtt: Option<crate::service::mqtt::settings::MqttSettings>,
}

/// Request limits. Each refusal is a problem+json naming the limit.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Largest request body in bytes (default 16 MiB).
    pub max_body_bytes: usize,
    /// Largest record in samples (default 2 097 152: 80 s at 25.6 kHz).
    pub max_samples: usize,
    /// Sustained requests per second per API key (token bucket refill rate).
    pub rate_per_second: f64,
    /// Token-bucket size: the burst a key may send at once.
    pub rate_burst: f64,
    /// Longest a request may take before it gets a 503.
    pub request_timeout: Duration,
}

/// The alert policy's wear-degree thresholds (in the core, with the policy).
pub use crate::assessment::Thresholds;

/// The alert episodes' delays and hysteresis (in the core, with the state machine).
pub use crate::assessment::episodes::EpisodePolicy;

/// Webhook delivery: retries with exponential back-off, `base · 2^(attempt−1)` capped at
/// `max_backoff`, up to `max_attempts`.
#[derive(Debug, Clone)]
pub struct WebhookSettings {
    pub max_attempts: i64,
    pub base_backoff: Duration,
    pub max_backoff: Duration,
    /// How often the worker looks for due deliveries when nothing wakes it.
    pub poll_interval: Duration,
    /// Timeout of one delivery attempt.
    pub timeout: Duration,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            address: "127.0.0.1:8080".parse().expect("valid address"),
            database_url: "gearwear.db".into(),
            signatures: default_signatures(),
            open_dashboard: false,
            require_registered_machines: false,
            log_json: false,
            limits: Limits {
                max_body_bytes: 16 << 20,
                max_samples: 2_097_152,
                rate_per_second: 50.0,
                rate_burst: 100.0,
                request_timeout: Duration::from_secs(15),
            },
            thresholds: Thresholds::default(),
            alerts: EpisodePolicy::default(),
            webhooks: WebhookSettings {
                max_attempts: 10,
                base_backoff: Duration::from_secs(2),
                max_backoff: Duration::from_secs(600),
                poll_interval: Duration::from_secs(1),
                timeout: Duration::from_secs(10),
            },
            raw_retention: Duration::from_secs(30 * 24 * 3600),
            idempotency_retention: Duration::from_secs(7 * 24 * 3600),
            mqtt: None,
        }
    }
}

/// The committed default signature table.
pub fn default_signatures() -> PathBuf {
    crate::signature::table::default_table_path()
}
