//! Command-line interface: argument parsing and dispatch. Every command is a thin wrapper
//! around library functions; `main` only calls [`run`].

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use crate::analysis::bifurcation::{self, grid};
use crate::analysis::report::{plot_run, simulate_report};
use crate::analysis::simulate::{RunSpec, Transient};
use crate::model::export::ModelExport;
use crate::model::{ModelAConfig, Wear};
use crate::plot;
use crate::solver::Dopri5Options;

/// gearwear: gearbox wear from one accelerometer record, by simulating the gearbox.
#[derive(Debug, Parser)]
#[command(name = "gearwear", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Simulate Model A at one (Ω1, ea): lines, motion state, plots.
    Simulate(SimulateArgs),
    /// Bifurcation diagram over Ω1 (the first seed's Figure 2).
    Bifurcation(BifurcationArgs),
    /// Print or export the resolved dimensionless model.
    Model(ModelArgs),
    /// Characteristic frequencies of the rig (the first seed's Table 2).
    Frequencies(FrequenciesArgs),
    /// Line amplitudes of x̄1 versus wear at one Ω1 (the first seed's Figure 17).
    WearLines(WearLinesArgs),
    /// Write a virtual accelerometer record (the model plus optional effects, gain and noise)
    /// to try `diagnose`, `calibrate` or the service with.
    Synth(SynthArgs),
    /// The second seed's 10-DOF space drive (Model B).
    ModelB(crate::model_b_cli::ModelBArgs),
    /// Run the wear-diagnosis HTTP service (API v1, dashboard, webhooks).
    Serve(crate::service::cli::ServeArgs),
    /// Create, list and revoke the service's API keys.
    Keys(crate::service::cli::KeysArgs),
    /// Simulate the signature table for diagnosis (ea × Ω1 × seeds).
    Precompute(crate::diagnosis_cli::PrecomputeArgs),
    /// Estimate the wear degree from an accelerometer record.
    Diagnose(crate::diagnosis_cli::DiagnoseArgs),
    /// Close the loop: fit, residual, effect attribution, refit (JSON report, plots).
    Calibrate(crate::closed_loop_cli::CalibrateArgs),
}

/// Options shared by the simulation commands.
#[derive(Debug, Args, Clone)]
pub struct RigArgs {
    /// Model A configuration file (default: the committed `configs/model_a.toml`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Planetary composite-error amplitude (units of b); default: the configuration's 0.1.
    #[arg(long)]
    pub planetary_error: Option<f64>,
}

impl RigArgs {
    pub(crate) fn load(&self) -> Result<ModelAConfig> {
        Ok(match &self.config {
            Some(p) => ModelAConfig::from_file(p)?,
            None => ModelAConfig::default_rig(),
        })
    }
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
    fn spec(&self, omega1: f64) -> RunSpec {
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

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Operating frequency Ω1 = stage-1 mesh frequency / ω_h.
    #[arg(long)]
    pub omega1: f64,
    /// Wear degree ea (fixed-axis composite-error amplitude, units of b = 5 µm; 0.1 … 1).
    #[arg(long)]
    pub ea: f64,
    /// Element to analyse (x1, x2, xsp1…4, xrp1…4).
    #[arg(long, default_value = "x1")]
    pub element: String,
    /// Write the JSON report here (default: stdout).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Write the time series (τ, x̄, x̄' of the element) as CSV here.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write PNG figures into this directory.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
}

#[derive(Debug, Args)]
pub struct BifurcationArgs {
    /// Wear degree ea.
    #[arg(long)]
    pub ea: f64,
    /// Ω1 grid as START:END:STEP, e.g. 0.01:5:0.01.
    #[arg(long)]
    pub omega1: String,
    /// Elements whose Poincaré samples are kept (comma-separated).
    #[arg(long, default_value = "x1,xrp1")]
    pub elements: String,
    /// CSV output (one row per Poincaré sample).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// PNG/SVG of the first element's diagram; the others get `_<element>` appended.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// CSV with one row per Ω1: state, Lyapunov exponent, ranges.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ExportFormat {
    Json,
}

#[derive(Debug, Args)]
pub struct ModelArgs {
    /// Export format.
    #[arg(long, value_enum, default_value_t = ExportFormat::Json)]
    pub export: ExportFormat,
    /// Wear degree ea used for the error amplitudes.
    #[arg(long, default_value_t = 0.1)]
    pub ea: f64,
    /// Output file (default: stdout).
    #[arg(long)]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
}

#[derive(Debug, Args)]
pub struct WearLinesArgs {
    /// Operating frequency Ω1.
    #[arg(long, default_value_t = 1.0)]
    pub omega1: f64,
    /// Wear grid START:END:STEP.
    #[arg(long, default_value = "0.1:1:0.05")]
    pub ea: String,
    /// Element to analyse.
    #[arg(long, default_value = "x1")]
    pub element: String,
    /// CSV output (one row per ea).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// PNG/SVG of the line amplitudes versus ea.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
    #[command(flatten)]
    pub solve: SolveArgs,
}

#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Wear degree ea of the virtual gearbox.
    #[arg(long)]
    pub ea: f64,
    /// Operating point Ω1 (1 = motor at 30 Hz on the paper's rig).
    #[arg(long, default_value_t = 1.0)]
    pub omega1: f64,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 25600.0)]
    pub sample_rate: f64,
    /// Duration, s.
    #[arg(long, default_value_t = 1.0)]
    pub duration: f64,
    /// Overall sensor gain.
    #[arg(long, default_value_t = 1.0)]
    pub gain: f64,
    /// Signal-to-noise ratio of the added white noise, dB.
    #[arg(long, default_value_t = 20.0)]
    pub snr_db: f64,
    /// Random seed (initial state, noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Shaft-rate modulation (eccentricity) sideband amplitude on mesh x1, units of b.
    #[arg(long)]
    pub eccentricity: Option<f64>,
    /// Planetary composite-error amplitude, units of b (default: the baseline 0.1).
    #[arg(long)]
    pub planetary: Option<f64>,
    /// Output file: `.wav` (32-bit float), `.f32` (raw little-endian) or `.csv` (one column).
    #[arg(long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub rig: RigArgs,
}

