//! `gearwear model-b …`: the second seed's space drive (Model B). Thin wrappers around
//! [`crate::analysis::model_b`]; `anyhow` is used here only.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use serde_json::json;

use super::common::write_or_print;
use crate::analysis::model_b::{
    self, Prepared, SimSpec, SolverKind, SolverSettings, return_difference_formula,
    simulate_reversal,
};
use crate::model::{ModelBConfig, ModelBOptions, StiffnessForm};
use crate::plot::{self, Panel, Series};

/// Arguments of `gearwear model-b`.
#[derive(Debug, Args)]
pub struct ModelBArgs {
    #[command(subcommand)]
    pub command: ModelBCommand,
    /// Model B configuration file (default: the committed `configs/model_b.toml`).
    #[arg(long, global = true)]
    pub config: Option<PathBuf>,
    /// Integrator.
    #[arg(long, value_enum, default_value_t = SolverArg::Rodas4, global = true)]
    pub solver: SolverArg,
    /// Relative tolerance.
    #[arg(long, default_value_t = 1e-8, global = true)]
    pub rtol: f64,
    /// Absolute tolerance (dimensionless deflections, units of b_ref = 10 µm).
    #[arg(long, default_value_t = 1e-10, global = true)]
    pub atol: f64,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum SolverArg {
    Rodas4,
    Dopri5,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum StiffnessArg {
    SquareWave,
    FirstHarmonic,
    Mean,
}

impl From<StiffnessArg> for StiffnessForm {
    fn from(s: StiffnessArg) -> Self {
        match s {
            StiffnessArg::SquareWave => StiffnessForm::SquareWave,
            StiffnessArg::FirstHarmonic => StiffnessForm::FirstHarmonic,
            StiffnessArg::Mean => StiffnessForm::Mean,
        }
    }
}

#[derive(Debug, Subcommand)]
pub enum ModelBCommand {
    /// Time response: transverse accelerations ÿ1..ÿ4, transmission error, output speed.
    Simulate {
        /// Simulated time, s (default: one stage-1 mesh period and a bit, 3.5 s).
        #[arg(long, default_value_t = 3.5)]
        duration: f64,
        /// Sample rate, Hz.
        #[arg(long, default_value_t = 20000.0)]
        sample_hz: f64,
        /// Mesh-stiffness form.
        #[arg(long, value_enum, default_value_t = StiffnessArg::SquareWave)]
        stiffness: StiffnessArg,
        /// JSON report (default: stdout).
        #[arg(long)]
        output: Option<PathBuf>,
        /// Directory for the PNG figures.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Return difference at the output: the formula against a simulated reversal (JSON, arcmin).
    ReturnDifference {
        /// Output torque of the reversal, N·m.
        #[arg(long, default_value_t = 20.0)]
        torque: f64,
        /// Reversal time and end of the run, s.
        #[arg(long, default_value_t = 0.2)]
        at: f64,
        #[arg(long, default_value_t = 1.5)]
        end: f64,
        #[arg(long)]
        output: Option<PathBuf>,
        /// PNG of the transmission error through the reversal.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Load drop with and without return difference, under both mesh-damping models (JSON:
    /// decay time, oscillations, peak, extrema larger than without).
    LoadDrop {
        #[arg(long, default_value_t = 0.05)]
        at: f64,
        #[arg(long, default_value_t = 1.0)]
        end: f64,
        #[arg(long, default_value_t = 5000.0)]
        sample_hz: f64,
        #[arg(long)]
        output: Option<PathBuf>,
        /// PNG of the two transmission-error curves.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Stiff vs explicit solver on Model B: steps, wall time, error against a tight reference.
    Solvers {
        #[arg(long, default_value_t = 3.5)]
        duration: f64,
        #[arg(long)]
        output: Option<PathBuf>,
    },
}

/// Run `gearwear model-b …`.
pub fn run(a: ModelBArgs) -> Result<()> {
    let cfg = match &a.config {
        Some(p) => ModelBConfig::from_file(p)?,
        None => ModelBConfig::default_rig(),
    };
    if !(a.rtol > 0.0 && a.atol > 0.0) {
        bail!("--rtol and --atol must be positive");
    }
    let solver = SolverSettings {
        kind: match a.solver {
            SolverArg::Rodas4 => SolverKind::Rodas4,
            SolverArg::Dopri5 => SolverKind::Dopri5,
        },
        rtol: a.rtol,
        atol: a.atol,
    };
    match a.command {
        ModelBCommand::Simulate {
            duration,
            sample_hz,
            stiffness,
            output,
            plot,
        } => simulate(&cfg, solver, duration, sample_hz, stiffness, output, plot),
        ModelBCommand::ReturnDifference {
            torque,
            at,
            end,
            output,
            plot,
        } => return_difference(&cfg, solver, torque, at, end, output, plot),
        ModelBCommand::LoadDrop {
            at,
            end,
            sample_hz,
            output,
            plot,
        } => load_drop(&cfg, solver, at, end, sample_hz, output, plot),
        ModelBCommand::Solvers { duration, output } => solvers(&cfg, duration, output),
    }
}

fn simulate(
    cfg: &ModelBConfig,
    solver: SolverSettings,
    duration: f64,
    sample_hz: f64,
    stiffness: StiffnessArg,
    output: Option<PathBuf>,
    plot_dir: Option<PathBuf>,
) -> Result<()> {
    let opts = ModelBOptions {
        stiffness: stiffness.into(),
        ..Default::default()
    };
    let p = Prepared::new(cfg, &opts)?;
    let spec = SimSpec {
        duration_s: duration,
        sample_hz,
        solver,
    };
    let rec = model_b::simulate(&p, &spec)?;
    let report = model_b::simulate_report(&p, &spec, &rec);
    if let Some(dir) = &plot_dir {
        let t = &rec.t;
        let names = ["ÿ1 (gear 1)", "ÿ2 (gear 2)", "ÿ3 (gear 3)", "ÿ4 (gear 4)"];
        let panels: Vec<Panel> = (0..4)
            .map(|k| Panel {
                title: names[k],
                x_label: "t (s)",
                y_label: "m/s²",
                series: vec![Series {
                    label: names[k],
                    x: t,
                    y: &rec.acc[k],
                }],
                dots: false,
                log_y: false,
                markers: vec![],
            })
            .collect();
        let path = dir.join("model_b_acceleration.png");
        plot::panels(
            &path,
            "Model B: transverse accelerations (contact-ratio shocks)",
            2,
            2,
            &panels,
        )?;
        eprintln!("wrote {}", path.display());
        // Zoom on the first shock of ÿ4.
        if let Some(&ts) = report.acc[3].2.first() {
            let (a, b) = (ts - 0.002, ts + 0.02);
            let idx: Vec<usize> = (0..t.len()).filter(|&k| t[k] >= a && t[k] <= b).collect();
            let tz: Vec<f64> = idx.iter().map(|&k| t[k]).collect();
            let yz: Vec<f64> = idx.iter().map(|&k| rec.acc[3][k]).collect();
            let path = dir.join("model_b_shock_zoom.png");
            plot::lines(
                &path,
                "Model B: ÿ4 around a contact-ratio shock",
                "t (s)",
                "ÿ4 (m/s²)",
                &[Series {
                    label: "ÿ4",
                    x: &tz,
                    y: &yz,
                }],
            )?;
            eprintln!("wrote {}", path.display());
        }
        let path = dir.join("model_b_dte_speed.png");
        plot::panels(
            &path,
            "Model B: transmission error and output speed",
            3,
            1,
            &[
                Panel {
                    title: "mesh deflections (dynamic transmission error along the lines of action)",
                    x_label: "t (s)",
                    y_label: "µm",
                    series: vec![
                        Series {
                            label: "δ1",
                            x: t,
                            y: &rec.mesh_um[0],
                        },
                        Series {
                            label: "δ2",
                            x: t,
                            y: &rec.mesh_um[1],
                        },
                    ],
                    dots: false,
                    log_y: false,
                    markers: vec![],
                },
                Panel {
                    title: "output transmission error θ5 − θ0/R",
                    x_label: "t (s)",
                    y_label: "arcmin",
                    series: vec![Series {
                        label: "DTE",
                        x: t,
                        y: &rec.dte_arcmin,
                    }],
                    dots: false,
                    log_y: false,
                    markers: vec![],
                },
                Panel {
                    title: "speed of gear 4 and of the load",
                    x_label: "t (s)",
                    y_label: "rad/s",
                    series: vec![
                        Series {
                            label: "θ̇4",
                            x: t,
                            y: &rec.omega4,
                        },
                        Series {
                            label: "θ̇5",
                            x: t,
                            y: &rec.omega5,
                        },
                    ],
                    dots: false,
                    log_y: false,
                    markers: vec![],
                },
            ],
        )?;
        eprintln!("wrote {}", path.display());
    }
    write_or_print(output.as_deref(), &serde_json::to_string_pretty(&report)?)
}

fn return_difference(
    cfg: &ModelBConfig,
    solver: SolverSettings,
    torque: f64,
    at: f64,
    end: f64,
    output: Option<PathBuf>,
    plot_path: Option<PathBuf>,
) -> Result<()> {
    if !(torque.is_finite() && torque > 0.0) {
        bail!("--torque must be a positive output torque in N·m");
    }
    let formula = return_difference_formula(cfg, torque, true);
    let sim = simulate_reversal(cfg, torque, true, at, end, &solver)?;
    if let Some(p) = &plot_path {
        plot::lines(
            p,
            &format!("Model B: reversal at {torque} N·m (output transmission error)"),
            "t (s)",
            "θ5 − θ0/R (arcmin)",
            &[Series {
                label: "DTE",
                x: &sim.t,
                y: &sim.dte,
            }],
        )?;
        eprintln!("wrote {}", p.display());
    }
    let rel = (sim.simulated_arcmin - formula.total) / formula.total;
    let v = json!({
        "unit": "arcmin at the output shaft",
        "torque_nm": torque,
        "formula_arcmin": formula.total,
        "simulated_arcmin": sim.simulated_arcmin,
        "relative_difference": rel,
        "formula_terms": formula,
        "reversal": sim,
        "solver": solver,
    });
    write_or_print(output.as_deref(), &serde_json::to_string_pretty(&v)?)
}

fn load_drop(
    cfg: &ModelBConfig,
    solver: SolverSettings,
    at: f64,
    end: f64,
    sample_hz: f64,
    output: Option<PathBuf>,
    plot_path: Option<PathBuf>,
) -> Result<()> {
    // Both mesh-damping models: only contact-only damping reproduces the paper's slow decay
    // (docs/model-b.md).
    let rep =
        model_b::load_drop_comparison(cfg, StiffnessForm::SquareWave, at, end, sample_hz, &solver)?;
    if let Some(p) = &plot_path {
        plot::panels(
            p,
            "Model B: load drop (load and motor torque to 0)",
            2,
            1,
            &[
                load_drop_panel(
                    "mesh damping only in contact (reproduces the paper)",
                    &rep.contact_only,
                ),
                load_drop_panel(
                    "mesh damping also inside the clearance (the paper's equations as written)",
                    &rep.viscous,
                ),
            ],
        )?;
        eprintln!("wrote {}", p.display());
    }
    write_or_print(output.as_deref(), &serde_json::to_string_pretty(&rep)?)
}

fn load_drop_panel<'a>(title: &'a str, r: &'a model_b::LoadDropReport) -> Panel<'a> {
    let (w, wo) = (&r.with_return_difference, &r.without_return_difference);
    Panel {
        title,
        x_label: "t (s)",
        y_label: "θ5 − θ0/R (arcmin)",
        series: vec![
            Series {
                label: "with return difference (backlash)",
                x: &w.t,
                y: &w.dte,
            },
            Series {
                label: "without (backlash 0)",
                x: &wo.t,
                y: &wo.dte,
            },
        ],
        dots: false,
        log_y: false,
        markers: vec![],
    }
}

fn solvers(cfg: &ModelBConfig, duration: f64, output: Option<PathBuf>) -> Result<()> {
    let p = Prepared::new(cfg, &ModelBOptions::default())?;
    let run = |kind, rtol: f64| -> Result<model_b::Record> {
        let spec = SimSpec {
            duration_s: duration,
            sample_hz: 20000.0,
            solver: SolverSettings {
                kind,
                rtol,
                atol: rtol * 1e-2,
            },
        };
        Ok(model_b::simulate(&p, &spec)?)
    };
    let reference = run(SolverKind::Dopri5, 1e-11)?;
    let peak_ref = reference.acc[0].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut rows = Vec::new();
    for (kind, rtol) in [
        (SolverKind::Dopri5, 1e-6),
        (SolverKind::Dopri5, 1e-8),
        (SolverKind::Rodas4, 1e-6),
        (SolverKind::Rodas4, 1e-8),
        (SolverKind::Rodas4, 1e-10),
    ] {
        let r = run(kind, rtol)?;
        let acc_err = (0..4)
            .map(|i| {
                r.acc[i]
                    .iter()
                    .zip(&reference.acc[i])
                    .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
            })
            .fold(0.0_f64, f64::max);
        let dte_err = r
            .dte_arcmin
            .iter()
            .zip(&reference.dte_arcmin)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        rows.push(json!({
            "solver": kind, "rtol": rtol, "atol": rtol * 1e-2,
            "steps": r.stats.steps, "rejected": r.stats.rejected, "rhs_evals": r.stats.rhs_evals,
            "wall_s": r.wall_s,
            "max_acc_error_m_s2": acc_err,
            "max_acc_error_relative_to_peak": acc_err / peak_ref,
            "max_dte_error_arcmin": dte_err,
        }));
    }
    let v = json!({
        "duration_s": duration,
        "reference": { "solver": "dopri5", "rtol": 1e-11, "atol": 1e-13,
            "steps": reference.stats.steps, "wall_s": reference.wall_s,
            "peak_acc_y1_m_s2": peak_ref },
        "runs": rows,
    });
    write_or_print(output.as_deref(), &serde_json::to_string_pretty(&v)?)
}
