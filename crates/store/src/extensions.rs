//! What a gearbox's table must cover and its extensions: the speeds its machines are
//! configured for and the speeds records ran at outside it (the demand), and the job that
//! extends a ready table to new columns — claimed by one replica at a time, like the table
//! job itself, while the table stays ready and in use.

use async_trait::async_trait;

use super::StoreResult;
use super::gearboxes::{GearboxRow, TableText};

/// A machine's configured speeds, as its gearbox's table demand reads them.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfiguredSpeeds {
    pub machine_id: String,
    /// Its nominal input-shaft rate (Hz).
    pub input_shaft_hz: Option<f64>,
    /// Its declared range of input-shaft rates (Hz).
    pub speed_range_hz: Option<(f64, f64)>,
}

/// A record's input-shaft rate outside its gearbox's table, written with the record
/// ([`crate::Ingest::table_speed`]) or by a re-read.
#[derive(Debug, Clone, PartialEq)]
pub struct TableSpeed {
    pub gearbox_id: String,
    /// The description's hash.
    pub hash: String,
    /// Hz, rounded to 0.01 when stored.
    pub input_hz: f64,
    pub machine_id: String,
}

/// The demand of gearboxes' tables and their extensions.
#[async_trait]
pub trait TableExtensionStore: Send + Sync {
    /// The configured speeds of every machine whose gearbox is `gearbox_id`.
    async fn configured_speeds(&self, gearbox_id: &str) -> StoreResult<Vec<ConfiguredSpeeds>>;
    /// The input-shaft rates (Hz) records ran at outside the table of description `hash`.
    async fn table_speeds(&self, gearbox_id: &str, hash: &str) -> StoreResult<Vec<f64>>;
    /// Store a measured speed (a repeat is kept once) and queue an extension of the table
    /// when it is ready and none is pending (see [`TableExtensionStore::request_extension`]).
    async fn add_table_speed(&self, s: &TableSpeed, now: i64) -> StoreResult<()>;
    /// Queue an extension of the table of description `hash`: only when the table is ready
    /// and no extension is queued or running (a failed one is queued again). `true` when
    /// queued.
    async fn request_extension(&self, id: &str, hash: &str, now: i64) -> StoreResult<bool>;
    /// Claim one extension for `worker` until `now + lease_ms`: a queued one, or a running one
    /// whose lease ran out. Compare-and-set: one replica wins each.
    async fn claim_extension(
        &self,
        now: i64,
        lease_ms: i64,
        worker: &str,
    ) -> StoreResult<Option<GearboxRow>>;
    /// Progress of a claimed extension (and the columns it computes towards, once known),
    /// renewing its lease; `false` when `worker` no longer holds it.
    #[allow(clippy::too_many_arguments)]
    async fn extension_progress(
        &self,
        id: &str,
        hash: &str,
        worker: &str,
        progress: f64,
        columns: Option<&[f64]>,
        lease_until: i64,
        now: i64,
    ) -> StoreResult<bool>;
    /// Finish a claimed extension: `Ok(Some(table))` replaces the stored table, `Ok(None)`
    /// keeps it (it covers the demand already) — either way no extension is pending any more;
    /// `Err(reason)` leaves the table as it was with the extension `failed`. `false` when
    /// `worker` no longer holds it (nothing is written).
    async fn finish_extension(
        &self,
        id: &str,
        hash: &str,
        worker: &str,
        result: Result<Option<TableText>, String>,
        now: i64,
    ) -> StoreResult<bool>;
    /// Give a claimed extension back (the replica is stopping): queued again at once.
    async fn release_extension(&self, id: &str, hash: &str, worker: &str) -> StoreResult<bool>;
}