#[derive(Debug, Args)]
pub struct FrequenciesArgs {
    /// Motor (input shaft) rate in Hz, to print absolute frequencies too.
    #[arg(long)]
    pub shaft_hz: Option<f64>,
    #[command(flatten)]
    pub rig: RigArgs,
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

fn write_or_print(path: Option<&Path>, text: &str) -> Result<()> {
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

fn wear(args: &RigArgs, ea: f64) -> Result<Wear> {
    if !(ea.is_finite() && ea >= 0.0) {
        bail!("--ea must be a wear degree ≥ 0 (the paper's range is 0.1 … 1), got {ea}");
    }
    Ok(Wear {
        ea,
        planetary: args.planetary_error,
    })
}

/// Run the CLI.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(a) => simulate(a),
        Command::Bifurcation(a) => bifurcation_cmd(a),
        Command::Model(a) => model_cmd(a),
        Command::Frequencies(a) => frequencies(a),
        Command::WearLines(a) => wear_lines(a),
        Command::Synth(a) => synth(a),
        Command::ModelB(a) => crate::model_b_cli::run(a),
        Command::Serve(a) => crate::service::cli::serve_cmd(a),
        Command::Keys(a) => crate::service::cli::keys_cmd(a),
        Command::Precompute(a) => crate::diagnosis_cli::precompute_cmd(a),
        Command::Diagnose(a) => crate::diagnosis_cli::diagnose_cmd(a),
        Command::Calibrate(a) => crate::closed_loop_cli::calibrate_cmd(a),
    }
}

fn simulate(a: SimulateArgs) -> Result<()> {
    let cfg = a.rig.load()?;
    let w = wear(&a.rig, a.ea)?;
    let model = cfg.assembly(w)?.resolve()?;
    let element = model.index(&a.element)?;
    let fr = cfg.tooth_counts().frequencies();
    let spec = a.solve.spec(a.omega1);
    let planetary = w.planetary.unwrap_or(cfg.assumed.planetary_error);
    let (report, traj) = simulate_report(&model, &fr, &spec, a.ea, planetary, element)?;
    if let Some(p) = &a.csv {
        let n = model.n();
        let (x, v) = (traj.series(element), traj.series(n + element));
        let mut s = format!("tau,{0},{0}_velocity\n", a.element);
        for k in 0..traj.len() {
            s.push_str(&format!("{:.9},{:.9},{:.9}\n", traj.tau[k], x[k], v[k]));
        }
        write_or_print(Some(p), &s)?;
    }
    if let Some(dir) = &a.plot {
        let paths = plot_run(dir, &report, &traj, element, &fr)?;
        for p in paths {
            eprintln!("wrote {}", p.display());
        }
    }
    write_or_print(a.output.as_deref(), &serde_json::to_string_pretty(&report)?)
}

