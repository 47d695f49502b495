//! A machine's own model: its physics fitted to its baseline records and its own table, one
//! row per machine for the baseline and gearbox description it was made from, computed by a
//! background job claimed by one replica at a time (like a gearbox's table job).

use async_trait::async_trait;

use super::StoreResult;

/// What a machine's own model is made from: a change of any of them queues it again.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PhysicsKey {
    pub machine_id: String,
    /// The machine row's creation time (a machine deleted and made again starts over).
    pub machine_created_at: i64,
    pub gearbox_id: String,
    pub gearbox_hash: String,
    pub baseline_version: i64,
}

/// A machine's own-model job and its result (without the table itself).
#[derive(Debug, Clone)]
pub struct PhysicsRow {
    pub key: PhysicsKey,
    /// `queued`, `running`, `ready`, `refused` or `failed`.
    pub status: String,
    /// 0–1 while running.
    pub progress: f64,
    /// Why the fit was refused, or why the job failed.
    pub error: Option<String>,
    /// The fitted physics (JSON), once fitted.
    pub report: Option<String>,
    pub claimed_by: Option<String>,
    pub lease_until: i64,
    pub attempts: i64,
    pub created_at: i64,
    pub updated_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
}

/// How an own-model job ended.
#[derive(Debug, Clone)]
pub enum PhysicsOutcome {
    /// The physics (JSON) and the machine's own table (JSON).
    Ready {
        report: String,
        table: String,
    },
    /// The core refused the fit (too few records or speeds, no better than the empirical
    /// calibration): its message.
    Refused(String),
    Failed(String),
}

/// Machines' own models.
#[async_trait]
pub trait PhysicsStore: Send + Sync {
    async fn get_machine_physics(&self, machine_id: &str) -> StoreResult<Option<PhysicsRow>>;
    /// The own table (JSON) of a machine whose model is ready for exactly `key`.
    async fn machine_own_table(&self, key: &PhysicsKey) -> StoreResult<Option<String>>;
    /// Queue the machine's own model for `key`: a new row, or the machine's row reset when it
    /// was made from anything else (its result dropped). `true` when queued; `false` when the
    /// row is for `key` already (whatever its status).
    async fn queue_machine_physics(&self, key: &PhysicsKey, now: i64) -> StoreResult<bool>;
    /// Claim one job for `worker` until `now + lease_ms`: one queued at `settled` or before,
    /// or a running one whose lease ran out. Compare-and-set: one replica wins each.
    async fn claim_machine_physics(
        &self,
        now: i64,
        lease_ms: i64,
        settled: i64,
        worker: &str,
    ) -> StoreResult<Option<PhysicsRow>>;
    /// Progress of a claimed job (and the fitted physics, once fitted), renewing its lease;
    /// `false` when `worker` no longer holds it (the lease ran out, or the machine's baseline
    /// or gearbox changed and the job was queued again).
    async fn machine_physics_progress(
        &self,
        machine_id: &str,
        worker: &str,
        progress: f64,
        report: Option<&str>,
        lease_until: i64,
        now: i64,
    ) -> StoreResult<bool>;
    /// Finish a claimed job; `false` when `worker` no longer holds it (nothing is written).
    async fn finish_machine_physics(
        &self,
        machine_id: &str,
        worker: &str,
        outcome: PhysicsOutcome,
        now: i64,
    ) -> StoreResult<bool>;
    /// Give a claimed job back (the replica is stopping): queued again at once.
    async fn release_machine_physics(&self, machine_id: &str, worker: &str) -> StoreResult<bool>;
}

