//! Machines: their configuration (`PUT /v1/machines/{id}`) and latest state.

use async_trait::async_trait;

use super::StoreResult;

/// A machine and its latest state.
#[derive(Debug, Clone)]
pub struct MachineRow {
    pub id: String,
    pub created_at: i64,
    pub updated_at: i64,
    pub record_count: i64,
    pub last_diagnosis_id: Option<String>,
    pub alert_level: String,
    /// Its gearbox (`gearboxes.id`); `None`: the paper's rig.
    pub gearbox_id: Option<String>,
    /// Nominal input-shaft rate (Hz), a hint for finding the mesh lines.
    pub input_shaft_hz: Option<f64>,
    /// The channel names it records; `None`: whatever a record brings.
    pub channels: Option<Vec<String>>,
    /// The record channel of its tachometer; `None`: a channel named `tacho`, if any.
    pub tacho_channel: Option<String>,
    /// Tachometer pulses per input-shaft revolution (at least 1).
    pub tacho_ppr: i64,
}

/// What `PUT /v1/machines/{id}` sets.
#[derive(Debug, Clone)]
pub struct MachineConfig {
    pub id: String,
    pub gearbox_id: Option<String>,
    pub input_shaft_hz: Option<f64>,
    pub channels: Option<Vec<String>>,
    pub tacho_channel: Option<String>,
    /// Pulses per input-shaft revolution (at least 1).
    pub tacho_ppr: i64,
}

/// Machines.
#[async_trait]
pub trait MachineStore: Send + Sync {
    async fn list_machines(&self) -> StoreResult<Vec<MachineRow>>;
    async fn get_machine(&self, id: &str) -> StoreResult<Option<MachineRow>>;
    /// Create or update a machine's configuration; `true` when the machine is new.
    async fn put_machine(&self, m: &MachineConfig, now: i64) -> StoreResult<bool>;
}

/// The SQL of [`MachineStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! machines_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::*;

        pub(crate) fn machine_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<MachineRow> {
            Ok(MachineRow {
                id: r.try_get("id")?,
                created_at: r.try_get("created_at")?,
                updated_at: r.try_get("updated_at")?,
                record_count: r.try_get("record_count")?,
                last_diagnosis_id: r.try_get("last_diagnosis_id")?,
                alert_level: r.try_get("alert_level")?,
                gearbox_id: r.try_get("gearbox_id")?,
                input_shaft_hz: r.try_get("input_shaft_hz")?,
                channels: r
                    .try_get::<Option<String>, _>("channels")?
                    .and_then(|c| serde_json::from_str(&c).ok()),
                tacho_channel: r.try_get("tacho_channel")?,
                tacho_ppr: r.try_get("tacho_ppr")?,
            })
        }

        #[async_trait::async_trait]
        impl $crate::MachineStore for $store {
            async fn list_machines(&self) -> StoreResult<Vec<MachineRow>> {
                let rows = sqlx::query("SELECT * FROM machines ORDER BY id")
                    .fetch_all(&self.pool)
                    .await?;
                rows.iter().map(machine_row).collect()
            }

            async fn get_machine(&self, id: &str) -> StoreResult<Option<MachineRow>> {
                let r = sqlx::query("SELECT * FROM machines WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(machine_row).transpose()
            }

            async fn put_machine(&self, m: &MachineConfig, now: i64) -> StoreResult<bool> {
                let channels = m
                    .channels
                    .as_ref()
                    .map(|c| serde_json::to_string(c).unwrap_or_default());
                let mut tx = self.pool.begin().await?;
                let ins = sqlx::query(
                    "INSERT INTO machines (id, created_at, updated_at, gearbox_id, \
                     input_shaft_hz, channels, tacho_channel, tacho_ppr) \
                     VALUES ($1, $2, $2, $3, $4, $5, $6, $7) ON CONFLICT (id) DO NOTHING",
                )
                .bind(&m.id)
                .bind(now)
                .bind(&m.gearbox_id)
                .bind(m.input_shaft_hz)
                .bind(&channels)
                .bind(&m.tacho_channel)
                .bind(m.tacho_ppr)
                .execute(&mut *tx)
                .await?;
                let created = ins.rows_affected() == 1;
                if !created {
                    sqlx::query(
                        "UPDATE machines SET gearbox_id = $2, input_shaft_hz = $3, \
                         channels = $4, updated_at = $5, tacho_channel = $6, tacho_ppr = $7 \
                         WHERE id = $1",
                    )
                    .bind(&m.id)
                    .bind(&m.gearbox_id)
                    .bind(m.input_shaft_hz)
                    .bind(&channels)
                    .bind(now)
                    .bind(&m.tacho_channel)
                    .bind(m.tacho_ppr)
                    .execute(&mut *tx)
                    .await?;
                }
                tx.commit().await?;
                Ok(created)
            }
        }
    };
}
pub(crate) use machines_sql;
