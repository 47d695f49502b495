//! Machines: their configuration (`PUT /v1/machines/{id}`), latest state and deletion.

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
    pub alert_level: gearwear_core::assessment::Level,
    /// Raised with every change of its baseline records (migration 0009): fitted baselines
    /// are kept by this number.
    pub baseline_version: i64,
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
    /// When it was first configured (`PUT /v1/machines/{id}`); `None`: it exists only
    /// because records were posted for it.
    pub registered_at: Option<i64>,
    /// What its channels measure: the JSON object of `channel_units` as checked and written
    /// by the service; `None`: unitless.
    pub channel_units: Option<String>,
    /// Its ISO 20816-3 group (1 or 2) and support (`rigid` or `flexible`), both or neither.
    pub iso_group: Option<i64>,
    pub iso_support: Option<String>,
    /// Its declared range of input-shaft rates `(lo, hi)` Hz: part of what its gearbox's
    /// table must cover.
    pub speed_range_hz: Option<(f64, f64)>,
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
    /// `channel_units` as JSON (checked by the caller).
    pub channel_units: Option<String>,
    pub iso_group: Option<i64>,
    pub iso_support: Option<String>,
    /// The declared range of input-shaft rates `(lo, hi)` Hz (checked by the caller).
    pub speed_range_hz: Option<(f64, f64)>,
}

/// What [`MachineStore::delete_machine`] took away.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct MachineDeletion {
    pub machine_id: String,
    /// Records (with their raw samples and baseline marks).
    pub records: u64,
    pub diagnoses: u64,
    /// Whether it had a calibration.
    pub calibration: bool,
    /// Stored `Idempotency-Key` answers about its records.
    pub idempotency_answers: u64,
    /// Its alert level before the deletion (`None`: it had only a calibration).
    pub alert_level: Option<gearwear_core::assessment::Level>,
}

