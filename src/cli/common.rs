//! What the command groups share: the rig and integration options, `START:END:STEP` grids,
//! the wear argument check, writing to a file or stdout, and the progress bar. The command
//! files import this module and never each other.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::analysis::simulate::{RunSpec, Transient};
use crate::gearbox::Gearbox;
use crate::model::Wear;
use crate::signature::SignatureTable;
use crate::solver::Dopri5Options;

/// Options shared by the simulation commands.
#[derive(Debug, Args, Clone)]
pub struct RigArgs {
    /// Gearbox description, TOML or JSON (default: the first paper's rig,
    /// `configs/gearboxes/wang2019.toml`; format in docs/gearbox.md).
    #[arg(long, value_name = "FILE")]
    pub gearbox: Option<PathBuf>,
    /// Planetary composite-error amplitude (units of the reference length); default: the
    /// description's (0.1 for the paper's rig).
    #[arg(long)]
    pub planetary_error: Option<f64>,
}

impl RigArgs {
    pub(crate) fn load(&self) -> Result<Gearbox> {
        load_gearbox(self.gearbox.as_deref())
    }
}

/// The gearbox of a `--gearbox FILE` option (default: the first paper's rig).
pub(crate) fn load_gearbox(path: Option<&Path>) -> Result<Gearbox> {
    Ok(match path {
        Some(p) => Gearbox::from_file(p)
            .with_context(|| format!("reading the gearbox description {}", p.display()))?,
        None => Gearbox::paper_rig(),
    })
}

/// Where a gearbox's signature table lives by default: the committed
/// `signatures/model_a_accel.json` for the paper's rig, `signatures/<name>.json` otherwise.
pub(crate) fn default_table_for(gb: &Gearbox) -> PathBuf {
    if gb.hash == Gearbox::paper_rig().hash {
        crate::signature::table::default_table_path()
    } else {
        PathBuf::from(format!("signatures/{}.json", gb.name()))
    }
}

/// The signature table for `--gearbox` / `--table`: the given table, else the gearbox's
/// default one (the paper rig's when neither is given). It must have been computed for the given
/// gearbox (or, with only `--table`, for the description it carries); `allow_stale` turns a
/// mismatch into a warning.
pub(crate) fn load_table(
    gearbox: Option<&Path>,
    table: Option<&Path>,
    allow_stale: bool,
) -> Result<SignatureTable> {
    let gb = match (gearbox, table) {
        (None, Some(_)) => None,
        (g, _) => Some(load_gearbox(g)?),
    };
    let path = match (table, &gb) {
        (Some(t), _) => t.to_path_buf(),
        (None, Some(gb)) => default_table_for(gb),
        (None, None) => crate::signature::table::default_table_path(),
    };
    let t = SignatureTable::load(&path).with_context(|| {
        format!(
            "loading the signature table (make it with `gearwear precompute{} --output {}`)",
            gearbox
                .map(|g| format!(" --gearbox {}", g.display()))
                .unwrap_or_default(),
            path.display()
        )
    })?;
    let check = match &gb {
        Some(gb) => t.check_model(gb),
        None => t.check_model(t.gearbox()),
    };
    if let Err(e) = check {
        if allow_stale {
            eprintln!("warning: {e}");
        } else {
            return Err(e.into());
        }
    }
    Ok(t)
}

/// The planetary error a run uses: the option's, else the gearbox's baseline (0 without a
/// planetary stage).
pub(crate) fn planetary_of(gb: &Gearbox, w: &Wear) -> f64 {
    w.planetary.or(gb.planetary_baseline()).unwrap_or(0.0)
}

