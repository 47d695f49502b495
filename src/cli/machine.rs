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
    /// The record channel of the machine's tachometer (default: a channel named `tacho`, when
    /// a record has one); it gives the measured speed and is not diagnosed.
    #[arg(long, value_name = "NAME")]
    pub tacho_channel: Option<String>,
    /// Tachometer pulses per input-shaft revolution.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub tacho_ppr: i64,
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
            if let Err(e) = crate::service::machines::check_tacho(
                s.tacho_channel.as_deref(),
                s.tacho_ppr,
                s.channels.as_deref(),
            ) {
                bail!(
                    "{}",
                    e.replace("`tacho_channel`", "--tacho-channel")
                        .replace("`tacho_ppr`", "--tacho-ppr")
                        .replace("`channels`", "--channels")
                );
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
                            tacho_channel: s.tacho_channel.clone(),
                            tacho_ppr: s.tacho_ppr,
                        },
                        now_ms(),
                    )
                    .await?;
                st.close().await;
                println!(
                    "{}",
                    serde_json::json!({"id": s.id, "gearbox": s.gearbox, "input_shaft_hz": s.input_shaft_hz,
                                       "channels": s.channels, "tacho_channel": s.tacho_channel,
                                       "tacho_ppr": s.tacho_ppr, "created": created})
                );
                Ok(())
            })
        }
    }
}
