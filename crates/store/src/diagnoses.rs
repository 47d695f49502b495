//! Stored diagnoses and their alert levels.

use async_trait::async_trait;

use super::StoreResult;

/// A diagnosis; `body`/`spectrum`/`evidence` are JSON texts, empty in summaries.
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
    pub alert_level: gearwear_core::assessment::Level,
    pub motion_state: String,
    pub body: String,
    pub spectrum: String,
    /// The record page's evidence plot (the core's `EvidencePlot`), `null` without one.
    pub evidence: String,
    /// False when the diagnosis has no wear degree (its gearbox's table was not ready).
    pub has_wear: bool,
    /// Novelty against the machine's baseline (deciding channel), when it has one.
    pub novelty_score: Option<f64>,
    pub novelty_threshold: Option<f64>,
    /// The channel that decides the alert.
    pub channel: Option<String>,
    /// When its record was measured, unix ms: the record's `recorded_at`, else its receive
    /// time. Series are ordered by it.
    pub measured_at: i64,
    /// The code of a withheld wear figure (`table-in-progress`, `outside-table`, …), `None`
    /// when the figure is given (and for diagnoses stored before migration 0012).
    pub wear_withheld: Option<String>,
    /// Whether its record is read again: `pending` (a table-in-progress diagnosis, until the
    /// table covers its record), `done` (a later diagnosis replaces it), `unavailable` (the
    /// record's raw samples were not kept); `None`: nothing to read again.
    pub reread_status: Option<String>,
    /// What the record came with besides its samples (JSON), while the re-read is pending; read
    /// with the full row only.
    pub reread_request: Option<String>,
    /// On a re-read diagnosis: the id of the diagnosis it replaces.
    pub replaces: Option<String>,
}

/// A diagnosis whose record is read again when its gearbox's table covers it.
#[derive(Debug, Clone)]
pub struct PendingReread {
    pub diagnosis_id: String,
    pub record_id: String,
    pub machine_id: String,
    /// What the record came with besides its samples (JSON).
    pub request: Option<String>,
}

/// Reading diagnoses back (they are written by
/// [`IngestStore::ingest`](super::IngestStore::ingest)).
#[async_trait]
pub trait DiagnosisStore: Send + Sync {
    /// Diagnosis summaries (no body) of one machine with `seq > after` and
    /// `created_at > since`, oldest first.
    async fn list_diagnoses(
        &self,
        machine_id: &str,
        after: i64,
        since: i64,
        limit: i64,
    ) -> StoreResult<Vec<DiagnosisRow>>;
    /// The latest `limit` diagnosis summaries of one machine by measurement time, oldest
    /// first (`measured_at`, ties by arrival).
    async fn recent_diagnoses(
        &self,
        machine_id: &str,
        limit: i64,
    ) -> StoreResult<Vec<DiagnosisRow>>;
    /// Like [`recent_diagnoses`](Self::recent_diagnoses), with each diagnosis's `body` (the
    /// answer's JSON; no spectrum): the series of a machine's trend.
    async fn series_diagnoses(
        &self,
        machine_id: &str,
        limit: i64,
    ) -> StoreResult<Vec<DiagnosisRow>>;
    async fn get_diagnosis(&self, id: &str) -> StoreResult<Option<DiagnosisRow>>;
    /// The latest diagnosis of one record (every stored record has one; a re-read adds
    /// another), found through the record's machine so that the lookup walks the
    /// `diagnoses_machine` index, not the whole table.
    async fn diagnosis_of_record(&self, record_id: &str) -> StoreResult<Option<DiagnosisRow>>;
    /// The pending re-reads of the machines whose gearbox is `gearbox_id`, oldest first.
    async fn pending_rereads(
        &self,
        gearbox_id: &str,
        limit: i64,
    ) -> StoreResult<Vec<PendingReread>>;
    /// The gearboxes with pending re-reads whose table is ready with no extension pending.
    async fn reread_gearboxes(&self) -> StoreResult<Vec<String>>;
    /// A stored record with its raw samples (`None` when they were not kept), for a re-read
    /// (`sha256` is left empty).
    async fn stored_record(&self, record_id: &str) -> StoreResult<Option<super::NewRecord>>;
    /// Replace a diagnosis's `evidence` text `from` with `to` (the record page's plot, drawn
    /// when first asked for); false when it is no longer `from` (another request or replica
    /// drew it first).
    async fn set_evidence(&self, diagnosis_id: &str, from: &str, to: &str) -> StoreResult<bool>;
    /// At most `limit` diagnoses (full rows) whose `evidence` starts with `prefix` (not drawn
    /// yet) and whose record, received before `before`, still has its raw samples: what is
    /// drawn before the retention drops those samples.
    async fn undrawn_evidence(
        &self,
        prefix: &str,
        before: i64,
        limit: i64,
    ) -> StoreResult<Vec<DiagnosisRow>>;
}

