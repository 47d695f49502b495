//! The figures of one simulated run (`gearwear simulate --plot DIR`): time history, phase
//! portrait with the Poincaré points, Poincaré section, spectrum over f/f1 and an overview.

use std::path::Path;

use gearwear_core::Result;
use gearwear_core::analysis::report::SimulationReport;
use gearwear_core::analysis::simulate::Trajectory;
use gearwear_core::signal::{self, Window};

use crate::{Panel, Series};

/// Write the four figures of one run (time history, phase portrait with the Poincaré points,
/// Poincaré section, spectrum over f/f1) and a 2×2 overview into `dir`. Returns the paths.
pub fn plot_run(
    dir: &Path,
    report: &SimulationReport,
    traj: &Trajectory,
    element: usize,
    lines: &[(String, f64)],
) -> Result<Vec<std::path::PathBuf>> {
    let n = traj.dim / 2;
    let x = traj.series(element);
    let v = traj.series(n + element);
    let t: Vec<f64> = traj
        .tau
        .iter()
        .map(|t| (t - traj.tau[0]) * traj.omega1 / std::f64::consts::TAU)
        .collect();
    let (px, pv): (Vec<f64>, Vec<f64>) = report.poincare.iter().cloned().unzip();
    let spec = signal::amplitude_spectrum(&x, traj.sample_rate_per_f1(), Window::Hann)?;
    let markers: Vec<(&str, f64)> = lines.iter().map(|(n, r)| (n.as_str(), *r)).collect();
    let band = spec
        .freq
        .iter()
        .position(|&f| f > 2.5)
        .unwrap_or(spec.freq.len());
    let (sf, sa) = (&spec.freq[..band], &spec.amplitude[..band]);
    let name = &report.element;
    let tag = format!("Ω1 = {:.3}, ea = {:.2}", report.omega1, report.ea);
    // The last 10 periods for the time history, so the waveform is visible.
    let tail = (10 * traj.samples_per_period).min(x.len());
    let (tt, xt) = (&t[t.len() - tail..], &x[x.len() - tail..]);
    let paths = [
        dir.join("time.png"),
        dir.join("phase.png"),
        dir.join("poincare.png"),
        dir.join("spectrum.png"),
        dir.join("overview.png"),
    ];
    crate::lines(
        &paths[0],
        &format!("{name}: time history ({tag})"),
        "t / T1 (stage-1 mesh periods)",
        &format!("{name} / b"),
        &[Series {
            label: name,
            x: tt,
            y: xt,
        }],
    )?;
    crate::phase_portrait(
        &paths[1],
        &format!("{name}: phase portrait ({tag})"),
        &x,
        &v,
        Some((&px, &pv)),
    )?;
    crate::scatter(
        &paths[2],
        &format!("{name}: Poincaré section ({tag})"),
        &format!("{name} / b"),
        "velocity",
        &px,
        &pv,
    )?;
    crate::spectrum(
        &paths[3],
        &format!("{name}: amplitude spectrum ({tag})"),
        &spec.freq,
        &spec.amplitude,
        &markers,
        2.5,
        true,
    )?;
    crate::panels(
        &paths[4],
        &format!("{} — {name}, {tag}, {}", report.model, report.motion_state),
        2,
        2,
        &[
            Panel {
                title: "time history (last 10 periods)",
                x_label: "t / T1",
                y_label: "x / b",
                series: vec![Series {
                    label: name,
                    x: tt,
                    y: xt,
                }],
                dots: false,
                log_y: false,
                markers: vec![],
            },
            Panel {
                title: "phase portrait",
                x_label: "x / b",
                y_label: "velocity",
                series: vec![Series {
                    label: name,
                    x: &x,
                    y: &v,
                }],
                dots: false,
                log_y: false,
                markers: vec![],
            },
            Panel {
                title: "Poincaré section",
                x_label: "x / b",
                y_label: "velocity",
                series: vec![Series {
                    label: name,
                    x: &px,
                    y: &pv,
                }],
                dots: true,
                log_y: false,
                markers: vec![],
            },
            Panel {
                title: "spectrum (f / f1)",
                x_label: "f / f1",
                y_label: "amplitude",
                series: vec![Series {
                    label: name,
                    x: sf,
                    y: sa,
                }],
                dots: false,
                log_y: true,
                markers: markers.clone(),
            },
        ],
    )?;
    Ok(paths.to_vec())
}
