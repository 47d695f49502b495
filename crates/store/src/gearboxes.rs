//! Gearbox descriptions and their signature-table jobs (claimed by one replica at a time).

use async_trait::async_trait;
pub use gearwear_core::signature::TableStatus;

use gearwear_core::gearbox::{Gearbox, GearboxDescription, GearboxError, TextFormat};

use super::StoreResult;

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
    pub status: TableStatus,
    /// 0–1 while running.
    pub progress: f64,
    pub error: Option<String>,
    pub claimed_by: Option<String>,
    /// A running job's lease (unix ms); a queued job's earliest claim (0: at once).
    pub lease_until: i64,
    pub attempts: i64,
    pub created_at: i64,
    pub updated_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    /// The Ω1 columns of the stored table (`None` while none is stored, and for the built-in
    /// rig, whose table is the served file).
    pub table_columns: Option<Vec<f64>>,
    /// An extension of the ready table to more columns, when one is pending (or failed).
    pub extension: Option<Extension>,
}

/// A pending extension of a ready table ([`crate::TableExtensionStore`]): a job of its own
/// beside the table, which stays ready and in use meanwhile.
#[derive(Debug, Clone, PartialEq)]
pub struct Extension {
    /// `queued`, `running` or `failed`.
    pub status: TableStatus,
    /// 0–1 while running.
    pub progress: f64,
    pub error: Option<String>,
    pub claimed_by: Option<String>,
    pub lease_until: i64,
    pub attempts: i64,
    /// The columns it computes towards (set when it is claimed).
    pub columns: Option<Vec<f64>>,
    pub queued_at: Option<i64>,
}

/// A computed table as stored: its JSON and its Ω1 columns.
#[derive(Debug, Clone)]
pub struct TableText {
    pub json: String,
    pub columns: Vec<f64>,
}

impl GearboxRow {
    /// The row of a new description (its table `queued`) and the gearbox it resolves to: the
    /// description parsed from `text` (`format`, else JSON when it starts with `{`, else TOML;
    /// `origin` names it in errors) and resolved.
    pub fn described(
        id: &str,
        text: &str,
        format: Option<TextFormat>,
        origin: &str,
    ) -> Result<(GearboxRow, Gearbox), GearboxError> {
        let d = GearboxDescription::parse(text, format, origin)?;
        let fmt = match format {
            Some(TextFormat::Json) => "json",
            Some(TextFormat::Toml) => "toml",
            None if text.trim_start().starts_with('{') => "json",
            None => "toml",
        };
        let gb = Gearbox::new(d)?;
        let now = crate::now_ms();
        let row = GearboxRow {
            id: id.to_string(),
            name: gb.name().to_string(),
            source: text.to_string(),
            source_format: fmt.into(),
            description: gb.description.canonical_json(),
            hash: gb.hash.clone(),
            builtin: false,
            status: TableStatus::Queued,
            progress: 0.0,
            error: None,
            claimed_by: None,
            lease_until: 0,
            attempts: 0,
            created_at: now,
            updated_at: now,
            started_at: None,
            finished_at: None,
            table_columns: None,
            extension: None,
        };
        Ok((row, gb))
    }
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

/// Gearboxes and their table jobs.
#[async_trait]
pub trait GearboxStore: Send + Sync {
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
    /// Claim one table job for `worker` until `now + lease_ms`: a queued one due (its
    /// `lease_until` at `now` or before), or a running one whose lease ran out (its replica
    /// stopped). Compare-and-set: one replica wins each job.
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
    /// Finish a claimed job: `Ok(table)` → `ready`, `Err(reason)` → `failed`. `false`
    /// when `worker` no longer holds it (nothing is written).
    async fn finish_gearbox_job(
        &self,
        id: &str,
        hash: &str,
        worker: &str,
        result: Result<TableText, String>,
        now: i64,
    ) -> StoreResult<bool>;
    /// Give a claimed job back (the replica is stopping): queued again at once, for any
    /// replica, instead of after its lease.
    async fn release_gearbox_job(&self, id: &str, hash: &str, worker: &str) -> StoreResult<bool>;
    /// Make a queued job due at once (what its table must cover changed); `true` when it was
    /// queued.
    async fn expedite_gearbox_job(&self, id: &str) -> StoreResult<bool>;
}

/// The SQL of [`GearboxStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! gearboxes_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::gearboxes::TableStatus;
        use $crate::*;

        pub(crate) const GEARBOX_COLS: &str = "id, name, source, source_format, description, \
            hash, builtin, status, progress, error, claimed_by, lease_until, attempts, \
            created_at, updated_at, started_at, finished_at, table_columns, extension_status, \
            extension_progress, extension_error, extension_claimed_by, extension_lease_until, \
            extension_attempts, extension_columns, extension_queued_at";

        fn status(text: String) -> StoreResult<TableStatus> {
            text.parse()
                .map_err(|e: gearwear_core::words::UnknownWord| StoreError::Decode(e.to_string()))
        }

        /// A JSON array of columns as stored.
        fn columns(text: Option<String>) -> StoreResult<Option<Vec<f64>>> {
            text.map(|t| {
                serde_json::from_str(&t)
                    .map_err(|e| StoreError::Decode(format!("table columns: {e}")))
            })
            .transpose()
        }

