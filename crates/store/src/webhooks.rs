//! Webhook subscriptions, their deliveries and the attempts of each delivery.

use async_trait::async_trait;
use serde::Serialize;

use super::StoreResult;

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
    /// The queued event ([`crate::events::QueuedEvent`] as JSON; a payload queued already
    /// rendered by an earlier build is delivered as it is).
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

/// Webhook subscriptions and deliveries.
#[async_trait]
pub trait WebhookStore: Send + Sync {
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
}

/// The SQL of [`WebhookStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! webhooks_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::*;

        pub(crate) fn webhook_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<WebhookRow> {
            let events: String = r.try_get("events")?;
            Ok(WebhookRow {
                id: r.try_get("id")?,
                url: r.try_get("url")?,
                secret: r.try_get("secret")?,
                events: events
                    .split(',')
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect(),
                created_at: r.try_get("created_at")?,
            })
        }

        /// Queue each event for every live subscription that asked for it, inside the
        /// caller's transaction (so an event exists exactly when what raised it is
        /// committed); `now` is the deliveries' creation and first due time. The payload
        /// column holds the typed event; the webhook worker renders it. Returns how many
        /// deliveries it queued.
        pub(crate) async fn queue_events(
            tx: &mut sqlx::Transaction<'_, $db>,
            events: &[$crate::events::QueuedEvent],
            now: i64,
        ) -> StoreResult<usize> {
            let hooks = sqlx::query("SELECT * FROM webhooks WHERE deleted_at IS NULL")
                .fetch_all(&mut **tx)
                .await?;
            if hooks.is_empty() {
                // Nothing to deliver: the events are not written out.
                return Ok(0);
            }
            let events = events
                .iter()
                .map(|q| Ok((q.event.name(), serde_json::to_string(q)?)))
                .collect::<Result<Vec<_>, serde_json::Error>>()
                .map_err(|e| StoreError::Decode(format!("an event cannot be written: {e}")))?;
            let mut queued = 0;
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
                    .bind(now)
                    .execute(&mut **tx)
                    .await?;
                    queued += 1;
                }
            }
            Ok(queued)
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

        #[async_trait::async_trait]
        impl $crate::WebhookStore for $store {
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
        }
    };
}
pub(crate) use webhooks_sql;