fn bifurcation_cmd(a: BifurcationArgs) -> Result<()> {
    let cfg = a.rig.load()?;
    let model = cfg.assembly(wear(&a.rig, a.ea)?)?.resolve()?;
    let (start, end, step) = parse_range(&a.omega1)?;
    let omegas = grid(start, end, step);
    let elements: Vec<usize> = a
        .elements
        .split(',')
        .map(|e| model.index(e.trim()))
        .collect::<crate::Result<_>>()?;
    if elements.is_empty() {
        bail!("--elements names no element");
    }
    let template = a.solve.spec(start);
    let bar = if std::io::stderr().is_terminal() {
        let b = ProgressBar::new(omegas.len() as u64);
        b.set_style(
            ProgressStyle::with_template("{spinner} Ω1 sweep [{bar:40}] {pos}/{len} ({eta} left)")
                .expect("static template")
                .progress_chars("=> "),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    let done = AtomicUsize::new(0);
    let t0 = std::time::Instant::now();
    let res = bifurcation::sweep(&model, &omegas, &template, &elements, &|| {
        done.fetch_add(1, Ordering::Relaxed);
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let secs = t0.elapsed().as_secs_f64();
    let st = res.total_stats();
    eprintln!(
        "{} Ω1 values in {secs:.2} s ({} steps, {} rejected, {} switches located, {} threads)",
        omegas.len(),
        st.steps,
        st.rejected,
        st.switches,
        rayon::current_num_threads()
    );
    if let Some(p) = &a.output {
        write_or_print(Some(p), &res.to_csv())?;
    }
    if let Some(p) = &a.summary {
        write_or_print(Some(p), &res.summary_csv())?;
    }
    if let Some(p) = &a.plot {
        for (e, name) in res.elements.iter().enumerate() {
            let path = if e == 0 { p.clone() } else { suffixed(p, name) };
            let (xs, ys) = res.scatter(e);
            plot::bifurcation(
                &path,
                &format!("Bifurcation of {name}, ea = {}", a.ea),
                "Ω1",
                &format!("{name} / b (Poincaré)"),
                &xs,
                &ys,
            )?;
            eprintln!("wrote {}", path.display());
        }
    }
    if a.output.is_none() && a.plot.is_none() && a.summary.is_none() {
        print!("{}", res.to_csv());
    }
    Ok(())
}

fn wear_lines(a: WearLinesArgs) -> Result<()> {
    use rayon::prelude::*;
    let cfg = a.rig.load()?;
    let fr = cfg.tooth_counts().frequencies();
    let (start, end, step) = parse_range(&a.ea)?;
    let eas = grid(start, end, step);
    let spec = a.solve.spec(a.omega1);
    let rows: Vec<_> = eas
        .par_iter()
        .map(|&ea| -> Result<_> {
            let w = wear(&a.rig, ea)?;
            let model = cfg.assembly(w)?.resolve()?;
            let element = model.index(&a.element)?;
            let planetary = w.planetary.unwrap_or(cfg.assumed.planetary_error);
            Ok(simulate_report(&model, &fr, &spec, ea, planetary, element)?.0)
        })
        .collect::<Result<_>>()?;
    let mut csv = String::from("ea,f1,f2,2f2,f3,f1/2,f1-f2,motion_state,lyapunov_per_period\n");
    for r in &rows {
        let l = &r.lines;
        csv.push_str(&format!(
            "{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{}\n",
            r.ea,
            l.f1,
            l.f2,
            l.two_f2,
            l.f3,
            l.half_f1,
            l.f1_minus_f2,
            r.motion_state,
            r.classification
                .lyapunov_per_period
                .map(|v| format!("{v:.4}"))
                .unwrap_or_default()
        ));
    }
    if let Some(p) = &a.plot {
        let x: Vec<f64> = rows.iter().map(|r| r.ea).collect();
        let cols: [(&str, Vec<f64>); 6] = [
            ("f1", rows.iter().map(|r| r.lines.f1).collect()),
            ("f2", rows.iter().map(|r| r.lines.f2).collect()),
            ("2f2", rows.iter().map(|r| r.lines.two_f2).collect()),
            ("f3", rows.iter().map(|r| r.lines.f3).collect()),
            ("f1/2", rows.iter().map(|r| r.lines.half_f1).collect()),
            ("f1-f2", rows.iter().map(|r| r.lines.f1_minus_f2).collect()),
        ];
        let series: Vec<plot::Series> = cols
            .iter()
            .map(|(l, y)| plot::Series { label: l, x: &x, y })
            .collect();
        plot::lines(
            p,
            &format!(
                "Line amplitudes of {} versus wear at Ω1 = {}",
                a.element, a.omega1
            ),
            "wear degree ea",
            &format!("peak amplitude of {} / b", a.element),
            &series,
        )?;
        eprintln!("wrote {}", p.display());
    }
    write_or_print(a.output.as_deref(), &csv)
}

fn synth(a: SynthArgs) -> Result<()> {
    use crate::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
    let cfg = a.rig.load()?;
    wear(&a.rig, a.ea)?;
    let spec = RigSpec {
        ea: a.ea,
        omega1: a.omega1,
        sample_rate: a.sample_rate,
        duration: a.duration,
        gain: a.gain,
        snr_db: a.snr_db,
        seed: a.seed,
        effects: RigEffects {
            eccentricity: a.eccentricity,
            planetary: a.planetary,
            ..Default::default()
        },
    };
    let rec = generate(&cfg, &spec)?;
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let bytes: Vec<u8> = match ext.as_str() {
        "wav" => {
            let fs = rec.sample_rate.round();
            if (fs - rec.sample_rate).abs() > 1e-9 || fs > u32::MAX as f64 {
                bail!(
                    "a WAV file needs a whole sample rate in Hz, got {}",
                    rec.sample_rate
                );
            }
            crate::record::encode_wav(&rec.samples, fs as u32, true)
        }
        "f32" | "raw" | "bin" => rec
            .samples
            .iter()
            .flat_map(|v| (*v as f32).to_le_bytes())
            .collect(),
        "csv" => rec
            .samples
            .iter()
            .map(|v| format!("{v:.9e}\n"))
            .collect::<String>()
            .into_bytes(),
        _ => bail!(
            "--output must end in .wav, .f32 or .csv, got {}",
            a.output.display()
        ),
    };
    if let Some(dir) = a.output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&a.output, bytes).with_context(|| format!("writing {}", a.output.display()))?;
    eprintln!(
        "wrote {} ({} samples at {} Hz; shaft {:.3} Hz, f1 {:.1} Hz)",
        a.output.display(),
        rec.samples.len(),
        rec.sample_rate,
        a.omega1 * cfg.reference_frequency_hz / cfg.gears.g1.teeth as f64,
        a.omega1 * cfg.reference_frequency_hz
    );
    Ok(())
}

fn suffixed(p: &Path, name: &str) -> PathBuf {
    let stem = p
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("bifurcation");
    let ext = p.extension().and_then(|s| s.to_str()).unwrap_or("png");
    p.with_file_name(format!("{stem}_{name}.{ext}"))
}

fn model_cmd(a: ModelArgs) -> Result<()> {
    let cfg = a.rig.load()?;
    let model = cfg.assembly(wear(&a.rig, a.ea)?)?.resolve()?;
    let ExportFormat::Json = a.export;
    let export = ModelExport::new(&model, &cfg);
    write_or_print(a.output.as_deref(), &serde_json::to_string_pretty(&export)?)
}

fn frequencies(a: FrequenciesArgs) -> Result<()> {
    let cfg = a.rig.load()?;
    let fr = cfg.tooth_counts().frequencies();
    let mut v = serde_json::to_value(fr)?;
    if let Some(hz) = a.shaft_hz {
        if !(hz.is_finite() && hz > 0.0) {
            bail!("--shaft-hz must be a positive rate in Hz, got {hz}");
        }
        let f1 = cfg.f1_hz(hz);
        let abs: serde_json::Map<String, serde_json::Value> = v
            .as_object()
            .expect("struct serialises to an object")
            .iter()
            .map(|(k, r)| (k.clone(), serde_json::json!(r.as_f64().unwrap_or(0.0) * f1)))
            .collect();
        v = serde_json::json!({ "ratio_to_f1": v, "hz": abs, "shaft_hz": hz });
    }
    println!("{}", serde_json::to_string_pretty(&v)?);
    Ok(())
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
