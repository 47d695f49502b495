//! The record path's writes: an accepted record, its diagnosis, its webhook deliveries and
//! the idempotent answer, in one transaction (or several records in one group commit).

use async_trait::async_trait;

use super::StoreResult;
use super::alerts::AlertInput;
use super::diagnoses::DiagnosisRow;
use super::events::DiagnosisEvent;
use super::extensions::TableSpeed;

/// An accepted record's metadata, features and (optionally) raw samples.
#[derive(Debug, Clone)]
pub struct NewRecord {
    pub id: String,
    pub machine_id: String,
    pub received_at: i64,
    pub recorded_at: Option<String>,
    /// When it was measured, unix ms: `recorded_at` parsed, else `received_at`.
    pub measured_at: i64,
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
    /// Members the service adds to each webhook event of this record besides the diagnosis
    /// row's (the deciding channel's `findings`, the record's `operating_state`, the
    /// machine's `trend_summary`), carried in [`DiagnosisEvent::extras`](crate::events::DiagnosisEvent::extras).
    pub event_extras: serde_json::Map<String, serde_json::Value>,
    /// Store the record only if its machine is registered (`registered_at` set by
    /// `PUT /v1/machines/{id}`), else fail with [`StoreError::UnregisteredMachine`](crate::StoreError::UnregisteredMachine)
    /// and store nothing; when false a record of an unknown machine creates it. Checked in
    /// the transaction, so a machine deleted meanwhile is not brought back.
    pub registered_only: bool,
    /// The record's step of its machine's alert episode (`None`: the episode is left as it
    /// is — the store's own tests).
    pub alert: Option<AlertInput>,
    /// The record ran outside its gearbox's table: its speed, stored with it as part of what
    /// the table must cover, and the table's extension queued (when it is ready and none is
    /// pending).
    pub table_speed: Option<TableSpeed>,
}

impl Ingest {
    /// The diagnosis as its events carry it, with the service's extras.
    pub fn diagnosis_event(&self) -> DiagnosisEvent {
        diagnosis_event(&self.diagnosis, &self.event_extras)
    }
}

/// A record read again ([`IngestStore::store_reread`]): its new diagnosis (`replaces` names the
/// pending one), the record's features as the new reading computed them, and the members its
/// webhook event carries besides the row's.
#[derive(Debug, Clone)]
pub struct Reread {
    pub diagnosis: DiagnosisRow,
    pub features: String,
    pub event_extras: serde_json::Map<String, serde_json::Value>,
}

/// Diagnosis `d` as its events carry it, with the service's `extras`.
pub fn diagnosis_event(
    d: &DiagnosisRow,
    extras: &serde_json::Map<String, serde_json::Value>,
) -> DiagnosisEvent {
    DiagnosisEvent {
        machine_id: d.machine_id.clone(),
        diagnosis_id: d.id.clone(),
        record_id: d.record_id.clone(),
        created_at: d.created_at,
        measured_at: d.measured_at,
        wear: d.has_wear.then_some(crate::events::Interval {
            estimate: d.ea_estimate,
            lower: d.ea_lower,
            upper: d.ea_upper,
        }),
        alert_level: d.alert_level,
        motion_state: d.motion_state.clone(),
        novelty: d
            .novelty_score
            .zip(d.novelty_threshold)
            .map(|(score, threshold)| crate::events::Novelty { score, threshold }),
        channel: d.channel.clone(),
        extras: extras.clone(),
    }
}

/// Accepted records and the answers to idempotency keys.
#[async_trait]
pub trait IngestStore: Send + Sync {
    async fn get_idempotent(&self, key_id: &str, idem_key: &str) -> StoreResult<Option<IdemRow>>;
    /// Write an accepted record in one transaction; how many webhook deliveries it queued.
    /// `StoreError::Conflict` when the idempotency key was stored meanwhile by a concurrent
    /// request.
    async fn ingest(&self, ing: &Ingest) -> StoreResult<usize>;
    /// Write several accepted records in ONE transaction (one commit, one fsync — group
    /// commit), each in its own savepoint: the result of each, in order. When the commit
    /// fails, every record gets that error and none is stored.
    async fn ingest_batch(&self, ings: &[Ingest]) -> Vec<StoreResult<usize>>;
    /// Store a re-read in one transaction: the pending diagnosis it replaces marked `done`
    /// (compare-and-set: `false`, and nothing written, when it is no longer pending — another
    /// replica stored its re-read), the new diagnosis, the record's new features (a baseline
    /// record's machine's `baseline_version` raised: its baseline changed), the machine's
    /// latest diagnosis when it was the one replaced, and its `diagnosis.created` event. The
    /// machine's alert episode is left as it is: the record was counted when it came.
    async fn store_reread(&self, r: &Reread) -> StoreResult<bool>;
    /// Set a pending re-read's status (`unavailable`: its record's raw samples are gone).
    async fn mark_reread(&self, diagnosis_id: &str, status: &str) -> StoreResult<()>;
}