/// The SQL of [`DiagnosisStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! diagnoses_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::*;

        const SUMMARY_COLS: &str = "seq, id, record_id, machine_id, created_at, ea_estimate, \
            ea_lower, ea_upper, alert_level, motion_state, has_wear, novelty_score, \
            novelty_threshold, channel, measured_at, wear_withheld, reread_status, replaces";

        fn diagnosis_row(
            r: &<$db as sqlx::Database>::Row,
            full: bool,
        ) -> StoreResult<DiagnosisRow> {
            diagnosis_row_with(r, full, false)
        }

        /// A row with its spectrum and evidence when `full`, with its body when `full` or `body`.
        fn diagnosis_row_with(
            r: &<$db as sqlx::Database>::Row,
            full: bool,
            body: bool,
        ) -> StoreResult<DiagnosisRow> {
            Ok(DiagnosisRow {
                seq: r.try_get("seq")?,
                id: r.try_get("id")?,
                record_id: r.try_get("record_id")?,
                machine_id: r.try_get("machine_id")?,
                created_at: r.try_get("created_at")?,
                ea_estimate: r.try_get("ea_estimate")?,
                ea_lower: r.try_get("ea_lower")?,
                ea_upper: r.try_get("ea_upper")?,
                alert_level: $crate::alerts::stored_level(r.try_get("alert_level")?)?,
                motion_state: r.try_get("motion_state")?,
                body: if full || body {
                    r.try_get("body")?
                } else {
                    String::new()
                },
                spectrum: if full {
                    r.try_get("spectrum")?
                } else {
                    String::new()
                },
                evidence: if full {
                    r.try_get("evidence")?
                } else {
                    String::new()
                },
                has_wear: r.try_get::<i64, _>("has_wear")? != 0,
                novelty_score: r.try_get("novelty_score")?,
                novelty_threshold: r.try_get("novelty_threshold")?,
                channel: r.try_get("channel")?,
                measured_at: r
                    .try_get::<Option<i64>, _>("measured_at")?
                    .unwrap_or(r.try_get("created_at")?),
                wear_withheld: r.try_get("wear_withheld")?,
                reread_status: r.try_get("reread_status")?,
                reread_request: if full {
                    r.try_get("reread_request")?
                } else {
                    None
                },
                replaces: r.try_get("replaces")?,
            })
        }

        /// The latest `limit` diagnoses of a machine by measurement time, oldest first; with
        /// their bodies when `body`. A diagnosis a re-read replaced is left out: the re-read
        /// stands for its record.
        async fn latest_by_measurement(
            pool: &sqlx::Pool<$db>,
            machine_id: &str,
            limit: i64,
            body: bool,
        ) -> StoreResult<Vec<DiagnosisRow>> {
            let cols = if body {
                format!("{SUMMARY_COLS}, body")
            } else {
                SUMMARY_COLS.to_string()
            };
            let rows = sqlx::query(sqlx::AssertSqlSafe(format!(
                "SELECT {cols} FROM diagnoses WHERE machine_id = $1 \
                 AND (reread_status IS NULL OR reread_status <> 'done') \
                 ORDER BY measured_at DESC, seq DESC LIMIT $2"
            )))
            .bind(machine_id)
            .bind(limit)
            .fetch_all(pool)
            .await?;
            let mut v: Vec<DiagnosisRow> = rows
                .iter()
                .map(|r| diagnosis_row_with(r, false, body))
                .collect::<StoreResult<_>>()?;
            v.reverse();
            Ok(v)
        }

        #[async_trait::async_trait]
        impl $crate::DiagnosisStore for $store {
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
                latest_by_measurement(&self.pool, machine_id, limit, false).await
            }

            async fn series_diagnoses(
                &self,
                machine_id: &str,
                limit: i64,
            ) -> StoreResult<Vec<DiagnosisRow>> {
                latest_by_measurement(&self.pool, machine_id, limit, true).await
            }

            async fn get_diagnosis(&self, id: &str) -> StoreResult<Option<DiagnosisRow>> {
                let r = sqlx::query("SELECT * FROM diagnoses WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(|r| diagnosis_row(r, true)).transpose()
            }

            async fn diagnosis_of_record(
                &self,
                record_id: &str,
            ) -> StoreResult<Option<DiagnosisRow>> {
                let r = sqlx::query(
                    "SELECT d.* FROM records r JOIN diagnoses d \
                     ON d.machine_id = r.machine_id AND d.record_id = r.id \
                     WHERE r.id = $1 ORDER BY d.seq DESC LIMIT 1",
                )
                .bind(record_id)
                .fetch_optional(&self.pool)
                .await?;
                r.as_ref().map(|r| diagnosis_row(r, true)).transpose()
            }

            async fn pending_rereads(
                &self,
                gearbox_id: &str,
                limit: i64,
            ) -> StoreResult<Vec<$crate::diagnoses::PendingReread>> {
                let rows = sqlx::query(
                    "SELECT d.id, d.record_id, d.machine_id, d.reread_request FROM diagnoses d \
                     JOIN machines m ON m.id = d.machine_id \
                     WHERE m.gearbox_id = $1 AND d.reread_status = 'pending' \
                     ORDER BY d.seq LIMIT $2",
                )
                .bind(gearbox_id)
                .bind(limit)
                .fetch_all(&self.pool)
                .await?;
                rows.iter()
                    .map(|r| {
                        Ok($crate::diagnoses::PendingReread {
                            diagnosis_id: r.try_get("id")?,
                            record_id: r.try_get("record_id")?,
                            machine_id: r.try_get("machine_id")?,
                            request: r.try_get("reread_request")?,
                        })
                    })
                    .collect()
            }

            async fn reread_gearboxes(&self) -> StoreResult<Vec<String>> {
                let rows = sqlx::query(
                    "SELECT DISTINCT g.id FROM diagnoses d \
                     JOIN machines m ON m.id = d.machine_id \
                     JOIN gearboxes g ON g.id = m.gearbox_id \
                     WHERE d.reread_status = 'pending' AND g.status = 'ready' \
                     AND g.extension_status IS NULL ORDER BY g.id",
                )
                .fetch_all(&self.pool)
                .await?;
                rows.iter().map(|r| Ok(r.try_get("id")?)).collect()
            }

            async fn set_evidence(
                &self,
                diagnosis_id: &str,
                from: &str,
                to: &str,
            ) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE diagnoses SET evidence = $3 WHERE id = $1 AND evidence = $2",
                )
                .bind(diagnosis_id)
                .bind(from)
                .bind(to)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn undrawn_evidence(
                &self,
                prefix: &str,
                before: i64,
                limit: i64,
            ) -> StoreResult<Vec<DiagnosisRow>> {
                let rows = sqlx::query(
                    "SELECT d.* FROM records r JOIN diagnoses d \
                     ON d.machine_id = r.machine_id AND d.record_id = r.id \
                     WHERE r.received_at < $1 AND r.samples IS NOT NULL \
                     AND d.evidence LIKE $2 ORDER BY d.seq LIMIT $3",
                )
                .bind(before)
                .bind(format!("{prefix}%"))
                .bind(limit)
                .fetch_all(&self.pool)
                .await?;
                rows.iter().map(|r| diagnosis_row(r, true)).collect()
            }

            async fn stored_record(&self, record_id: &str) -> StoreResult<Option<NewRecord>> {
                let r = sqlx::query("SELECT * FROM records WHERE id = $1")
                    .bind(record_id)
                    .fetch_optional(&self.pool)
                    .await?;
                let Some(r) = r else {
                    return Ok(None);
                };
                Ok(Some(NewRecord {
                    id: r.try_get("id")?,
                    machine_id: r.try_get("machine_id")?,
                    received_at: r.try_get("received_at")?,
                    recorded_at: r.try_get("recorded_at")?,
                    measured_at: r
                        .try_get::<Option<i64>, _>("measured_at")?
                        .unwrap_or(r.try_get("received_at")?),
                    sensor: r.try_get("sensor")?,
                    content_type: r.try_get("content_type")?,
                    sample_rate_hz: r.try_get("sample_rate_hz")?,
                    shaft_hz: r.try_get("shaft_hz")?,
                    sample_count: r.try_get("sample_count")?,
                    sha256: String::new(),
                    features: r.try_get("features")?,
                    samples: r.try_get("samples")?,
                    baseline: r.try_get::<i64, _>("baseline")? != 0,
                    channels: r
                        .try_get::<Option<String>, _>("channels")?
                        .and_then(|c| serde_json::from_str(&c).ok()),
                }))
            }
        }
    };
}
pub(crate) use diagnoses_sql;
