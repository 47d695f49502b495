//! The record path's writes: an accepted record, its diagnosis, its webhook deliveries and
//! the idempotent answer, in one transaction (or several records in one group commit).

use std::sync::OnceLock;

use async_trait::async_trait;

use super::StoreResult;
use super::diagnoses::{DiagnosisRow, level_rank, novelty_json, wear_json};

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

/// A record's first statement: a write, so that SQLite takes its write lock at once (waiting on
/// the busy timeout) instead of failing to upgrade a read lock later. It hands back the
/// machine's alert level before this record (the no-op update returns the stored row; a new
/// machine's is the column default): one round trip instead of an insert and a select, and on
/// PostgreSQL the row stays locked until the commit, so a concurrent record cannot read the
/// same previous level.
pub(crate) const UPSERT_MACHINE: &str = "INSERT INTO machines (id, created_at, updated_at) \
    VALUES ($1, $2, $2) ON CONFLICT (id) DO UPDATE SET updated_at = machines.updated_at \
    RETURNING alert_level";
/// The answer to the request's `Idempotency-Key`.
pub(crate) const INSERT_IDEMPOTENCY: &str = "INSERT INTO idempotency_keys \
    (key_id, idem_key, request_hash, status, response, created_at) \
    VALUES ($1, $2, $3, $4, $5, $6)";
pub(crate) const INSERT_RECORD: &str = "INSERT INTO records (id, machine_id, received_at, \
    recorded_at, sensor, content_type, sample_rate_hz, shaft_hz, sample_count, sha256, features, samples, \
    baseline, baseline_at, channels) \
    VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15)";
pub(crate) const INSERT_DIAGNOSIS: &str = "INSERT INTO diagnoses (id, record_id, machine_id, \
    created_at, ea_estimate, ea_lower, ea_upper, alert_level, motion_state, body, spectrum, has_wear, \
    novelty_score, novelty_threshold, channel) \
    VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15)";
/// The machine's state after the record.
pub(crate) const UPDATE_MACHINE: &str = "UPDATE machines SET updated_at = $2, \
    record_count = record_count + 1, last_diagnosis_id = $3, alert_level = $4 WHERE id = $1";
/// The subscriptions the record's events may go to.
pub(crate) const SELECT_WEBHOOKS: &str = "SELECT * FROM webhooks WHERE deleted_at IS NULL";

/// A record's statements (machine, idempotent answer when there is one, record, diagnosis,
/// machine state, webhooks) as one text, `;`-separated, each statement's `$n` renumbered after
/// the previous statements' parameters, so that one list of arguments, bound statement after
/// statement, serves them all (SQLite numbers `$n` through a multi-statement query).
pub(crate) fn record_writes_sql(with_idempotency: bool) -> &'static str {
    static SQL: [OnceLock<String>; 2] = [OnceLock::new(), OnceLock::new()];
    SQL[usize::from(with_idempotency)].get_or_init(|| {
        let idempotency = with_idempotency.then_some(INSERT_IDEMPOTENCY);
        let statements = [Some(UPSERT_MACHINE), idempotency]
            .into_iter()
            .flatten()
            .chain([
                INSERT_RECORD,
                INSERT_DIAGNOSIS,
                UPDATE_MACHINE,
                SELECT_WEBHOOKS,
            ]);
        let mut offset = 0;
        let mut out = Vec::new();
        for sql in statements {
            let (text, count) = renumbered(sql, offset);
            out.push(text);
            offset += count;
        }
        out.join(";\n")
    })
}

/// `sql` with every `$n` made `$(n + offset)`, and the largest `n`.
fn renumbered(sql: &str, offset: usize) -> (String, usize) {
    let mut out = String::with_capacity(sql.len() + 16);
    let mut largest = 0;
    let mut rest = sql;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..=i]);
        rest = &rest[i + 1..];
        let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
        let n: usize = rest[..digits].parse().expect("a numbered parameter");
        largest = largest.max(n);
        out.push_str(&(n + offset).to_string());
        rest = &rest[digits..];
    }
    out.push_str(rest);
    (out, largest)
}

