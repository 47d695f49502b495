//! Where the service's database is: one rule for every subcommand that opens it (`serve`,
//! `keys`, `gearbox add|list|show --id`, `machine set|delete`), so that a key made by
//! `keys create` is in the database `serve` reads, whatever directory each was run from.
//!
//! The first of:
//! 1. `--database-url URL`;
//! 2. the environment variable `GEARWEAR_DATABASE_URL`;
//! 3. the environment variable `DATABASE_URL` (the generic name many tools share, so the
//!    product's own name wins over it);
//! 4. the file `gearwear.db` in the user's data directory, `gearwear/` under it: on Linux
//!    `$XDG_DATA_HOME/gearwear/gearwear.db` when `XDG_DATA_HOME` is an absolute path, else
//!    `~/.local/share/gearwear/gearwear.db` (macOS: `~/Library/Application Support/gearwear/`,
//!    Windows: `%APPDATA%\gearwear\`); the directory is made when missing.
//!
//! An empty value counts as not given. A URL starting with `postgres://` or `postgresql://`
//! is a PostgreSQL database, anything else a SQLite file (a relative path is relative to the
//! current directory, as before: `--database-url gearwear.db` still opens `./gearwear.db`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};

/// The `--database-url` option, flattened into every subcommand that opens the database.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct DatabaseArg {
    /// The service's database: `postgres://user@host:5432/db` for PostgreSQL, else a SQLite
    /// file. Default: $GEARWEAR_DATABASE_URL, else $DATABASE_URL, else gearwear.db in the
    /// user's data directory (Linux: $XDG_DATA_HOME/gearwear/, else ~/.local/share/gearwear/).
    #[arg(long, value_name = "URL", global = true)]
    pub database_url: Option<String>,
}

/// Where [`Database::url`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    Flag,
    GearwearEnv,
    DatabaseUrlEnv,
    /// The file in the user's data directory.
    Default,
}

/// A resolved database location.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Database {
    /// What the store opens (`postgres://…` or a SQLite path).
    pub url: String,
    pub source: Source,
}

impl DatabaseArg {
    /// The database this invocation uses ([`resolve`] with the process's environment and the
    /// user's data directory); for the default file, its directory is made when missing.
    pub fn resolve(&self) -> Result<Database> {
        let env = |k: &str| std::env::var(k).ok();
        let db = resolve(self.database_url.as_deref(), env, default_path)?;
        if db.source == Source::Default {
            if let Some(dir) = Path::new(&db.url).parent() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating the data directory {}", dir.display()))?;
            }
            let here = std::fs::canonicalize("gearwear.db").ok();
            if here.is_some() && here != std::fs::canonicalize(&db.url).ok() {
                eprintln!(
                    "note: ./gearwear.db exists here, but the default database is {}; to keep \
                     using the one here pass --database-url gearwear.db (or set \
                     GEARWEAR_DATABASE_URL)",
                    db.url
                );
            }
        }
        Ok(db)
    }
}

/// The database named by `flag`, else by the environment (`env` looks a variable up), else
/// `default()` — see the module's documentation for the order.
pub fn resolve(
    flag: Option<&str>,
    env: impl Fn(&str) -> Option<String>,
    default: impl FnOnce() -> Result<PathBuf>,
) -> Result<Database> {
    let given = |v: Option<String>| v.filter(|s| !s.trim().is_empty());
    if let Some(url) = given(flag.map(str::to_string)) {
        return Ok(Database {
            url,
            source: Source::Flag,
        });
    }
    if let Some(url) = given(env("GEARWEAR_DATABASE_URL")) {
        return Ok(Database {
            url,
            source: Source::GearwearEnv,
        });
    }
    if let Some(url) = given(env("DATABASE_URL")) {
        return Ok(Database {
            url,
            source: Source::DatabaseUrlEnv,
        });
    }
    let path = default()?;
    Ok(Database {
        url: path.to_str().map(str::to_string).with_context(|| {
            format!(
                "the default database path {} is not valid UTF-8; give --database-url",
                path.display()
            )
        })?,
        source: Source::Default,
    })
}

