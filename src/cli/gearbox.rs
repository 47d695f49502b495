//! The `gearbox` command group: check a description, show what it resolves to, print its
//! kinematics.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};

use super::common::load_gearbox;
use crate::database::{Database, DatabaseArg};
use crate::signature::line_set::gearbox_line_set;
use crate::signature::precompute::default_grid;

#[derive(Debug, Args)]
pub struct GearboxArgs {
    #[command(subcommand)]
    pub command: GearboxCommand,
}

#[derive(Debug, Subcommand)]
pub enum GearboxCommand {
    /// Every shaft rate and mesh frequency at an input-shaft rate (JSON).
    Kinematics(KinematicsArgs),
    /// Validate a description and show what it resolves to: the assumed values, the model's
    /// reference frequency, the measured lines and the default signature grid (JSON). With
    /// `--id`: a gearbox stored in the service's database, with its table job's status.
    Show(ShowArgs),
    /// Store a description in the service's database (like `PUT /v1/gearboxes/{id}`): a
    /// running service precomputes its signature table in the background.
    Add(AddArgs),
    /// The gearboxes stored in the service's database, with their table status.
    List(DatabaseArg),
}

#[derive(Debug, Args)]
pub struct AddArgs {
    /// Gearbox description, TOML or JSON.
    #[arg(long, value_name = "FILE")]
    pub gearbox: PathBuf,
    /// Id to store it under (default: the description's name).
    #[arg(long)]
    pub id: Option<String>,
    #[command(flatten)]
    pub store: DatabaseArg,
}

#[derive(Debug, Args)]
pub struct KinematicsArgs {
    /// Gearbox description, TOML or JSON (default: the first paper's rig).
    #[arg(long, value_name = "FILE")]
    pub gearbox: Option<PathBuf>,
    /// Input-shaft rate in Hz.
    #[arg(long)]
    pub input_hz: f64,
}

#[derive(Debug, Args)]
pub struct ShowArgs {
    /// Gearbox description, TOML or JSON (default: the first paper's rig).
    #[arg(long, value_name = "FILE", conflicts_with = "id")]
    pub gearbox: Option<PathBuf>,
    /// A gearbox stored in the service's database (`gearbox add`, `PUT /v1/gearboxes/{id}`).
    #[arg(long)]
    pub id: Option<String>,
    #[command(flatten)]
    pub store: DatabaseArg,
}

fn open_store(db: &Database) -> Result<std::sync::Arc<dyn crate::store::Store>> {
    crate::runtime()?.block_on(db.open())
}

/// `gearwear gearbox …`.
pub fn run(a: GearboxArgs) -> Result<()> {
    match a.command {
        GearboxCommand::Kinematics(k) => {
            if !(k.input_hz.is_finite() && k.input_hz > 0.0) {
                bail!(
                    "--input-hz must be a positive rate in Hz, got {}",
                    k.input_hz
                );
            }
            let gb = load_gearbox(k.gearbox.as_deref())?;
            let mut v = serde_json::to_value(gb.kinematics(k.input_hz))?;
            v["gearbox"] = serde_json::json!(gb.name());
            if !gb.warnings.is_empty() {
                v["warnings"] = serde_json::json!(gb.warnings);
            }
            println!("{}", serde_json::to_string_pretty(&v)?);
        }
        GearboxCommand::Add(a) => {
            let text = std::fs::read_to_string(&a.gearbox)
                .with_context(|| format!("reading {}", a.gearbox.display()))?;
            let fmt = match a.gearbox.extension().and_then(|e| e.to_str()) {
                Some("json") => Some(crate::gearbox::TextFormat::Json),
                Some("toml") => Some(crate::gearbox::TextFormat::Toml),
                _ => None,
            };
            let origin = a.gearbox.display().to_string();
            let probe = crate::gearbox::GearboxDescription::parse(&text, fmt, &origin)?;
            let id = a.id.unwrap_or_else(|| probe.name.clone());
            if !crate::machine::is_valid_id(&id) {
                bail!(
                    "a gearbox id is 1 to 64 characters of letters, digits, `.`, `_` and `-`, got `{id}`"
                );
            }
            if id == crate::machine::BUILTIN_GEARBOX_ID {
                bail!("`{id}` is the built-in paper rig; choose another --id");
            }
            let (row, _) = crate::store::GearboxRow::described(&id, &text, fmt, &origin)?;
            let db = a.store.resolve()?;
            let rt = crate::runtime()?;
            let outcome = rt.block_on(async {
                let st = db.open().await?;
                let o = st.put_gearbox(&row).await?;
                st.close().await;
                anyhow::Ok(o)
            })?;
            let what = match outcome {
                crate::store::PutOutcome::Created => "stored",
                crate::store::PutOutcome::Replaced => "replaced; its table is recomputed",
                crate::store::PutOutcome::Unchanged => "unchanged (the same description)",
            };
            eprintln!(
                "gearbox `{id}` {what} in {}; a running `gearwear serve` on this database \
                 precomputes its table (watch: gearwear gearbox show --id {id})",
                db.describe()
            );
            println!(
                "{}",
                serde_json::json!({"id": id, "hash": row.hash, "outcome": format!("{outcome:?}").to_lowercase()})
            );
        }
        GearboxCommand::List(a) => {
            let st = open_store(&a.resolve()?)?;
            let rows = crate::runtime()?.block_on(st.list_gearboxes())?;
            let v: Vec<_> = rows
                .iter()
                .map(|r| crate::views::gearbox_json(r, None, false))
                .collect();
            println!("{}", serde_json::to_string_pretty(&v)?);
        }
        GearboxCommand::Show(s) if s.id.is_some() => {
            let id = s.id.unwrap_or_default();
            let db = s.store.resolve()?;
            let st = open_store(&db)?;
            let Some(row) = crate::runtime()?.block_on(st.get_gearbox(&id))? else {
                bail!(
                    "no gearbox `{id}` in {}; add it with `gearwear gearbox add --gearbox FILE --id {id}`",
                    db.describe()
                );
            };
            let d: crate::gearbox::GearboxDescription = serde_json::from_str(&row.description)?;
            let gb = crate::gearbox::Gearbox::new(d)?;
            let v = crate::views::gearbox_json(&row, Some(&gb), true);
            println!("{}", serde_json::to_string_pretty(&v)?);
        }
        GearboxCommand::Show(s) => {
            let gb = load_gearbox(s.gearbox.as_deref())?;
            let f_ref = gb.reference_frequency_hz();
            let v = serde_json::json!({
                "name": gb.name(),
                "hash": gb.hash,
                "valid": true,
                "warnings": gb.warnings,
                "dynamics_estimated": gb.dynamics_estimated(),
                "reference_frequency_hz": f_ref,
                "input_hz_at_omega1_1": f_ref / gb.f1_hz(1.0),
                "mesh_ratios": gb.mesh_ratios,
                "wear_stages": gb.wear_stages(),
                "sensor_element": gb.physics.meshes[gb.physics.sensor_element].name,
                "lines": gearbox_line_set(&gb),
                "default_grid": default_grid(&gb),
                "assumed": gb.assumed,
                "coordinates": gb.physics.dofs,
                "meshes": gb.physics.meshes,
                "description": gb.description,
            });
            println!("{}", serde_json::to_string_pretty(&v)?);
        }
    }
    Ok(())
}