/// A unique violation of the idempotent answers' key (in a multi-statement query, where the
/// statement that failed is known only by its message).
pub(crate) fn is_idempotency_violation(e: &sqlx::Error) -> bool {
    matches!(e, sqlx::Error::Database(d)
        if d.is_unique_violation() && d.message().contains("idempotency_keys"))
}

/// Accepted records and the answers to idempotency keys.
#[async_trait]
pub trait IngestStore: Send + Sync {
    async fn get_idempotent(&self, key_id: &str, idem_key: &str) -> StoreResult<Option<IdemRow>>;
    /// Write an accepted record in one transaction. `StoreError::Conflict` when the
    /// idempotency key was stored meanwhile by a concurrent request.
    async fn ingest(&self, ing: &Ingest) -> StoreResult<()>;
    /// Write several accepted records in ONE transaction (one commit, one fsync — group
    /// commit), each in its own savepoint: the result of each, in order. When the commit
    /// fails, every record gets that error and none is stored.
    async fn ingest_batch(&self, ings: &[Ingest]) -> Vec<StoreResult<()>>;
}

/// The SQL of [`IngestStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! ingest_sql {
    ($store:ident, $db:ty, one_query: $one_query:expr) => {
        /// Write a record's statements as one query (a backend that takes several statements
        /// with parameters in one query: SQLite).
        const ONE_QUERY: bool = $one_query;

        use super::webhooks::webhook_row;
        use super::$store;
        use sqlx::Row;
        use $crate::store::ingest::{
            INSERT_DIAGNOSIS, INSERT_IDEMPOTENCY, INSERT_RECORD, SELECT_WEBHOOKS, UPDATE_MACHINE,
            UPSERT_MACHINE, is_idempotency_violation, record_writes_sql,
        };
        use $crate::store::*;

        type Query<'q> = sqlx::query::Query<'q, $db, <$db as sqlx::Database>::Arguments>;

        /// Every write of one accepted record, inside the caller's transaction.
        async fn ingest_in(tx: &mut sqlx::Transaction<'_, $db>, ing: &Ingest) -> StoreResult<()> {
            let rec = &ing.record;
            let (prev, hooks) = if ONE_QUERY {
                writes_in_one_query(tx, ing).await?
            } else {
                writes_by_statement(tx, ing).await?
            };
            let event_id = new_id();
            let events = ingest_events(&prev, ing, &event_id);
            for h in &hooks {
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

        /// The record's writes ([`RECORD_WRITES`]) one statement at a time: the machine's
        /// previous alert level and the live webhooks.
        async fn writes_by_statement(
            tx: &mut sqlx::Transaction<'_, $db>,
            ing: &Ingest,
        ) -> StoreResult<(String, Vec<WebhookRow>)> {
            let (rec, d) = (&ing.record, &ing.diagnosis);
            let prev: String = bind_machine(sqlx::query(UPSERT_MACHINE), rec)
                .fetch_one(&mut **tx)
                .await?
                .try_get("alert_level")?;
            if let Some(i) = &ing.idempotency {
                let r = bind_idempotency(sqlx::query(INSERT_IDEMPOTENCY), i, rec)
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
            bind_record(sqlx::query(INSERT_RECORD), rec)
                .execute(&mut **tx)
                .await?;
            bind_diagnosis(sqlx::query(INSERT_DIAGNOSIS), d)
                .execute(&mut **tx)
                .await?;
            bind_machine_state(sqlx::query(UPDATE_MACHINE), rec, d)
                .execute(&mut **tx)
                .await?;
            let hooks = sqlx::query(SELECT_WEBHOOKS).fetch_all(&mut **tx).await?;
            Ok((
                prev,
                hooks.iter().map(webhook_row).collect::<StoreResult<_>>()?,
            ))
        }

        /// The record's writes as ONE query, the statements separated by `;` and numbered
        /// through ([`record_writes_sql`]): one round trip to the connection instead of one a
        /// statement. Its rows are the machine's previous alert level, then the live webhooks.
        async fn writes_in_one_query(
            tx: &mut sqlx::Transaction<'_, $db>,
            ing: &Ingest,
        ) -> StoreResult<(String, Vec<WebhookRow>)> {
            let (rec, d) = (&ing.record, &ing.diagnosis);
            let mut q = sqlx::query(sqlx::AssertSqlSafe(record_writes_sql(
                ing.idempotency.is_some(),
            )));
            q = bind_machine(q, rec);
            if let Some(i) = &ing.idempotency {
                q = bind_idempotency(q, i, rec);
            }
            q = bind_machine_state(bind_diagnosis(bind_record(q, rec), d), rec, d);
            let rows = q.fetch_all(&mut **tx).await.map_err(|e| {
                if is_idempotency_violation(&e) {
                    StoreError::Conflict("idempotency key".into())
                } else {
                    StoreError::from(e)
                }
            })?;
            let Some((machine, hooks)) = rows.split_first() else {
                return Err(StoreError::Db(sqlx::Error::RowNotFound));
            };
            Ok((
                machine.try_get("alert_level")?,
                hooks.iter().map(webhook_row).collect::<StoreResult<_>>()?,
            ))
        }

        fn bind_machine<'q>(q: Query<'q>, rec: &'q NewRecord) -> Query<'q> {
            q.bind(&rec.machine_id).bind(rec.received_at)
        }

        fn bind_idempotency<'q>(q: Query<'q>, i: &'q IdemRow, rec: &'q NewRecord) -> Query<'q> {
            q.bind(&i.key_id)
                .bind(&i.idem_key)
                .bind(&i.request_hash)
                .bind(i.status)
                .bind(&i.response)
                .bind(rec.received_at)
        }

        fn bind_record<'q>(q: Query<'q>, rec: &'q NewRecord) -> Query<'q> {
            q.bind(&rec.id)
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
                .bind(
                    rec.channels
                        .as_ref()
                        .map(|c| serde_json::to_string(c).unwrap_or_default()),
                )
        }

        fn bind_diagnosis<'q>(q: Query<'q>, d: &'q DiagnosisRow) -> Query<'q> {
            q.bind(&d.id)
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
        }

        fn bind_machine_state<'q>(
            q: Query<'q>,
            rec: &'q NewRecord,
            d: &'q DiagnosisRow,
        ) -> Query<'q> {
            q.bind(&rec.machine_id)
                .bind(rec.received_at)
                .bind(&d.id)
                .bind(&d.alert_level)
        }

        #[async_trait::async_trait]
        impl $crate::store::IngestStore for $store {
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
                        return ings
                            .iter()
                            .map(|_| Err(StoreError::Shared(e.clone())))
                            .collect();
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
                    return ings
                        .iter()
                        .map(|_| Err(StoreError::Shared(e.clone())))
                        .collect();
                }
                out
            }
        }
    };
}
pub(crate) use ingest_sql;

#[cfg(test)]
mod tests {
    use super::*;

    /// One list of arguments binds every statement of the one-query write: the parameters run
    /// through without a gap or a repeat across statements.
    #[test]
    fn a_record_s_statements_are_numbered_through() {
        let sql = record_writes_sql(true);
        let statements: Vec<&str> = sql.split(";\n").collect();
        assert_eq!(statements.len(), 6);
        assert!(statements[0].contains("VALUES ($1, $2, $2)"), "{sql}");
        assert!(
            statements[1].contains("VALUES ($3, $4, $5, $6, $7, $8)"),
            "{sql}"
        );
        assert!(statements[2].contains("VALUES ($9, $10,") && statements[2].contains("$23)"));
        assert!(statements[3].contains("VALUES ($24, $25,") && statements[3].contains("$38)"));
        assert!(
            statements[4].contains("alert_level = $42 WHERE id = $39"),
            "{sql}"
        );
        assert_eq!(statements[5], SELECT_WEBHOOKS);
        let plain = record_writes_sql(false);
        assert!(
            plain.contains("alert_level = $36 WHERE id = $33"),
            "{plain}"
        );
    }
}
