//! Baselines: the records of a machine marked healthy, and their features.

use async_trait::async_trait;

use super::StoreResult;

/// A baseline record's stored features.
#[derive(Debug, Clone)]
pub struct BaselineRecord {
    pub id: String,
    pub received_at: i64,
    /// When it was measured (its `recorded_at`, else its receive time), unix ms.
    pub measured_at: i64,
    pub baseline_at: Option<i64>,
    /// The record's features JSON (as stored with it).
    pub features: String,
}

/// Baseline records.
#[async_trait]
pub trait BaselineStore: Send + Sync {
    /// Mark (or unmark) records of one machine as baseline; how many changed. Ids of other
    /// machines' records are ignored.
    async fn set_baseline(
        &self,
        machine_id: &str,
        record_ids: &[String],
        baseline: bool,
        now: i64,
    ) -> StoreResult<u64>;
    /// Unmark every baseline record of a machine; how many.
    async fn clear_baseline(&self, machine_id: &str) -> StoreResult<u64>;
    /// The machine's baseline records with their features, oldest first.
    async fn baseline_records(&self, machine_id: &str) -> StoreResult<Vec<BaselineRecord>>;
    /// Which of these record ids belong to the machine.
    async fn machine_record_ids(
        &self,
        machine_id: &str,
        record_ids: &[String],
    ) -> StoreResult<Vec<String>>;
}

/// The SQL of [`BaselineStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! baselines_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::*;

        /// Raise the machine's `baseline_version` (its baseline changed in this transaction).
        async fn bump_version(
            tx: &mut sqlx::Transaction<'_, $db>,
            machine_id: &str,
        ) -> StoreResult<()> {
            sqlx::query(
                "UPDATE machines SET baseline_version = baseline_version + 1 WHERE id = $1",
            )
            .bind(machine_id)
            .execute(&mut **tx)
            .await?;
            Ok(())
        }

        #[async_trait::async_trait]
        impl $crate::BaselineStore for $store {
            async fn set_baseline(
                &self,
                machine_id: &str,
                record_ids: &[String],
                baseline: bool,
                now: i64,
            ) -> StoreResult<u64> {
                let mut tx = self.pool.begin().await?;
                let mut n = 0;
                for id in record_ids {
                    let r = sqlx::query(
                        "UPDATE records SET baseline = $3, baseline_at = $4 \
                         WHERE id = $1 AND machine_id = $2 AND baseline <> $3",
                    )
                    .bind(id)
                    .bind(machine_id)
                    .bind(baseline as i64)
                    .bind(baseline.then_some(now))
                    .execute(&mut *tx)
                    .await?;
                    n += r.rows_affected();
                }
                if n > 0 {
                    bump_version(&mut tx, machine_id).await?;
                }
                tx.commit().await?;
                Ok(n)
            }

            async fn clear_baseline(&self, machine_id: &str) -> StoreResult<u64> {
                let mut tx = self.pool.begin().await?;
                let r = sqlx::query(
                    "UPDATE records SET baseline = 0, baseline_at = NULL \
                     WHERE machine_id = $1 AND baseline = 1",
                )
                .bind(machine_id)
                .execute(&mut *tx)
                .await?;
                if r.rows_affected() > 0 {
                    bump_version(&mut tx, machine_id).await?;
                }
                tx.commit().await?;
                Ok(r.rows_affected())
            }

            async fn baseline_records(&self, machine_id: &str) -> StoreResult<Vec<BaselineRecord>> {
                let rows = sqlx::query(
                    "SELECT id, received_at, measured_at, baseline_at, features FROM records \
                     WHERE machine_id = $1 AND baseline = 1 ORDER BY measured_at, id",
                )
                .bind(machine_id)
                .fetch_all(&self.pool)
                .await?;
                rows.iter()
                    .map(|r| -> StoreResult<BaselineRecord> {
                        let received_at: i64 = r.try_get("received_at")?;
                        Ok(BaselineRecord {
                            id: r.try_get("id")?,
                            received_at,
                            measured_at: r
                                .try_get::<Option<i64>, _>("measured_at")?
                                .unwrap_or(received_at),
                            baseline_at: r.try_get("baseline_at")?,
                            features: r.try_get("features")?,
                        })
                    })
                    .collect()
            }

            async fn machine_record_ids(
                &self,
                machine_id: &str,
                record_ids: &[String],
            ) -> StoreResult<Vec<String>> {
                let mut out = Vec::new();
                for id in record_ids {
                    let r = sqlx::query("SELECT id FROM records WHERE id = $1 AND machine_id = $2")
                        .bind(id)
                        .bind(machine_id)
                        .fetch_optional(&self.pool)
                        .await?;
                    if let Some(r) = r {
                        out.push(r.try_get("id")?);
                    }
                }
                Ok(out)
            }
        }
    };
}
pub(crate) use baselines_sql;
