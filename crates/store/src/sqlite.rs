//! The SQLite backend: one file, WAL journal, `synchronous = FULL`, foreign keys on.

use std::str::FromStr;
use std::time::Duration;

use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

/// [`Store`](super::Store) on a SQLite file.
pub struct SqliteStore {
    pool: sqlx::SqlitePool,
}

impl SqliteStore {
    /// Open (creating if missing) the file at `path` and run the migrations.
    pub async fn connect(path: &str) -> super::StoreResult<Self> {
        let opts = SqliteConnectOptions::from_str("sqlite://")?
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .busy_timeout(Duration::from_secs(10))
            .foreign_keys(true);
        // No ping before handing out a connection (sqlx's default): a SQLite connection is a
        // file handle in this process and does not go stale, and the ping is a round trip to the
        // connection's worker thread on every query (≈ 0.025 ms of server CPU measured on one
        // authenticated request: 0.225 ms with the ping, 0.200 without; ≈ 15 queries a record).
        let pool = SqlitePoolOptions::new()
            .test_before_acquire(false)
            .max_connections(8)
            .acquire_timeout(Duration::from_secs(10))
            .connect_with(opts)
            .await?;
        sqlx::migrate!("../../migrations/sqlite").run(&pool).await?;
        Ok(SqliteStore { pool })
    }
}

crate::backend!(SqliteStore, sqlx::Sqlite, "sqlite");

#[cfg(test)]
mod tests {
    use std::str::FromStr;
    use std::time::Duration;

    use sqlx::Connection;
    use sqlx::sqlite::{SqliteConnectOptions, SqliteConnection, SqliteJournalMode};

    use crate::StoreError;

    fn code(e: &sqlx::Error) -> String {
        match e {
            sqlx::Error::Database(d) => d.code().unwrap_or_default().into_owned(),
            other => panic!("not a database error: {other}"),
        }
    }

    /// A busy SQLite file is "unavailable" (503, retry) whatever extended code SQLite gives:
    /// sqlx reports the extended code, so matching the primary code `"5"` alone let
    /// `SQLITE_BUSY_SNAPSHOT` (517) through as a 500.
    #[tokio::test]
    async fn busy_sqlite_is_unavailable_whatever_its_extended_code() {
        let dir = std::env::temp_dir().join(format!("gearwear-busy-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let opts = SqliteConnectOptions::from_str("sqlite://")
            .unwrap()
            .filename(dir.join("busy.db"))
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .busy_timeout(Duration::ZERO);
        let mut a = SqliteConnection::connect_with(&opts).await.unwrap();
        let mut b = SqliteConnection::connect_with(&opts).await.unwrap();
        for q in [
            "CREATE TABLE t (x INTEGER PRIMARY KEY)",
            "INSERT INTO t VALUES (1)",
        ] {
            sqlx::query(q).execute(&mut a).await.unwrap();
        }
        // A read transaction whose snapshot another connection's commit made stale cannot
        // become a writer: SQLITE_BUSY_SNAPSHOT.
        sqlx::query("BEGIN").execute(&mut a).await.unwrap();
        sqlx::query("SELECT * FROM t")
            .fetch_all(&mut a)
            .await
            .unwrap();
        sqlx::query("INSERT INTO t VALUES (2)")
            .execute(&mut b)
            .await
            .unwrap();
        let e = sqlx::query("INSERT INTO t VALUES (3)")
            .execute(&mut a)
            .await
            .unwrap_err();
        assert_eq!(code(&e), "517");
        assert!(StoreError::Db(e).is_unavailable());
        sqlx::query("ROLLBACK").execute(&mut a).await.unwrap();
        // Another connection holds the write lock: SQLITE_BUSY.
        sqlx::query("BEGIN IMMEDIATE")
            .execute(&mut b)
            .await
            .unwrap();
        let e = sqlx::query("INSERT INTO t VALUES (4)")
            .execute(&mut a)
            .await
            .unwrap_err();
        assert_eq!(code(&e), "5");
        assert!(StoreError::Db(e).is_unavailable());
        sqlx::query("ROLLBACK").execute(&mut b).await.unwrap();
        // A bug is not: a primary-key violation (SQLITE_CONSTRAINT_PRIMARYKEY, 1555).
        let e = sqlx::query("INSERT INTO t VALUES (1)")
            .execute(&mut a)
            .await
            .unwrap_err();
        assert_eq!(code(&e), "1555");
        assert!(!StoreError::Db(e).is_unavailable());
        drop((a, b));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