/// The SQL of [`TableExtensionStore`] for one backend, as the other resources' macros.
macro_rules! extensions_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use super::gearboxes::{GEARBOX_COLS, gearbox_row};
        use sqlx::Row;
        use $crate::extensions::{ConfiguredSpeeds, TableSpeed};
        use $crate::*;

        /// [`TableExtensionStore::add_table_speed`] inside the caller's transaction.
        pub(crate) async fn add_table_speed_in(
            tx: &mut sqlx::Transaction<'_, $db>,
            s: &TableSpeed,
            now: i64,
        ) -> StoreResult<()> {
            sqlx::query(
                "INSERT INTO table_speeds (gearbox_id, hash, input_hz, machine_id, created_at) \
                 VALUES ($1, $2, $3, $4, $5) ON CONFLICT (gearbox_id, hash, input_hz) DO NOTHING",
            )
            .bind(&s.gearbox_id)
            .bind(&s.hash)
            .bind((s.input_hz * 100.0).round() / 100.0)
            .bind(&s.machine_id)
            .bind(now)
            .execute(&mut **tx)
            .await?;
            request_in(&mut **tx, &s.gearbox_id, &s.hash, now).await?;
            Ok(())
        }

        async fn request_in(
            c: &mut <$db as sqlx::Database>::Connection,
            id: &str,
            hash: &str,
            now: i64,
        ) -> StoreResult<bool> {
            let r = sqlx::query(
                "UPDATE gearboxes SET extension_status = 'queued', extension_error = NULL, \
                 extension_progress = 0, extension_claimed_by = NULL, \
                 extension_lease_until = 0, extension_columns = NULL, \
                 extension_queued_at = $3 \
                 WHERE id = $1 AND hash = $2 AND builtin = 0 AND status = 'ready' \
                 AND (extension_status IS NULL OR extension_status = 'failed')",
            )
            .bind(id)
            .bind(hash)
            .bind(now)
            .execute(&mut *c)
            .await?;
            Ok(r.rows_affected() == 1)
        }

        #[async_trait::async_trait]
        impl $crate::TableExtensionStore for $store {
            async fn configured_speeds(
                &self,
                gearbox_id: &str,
            ) -> StoreResult<Vec<ConfiguredSpeeds>> {
                let rows = sqlx::query(
                    "SELECT id, input_shaft_hz, speed_lo_hz, speed_hi_hz FROM machines \
                     WHERE gearbox_id = $1 ORDER BY id",
                )
                .bind(gearbox_id)
                .fetch_all(&self.pool)
                .await?;
                rows.iter()
                    .map(|r| {
                        let lo: Option<f64> = r.try_get("speed_lo_hz")?;
                        let hi: Option<f64> = r.try_get("speed_hi_hz")?;
                        Ok(ConfiguredSpeeds {
                            machine_id: r.try_get("id")?,
                            input_shaft_hz: r.try_get("input_shaft_hz")?,
                            speed_range_hz: lo.zip(hi),
                        })
                    })
                    .collect()
            }

            async fn table_speeds(&self, gearbox_id: &str, hash: &str) -> StoreResult<Vec<f64>> {
                let rows = sqlx::query(
                    "SELECT input_hz FROM table_speeds WHERE gearbox_id = $1 AND hash = $2 \
                     ORDER BY input_hz",
                )
                .bind(gearbox_id)
                .bind(hash)
                .fetch_all(&self.pool)
                .await?;
                rows.iter()
                    .map(|r| Ok(r.try_get("input_hz")?))
                    .collect()
            }

            async fn add_table_speed(&self, s: &TableSpeed, now: i64) -> StoreResult<()> {
                let mut tx = self.pool.begin().await?;
                add_table_speed_in(&mut tx, s, now).await?;
                tx.commit().await?;
                Ok(())
            }

            async fn request_extension(
                &self,
                id: &str,
                hash: &str,
                now: i64,
            ) -> StoreResult<bool> {
                let mut c = self.pool.acquire().await?;
                request_in(&mut c, id, hash, now).await
            }

            async fn claim_extension(
                &self,
                now: i64,
                lease_ms: i64,
                worker: &str,
            ) -> StoreResult<Option<GearboxRow>> {
                let due = sqlx::query(
                    "SELECT id, hash FROM gearboxes WHERE builtin = 0 AND status = 'ready' \
                     AND (extension_status = 'queued' OR (extension_status = 'running' \
                     AND extension_lease_until < $1)) \
                     ORDER BY extension_queued_at, id LIMIT 4",
                )
                .bind(now)
                .fetch_all(&self.pool)
                .await?;
                for r in due {
                    let id: String = r.try_get("id")?;
                    let hash: String = r.try_get("hash")?;
                    // Compare-and-set: only one replica wins each extension.
                    let c = sqlx::query(
                        "UPDATE gearboxes SET extension_status = 'running', \
                         extension_claimed_by = $3, extension_lease_until = $4, \
                         extension_attempts = extension_attempts + 1 \
                         WHERE id = $1 AND hash = $5 AND builtin = 0 AND status = 'ready' \
                         AND (extension_status = 'queued' OR (extension_status = 'running' \
                         AND extension_lease_until < $2))",
                    )
                    .bind(&id)
                    .bind(now)
                    .bind(worker)
                    .bind(now + lease_ms)
                    .bind(&hash)
                    .execute(&self.pool)
                    .await?;
                    if c.rows_affected() == 1 {
                        let r = sqlx::query(sqlx::AssertSqlSafe(format!(
                            "SELECT {GEARBOX_COLS} FROM gearboxes WHERE id = $1"
                        )))
                        .bind(&id)
                        .fetch_optional(&self.pool)
                        .await?;
                        return r.as_ref().map(gearbox_row).transpose();
                    }
                }
                Ok(None)
            }

            #[allow(clippy::too_many_arguments)]
            async fn extension_progress(
                &self,
                id: &str,
                hash: &str,
                worker: &str,
                progress: f64,
                columns: Option<&[f64]>,
                lease_until: i64,
                now: i64,
            ) -> StoreResult<bool> {
                let cols = columns.map(|c| serde_json::to_string(c).unwrap_or_default());
                let r = sqlx::query(
                    "UPDATE gearboxes SET extension_progress = $4, extension_lease_until = $5, \
                     extension_columns = COALESCE($6, extension_columns), updated_at = $7 \
                     WHERE id = $1 AND hash = $2 AND extension_claimed_by = $3 \
                     AND extension_status = 'running'",
                )
                .bind(id)
                .bind(hash)
                .bind(worker)
                .bind(progress)
                .bind(lease_until)
                .bind(cols)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn finish_extension(
                &self,
                id: &str,
                hash: &str,
                worker: &str,
                result: Result<Option<TableText>, String>,
                now: i64,
            ) -> StoreResult<bool> {
                let held = "WHERE id = $1 AND hash = $2 AND extension_claimed_by = $3 \
                            AND extension_status = 'running'";
                let r = match result {
                    Ok(None) => {
                        sqlx::query(sqlx::AssertSqlSafe(format!(
                            "UPDATE gearboxes SET extension_status = NULL, \
                             extension_progress = 0, extension_error = NULL, \
                             extension_claimed_by = NULL, extension_lease_until = 0, \
                             extension_columns = NULL, extension_attempts = 0, \
                             updated_at = $4 {held}"
                        )))
                        .bind(id)
                        .bind(hash)
                        .bind(worker)
                        .bind(now)
                        .execute(&self.pool)
                        .await?
                    }
                    Ok(Some(t)) => {
                        let cols = serde_json::to_string(&t.columns).unwrap_or_default();
                        sqlx::query(sqlx::AssertSqlSafe(format!(
                            "UPDATE gearboxes SET signature_table = $4, table_columns = $5, \
                             extension_status = NULL, extension_progress = 0, \
                             extension_error = NULL, extension_claimed_by = NULL, \
                             extension_lease_until = 0, extension_columns = NULL, \
                             extension_attempts = 0, updated_at = $6, finished_at = $6 {held}"
                        )))
                        .bind(id)
                        .bind(hash)
                        .bind(worker)
                        .bind(t.json)
                        .bind(cols)
                        .bind(now)
                        .execute(&self.pool)
                        .await?
                    }
                    Err(e) => {
                        sqlx::query(sqlx::AssertSqlSafe(format!(
                            "UPDATE gearboxes SET extension_status = 'failed', \
                             extension_error = $4, extension_lease_until = 0, \
                             updated_at = $5 {held}"
                        )))
                        .bind(id)
                        .bind(hash)
                        .bind(worker)
                        .bind(e)
                        .bind(now)
                        .execute(&self.pool)
                        .await?
                    }
                };
                Ok(r.rows_affected() == 1)
            }

            async fn release_extension(
                &self,
                id: &str,
                hash: &str,
                worker: &str,
            ) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE gearboxes SET extension_status = 'queued', \
                     extension_claimed_by = NULL, extension_lease_until = 0 \
                     WHERE id = $1 AND hash = $2 AND extension_claimed_by = $3 \
                     AND extension_status = 'running'",
                )
                .bind(id)
                .bind(hash)
                .bind(worker)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }
        }
    };
}
pub(crate) use extensions_sql;
