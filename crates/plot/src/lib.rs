//! PNG/SVG figures (plotters, embedded DejaVu Sans: no system font library needed).
//!
//! The output format follows the path's extension: `.png` (bitmap) or `.svg` (vector); any
//! other extension is an [`Error::Plot`](gearwear_core::Error::Plot). Parent directories are
//! created when missing.
//!
//! Non-finite points are skipped (a line is broken at them rather than joined across); when no
//! finite point remains the function returns `Error::Plot { reason: "no finite data", .. }`.
//! Axis ranges follow the data with a small margin; constant data gets a non-zero range.
//!
//! Every public function maps its arguments onto one internal chart description and one
//! renderer, so all figures share fonts, colours, margins and mesh style.

use std::path::Path;

use gearwear_core::Result;
use plotters::prelude::*;

mod chart;
mod draw;
mod font;
mod render;
pub mod run;
mod ticks;

use chart::{Chart, Layer, palette, zip_pts};
use render::{plot_err, render};
pub use run::plot_run;

/// Default figure size in pixels (width, height) for single-chart figures.
pub const DEFAULT_SIZE: (u32, u32) = (1000, 600);

/// One named curve: `x[i]` against `y[i]` (the shorter slice sets the length).
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    pub label: &'a str,
    pub x: &'a [f64],
    pub y: &'a [f64],
}

/// One panel of a multi-panel figure (see [`panels`]).
#[derive(Debug, Clone)]
pub struct Panel<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    /// Drawn as lines, or as dots when `dots` is true.
    pub series: Vec<Series<'a>>,
    pub dots: bool,
    /// Logarithmic amplitude axis (values clamped to a floor of max·1e-6).
    pub log_y: bool,
    /// Vertical dashed markers with labels at these x positions (those outside the x range are
    /// skipped).
    pub markers: Vec<(&'a str, f64)>,
}

// ---------------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------------

/// Lines of several series on one chart, legend when more than one series.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<()> {
    let mut c = Chart::new(title, x_label, y_label);
    let legend = series.len() > 1;
    for (i, s) in series.iter().enumerate() {
        c.layers.push(Layer::Line {
            label: legend.then(|| s.label.to_string()),
            pts: zip_pts(s.x, s.y),
            color: palette(i),
            width: 2,
        });
    }
    render(path, DEFAULT_SIZE, None, 1, 1, &[c])
}

/// Phase portrait: `x` against `v` as a thin line, with optional Poincaré points as red dots.
pub fn phase_portrait(
    path: &Path,
    title: &str,
    x: &[f64],
    v: &[f64],
    poincare: Option<(&[f64], &[f64])>,
) -> Result<()> {
    let mut c = Chart::new(title, "x", "ẋ");
    c.layers.push(Layer::Line {
        label: poincare.map(|_| "trajectory".to_string()),
        pts: zip_pts(x, v),
        color: RGBAColor(31, 119, 180, 0.8),
        width: 1,
    });
    if let Some((px, pv)) = poincare {
        c.layers.push(Layer::Dots {
            label: Some("Poincaré section".to_string()),
            pts: zip_pts(px, pv),
            color: RGBAColor(214, 39, 40, 1.0),
            radius: 3,
        });
    }
    render(path, DEFAULT_SIZE, None, 1, 1, &[c])
}

/// Scatter of points (e.g. a Poincaré section).
pub fn scatter(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    x: &[f64],
    y: &[f64],
) -> Result<()> {
    let mut c = Chart::new(title, x_label, y_label);
    c.layers.push(Layer::Dots {
        label: None,
        pts: zip_pts(x, y),
        color: RGBAColor(31, 119, 180, 0.85),
        radius: 3,
    });
    render(path, DEFAULT_SIZE, None, 1, 1, &[c])
}

/// Amplitude spectrum over normalised frequency `f/f1`, x range `[0, x_max]`, with vertical
/// dashed markers and labels at the given normalised frequencies. With `log_y` the amplitude
/// axis is logarithmic and values are clamped to a floor of `max·1e-6`.
pub fn spectrum(
    path: &Path,
    title: &str,
    freq_norm: &[f64],
    amplitude: &[f64],
    markers: &[(&str, f64)],
    x_max: f64,
    log_y: bool,
) -> Result<()> {
    if !(x_max.is_finite() && x_max > 0.0) {
        return Err(plot_err(
            path,
            format!("spectrum x_max must be finite and > 0, got {x_max}"),
        ));
    }
    let mut c = Chart::new(title, "f / f1", "amplitude");
    c.x_range = Some((0.0, x_max));
    c.y_from_zero = true;
    c.log_y = log_y;
    c.markers = markers.iter().map(|&(l, v)| (l.to_string(), v)).collect();
    c.layers.push(Layer::Line {
        label: None,
        pts: zip_pts(freq_norm, amplitude),
        color: RGBAColor(31, 119, 180, 1.0),
        width: 1,
    });
    render(path, DEFAULT_SIZE, None, 1, 1, &[c])
}