/// The SQL of [`PhysicsStore`] for one backend, as the other resources' macros.
macro_rules! physics_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::physics::{PhysicsKey, PhysicsOutcome, PhysicsRow};
        use $crate::*;

        const COLS: &str = "machine_id, machine_created_at, gearbox_id, gearbox_hash, \
            baseline_version, status, progress, error, report, claimed_by, lease_until, \
            attempts, created_at, updated_at, started_at, finished_at";

        fn physics_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<PhysicsRow> {
            Ok(PhysicsRow {
                key: PhysicsKey {
                    machine_id: r.try_get("machine_id")?,
                    machine_created_at: r.try_get("machine_created_at")?,
                    gearbox_id: r.try_get("gearbox_id")?,
                    gearbox_hash: r.try_get("gearbox_hash")?,
                    baseline_version: r.try_get("baseline_version")?,
                },
                status: r.try_get("status")?,
                progress: r.try_get("progress")?,
                error: r.try_get("error")?,
                report: r.try_get("report")?,
                claimed_by: r.try_get("claimed_by")?,
                lease_until: r.try_get("lease_until")?,
                attempts: r.try_get("attempts")?,
                created_at: r.try_get("created_at")?,
                updated_at: r.try_get("updated_at")?,
                started_at: r.try_get("started_at")?,
                finished_at: r.try_get("finished_at")?,
            })
        }

        #[async_trait::async_trait]
        impl $crate::PhysicsStore for $store {
            async fn get_machine_physics(
                &self,
                machine_id: &str,
            ) -> StoreResult<Option<PhysicsRow>> {
                let r = sqlx::query(sqlx::AssertSqlSafe(format!(
                    "SELECT {COLS} FROM machine_physics WHERE machine_id = $1"
                )))
                .bind(machine_id)
                .fetch_optional(&self.pool)
                .await?;
                r.as_ref().map(physics_row).transpose()
            }

            async fn machine_own_table(&self, k: &PhysicsKey) -> StoreResult<Option<String>> {
                let r = sqlx::query(
                    "SELECT own_table FROM machine_physics WHERE machine_id = $1 \
                     AND machine_created_at = $2 AND gearbox_id = $3 AND gearbox_hash = $4 \
                     AND baseline_version = $5 AND status = 'ready'",
                )
                .bind(&k.machine_id)
                .bind(k.machine_created_at)
                .bind(&k.gearbox_id)
                .bind(&k.gearbox_hash)
                .bind(k.baseline_version)
                .fetch_optional(&self.pool)
                .await?;
                Ok(match r {
                    Some(r) => r.try_get("own_table")?,
                    None => None,
                })
            }

            async fn queue_machine_physics(&self, k: &PhysicsKey, now: i64) -> StoreResult<bool> {
                let r = sqlx::query(
                    "INSERT INTO machine_physics (machine_id, machine_created_at, gearbox_id, \
                     gearbox_hash, baseline_version, status, progress, created_at, updated_at) \
                     VALUES ($1, $2, $3, $4, $5, 'queued', 0, $6, $6) \
                     ON CONFLICT (machine_id) DO UPDATE SET \
                     machine_created_at = excluded.machine_created_at, \
                     gearbox_id = excluded.gearbox_id, gearbox_hash = excluded.gearbox_hash, \
                     baseline_version = excluded.baseline_version, status = 'queued', \
                     progress = 0, error = NULL, report = NULL, own_table = NULL, \
                     claimed_by = NULL, lease_until = 0, attempts = 0, \
                     created_at = excluded.created_at, updated_at = excluded.updated_at, \
                     started_at = NULL, finished_at = NULL \
                     WHERE machine_physics.machine_created_at <> excluded.machine_created_at \
                     OR machine_physics.gearbox_id <> excluded.gearbox_id \
                     OR machine_physics.gearbox_hash <> excluded.gearbox_hash \
                     OR machine_physics.baseline_version <> excluded.baseline_version",
                )
                .bind(&k.machine_id)
                .bind(k.machine_created_at)
                .bind(&k.gearbox_id)
                .bind(&k.gearbox_hash)
                .bind(k.baseline_version)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn claim_machine_physics(
                &self,
                now: i64,
                lease_ms: i64,
                settled: i64,
                worker: &str,
            ) -> StoreResult<Option<PhysicsRow>> {
                let due = sqlx::query(
                    "SELECT machine_id, baseline_version FROM machine_physics \
                     WHERE (status = 'queued' AND updated_at <= $2) \
                     OR (status = 'running' AND lease_until < $1) \
                     ORDER BY updated_at, machine_id LIMIT 4",
                )
                .bind(now)
                .bind(settled)
                .fetch_all(&self.pool)
                .await?;
                for r in due {
                    let id: String = r.try_get("machine_id")?;
                    let version: i64 = r.try_get("baseline_version")?;
                    let c = sqlx::query(
                        "UPDATE machine_physics SET status = 'running', claimed_by = $3, \
                         lease_until = $4, attempts = attempts + 1, updated_at = $2, \
                         started_at = COALESCE(started_at, $2) \
                         WHERE machine_id = $1 AND baseline_version = $5 \
                         AND (status = 'queued' OR (status = 'running' AND lease_until < $2))",
                    )
                    .bind(&id)
                    .bind(now)
                    .bind(worker)
                    .bind(now + lease_ms)
                    .bind(version)
                    .execute(&self.pool)
                    .await?;
                    if c.rows_affected() == 1 {
                        return self.get_machine_physics(&id).await;
                    }
                }
                Ok(None)
            }

            async fn machine_physics_progress(
                &self,
                machine_id: &str,
                worker: &str,
                progress: f64,
                report: Option<&str>,
                lease_until: i64,
                now: i64,
            ) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE machine_physics SET progress = $3, report = COALESCE($4, report), \
                     lease_until = $5, updated_at = $6 \
                     WHERE machine_id = $1 AND claimed_by = $2 AND status = 'running'",
                )
                .bind(machine_id)
                .bind(worker)
                .bind(progress)
                .bind(report)
                .bind(lease_until)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn finish_machine_physics(
                &self,
                machine_id: &str,
                worker: &str,
                outcome: PhysicsOutcome,
                now: i64,
            ) -> StoreResult<bool> {
                let (status, report, table, error, progress) = match outcome {
                    PhysicsOutcome::Ready { report, table } => {
                        ("ready", Some(report), Some(table), None, 1.0)
                    }
                    PhysicsOutcome::Refused(e) => ("refused", None, None, Some(e), 1.0),
                    PhysicsOutcome::Failed(e) => ("failed", None, None, Some(e), 0.0),
                };
                let r = sqlx::query(
                    "UPDATE machine_physics SET status = $3, report = COALESCE($4, report), \
                     own_table = $5, error = $6, progress = $7, finished_at = $8, \
                     updated_at = $8, lease_until = 0 \
                     WHERE machine_id = $1 AND claimed_by = $2 AND status = 'running'",
                )
                .bind(machine_id)
                .bind(worker)
                .bind(status)
                .bind(report)
                .bind(table)
                .bind(error)
                .bind(progress)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn release_machine_physics(
                &self,
                machine_id: &str,
                worker: &str,
            ) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE machine_physics SET status = 'queued', claimed_by = NULL, \
                     lease_until = 0 \
                     WHERE machine_id = $1 AND claimed_by = $2 AND status = 'running'",
                )
                .bind(machine_id)
                .bind(worker)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }
        }
    };
}
pub(crate) use physics_sql;
