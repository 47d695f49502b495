//! `gearwear serve` and `gearwear keys …`: argument structs and bodies (the `Command` enum in
//! `crate::cli` only dispatches here).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};

use super::{AppState, check_exposure, serve};
use crate::configuration::{EpisodePolicy, Settings, Thresholds};
use crate::database::DatabaseArg;
use crate::keys::{self, Scope};
use crate::store::{self, KeyRow, now_ms};

/// `gearwear serve`.
#[derive(Debug, Args, Clone)]
pub struct ServeArgs {
    /// Address to listen on. A non-loopback address needs at least one API key.
    #[arg(long, default_value = "127.0.0.1:8080", env = "GEARWEAR_ADDRESS")]
    pub address: SocketAddr,
    #[command(flatten)]
    pub database: DatabaseArg,
    /// Signature table (default: the committed `signatures/model_a_accel.json`).
    #[arg(long, env = "GEARWEAR_SIGNATURES")]
    pub signatures: Option<PathBuf>,
    /// Serve with a signature table computed for another model configuration (logged).
    #[arg(long)]
    pub allow_stale_table: bool,
    /// Turn off authentication for reads: the dashboard and every read endpoint answer without
    /// an API key (ingest and admin still need one). For a trusted network only. (Old name:
    /// --open-dashboard, still accepted.)
    #[arg(
        long = "dashboard-without-key",
        alias = "open-dashboard",
        env = "GEARWEAR_DASHBOARD_WITHOUT_KEY"
    )]
    pub open_dashboard: bool,
    /// Take records only for machines registered with PUT /v1/machines/{id} (or `gearwear
    /// machine set`): a record for any other machine id is refused (404 unknown-machine) and
    /// nothing is stored. Without it, a record for a new id creates the machine.
    #[arg(long, env = "GEARWEAR_REQUIRE_REGISTERED_MACHINES")]
    pub require_registered_machines: bool,
    /// Log JSON lines.
    #[arg(long, env = "GEARWEAR_LOG_JSON")]
    pub log_json: bool,
    /// Largest request body (bytes).
    #[arg(long, default_value_t = 16 << 20)]
    pub max_body_bytes: usize,
    /// Largest record (samples).
    #[arg(long, default_value_t = 2_097_152)]
    pub max_samples: usize,
    /// Requests per second per API key (token bucket refill).
    #[arg(long, default_value_t = 50.0)]
    pub rate_per_second: f64,
    /// Burst per API key (token bucket size).
    #[arg(long, default_value_t = 100.0)]
    pub rate_burst: f64,
    /// Request timeout (seconds).
    #[arg(long, default_value_t = 15.0)]
    pub request_timeout_s: f64,
    /// Days to keep raw samples (0: do not store them).
    #[arg(long, default_value_t = 30.0)]
    pub raw_retention_days: f64,
    /// Days to keep the stored answers to `Idempotency-Key`s (a retry within it is answered
    /// with the original result, later the key is forgotten).
    #[arg(long, default_value_t = 7.0)]
    pub idempotency_retention_days: f64,
    /// Wear degree (ea) at which a machine turns `warning`.
    #[arg(long, default_value_t = Thresholds::default().warning)]
    pub warning_ea: f64,
    /// Take records from an MQTT broker too: `mqtt://[user[:password]@]host[:port]` (plain
    /// TCP). Each message on --mqtt-topic goes through the record endpoint's path.
    #[arg(long, env = "GEARWEAR_MQTT_URL")]
    pub mqtt_url: Option<String>,
    /// The topic filter to subscribe to (QoS 1); its one `+` level is the machine id.
    #[arg(long, default_value = "plant/+/vibration", env = "GEARWEAR_MQTT_TOPIC")]
    pub mqtt_topic: String,
    /// The client id of the broker session (persistent: records published while the service
    /// is down wait at the broker). One per replica; replicas share a topic with
    /// `$share/GROUP/FILTER`.
    #[arg(long, default_value = "gearwear", env = "GEARWEAR_MQTT_CLIENT_ID")]
    pub mqtt_client_id: String,
    /// Where a refused payload's problem (JSON) is published.
    #[arg(
        long,
        default_value = "gearwear/errors",
        env = "GEARWEAR_MQTT_ERROR_TOPIC"
    )]
    pub mqtt_error_topic: String,
    /// Wear degree (ea) at which a machine turns `alarm`.
    #[arg(long, default_value_t = Thresholds::default().alarm)]
    pub alarm_ea: f64,
    /// Consecutive records at warning or above (alarm) that open (escalate) a machine's alert:
    /// one noisy record opens none.
    #[arg(long, env = "GEARWEAR_ALERT_OPEN_AFTER", default_value_t = EpisodePolicy::default().open_after)]
    pub alert_open_after: u32,
    /// Consecutive records below the close threshold that close a machine's alert.
    #[arg(long, env = "GEARWEAR_ALERT_CLOSE_AFTER", default_value_t = EpisodePolicy::default().close_after)]
    pub alert_close_after: u32,
    /// Severity under which a record counts towards closing an alert, as a fraction of the
    /// warning severity (1 = no hysteresis; docs/service.md#alerts).
    #[arg(long, env = "GEARWEAR_ALERT_CLOSE_BELOW", default_value_t = EpisodePolicy::default().close_below)]
    pub alert_close_below: f64,
}