        pub(crate) fn gearbox_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<GearboxRow> {
            let extension = match r.try_get::<Option<String>, _>("extension_status")? {
                None => None,
                Some(s) => Some($crate::gearboxes::Extension {
                    status: status(s)?,
                    progress: r.try_get("extension_progress")?,
                    error: r.try_get("extension_error")?,
                    claimed_by: r.try_get("extension_claimed_by")?,
                    lease_until: r.try_get("extension_lease_until")?,
                    attempts: r.try_get("extension_attempts")?,
                    columns: columns(r.try_get("extension_columns")?)?,
                    queued_at: r.try_get("extension_queued_at")?,
                }),
            };
            Ok(GearboxRow {
                id: r.try_get("id")?,
                name: r.try_get("name")?,
                source: r.try_get("source")?,
                source_format: r.try_get("source_format")?,
                description: r.try_get("description")?,
                hash: r.try_get("hash")?,
                builtin: r.try_get::<i64, _>("builtin")? != 0,
                status: status(r.try_get("status")?)?,
                progress: r.try_get("progress")?,
                error: r.try_get("error")?,
                claimed_by: r.try_get("claimed_by")?,
                lease_until: r.try_get("lease_until")?,
                attempts: r.try_get("attempts")?,
                created_at: r.try_get("created_at")?,
                updated_at: r.try_get("updated_at")?,
                started_at: r.try_get("started_at")?,
                finished_at: r.try_get("finished_at")?,
                table_columns: columns(r.try_get("table_columns")?)?,
                extension,
            })
        }

        #[async_trait::async_trait]
        impl $crate::GearboxStore for $store {
            async fn put_gearbox(&self, g: &GearboxRow) -> StoreResult<PutOutcome> {
                let mut tx = self.pool.begin().await?;
                // A write first (SQLite takes its write lock at once).
                let ins = sqlx::query(
                    "INSERT INTO gearboxes (id, name, source, source_format, description, hash, \
                     builtin, status, progress, created_at, updated_at, lease_until) \
                     VALUES ($1, $2, $3, $4, $5, $6, 0, 'queued', 0, $7, $7, $8) \
                     ON CONFLICT (id) DO NOTHING",
                )
                .bind(&g.id)
                .bind(&g.name)
                .bind(&g.source)
                .bind(&g.source_format)
                .bind(&g.description)
                .bind(&g.hash)
                .bind(g.created_at)
                .bind(g.lease_until)
                .execute(&mut *tx)
                .await?;
                let outcome = if ins.rows_affected() == 1 {
                    PutOutcome::Created
                } else {
                    let upd = sqlx::query(
                        "UPDATE gearboxes SET name = $2, source = $3, source_format = $4, \
                         description = $5, hash = $6, status = 'queued', progress = 0, \
                         error = NULL, claimed_by = NULL, lease_until = $8, attempts = 0, \
                         signature_table = NULL, updated_at = $7, started_at = NULL, \
                         finished_at = NULL, table_columns = NULL, extension_status = NULL, \
                         extension_progress = 0, extension_error = NULL, \
                         extension_claimed_by = NULL, extension_lease_until = 0, \
                         extension_attempts = 0, extension_columns = NULL, \
                         extension_queued_at = NULL \
                         WHERE id = $1 AND hash <> $6 AND builtin = 0",
                    )
                    .bind(&g.id)
                    .bind(&g.name)
                    .bind(&g.source)
                    .bind(&g.source_format)
                    .bind(&g.description)
                    .bind(&g.hash)
                    .bind(g.created_at)
                    .bind(g.lease_until)
                    .execute(&mut *tx)
                    .await?;
                    if upd.rows_affected() == 1 {
                        // The speeds measured against the old description go with it.
                        sqlx::query("DELETE FROM table_speeds WHERE gearbox_id = $1 AND hash <> $2")
                            .bind(&g.id)
                            .bind(&g.hash)
                            .execute(&mut *tx)
                            .await?;
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
                    "SELECT id, hash FROM gearboxes WHERE builtin = 0 AND \
                     ((status = 'queued' AND lease_until <= $1) \
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
                         WHERE id = $1 AND hash = $5 AND builtin = 0 AND \
                         ((status = 'queued' AND lease_until <= $2) \
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
                result: Result<TableText, String>,
                now: i64,
            ) -> StoreResult<bool> {
                let (status, table, cols, error, progress) = match result {
                    Ok(t) => (
                        TableStatus::Ready,
                        Some(t.json),
                        Some(serde_json::to_string(&t.columns).unwrap_or_default()),
                        None,
                        1.0,
                    ),
                    Err(e) => (TableStatus::Failed, None, None, Some(e), 0.0),
                };
                let r = sqlx::query(
                    "UPDATE gearboxes SET status = $4, signature_table = $5, error = $6, \
                     progress = $7, finished_at = $8, updated_at = $8, lease_until = 0, \
                     table_columns = $9 \
                     WHERE id = $1 AND hash = $2 AND claimed_by = $3 AND status = 'running'",
                )
                .bind(id)
                .bind(hash)
                .bind(worker)
                .bind(status.as_str())
                .bind(table)
                .bind(error)
                .bind(progress)
                .bind(now)
                .bind(cols)
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

            async fn expedite_gearbox_job(&self, id: &str) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE gearboxes SET lease_until = 0 \
                     WHERE id = $1 AND status = 'queued' AND builtin = 0",
                )
                .bind(id)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }
        }
    };
}
pub(crate) use gearboxes_sql;
