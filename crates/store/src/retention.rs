//! Retention: what is forgotten after a while (raw samples, idempotent answers).

use async_trait::async_trait;

use super::StoreResult;

/// Purges, run hourly by the service.
#[async_trait]
pub trait RetentionStore: Send + Sync {
    /// Drop raw samples of records received before `before`; returns how many.
    async fn purge_samples(&self, before: i64) -> StoreResult<u64>;
    /// Forget the stored answers to idempotency keys created before `before`; returns how many.
    async fn purge_idempotency(&self, before: i64) -> StoreResult<u64>;
}

/// The SQL of [`RetentionStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! retention_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use $crate::*;

        #[async_trait::async_trait]
        impl $crate::RetentionStore for $store {
            async fn purge_samples(&self, before: i64) -> StoreResult<u64> {
                let r = sqlx::query(
                    "UPDATE records SET samples = NULL \
                     WHERE received_at < $1 AND samples IS NOT NULL",
                )
                .bind(before)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected())
            }

            async fn purge_idempotency(&self, before: i64) -> StoreResult<u64> {
                let r = sqlx::query("DELETE FROM idempotency_keys WHERE created_at < $1")
                    .bind(before)
                    .execute(&self.pool)
                    .await?;
                Ok(r.rows_affected())
            }
        }
    };
}
pub(crate) use retention_sql;
