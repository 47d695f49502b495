//! `gearwear alerts list|ack`: the service's alert episodes in its database (like
//! `GET /v1/alerts` and `POST /v1/alerts/{id}/acknowledge`; docs/service.md#alerts).

use anyhow::{Result, bail};
use clap::{Args, Subcommand, ValueEnum};

use crate::database::DatabaseArg;
use crate::store::{Acknowledged, AlertFilter, now_ms};
use crate::views::alert_json;

#[derive(Debug, Args)]
pub struct AlertsArgs {
    #[command(subcommand)]
    pub command: AlertsCommand,
    #[command(flatten)]
    pub store: DatabaseArg,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum StateArg {
    /// Open or acknowledged.
    Open,
    Closed,
    All,
}

#[derive(Debug, Subcommand)]
pub enum AlertsCommand {
    /// Alerts, newest opened first: one JSON object per line.
    List {
        #[arg(long, value_enum, default_value = "open")]
        state: StateArg,
        /// Only this machine's.
        #[arg(long, value_name = "ID")]
        machine: Option<String>,
        /// At most this many.
        #[arg(long, default_value_t = 100)]
        limit: i64,
    },
    /// Acknowledge an open alert with a note of what was done.
    Ack {
        /// The alert's id (`gearwear alerts list`).
        id: String,
        /// What was done.
        #[arg(long)]
        note: String,
        /// Who acknowledges (the API records the key's id; here a name).
        #[arg(long, default_value = "cli")]
        by: String,
    },
}

pub fn run(a: AlertsArgs) -> Result<()> {
    let db = a.store.resolve()?;
    crate::runtime()?.block_on(async move {
        let st = db.open().await?;
        let r = match a.command {
            AlertsCommand::List {
                state,
                machine,
                limit,
            } => {
                let filter = match state {
                    StateArg::Open => AlertFilter::Open,
                    StateArg::Closed => AlertFilter::Closed,
                    StateArg::All => AlertFilter::All,
                };
                if !(1..=100_000).contains(&limit) {
                    bail!("--limit must be from 1 to 100000, got {limit}");
                }
                let rows = st.list_alerts(filter, machine.as_deref(), limit).await?;
                for r in &rows {
                    println!("{}", alert_json(r));
                }
                eprintln!("{} alert(s) in {}", rows.len(), db.describe());
                Ok(())
            }
            AlertsCommand::Ack { id, note, by } => {
                let note = note.trim();
                if note.is_empty() {
                    bail!("--note must say what was done");
                }
                match st.acknowledge_alert(&id, &by, note, now_ms()).await? {
                    Acknowledged::Done(a) => {
                        println!("{}", alert_json(&a));
                        Ok(())
                    }
                    Acknowledged::Unknown => {
                        bail!("no alert `{id}` in {}", db.describe())
                    }
                    Acknowledged::Refused(a) => bail!(
                        "alert `{id}` is {} already; nothing to acknowledge",
                        a.state
                    ),
                }
            }
        };
        st.close().await;
        r
    })
}
