//! `gearwear machine set|delete`: a machine's configuration in the service's database (like
//! `PUT /v1/machines/{id}`, which also registers it), and its deletion with everything of it
//! (like `DELETE /v1/machines/{id}`).

use anyhow::{Result, bail};
use clap::{Args, Subcommand};

use super::units::UnitArgs;
use crate::database::DatabaseArg;
use crate::machine::{BUILTIN_GEARBOX_ID as BUILTIN_ID, MAX_TACHO_PPR, TachoProblem, check_tacho};
use crate::store::{MachineConfig, now_ms};

#[derive(Debug, Args)]
pub struct MachineArgs {
    #[command(subcommand)]
    pub command: MachineCommand,
}

#[derive(Debug, Subcommand)]
pub enum MachineCommand {
    /// Point a machine at a stored gearbox, with its nominal input-shaft rate, channels,
    /// tachometer, the channels' units and its ISO 20816-3 class (this registers it:
    /// `serve --require-registered-machines` takes its records).
    Set(Box<SetArgs>),
    /// Delete a machine and everything of it: records, diagnoses, baseline, calibration
    /// (webhooks subscribed to `machine.deleted` are told). There is no undo.
    Delete(DeleteArgs),
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
    /// The input shaft's range of rates, `LO:HI` in Hz, that the gearbox's table must cover
    /// (like `speed_range_hz`; a running service extends the table when a record needs it).
    #[arg(long, value_name = "LO:HI")]
    pub speed_range_hz: Option<String>,
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
    /// What the channels measure and the machine's ISO 20816-3 class (`channel_units`,
    /// `iso_20816`).
    #[command(flatten)]
    pub units: UnitArgs,
    #[command(flatten)]
    pub store: DatabaseArg,
}

#[derive(Debug, Args)]
pub struct DeleteArgs {
    /// The machine's id.
    pub id: String,
    #[command(flatten)]
    pub store: DatabaseArg,
}

/// `gearwear machine …`.
pub fn run(a: MachineArgs) -> Result<()> {
    match a.command {
        MachineCommand::Set(s) => set(*s),
        MachineCommand::Delete(d) => delete(d),
    }
}

fn check_id(id: &str) -> Result<()> {
    if !crate::machine::is_valid_id(id) {
        bail!(
            "a machine id is 1 to 64 characters of letters, digits, `.`, `_` and `-`, got `{id}`"
        );
    }
    Ok(())
}

/// `gearwear machine delete ID`: one transaction, as `DELETE /v1/machines/{id}` (a running
/// service's webhook worker sends the `machine.deleted` events it queues).
fn delete(d: DeleteArgs) -> Result<()> {
    check_id(&d.id)?;
    let db = d.store.resolve()?;
    crate::runtime()?.block_on(async move {
        let st = db.open().await?;
        let gone = st.delete_machine(&d.id, now_ms()).await?;
        st.close().await;
        let Some(gone) = gone else {
            bail!(
                "no machine `{}` in {} (deleted already, or it never had a record, a \
                 configuration or a calibration there)",
                d.id,
                db.describe()
            );
        };
        eprintln!(
            "deleted machine `{}` from {}: {} records, {} diagnoses{}",
            d.id,
            db.describe(),
            gone.records,
            gone.diagnoses,
            if gone.calibration {
                ", its calibration"
            } else {
                ""
            }
        );
        println!(
            "{}",
            serde_json::json!({"id": d.id, "deleted": true, "records": gone.records,
                               "diagnoses": gone.diagnoses, "calibration": gone.calibration})
        );
        Ok(())
    })
}

/// `gearwear machine set ID …`.
fn set(s: SetArgs) -> Result<()> {
    check_id(&s.id)?;
    if let Some(hz) = s.input_shaft_hz
        && !(hz.is_finite() && hz > 0.0 && hz <= 1000.0)
    {
        bail!("--input-shaft-hz must be a rate in Hz above 0 and at most 1000, got {hz}");
    }
    let speed_range_hz = match s.speed_range_hz.as_deref() {
        None => None,
        Some(t) => {
            let parsed = t.split_once(':').and_then(|(a, b)| {
                Some((a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?))
            });
            match parsed {
                Some((lo, hi)) if lo.is_finite() && lo > 0.0 && lo < hi && hi <= 1000.0 => {
                    Some((lo, hi))
                }
                _ => bail!(
                    "--speed-range-hz is LO:HI, the input shaft's lowest and highest rate in Hz \
                     (above 0, LO below HI, at most 1000), got `{t}`"
                ),
            }
        }
    };
    if let Err(e) = check_tacho(
        s.tacho_channel.as_deref(),
        s.tacho_ppr,
        s.channels.as_deref(),
    ) {
        bail!("{}", tacho_message(&e));
    }
    let (channel_units, iso) = s
        .units
        .check(s.channels.as_deref(), s.tacho_channel.as_deref())?;
    let db = s.store.resolve()?;
    crate::runtime()?.block_on(async move {
        let st = db.open().await?;
        if s.gearbox != BUILTIN_ID && st.get_gearbox(&s.gearbox).await?.is_none() {
            bail!(
                "no gearbox `{}` in {}; add it first with `gearwear gearbox add --gearbox FILE --id {}`",
                s.gearbox,
                db.describe(),
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
                    channel_units: channel_units.clone(),
                    iso_group: iso.map(|c| i64::from(c.group)),
                    iso_support: iso.map(|c| c.support.as_str().to_string()),
                    speed_range_hz,
                },
                now_ms(),
            )
            .await?;
        st.close().await;
        let units: Option<serde_json::Value> =
            channel_units.as_deref().and_then(|t| serde_json::from_str(t).ok());
        println!(
            "{}",
            serde_json::json!({"id": s.id, "gearbox": s.gearbox, "input_shaft_hz": s.input_shaft_hz,
                               "channels": s.channels, "tacho_channel": s.tacho_channel,
                               "tacho_ppr": s.tacho_ppr, "channel_units": units,
                               "iso_20816": iso, "created": created})
        );
        Ok(())
    })
}

/// A tachometer problem in the command line's words (its flags).
fn tacho_message(p: &TachoProblem) -> String {
    match p {
        TachoProblem::PulsesPerRev(got) => format!(
            "--tacho-ppr is the tachometer's pulses per input-shaft revolution, a whole number \
             from 1 to {MAX_TACHO_PPR}, got {got}"
        ),
        TachoProblem::ChannelName => {
            "--tacho-channel is a channel name of 1 to 64 characters".into()
        }
        TachoProblem::ChannelDiagnosed(t) => format!(
            "--tacho-channel `{t}` is also in --channels: the tachometer's channel gives the \
             speed and is not diagnosed; list only the vibration channels in --channels"
        ),
    }
}