impl ServeArgs {
    /// The settings, with the database resolved (see [`crate::database`]).
    pub fn settings(&self) -> Result<Settings> {
        let mut s = Settings {
            address: self.address,
            database_url: self.database.resolve()?.url,
            open_dashboard: self.open_dashboard,
            require_registered_machines: self.require_registered_machines,
            log_json: self.log_json,
            ..Settings::default()
        };
        if let Some(p) = &self.signatures {
            s.signatures = p.clone();
        }
        let pos = |name: &str, v: f64| -> Result<f64> {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                bail!("--{name} must be a positive number, got {v}")
            }
        };
        s.limits.max_body_bytes = self.max_body_bytes;
        s.limits.max_samples = self.max_samples;
        s.limits.rate_per_second = pos("rate-per-second", self.rate_per_second)?;
        s.limits.rate_burst = pos("rate-burst", self.rate_burst)?;
        s.limits.request_timeout =
            Duration::from_secs_f64(pos("request-timeout-s", self.request_timeout_s)?);
        if !(self.raw_retention_days >= 0.0 && self.raw_retention_days.is_finite()) {
            bail!("--raw-retention-days must be ≥ 0");
        }
        s.raw_retention = Duration::from_secs_f64(self.raw_retention_days * 86_400.0);
        s.idempotency_retention = Duration::from_secs_f64(
            86_400.0
                * pos(
                    "idempotency-retention-days",
                    self.idempotency_retention_days,
                )?,
        );
        if !(self.warning_ea < self.alarm_ea) {
            bail!("--warning-ea must be below --alarm-ea");
        }
        s.thresholds.warning = self.warning_ea;
        s.thresholds.alarm = self.alarm_ea;
        if self.alert_open_after == 0 || self.alert_close_after == 0 {
            bail!("--alert-open-after and --alert-close-after must be at least 1 record");
        }
        if !(self.alert_close_below > 0.0 && self.alert_close_below <= 1.0) {
            bail!(
                "--alert-close-below must be in (0, 1], got {}",
                self.alert_close_below
            );
        }
        s.alerts = EpisodePolicy {
            open_after: self.alert_open_after,
            close_after: self.alert_close_after,
            close_below: self.alert_close_below,
        };
        if let Some(url) = &self.mqtt_url {
            s.mqtt = Some(
                super::mqtt::MqttSettings::parse(
                    url,
                    &self.mqtt_topic,
                    &self.mqtt_client_id,
                    &self.mqtt_error_topic,
                )
                .map_err(anyhow::Error::msg)?,
            );
        }
        Ok(s)
    }
}

/// `gearwear keys`.
#[derive(Debug, Args, Clone)]
pub struct KeysArgs {
    #[command(subcommand)]
    pub command: KeysCommand,
    /// The database holding the keys: the one `serve` uses (the same rule finds it).
    #[command(flatten)]
    pub database: DatabaseArg,
}