/// `gearwear/gearwear.db` under the user's data directory ([`dirs::data_dir`]: on Linux
/// `$XDG_DATA_HOME` when absolute, else `$HOME/.local/share`).
pub fn default_path() -> Result<PathBuf> {
    match dirs::data_dir() {
        Some(d) => Ok(d.join("gearwear").join("gearwear.db")),
        None => bail!(
            "no data directory for the default database (neither XDG_DATA_HOME nor HOME is \
             set): give --database-url or GEARWEAR_DATABASE_URL"
        ),
    }
}

impl Database {
    /// The database for people: a SQLite file as an absolute path (which directory a relative
    /// one is in is the point), a PostgreSQL URL without its password.
    pub fn describe(&self) -> String {
        describe(&self.url)
    }

    /// Open the store (running its migrations).
    pub async fn open(&self) -> Result<Arc<dyn crate::store::Store>> {
        crate::store::connect(&self.url)
            .await
            .with_context(|| format!("opening the database {}", self.describe()))
    }
}

/// [`Database::describe`] of a URL.
pub fn describe(url: &str) -> String {
    if url.starts_with("postgres://") || url.starts_with("postgresql://") {
        return redact(url);
    }
    let path = url
        .strip_prefix("sqlite://")
        .or_else(|| url.strip_prefix("sqlite:"))
        .unwrap_or(url);
    let p = Path::new(path);
    if p.is_relative()
        && let Ok(cwd) = std::env::current_dir()
    {
        return cwd.join(p).display().to_string();
    }
    path.to_string()
}

/// A database URL without its password, for messages.
pub fn redact(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(s), Some(at)) if at > s => {
            let creds = &url[s + 3..at];
            match creds.split_once(':') {
                Some((user, _)) => format!("{}{user}:***{}", &url[..s + 3], &url[at..]),
                None => url.to_string(),
            }
        }
        _ => url.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env_of<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    fn default() -> Result<PathBuf> {
        Ok(PathBuf::from("/data/gearwear/gearwear.db"))
    }

    /// The flag wins, then GEARWEAR_DATABASE_URL, then DATABASE_URL, then the default file;
    /// empty values are skipped.
    #[test]
    fn the_flag_then_the_product_s_variable_then_the_generic_one_then_the_default() {
        let both = [
            ("GEARWEAR_DATABASE_URL", "postgres://g@h/gw"),
            ("DATABASE_URL", "postgres://d@h/db"),
        ];
        let r = |flag: Option<&str>, vars: &[(&str, &str)]| {
            resolve(flag, env_of(vars), default).unwrap()
        };
        assert_eq!(
            r(Some("flag.db"), &both),
            Database {
                url: "flag.db".into(),
                source: Source::Flag
            }
        );
        assert_eq!(r(None, &both).url, "postgres://g@h/gw");
        assert_eq!(r(None, &both).source, Source::GearwearEnv);
        assert_eq!(r(None, &both[1..]).url, "postgres://d@h/db");
        assert_eq!(r(None, &both[1..]).source, Source::DatabaseUrlEnv);
        assert_eq!(r(None, &[]).url, "/data/gearwear/gearwear.db");
        assert_eq!(r(None, &[]).source, Source::Default);
        let empty = [("GEARWEAR_DATABASE_URL", ""), ("DATABASE_URL", " ")];
        assert_eq!(r(Some(""), &empty).source, Source::Default);
        // The default is not even looked for when something was given.
        let fails = || -> Result<PathBuf> { bail!("no home") };
        assert!(resolve(None, env_of(&both), fails).is_ok());
        assert!(resolve(None, env_of(&[]), fails).is_err());
    }

    #[test]
    fn descriptions_name_the_file_absolutely_and_hide_passwords() {
        assert_eq!(
            describe("postgres://u:secret@h:5432/db"),
            "postgres://u:***@h:5432/db"
        );
        assert_eq!(describe("/var/lib/gw.db"), "/var/lib/gw.db");
        assert_eq!(describe("sqlite:///var/lib/gw.db"), "/var/lib/gw.db");
        let rel = describe("gearwear.db");
        assert!(Path::new(&rel).is_absolute(), "{rel}");
        assert!(rel.ends_with("/gearwear.db"), "{rel}");
        assert_eq!(redact("gearwear.db"), "gearwear.db");
    }
}