/// Options of the integration.
#[derive(Debug, Args, Clone)]
pub struct SolveArgs {
    /// Retained stage-1 mesh periods.
    #[arg(long, default_value_t = 80)]
    pub periods: usize,
    /// Samples per stage-1 mesh period.
    #[arg(long, default_value_t = 256)]
    pub samples_per_period: usize,
    /// Minimum transient, dimensionless time τ.
    #[arg(long, default_value_t = Transient::default().tau)]
    pub transient_tau: f64,
    /// Minimum transient, stage-1 mesh periods.
    #[arg(long, default_value_t = Transient::default().periods)]
    pub transient_periods: f64,
    /// Relative tolerance of the adaptive solver.
    #[arg(long, default_value_t = Dopri5Options::default().rtol)]
    pub rtol: f64,
    /// Absolute tolerance of the adaptive solver.
    #[arg(long, default_value_t = Dopri5Options::default().atol)]
    pub atol: f64,
    /// Skip the largest-Lyapunov-exponent estimate (a twin trajectory; halves the cost, the
    /// motion state then comes from the Poincaré geometry alone).
    #[arg(long)]
    pub no_lyapunov: bool,
}

impl SolveArgs {
    pub(crate) fn spec(&self, omega1: f64) -> RunSpec {
        RunSpec {
            omega1,
            periods: self.periods,
            samples_per_period: self.samples_per_period,
            transient: Transient {
                tau: self.transient_tau,
                periods: self.transient_periods,
            },
            initial: Vec::new(),
            solver: Dopri5Options {
                rtol: self.rtol,
                atol: self.atol,
                ..Default::default()
            },
            lyapunov: !self.no_lyapunov,
        }
    }
}

/// Parse `START:END:STEP`.
pub fn parse_range(s: &str) -> Result<(f64, f64, f64)> {
    let parts: Vec<&str> = s.split(':').collect();
    if parts.len() != 3 {
        bail!("expected START:END:STEP (e.g. 0.01:5:0.01), got `{s}`");
    }
    let p = |x: &str| -> Result<f64> {
        x.trim()
            .parse::<f64>()
            .with_context(|| format!("`{x}` is not a number"))
    };
    let (a, b, c) = (p(parts[0])?, p(parts[1])?, p(parts[2])?);
    if !(a > 0.0 && b >= a && c > 0.0) {
        bail!("need 0 < START ≤ END and STEP > 0, got {a}:{b}:{c}");
    }
    if (b - a) / c > 1e6 {
        bail!("{} grid points is too many", ((b - a) / c) as u64);
    }
    Ok((a, b, c))
}

/// Write `text` to `path` (creating its folder), or print it to stdout when there is no path.
pub(crate) fn write_or_print(path: Option<&Path>, text: &str) -> Result<()> {
    match path {
        Some(p) => {
            if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
            }
            std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))
        }
        None => {
            println!("{text}");
            Ok(())
        }
    }
}

/// The rig's wear for `--ea`, refusing a negative or non-finite degree.
pub(crate) fn wear(args: &RigArgs, ea: f64) -> Result<Wear> {
    if !(ea.is_finite() && ea >= 0.0) {
        bail!("--ea must be a wear degree ≥ 0 (the paper's range is 0.1 … 1), got {ea}");
    }
    Ok(Wear {
        ea,
        planetary: args.planetary_error,
    })
}

/// A progress bar `{spinner} WHAT [bar] pos/len (eta left)` on a terminal, hidden otherwise.
pub(crate) fn progress_bar(len: u64, what: &str) -> ProgressBar {
    if std::io::stderr().is_terminal() {
        let b = ProgressBar::new(len);
        b.set_style(
            ProgressStyle::with_template(&format!(
                "{{spinner}} {what} [{{bar:40}}] {{pos}}/{{len}} ({{eta}} left)"
            ))
            .expect("static template")
            .progress_chars("=> "),
        );
        b
    } else {
        ProgressBar::hidden()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_parsing() {
        assert_eq!(parse_range("0.01:5:0.01").unwrap(), (0.01, 5.0, 0.01));
        assert!(parse_range("1:0.5:0.1").is_err());
        assert!(parse_range("a:b:c").is_err());
        assert!(parse_range("0:1").is_err());
        assert!(parse_range("0.1:1:0").is_err());
    }
}