/// Bifurcation diagram: many small semi-transparent black dots, `param[i]` against `value[i]`.
pub fn bifurcation(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    param: &[f64],
    value: &[f64],
) -> Result<()> {
    let mut c = Chart::new(title, x_label, y_label);
    c.layers.push(Layer::Dots {
        label: None,
        pts: zip_pts(param, value),
        color: RGBAColor(0, 0, 0, 0.45),
        radius: 1,
    });
    render(path, DEFAULT_SIZE, None, 1, 1, &[c])
}

/// A multi-panel figure: `panels` in a `rows × cols` grid under an overall `title`.
///
/// The figure grows with the grid (at least [`DEFAULT_SIZE`], about 640 × 420 px per panel) so
/// that the labels stay readable. Unused grid cells stay blank.
pub fn panels(path: &Path, title: &str, rows: usize, cols: usize, panels: &[Panel]) -> Result<()> {
    if rows == 0 || cols == 0 {
        return Err(plot_err(
            path,
            format!("grid must be at least 1×1, got {rows}×{cols}"),
        ));
    }
    if panels.is_empty() {
        return Err(plot_err(path, "no panels given"));
    }
    if panels.len() > rows * cols {
        return Err(plot_err(
            path,
            format!("{} panels do not fit a {rows}×{cols} grid", panels.len()),
        ));
    }
    let charts: Vec<Chart> = panels
        .iter()
        .map(|p| {
            let mut c = Chart::new(p.title, p.x_label, p.y_label);
            c.log_y = p.log_y;
            c.compact = true;
            c.markers = p.markers.iter().map(|&(l, v)| (l.to_string(), v)).collect();
            let legend = p.series.len() > 1;
            for (i, s) in p.series.iter().enumerate() {
                let label = legend.then(|| s.label.to_string());
                let pts = zip_pts(s.x, s.y);
                if p.dots {
                    let RGBAColor(r, g, b, _) = palette(i);
                    c.layers.push(Layer::Dots {
                        label,
                        pts,
                        color: RGBAColor(r, g, b, 0.85),
                        radius: 2,
                    });
                } else {
                    c.layers.push(Layer::Line {
                        label,
                        pts,
                        color: palette(i),
                        width: 1,
                    });
                }
            }
            c
        })
        .collect();
    let w = (640 * cols as u32).max(DEFAULT_SIZE.0);
    let h = (420 * rows as u32 + 50).max(DEFAULT_SIZE.1);
    let suptitle = (!title.is_empty()).then_some(title);
    render(path, (w, h), suptitle, rows, cols, &charts)
}

/// A band plot: the `mid` line with a shaded `[lower, upper]` interval and labelled horizontal
/// threshold lines (e.g. a wear trend with alarm levels).
#[allow(clippy::too_many_arguments)]
pub fn band(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    x: &[f64],
    mid: &[f64],
    lower: &[f64],
    upper: &[f64],
    thresholds: &[(&str, f64)],
) -> Result<()> {
    let mut c = Chart::new(title, x_label, y_label);
    let n = x.len().min(lower.len()).min(upper.len());
    let tri: Vec<Option<(f64, f64, f64)>> = (0..n)
        .map(|i| {
            let (xi, lo, hi) = (x[i], lower[i], upper[i]);
            (xi.is_finite() && lo.is_finite() && hi.is_finite()).then_some((xi, lo, hi))
        })
        .collect();
    c.layers.push(Layer::Band {
        pts: tri,
        color: RGBAColor(31, 119, 180, 0.22),
    });
    c.layers.push(Layer::Line {
        label: None,
        pts: zip_pts(x, mid),
        color: RGBAColor(31, 119, 180, 1.0),
        width: 2,
    });
    c.thresholds = thresholds
        .iter()
        .map(|&(l, v)| (l.to_string(), v))
        .collect();
    render(path, DEFAULT_SIZE, None, 1, 1, &[c])
}

// ---------------------------------------------------------------------------------------------
// Internal chart description
// ---------------------------------------------------------------------------------------------
