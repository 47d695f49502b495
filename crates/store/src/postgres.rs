//! The PostgreSQL backend, for several replicas sharing one store.

use std::time::Duration;

use sqlx::postgres::PgPoolOptions;

/// [`Store`](super::Store) on a PostgreSQL database.
pub struct PgStore {
    pool: sqlx::PgPool,
}

impl PgStore {
    /// Connect to `url` (`postgres://user@host:port/db`) and run the migrations.
    pub async fn connect(url: &str) -> super::StoreResult<Self> {
        let pool = PgPoolOptions::new()
            .max_connections(16)
            .acquire_timeout(Duration::from_secs(5))
            .connect(url)
            .await?;
        sqlx::migrate!("../../migrations/postgres")
            .run(&pool)
            .await?;
        Ok(PgStore { pool })
    }
}

#[async_trait::async_trait]
impl super::Store for PgStore {
    fn kind(&self) -> &'static str {
        "postgres"
    }

    async fn ping(&self) -> super::StoreResult<()> {
        sqlx::query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }

    async fn close(&self) {
        self.pool.close().await;
    }
}

// The SQL of each resource on this backend, one module each.
mod keys {
    crate::keys::keys_sql!(PgStore, sqlx::Postgres);
}
mod ingest {
    crate::ingest::ingest_sql!(PgStore, sqlx::Postgres);
}
mod diagnoses {
    crate::diagnoses::diagnoses_sql!(PgStore, sqlx::Postgres);
}
mod machines {
    crate::machines::machines_sql!(PgStore, sqlx::Postgres);
}
mod webhooks {
    crate::webhooks::webhooks_sql!(PgStore, sqlx::Postgres);
}
mod retention {
    crate::retention::retention_sql!(PgStore, sqlx::Postgres);
}
mod calibration {
    crate::calibration::calibration_sql!(PgStore, sqlx::Postgres);
}
mod gearboxes {
    crate::gearboxes::gearboxes_sql!(PgStore, sqlx::Postgres);
}
mod baselines {
    crate::baselines::baselines_sql!(PgStore, sqlx::Postgres);
}
