//! `gearwear machine set`: a machine's configuration in the service's database (like
//! `PUT /v1/machines/{id}`).

use anyhow::{Result, bail};
use clap::{Args, Subcommand};

use super::gearbox::StoreArgs;
use crate::service::gearboxes::BUILTIN_ID;
use crate::store::{MachineConfig, now_ms};

#[derive(Debug, Args)]
pub struct MachineArgs {
    #[command(subcommand)]
    pub command: MachineCommand,
}

#[derive(Debug, Subcommand)]
pub enum MachineCommand {
    /// Point a machine at a stored gearbox, with its nominal input-shaft rate and channels.
    Set(SetArgs),
}

#[derive(Debug, Args)]
pub struct SetArgs {
    /// The machine's id.
    pub id: String,
    /// A stored gearbox's id (`gearwear gearbox add`); default the built-in paper rig.
    #[arg(long, default_value = BUILTIN_ID)]
    pub gearbox: String,
    /// Nominal input-shaft rate in Hz (a hint for finding the mesh lines).
    #[arg(long)]
    pub input_shaft_hz: Option<f64>,
    /// Channel names the machine records, comma-separated (default: whatever a record brings).
    #[arg(long, value_delimiter = ',')]
    pub channels: Option<Vec<String>>,
    #[command(flatten)]
    pub store: StoreArgs,
}

/// `gearwear machine …`.
pub fn run(a: MachineArgs) -> Result<()> {
    match a.command {
        MachineCommand::Set(s) => {
            if crate::service::http::check_machine_id(&s.id).is_err() {
                bail!(
                    "a machine id is 1 to 64 characters of letters, digits, `.`, `_` and `-`, got `{}`",
                    s.id
                );
            }
            if let Some(hz) = s.input_shaft_hz
                && !(hz.is_finite() && hz > 0.0 && hz <= 1000.0)
            {
                bail!("--input-shaft-hz must be a rate in Hz above 0 and at most 1000, got {hz}");
            }
            let url = s.store.database_url.clone();
            crate::service::cli::runtime()?.block_on(async move {
                let st = crate::store::connect(&url)
                    .await
                    .map_err(|e| anyhow::anyhow!("opening the store {url}: {e}"))?;
                if s.gearbox != BUILTIN_ID && st.get_gearbox(&s.gearbox).await?.is_none() {
                    bail!(
                        "no gearbox `{}` in {url}; add it first with `gearwear gearbox add --gearbox FILE --id {}`",
                        s.gearbox,
                        s.gearbox
                    );
                }
                let created = st
                    .put_machine(
                        &MachineConfig {
                            id: s.id.clone(),
                            gearbox_id: (s.gearbox != BUILTIN_ID).then(|| s.gearbox.clone()),
                            input_shaft_hz: s.input_shaft_hz,
                            channels: s.channels.clone(),
                        },
                        now_ms(),
                    )
                    .await?;
                st.close().await;
                println!(
                    "{}",
                    serde_json::json!({"id": s.id, "gearbox": s.gearbox, "input_shaft_hz": s.input_shaft_hz,
                                       "channels": s.channels, "created": created})
                );
                Ok(())
            })
        }
    }
}