/// The SQL of [`IngestStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! ingest_sql {
    ($store:ident, $db:ty) => {
        use super::alerts::step_in;
        use super::webhooks::queue_events;
        use $crate::events::{Event, QueuedEvent};
        use super::$store;
        use sqlx::Row;
        use $crate::*;

        /// Every write of one accepted record, inside the caller's transaction; how many
        /// webhook deliveries it queued.
        async fn ingest_in(
            tx: &mut sqlx::Transaction<'_, $db>,
            ing: &Ingest,
        ) -> StoreResult<usize> {
            let (rec, d) = (&ing.record, &ing.diagnosis);
            lock_machine(tx, ing).await?;
            if let Some(i) = &ing.idempotency {
                let r = sqlx::query(
                    "INSERT INTO idempotency_keys \
                     (key_id, idem_key, request_hash, status, response, created_at, machine_id) \
                     VALUES ($1, $2, $3, $4, $5, $6, $7)",
                )
                .bind(&i.key_id)
                .bind(&i.idem_key)
                .bind(&i.request_hash)
                .bind(i.status)
                .bind(&i.response)
                .bind(rec.received_at)
                .bind(&rec.machine_id)
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
                 samples, baseline, baseline_at, channels, measured_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16)",
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
            .bind(
                rec.channels
                    .as_ref()
                    .map(|c| serde_json::to_string(c).unwrap_or_default()),
            )
            .bind(rec.measured_at)
            .execute(&mut **tx)
            .await?;
            insert_diagnosis(tx, d).await?;
            if let Some(speed) = &ing.table_speed {
                super::extensions::add_table_speed_in(tx, speed, rec.received_at).await?;
            }
            sqlx::query(
                "UPDATE machines SET updated_at = $2, record_count = record_count + 1, \
                 last_diagnosis_id = $3, alert_level = $4, \
                 baseline_version = baseline_version + $5 WHERE id = $1",
            )
            .bind(&rec.machine_id)
            .bind(rec.received_at)
            .bind(&d.id)
            .bind(d.alert_level.as_str())
            .bind(rec.baseline as i64)
            .execute(&mut **tx)
            .await?;
            let diagnosis = ing.diagnosis_event();
            let mut events = Vec::new();
            if let Some(a) = &ing.alert {
                let step = step_in(tx, &rec.machine_id, &rec.id, a, &diagnosis, rec.received_at);
                events.extend(step.await?);
            }
            events.insert(
                0,
                QueuedEvent::new(new_id(), Event::DiagnosisCreated { diagnosis }),
            );
            queue_events(tx, &events, rec.received_at).await
        }

        /// The diagnosis's row, inside the caller's transaction.
        async fn insert_diagnosis(
            tx: &mut sqlx::Transaction<'_, $db>,
            d: &DiagnosisRow,
        ) -> StoreResult<()> {
            sqlx::query(
                "INSERT INTO diagnoses (id, record_id, machine_id, created_at, ea_estimate, \
                 ea_lower, ea_upper, alert_level, motion_state, body, spectrum, has_wear, \
                 novelty_score, novelty_threshold, channel, measured_at, evidence, \
                 wear_withheld, reread_status, reread_request, replaces) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, \
                 $17, $18, $19, $20, $21)",
            )
            .bind(&d.id)
            .bind(&d.record_id)
            .bind(&d.machine_id)
            .bind(d.created_at)
            .bind(d.ea_estimate)
            .bind(d.ea_lower)
            .bind(d.ea_upper)
            .bind(d.alert_level.as_str())
            .bind(&d.motion_state)
            .bind(&d.body)
            .bind(&d.spectrum)
            .bind(d.has_wear as i64)
            .bind(d.novelty_score)
            .bind(d.novelty_threshold)
            .bind(&d.channel)
            .bind(d.measured_at)
            .bind(&d.evidence)
            .bind(&d.wear_withheld)
            .bind(&d.reread_status)
            .bind(&d.reread_request)
            .bind(&d.replaces)
            .execute(&mut **tx)
            .await?;
            Ok(())
        }

        /// [`IngestStore::store_reread`]'s writes inside its transaction; `false` when the
        /// diagnosis it replaces is no longer pending.
        async fn reread_in(tx: &mut sqlx::Transaction<'_, $db>, r: &Reread) -> StoreResult<bool> {
            let d = &r.diagnosis;
            let old = d.replaces.as_deref().unwrap_or_default();
            let claimed = sqlx::query(
                "UPDATE diagnoses SET reread_status = 'done', reread_request = NULL \
                 WHERE id = $1 AND machine_id = $2 AND reread_status = 'pending'",
            )
            .bind(old)
            .bind(&d.machine_id)
            .execute(&mut **tx)
            .await?;
            if claimed.rows_affected() != 1 {
                return Ok(false);
            }
            insert_diagnosis(tx, d).await?;
            let baseline: Option<i64> = sqlx::query(
                "UPDATE records SET features = $2 WHERE id = $1 RETURNING baseline",
            )
            .bind(&d.record_id)
            .bind(&r.features)
            .fetch_optional(&mut **tx)
            .await?
            .map(|row| row.try_get("baseline"))
            .transpose()?;
            sqlx::query(
                "UPDATE machines SET baseline_version = baseline_version + $3, \
                 last_diagnosis_id = CASE WHEN last_diagnosis_id = $4 THEN $2 \
                 ELSE last_diagnosis_id END WHERE id = $1",
            )
            .bind(&d.machine_id)
            .bind(&d.id)
            .bind(baseline.unwrap_or(0).min(1))
            .bind(old)
            .execute(&mut **tx)
            .await?;
            let event = QueuedEvent::new(
                new_id(),
                Event::DiagnosisCreated {
                    diagnosis: $crate::ingest::diagnosis_event(d, &r.event_extras),
                },
            );
            queue_events(tx, &[event], d.created_at).await?;
            Ok(true)
        }

        /// The machine's alert level before this record, taking the machine's row lock. A
        /// write first: SQLite then takes its write lock at once (waiting on the busy
        /// timeout) instead of failing to upgrade a read lock later. The no-op update returns
        /// the stored row; on PostgreSQL the row stays locked until the commit, so a
        /// concurrent record cannot read the same previous level. With
        /// [`Ingest::registered_only`] only a registered machine's row is touched, and a
        /// machine that is not one refuses the record; otherwise a new machine's row is made
        /// with the column defaults.
        async fn lock_machine(
            tx: &mut sqlx::Transaction<'_, $db>,
            ing: &Ingest,
        ) -> StoreResult<String> {
            let rec = &ing.record;
            if ing.registered_only {
                let r = sqlx::query(
                    "UPDATE machines SET updated_at = machines.updated_at \
                     WHERE id = $1 AND registered_at IS NOT NULL RETURNING alert_level",
                )
                .bind(&rec.machine_id)
                .fetch_optional(&mut **tx)
                .await?;
                return match r {
                    Some(r) => Ok(r.try_get("alert_level")?),
                    None => Err(StoreError::UnregisteredMachine(rec.machine_id.clone())),
                };
            }
            Ok(sqlx::query(
                "INSERT INTO machines (id, created_at, updated_at) VALUES ($1, $2, $2) \
                 ON CONFLICT (id) DO UPDATE SET updated_at = machines.updated_at \
                 RETURNING alert_level",
            )
            .bind(&rec.machine_id)
            .bind(rec.received_at)
            .fetch_one(&mut **tx)
            .await?
            .try_get("alert_level")?)
        }

        #[async_trait::async_trait]
        impl $crate::IngestStore for $store {
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

            async fn ingest(&self, ing: &Ingest) -> StoreResult<usize> {
                let mut tx = self.pool.begin().await?;
                let queued = ingest_in(&mut tx, ing).await?;
                tx.commit().await.map_err(|e| {
                    if is_unique_violation(&e) {
                        StoreError::Conflict("idempotency key".into())
                    } else {
                        e.into()
                    }
                })?;
                Ok(queued)
            }

            async fn ingest_batch(&self, ings: &[Ingest]) -> Vec<StoreResult<usize>> {
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
                        let queued = ingest_in(&mut sp, ing).await?;
                        sp.commit().await?;
                        Ok::<usize, StoreError>(queued)
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

            async fn store_reread(&self, r: &Reread) -> StoreResult<bool> {
                let mut tx = self.pool.begin().await?;
                if !reread_in(&mut tx, r).await? {
                    tx.rollback().await?;
                    return Ok(false);
                }
                tx.commit().await?;
                Ok(true)
            }

            async fn mark_reread(&self, diagnosis_id: &str, status: &str) -> StoreResult<()> {
                sqlx::query(
                    "UPDATE diagnoses SET reread_status = $2, reread_request = NULL \
                     WHERE id = $1 AND reread_status = 'pending'",
                )
                .bind(diagnosis_id)
                .bind(status)
                .execute(&self.pool)
                .await?;
                Ok(())
            }
        }
    };
}
pub(crate) use ingest_sql;
