//! A machine's current calibration (`calibrations` table).

use async_trait::async_trait;

use super::StoreResult;

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

/// Calibrations, one per machine.
#[async_trait]
pub trait CalibrationStore: Send + Sync {
    /// Store a machine's calibration, replacing the one it had.
    async fn put_calibration(&self, c: &CalibrationRow) -> StoreResult<()>;
    async fn get_calibration(&self, machine_id: &str) -> StoreResult<Option<CalibrationRow>>;
    /// Clear it; `false` if the machine had none.
    async fn delete_calibration(&self, machine_id: &str) -> StoreResult<bool>;
}

/// The SQL of [`CalibrationStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! calibration_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::*;

        #[async_trait::async_trait]
        impl $crate::CalibrationStore for $store {
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
        }
    };
}
pub(crate) use calibration_sql;
