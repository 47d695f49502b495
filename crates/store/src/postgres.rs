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

crate::backend!(PgStore, sqlx::Postgres, "postgres");