#[derive(Debug, Subcommand, Clone)]
pub enum KeysCommand {
    /// Create a key and print it once (only its hash is stored).
    Create {
        /// Comma-separated scopes: ingest, read, acknowledge (alerts; read does not give it), admin.
        #[arg(long, default_value = "ingest,read")]
        scope: String,
        /// A label to recognise the key by.
        #[arg(long, default_value = "")]
        label: String,
    },
    /// List keys (ids, scopes, labels; never secrets).
    List,
    /// Revoke a key by id.
    Revoke { id: String },
}

/// Create a key in a store; returns the full token (to show once).
pub async fn create_key(
    store: &dyn store::Store,
    scopes: &[Scope],
    label: &str,
) -> Result<(KeyRow, String)> {
    let k = keys::generate();
    let row = KeyRow {
        id: k.id.clone(),
        hash: k.hash,
        scopes: scopes.to_vec(),
        label: label.to_string(),
        created_at: now_ms(),
        revoked_at: None,
    };
    store.insert_key(&row).await?;
    Ok((row, k.token))
}

pub fn keys_cmd(a: KeysArgs) -> Result<()> {
    let db = a.database.resolve()?;
    crate::runtime()?.block_on(async move {
        let store = db.open().await?;
        match a.command {
            KeysCommand::Create { scope, label } => {
                let scopes = Scope::parse_list(&scope).map_err(|w| {
                    anyhow::anyhow!("unknown scope `{w}`: use ingest, read, acknowledge or admin")
                })?;
                if scopes.is_empty() {
                    bail!("give at least one scope: --scope ingest,read");
                }
                let (row, token) = create_key(store.as_ref(), &scopes, &label).await?;
                eprintln!(
                    "created key {} with scopes {} in {} (a service started on another \
                     database will not know it) — this is the only time it is shown:",
                    row.id,
                    Scope::join(&row.scopes),
                    db.describe()
                );
                println!("{token}");
            }
            KeysCommand::List => {
                println!("id\tscopes\tcreated_at\trevoked_at\tlabel");
                for k in store.list_keys().await? {
                    println!(
                        "{}\t{}\t{}\t{}\t{}",
                        k.id,
                        Scope::join(&k.scopes),
                        crate::time::rfc3339(k.created_at),
                        k.revoked_at
                            .map(crate::time::rfc3339)
                            .unwrap_or_else(|| "-".into()),
                        k.label
                    );
                }
            }
            KeysCommand::Revoke { id } => {
                if store.revoke_key(&id, now_ms()).await? {
                    eprintln!("revoked key {id}");
                } else {
                    bail!("no active key with id {id} (see `gearwear keys list`)");
                }
            }
        }
        store.close().await;
        Ok(())
    })
}

pub use crate::database::redact;

pub fn serve_cmd(a: ServeArgs) -> Result<()> {
    let settings = a.settings()?;
    let a_allow_stale = a.allow_stale_table;
    crate::telemetry::init(settings.log_json);
    crate::runtime()?.block_on(async move {
        let database = crate::database::describe(&settings.database_url);
        let store = store::connect(&settings.database_url)
            .await
            .with_context(|| format!("opening the database {database}"))?;
        check_exposure(&settings.address, store.active_key_count().await?)
            .map_err(anyhow::Error::msg)?;
        let diagnoser = super::signatures::load(&settings.signatures, a_allow_stale)
            .with_context(|| format!("loading the signature table {}", settings.signatures.display()))?;
        let listener = tokio::net::TcpListener::bind(settings.address)
            .await
            .with_context(|| format!("binding {}", settings.address))?;
        let addr = listener.local_addr()?;
        tracing::info!(%addr, store = store.kind(), %database, dashboard_without_key = settings.open_dashboard, require_registered_machines = settings.require_registered_machines, "gearwear serving; dashboard at http://{addr}/; API keys and machines live in {database}");
        let state = AppState::new(settings, store.clone(), Arc::new(diagnoser));
        serve(state, listener, shutdown_signal()).await?;
        store.close().await;
        tracing::info!("stopped");
        Ok(())
    })
}

/// Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {}
        _ = term => {}
    }
    tracing::info!("shutdown signal: finishing in-flight requests");
}
