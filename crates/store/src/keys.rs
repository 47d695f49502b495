//! API keys: the stored hash, scopes and revocation of each key.

use async_trait::async_trait;
use serde::Serialize;

use super::StoreResult;

/// What a key may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Scope {
    /// POST records.
    Ingest,
    /// GET machines, diagnoses, alerts, the dashboard.
    Read,
    /// Acknowledge alerts (`POST /v1/alerts/{id}/acknowledge`); `read` does not give it.
    Acknowledge,
    /// Manage webhooks (and everything else).
    Admin,
}

impl Scope {
    pub fn as_str(self) -> &'static str {
        match self {
            Scope::Ingest => "ingest",
            Scope::Read => "read",
            Scope::Acknowledge => "acknowledge",
            Scope::Admin => "admin",
        }
    }

    pub fn parse(s: &str) -> Option<Scope> {
        match s.trim() {
            "ingest" => Some(Scope::Ingest),
            "read" => Some(Scope::Read),
            "acknowledge" => Some(Scope::Acknowledge),
            "admin" => Some(Scope::Admin),
            _ => None,
        }
    }

    /// `"ingest,read"` → scopes, sorted and deduplicated; `Err(word)` names an unknown scope.
    pub fn parse_list(s: &str) -> Result<Vec<Scope>, String> {
        let mut out = Vec::new();
        for w in s.split(',').filter(|w| !w.trim().is_empty()) {
            out.push(Scope::parse(w).ok_or_else(|| w.trim().to_string())?);
        }
        out.sort();
        out.dedup();
        Ok(out)
    }

    pub fn join(scopes: &[Scope]) -> String {
        scopes
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// Does a key with `held` scopes grant `needed`? `admin` grants everything.
pub fn grants(held: &[Scope], needed: Scope) -> bool {
    held.contains(&needed) || held.contains(&Scope::Admin)
}

/// An API key as stored (hash only).
#[derive(Debug, Clone, Serialize)]
pub struct KeyRow {
    pub id: String,
    #[serde(skip)]
    pub hash: String,
    pub scopes: Vec<Scope>,
    pub label: String,
    pub created_at: i64,
    pub revoked_at: Option<i64>,
}

/// API keys.
#[async_trait]
pub trait KeyStore: Send + Sync {
    async fn insert_key(&self, key: &KeyRow) -> StoreResult<()>;
    async fn get_key(&self, id: &str) -> StoreResult<Option<KeyRow>>;
    async fn list_keys(&self) -> StoreResult<Vec<KeyRow>>;
    /// Revoke; `false` if no such (unrevoked) key.
    async fn revoke_key(&self, id: &str, now: i64) -> StoreResult<bool>;
    async fn active_key_count(&self) -> StoreResult<i64>;
}

/// The SQL of [`KeyStore`] for one backend: `$store` is the store type, `$db` its
/// sqlx database; invoked in a module of its own inside the backend's module. Both backends
/// run the same text.
macro_rules! keys_sql {
    ($store:ident, $db:ty) => {
        use super::$store;
        use sqlx::Row;
        use $crate::keys::Scope;
        use $crate::*;

        fn key_row(r: &<$db as sqlx::Database>::Row) -> StoreResult<KeyRow> {
            let scopes: String = r.try_get("scopes")?;
            Ok(KeyRow {
                id: r.try_get("id")?,
                hash: r.try_get("hash")?,
                scopes: Scope::parse_list(&scopes).unwrap_or_default(),
                label: r.try_get("label")?,
                created_at: r.try_get("created_at")?,
                revoked_at: r.try_get("revoked_at")?,
            })
        }

        #[async_trait::async_trait]
        impl $crate::KeyStore for $store {
            async fn insert_key(&self, k: &KeyRow) -> StoreResult<()> {
                sqlx::query(
                    "INSERT INTO api_keys (id, hash, scopes, label, created_at, revoked_at) \
                     VALUES ($1, $2, $3, $4, $5, $6)",
                )
                .bind(&k.id)
                .bind(&k.hash)
                .bind(Scope::join(&k.scopes))
                .bind(&k.label)
                .bind(k.created_at)
                .bind(k.revoked_at)
                .execute(&self.pool)
                .await?;
                Ok(())
            }

            async fn get_key(&self, id: &str) -> StoreResult<Option<KeyRow>> {
                let r = sqlx::query("SELECT * FROM api_keys WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                r.as_ref().map(key_row).transpose()
            }

            async fn list_keys(&self) -> StoreResult<Vec<KeyRow>> {
                let rows = sqlx::query("SELECT * FROM api_keys ORDER BY created_at, id")
                    .fetch_all(&self.pool)
                    .await?;
                rows.iter().map(key_row).collect()
            }

            async fn revoke_key(&self, id: &str, now: i64) -> StoreResult<bool> {
                let r = sqlx::query(
                    "UPDATE api_keys SET revoked_at = $2 WHERE id = $1 AND revoked_at IS NULL",
                )
                .bind(id)
                .bind(now)
                .execute(&self.pool)
                .await?;
                Ok(r.rows_affected() == 1)
            }

            async fn active_key_count(&self) -> StoreResult<i64> {
                let r = sqlx::query("SELECT COUNT(*) AS n FROM api_keys WHERE revoked_at IS NULL")
                    .fetch_one(&self.pool)
                    .await?;
                Ok(r.try_get("n")?)
            }
        }
    };
}
pub(crate) use keys_sql;
