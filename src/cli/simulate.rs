//! The `simulate`, `bifurcation` and `wear-lines` commands: runs of a gearbox's model at one
//! or more operating points.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Result, bail};
use clap::Args;

use super::common::{
    RigArgs, SolveArgs, parse_range, planetary_of, progress_bar, wear, write_or_print,
};
use crate::analysis::bifurcation::{self, grid};
use crate::analysis::report::simulate_report;
use crate::plot;
use crate::plot::plot_run;

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

/// `gearwear simulate`.
pub fn simulate_cmd(a: SimulateArgs) -> Result<()> {
    let gb = a.rig.load()?;
    let w = wear(&a.rig, a.ea)?;
    let model = gb.assembly(w)?.resolve()?;
    let element = model.index(&a.element)?;
    let lines = gb.report_lines();
    let spec = a.solve.spec(a.omega1);
    let planetary = planetary_of(&gb, &w);
    let (report, traj) = simulate_report(&model, &lines, &spec, a.ea, planetary, element)?;
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
        let paths = plot_run(dir, &report, &traj, element, &lines)?;
        for p in paths {
            eprintln!("wrote {}", p.display());
        }
    }
    write_or_print(a.output.as_deref(), &serde_json::to_string_pretty(&report)?)
}

/// `gearwear bifurcation`.
pub fn bifurcation_cmd(a: BifurcationArgs) -> Result<()> {
    let gb = a.rig.load()?;
    let model = gb.assembly(wear(&a.rig, a.ea)?)?.resolve()?;
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
    let bar = progress_bar(omegas.len() as u64, "Ω1 sweep");
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

/// `gearwear wear-lines`.
pub fn wear_lines_cmd(a: WearLinesArgs) -> Result<()> {
    use rayon::prelude::*;
    let gb = a.rig.load()?;
    let lines = gb.report_lines();
    let (start, end, step) = parse_range(&a.ea)?;
    let eas = grid(start, end, step);
    let spec = a.solve.spec(a.omega1);
    let rows: Vec<_> = eas
        .par_iter()
        .map(|&ea| -> Result<_> {
            let w = wear(&a.rig, ea)?;
            let model = gb.assembly(w)?.resolve()?;
            let element = model.index(&a.element)?;
            let planetary = planetary_of(&gb, &w);
            Ok(simulate_report(&model, &lines, &spec, ea, planetary, element)?.0)
        })
        .collect::<Result<_>>()?;
    let names: Vec<&str> = lines.iter().map(|(n, _)| n.as_str()).collect();
    let mut csv = format!("ea,{},motion_state,lyapunov_per_period\n", names.join(","));
    for r in &rows {
        let amps: Vec<String> = names
            .iter()
            .map(|n| format!("{:.6}", r.lines.get(n)))
            .collect();
        csv.push_str(&format!(
            "{},{},{},{}\n",
            r.ea,
            amps.join(","),
            r.motion_state,
            r.classification
                .lyapunov_per_period
                .map(|v| format!("{v:.4}"))
                .unwrap_or_default()
        ));
    }
    if let Some(p) = &a.plot {
        let x: Vec<f64> = rows.iter().map(|r| r.ea).collect();
        let cols: Vec<(&str, Vec<f64>)> = names
            .iter()
            .map(|n| (*n, rows.iter().map(|r| r.lines.get(n)).collect()))
            .collect();
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

fn suffixed(p: &Path, name: &str) -> PathBuf {
    let stem = p
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("bifurcation");
    let ext = p.extension().and_then(|s| s.to_str()).unwrap_or("png");
    p.with_file_name(format!("{stem}_{name}.{ext}"))
}