/// Machines.
#[async_trait]
pub trait MachineStore: Send + Sync {
    async fn list_machines(&self) -> StoreResult<Vec<MachineRow>>;
    async fn get_machine(&self, id: &str) -> StoreResult<Option<MachineRow>>;
    /// Create or update a machine's configuration; `true` when the machine is new. Either
    /// way the machine is registered from then on (`registered_at`, kept from the first
    /// time).
    async fn put_machine(&self, m: &MachineConfig, now: i64) -> StoreResult<bool>;
    /// Delete a machine and everything of it in one transaction — its diagnoses, records
    /// (raw samples and baseline marks with them), calibration and the stored
    /// `Idempotency-Key` answers about it — and queue a `machine.deleted` event for the
    /// webhooks that subscribe to it. Deliveries already queued about the machine stay and
    /// are still sent. `None` (nothing written) when there was no such machine (no row and no
    /// calibration).
    async fn delete_machine(&self, id: &str, now: i64) -> StoreResult<Option<MachineDeletion>>;
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
                alert_level: $crate::alerts::stored_level(r.try_get("alert_level")?)?,
                baseline_version: r.try_get("baseline_version")?,
                gearbox_id: r.try_get("gearbox_id")?,
                input_shaft_hz: r.try_get("input_shaft_hz")?,
                channels: r
                    .try_get::<Option<String>, _>("channels")?
                    .and_then(|c| serde_json::from_str(&c).ok()),
                tacho_channel: r.try_get("tacho_channel")?,
                tacho_ppr: r.try_get("tacho_ppr")?,
                registered_at: r.try_get("registered_at")?,
                channel_units: r.try_get("channel_units")?,
                iso_group: r.try_get("iso_group")?,
                iso_support: r.try_get("iso_support")?,
                speed_range_hz: r
                    .try_get::<Option<f64>, _>("speed_lo_hz")?
                    .zip(r.try_get::<Option<f64>, _>("speed_hi_hz")?),
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
                     input_shaft_hz, channels, tacho_channel, tacho_ppr, channel_units, \
                     iso_group, iso_support, registered_at, speed_lo_hz, speed_hi_hz) \
                     VALUES ($1, $2, $2, $3, $4, $5, $6, $7, $8, $9, $10, $2, $11, $12) \
                     ON CONFLICT (id) DO NOTHING",
                )
                .bind(&m.id)
                .bind(now)
                .bind(&m.gearbox_id)
                .bind(m.input_shaft_hz)
                .bind(&channels)
                .bind(&m.tacho_channel)
                .bind(m.tacho_ppr)
                .bind(&m.channel_units)
                .bind(m.iso_group)
                .bind(&m.iso_support)
                .bind(m.speed_range_hz.map(|r| r.0))
                .bind(m.speed_range_hz.map(|r| r.1))
                .execute(&mut *tx)
                .await?;
                let created = ins.rows_affected() == 1;
                if !created {
                    sqlx::query(
                        "UPDATE machines SET gearbox_id = $2, input_shaft_hz = $3, \
                         channels = $4, updated_at = $5, tacho_channel = $6, tacho_ppr = $7, \
                         channel_units = $8, iso_group = $9, iso_support = $10, \
                         registered_at = COALESCE(registered_at, $5), speed_lo_hz = $11, \
                         speed_hi_hz = $12 WHERE id = $1",
                    )
                    .bind(&m.id)
                    .bind(&m.gearbox_id)
                    .bind(m.input_shaft_hz)
                    .bind(&channels)
                    .bind(now)
                    .bind(&m.tacho_channel)
                    .bind(m.tacho_ppr)
                    .bind(&m.channel_units)
                    .bind(m.iso_group)
                    .bind(&m.iso_support)
                    .bind(m.speed_range_hz.map(|r| r.0))
                    .bind(m.speed_range_hz.map(|r| r.1))
                    .execute(&mut *tx)
                    .await?;
                }
                tx.commit().await?;
                Ok(created)
            }

            async fn delete_machine(
                &self,
                id: &str,
                now: i64,
            ) -> StoreResult<Option<MachineDeletion>> {
                let mut tx = self.pool.begin().await?;
                // A write first, on the machine's row: SQLite takes its write lock at once,
                // and on PostgreSQL a record being stored for the machine (which locks the
                // same row first) either commits before (its rows are deleted here) or waits
                // and then finds no machine.
                let alert_level = sqlx::query(
                    "UPDATE machines SET updated_at = $2 WHERE id = $1 RETURNING alert_level",
                )
                .bind(id)
                .bind(now)
                .fetch_optional(&mut *tx)
                .await?
                .map(|r| $crate::alerts::stored_level(r.try_get("alert_level")?))
                .transpose()?;
                let deleted = |table_where: &'static str| {
                    let q = sqlx::AssertSqlSafe(format!("DELETE FROM {table_where}"));
                    sqlx::query(q).bind(id.to_string())
                };
                // Children before parents (diagnoses name records, both name the machine).
                let diagnoses = deleted("diagnoses WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                let records = deleted("records WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                let idempotency_answers = deleted("idempotency_keys WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                let calibration = deleted("calibrations WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?
                    .rows_affected()
                    > 0;
                // Its alert episodes, their audit trail and counts go with it.
                deleted(
                    "alert_events WHERE alert_id IN (SELECT id FROM alerts WHERE machine_id = $1)",
                )
                .execute(&mut *tx)
                .await?;
                deleted("alerts WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?;
                deleted("alert_trackers WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?;
                // Its own model (physics and table) too.
                deleted("machine_physics WHERE machine_id = $1")
                    .execute(&mut *tx)
                    .await?;
                deleted("machines WHERE id = $1").execute(&mut *tx).await?;
                if alert_level.is_none() && !calibration {
                    // Nothing was there: nothing to announce (the transaction wrote nothing).
                    tx.rollback().await?;
                    return Ok(None);
                }
                let d = MachineDeletion {
                    machine_id: id.to_string(),
                    records,
                    diagnoses,
                    calibration,
                    idempotency_answers,
                    alert_level,
                };
                let event = $crate::events::QueuedEvent::new(
                    new_id(),
                    $crate::events::Event::MachineDeleted {
                        deletion: d.clone(),
                        deleted_at: now,
                    },
                );
                super::webhooks::queue_events(&mut tx, &[event], now).await?;
                tx.commit().await?;
                Ok(Some(d))
            }
        }
    };
}
pub(crate) use machines_sql;
