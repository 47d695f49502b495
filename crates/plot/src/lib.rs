//! PNG/SVG figures (plotters, embedded DejaVu Sans: no system font library needed).
//!
//! The output format follows the path's extension: `.png` (bitmap) or `.svg` (vector); any
//! other extension is an [`Error::Plot`]. Parent directories are created when missing.
//!
//! Non-finite points are skipped (a line is broken at them rather than joined across); when no
//! finite point remains the function returns `Error::Plot { reason: "no finite data", .. }`.
//! Axis ranges follow the data with a small margin; constant data gets a non-zero range.
//!
//! Every public function maps its arguments onto one internal chart description and one
//! renderer, so all figures share fonts, colours, margins and mesh style.

use std::error::Error as StdError;
use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use gearwear_core::{Error, Result};

pub mod run;
pub use run::plot_run;

/// Default figure size in pixels (width, height) for single-chart figures.
pub const DEFAULT_SIZE: (u32, u32) = (1000, 600);

/// Font family used everywhere (registered from the embedded DejaVu Sans).
const FONT: &str = "sans-serif";

static FONT_BYTES: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

/// Register the embedded font exactly once; later calls return the first outcome.
fn ensure_font() -> std::result::Result<(), String> {
    static REGISTERED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
                .map_err(|_| "embedded font DejaVuSans.ttf could not be parsed".to_string())
        })
        .clone()
}

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

type Pt = Option<(f64, f64)>;

enum Layer {
    /// Polyline, broken at `None` (non-finite) points.
    Line {
        label: Option<String>,
        pts: Vec<Pt>,
        color: RGBAColor,
        width: u32,
    },
    /// Filled dots of `radius` px.
    Dots {
        label: Option<String>,
        pts: Vec<Pt>,
        color: RGBAColor,
        radius: u32,
    },
    /// Shaded interval `(x, lower, upper)`, broken at `None` points.
    Band {
        pts: Vec<Option<(f64, f64, f64)>>,
        color: RGBAColor,
    },
}

struct Chart {
    title: String,
    x_label: String,
    y_label: String,
    layers: Vec<Layer>,
    /// Fixed x range; otherwise from the data.
    x_range: Option<(f64, f64)>,
    /// Linear y axis starts at zero when the data are non-negative.
    y_from_zero: bool,
    log_y: bool,
    /// Vertical dashed markers (label, x).
    markers: Vec<(String, f64)>,
    /// Horizontal dashed threshold lines (label, y).
    thresholds: Vec<(String, f64)>,
    /// Smaller fonts and margins (multi-panel figures).
    compact: bool,
}

impl Chart {
    fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Chart {
            title: title.to_string(),
            x_label: x_label.to_string(),
            y_label: y_label.to_string(),
            layers: Vec::new(),
            x_range: None,
            y_from_zero: false,
            log_y: false,
            markers: Vec::new(),
            thresholds: Vec::new(),
            compact: false,
        }
    }
}

/// Pairs `(x[i], y[i])`, `None` where either is non-finite.
fn zip_pts(x: &[f64], y: &[f64]) -> Vec<Pt> {
    x.iter()
        .zip(y)
        .map(|(&a, &b)| (a.is_finite() && b.is_finite()).then_some((a, b)))
        .collect()
}

/// Matplotlib's "tab10" palette.
fn palette(i: usize) -> RGBAColor {
    const C: [(u8, u8, u8); 10] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ];
    let (r, g, b) = C[i % C.len()];
    RGBAColor(r, g, b, 1.0)
}

fn plot_err(path: &Path, reason: impl Into<String>) -> Error {
    Error::Plot {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// Font sizes (px) for one chart.
struct Fonts {
    title: f64,
    axis: f64,
    tick: f64,
    note: f64,
}

impl Fonts {
    fn of(compact: bool) -> Self {
        if compact {
            Fonts {
                title: 21.0,
                axis: 18.0,
                tick: 15.0,
                note: 15.0,
            }
        } else {
            Fonts {
                title: 24.0,
                axis: 20.0,
                tick: 17.0,
                note: 16.0,
            }
        }
    }
}

/// Axis ranges of a chart: `((x0, x1), (y0, y1))`, or `None` without finite data.
fn ranges(c: &Chart) -> Option<((f64, f64), (f64, f64))> {
    let mut xs = MinMax::default();
    for l in &c.layers {
        match l {
            Layer::Line { pts, .. } | Layer::Dots { pts, .. } => {
                pts.iter().flatten().for_each(|&(x, _)| xs.add(x))
            }
            Layer::Band { pts, .. } => pts.iter().flatten().for_each(|&(x, _, _)| xs.add(x)),
        }
    }
    let (x0, x1) = match c.x_range {
        Some(r) => r,
        None => {
            let (a, b) = xs.get()?;
            pad(a, b, 0.02)
        }
    };
    let in_x = |x: f64| x >= x0 && x <= x1;
    // y over the points inside the x range (a fixed x range may hide large values).
    let mut ys = MinMax::default();
    let mut any = false;
    for l in &c.layers {
        match l {
            Layer::Line { pts, .. } | Layer::Dots { pts, .. } => {
                for &(x, y) in pts.iter().flatten() {
                    any = true;
                    if in_x(x) {
                        ys.add(y)
                    }
                }
            }
            Layer::Band { pts, .. } => {
                for &(x, lo, hi) in pts.iter().flatten() {
                    any = true;
                    if in_x(x) {
                        ys.add(lo);
                        ys.add(hi);
                    }
                }
            }
        }
    }
    if !any {
        return None;
    }
    for (_, t) in &c.thresholds {
        if t.is_finite() {
            ys.add(*t);
        }
    }
    let (lo, hi) = ys.get().unwrap_or((0.0, 1.0));
    let y = if c.log_y {
        let top = if hi > 0.0 { hi } else { 1.0 };
        let floor = top * 1e-6;
        // At least one decade, so that a decade tick (the only labelled ones) is visible.
        let bottom = lo.max(floor).min(top / 10.0);
        // Half a decade of head room, a little below the floor.
        (bottom / 1.5, top * 3.0)
    } else if c.y_from_zero && lo >= 0.0 {
        let (_, b) = pad(0.0, hi, 0.05);
        (0.0, b)
    } else {
        pad(lo, hi, 0.05)
    };
    Some(((x0, x1), y))
}

#[derive(Default)]
struct MinMax(Option<(f64, f64)>);

impl MinMax {
    fn add(&mut self, v: f64) {
        self.0 = Some(match self.0 {
            None => (v, v),
            Some((a, b)) => (a.min(v), b.max(v)),
        });
    }
    fn get(&self) -> Option<(f64, f64)> {
        self.0
    }
}

/// Widen `[a, b]` by `frac` of its span on each side; a zero span becomes `±max(|a|·5 %, 1)`.
fn pad(a: f64, b: f64, frac: f64) -> (f64, f64) {
    let span = b - a;
    if span > f64::EPSILON * a.abs().max(b.abs()).max(1e-300) && span.is_finite() {
        (a - frac * span, b + frac * span)
    } else {
        let d = if a != 0.0 {
            (a.abs() * 0.05).max(1e-12)
        } else {
            1.0
        };
        (a - d, b + d)
    }
}

// ---------------------------------------------------------------------------------------------
// Rendering
// ---------------------------------------------------------------------------------------------

type DrawResult = std::result::Result<(), Box<dyn StdError>>;

enum Format {
    Png,
    Svg,
}

/// Draw `charts` in a `rows × cols` grid into `path` (format from the extension).
fn render(
    path: &Path,
    size: (u32, u32),
    suptitle: Option<&str>,
    rows: usize,
    cols: usize,
    charts: &[Chart],
) -> Result<()> {
    let format = match path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
    {
        Some("png") => Format::Png,
        Some("svg") => Format::Svg,
        other => {
            return Err(plot_err(
                path,
                format!(
                    "unsupported output format {:?}: use a .png or .svg file name",
                    other.unwrap_or("")
                ),
            ));
        }
    };
    // Every chart needs finite data; check before touching the file system.
    let mut all_ranges = Vec::with_capacity(charts.len());
    for c in charts {
        match ranges(c) {
            Some(r) => all_ranges.push(r),
            None => {
                let what = if charts.len() > 1 {
                    format!("no finite data (panel \"{}\")", c.title)
                } else {
                    "no finite data".to_string()
                };
                return Err(plot_err(path, what));
            }
        }
    }
    ensure_font().map_err(|r| plot_err(path, r))?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| {
            plot_err(
                path,
                format!("cannot create directory {}: {e}", dir.display()),
            )
        })?;
    }
    let result = match format {
        Format::Png => {
            let root = BitMapBackend::new(path, size).into_drawing_area();
            draw_figure(&root, true, suptitle, rows, cols, charts, &all_ranges)
        }
        Format::Svg => {
            let root = SVGBackend::new(path, size).into_drawing_area();
            draw_figure(&root, false, suptitle, rows, cols, charts, &all_ranges)
        }
    };
    result.map_err(|e| plot_err(path, e.to_string()))
}

type Ranges = ((f64, f64), (f64, f64));

fn draw_figure<DB>(
    root: &DrawingArea<DB, Shift>,
    bitmap: bool,
    suptitle: Option<&str>,
    rows: usize,
    cols: usize,
    charts: &[Chart],
    ranges: &[Ranges],
) -> DrawResult
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let area = match suptitle {
        Some(t) => {
            // An explicit header strip: `titled()` puts the text flush against the top edge.
            let (header, body) = root.split_vertically(54);
            let (w, h) = header.dim_in_pixel();
            let style = (FONT, 28.0)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Center, VPos::Center));
            header.draw_text(t, &style, (w as i32 / 2, h as i32 / 2 + 4))?;
            body
        }
        None => root.clone(),
    };
    let cells = if rows * cols == 1 {
        vec![area]
    } else {
        area.split_evenly((rows, cols))
    };
    for ((c, r), cell) in charts.iter().zip(ranges).zip(&cells) {
        draw_chart(cell, bitmap, c, *r)?;
    }
    root.present()?;
    Ok(())
}

fn draw_chart<DB>(area: &DrawingArea<DB, Shift>, bitmap: bool, c: &Chart, r: Ranges) -> DrawResult
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
{
    let f = Fonts::of(c.compact);
    let ((x0, x1), (y0, y1)) = r;
    let mut builder = ChartBuilder::on(area);
    builder
        .margin_top(if c.compact { 6 } else { 10 })
        .margin_bottom(if c.compact { 6 } else { 10 })
        .margin_left(if c.compact { 8 } else { 14 })
        .margin_right(if c.compact { 18 } else { 28 })
        .x_label_area_size(if c.compact { 52 } else { 62 })
        .y_label_area_size(if c.compact { 84 } else { 96 });
    if !c.title.is_empty() {
        builder.caption(&c.title, (FONT, f.title).into_font().color(&BLACK));
    }
    if c.log_y {
        let chart = builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale())?;
        fill_chart(chart, bitmap, c, &f, (y0, y1), true)
    } else {
        let chart = builder.build_cartesian_2d(x0..x1, y0..y1)?;
        fill_chart(chart, bitmap, c, &f, (y0, y1), false)
    }
}

/// Tick label for a log axis: `1e-3`, `0.01`, `10`, `1e4`.
fn log_tick(v: &f64) -> String {
    let v = *v;
    if v <= 0.0 || !v.is_finite() {
        return String::new();
    }
    let e = v.log10();
    if (e - e.round()).abs() > 1e-6 {
        return String::new(); // only label the decades
    }
    let e = e.round() as i32;
    if (-2..=3).contains(&e) {
        format!("{:.*}", (-e).max(0) as usize, 10f64.powi(e))
    } else {
        format!("1e{e}")
    }
}

/// Formatter for linear-axis ticks: the fewest decimals that represent every tick exactly
/// (`0`, `0.5`, `1.0`, … rather than `10.0`, `20.0`), scientific notation for very large or
/// very small magnitudes.
fn tick_formatter(ticks: &[f64]) -> impl Fn(&f64) -> String + use<> {
    let max_abs = ticks.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let sci = max_abs >= 1e5 || (max_abs > 0.0 && max_abs < 1e-3);
    let step = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let tol = if step.is_finite() {
        step * 1e-6
    } else {
        max_abs.max(1e-300) * 1e-9
    };
    let decimals = (0..=10)
        .find(|&d| {
            ticks.iter().all(|v| {
                format!("{v:.d$}")
                    .parse::<f64>()
                    .is_ok_and(|p| (p - v).abs() <= tol)
            })
        })
        .unwrap_or(10);
    move |v: &f64| {
        let v = *v;
        let s = if sci {
            if v == 0.0 {
                "0".to_string()
            } else {
                // round away float noise, then shortest exponent form (2.5e-4, 1e6)
                let r: f64 = format!("{v:.6e}").parse().unwrap_or(v);
                format!("{r:e}")
            }
        } else {
            format!("{v:.decimals$}")
        };
        // "-0", "-0.00" → "0", "0.00"
        if s.starts_with('-') && s[1..].chars().all(|ch| ch == '0' || ch == '.') {
            s[1..].to_string()
        } else {
            s
        }
    }
}

fn fill_chart<'a, DB, Y>(
    mut chart: ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
    bitmap: bool,
    c: &Chart,
    f: &Fonts,
    (y0, y1): (f64, f64),
    log_y: bool,
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let axis_font = (FONT, f.axis).into_font().color(&BLACK);
    let tick_font = (FONT, f.tick).into_font().color(&BLACK.mix(0.85));
    let n_x = if c.compact { 7 } else { 10 };
    let n_y = if c.compact { 7 } else { 9 };
    let x_fmt = {
        let r = chart.x_range();
        tick_formatter(&RangedCoordf64::from(r.start..r.end).key_points(n_x))
    };
    let y_fmt = tick_formatter(&RangedCoordf64::from(y0..y1).key_points(n_y));
    {
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(c.x_label.as_str())
            .y_desc(c.y_label.as_str())
            .axis_desc_style(axis_font)
            .label_style(tick_font)
            .bold_line_style(BLACK.mix(0.10))
            .light_line_style(BLACK.mix(0.035))
            .axis_style(BLACK.mix(0.8))
            .x_labels(n_x)
            .y_labels(n_y)
            .x_label_formatter(&x_fmt);
        if log_y {
            mesh.y_label_formatter(&log_tick);
        } else {
            mesh.y_label_formatter(&y_fmt);
        }
        mesh.draw()?;
    }

    let (xr0, xr1) = {
        let r = chart.x_range();
        (r.start, r.end)
    };
    let inside_x = |x: f64| x >= xr0 && x <= xr1;
    let floor = if log_y { y0 } else { f64::NEG_INFINITY };
    let clamp_y = |y: f64| if log_y { y.max(floor) } else { y };

    let mut legend = false;
    for layer in &c.layers {
        match layer {
            Layer::Band { pts, color } => {
                for seg in segments(pts) {
                    if seg.len() < 2 {
                        continue;
                    }
                    let poly: Vec<(f64, f64)> = seg
                        .iter()
                        .map(|&(x, _, hi)| (x, clamp_y(hi)))
                        .chain(seg.iter().rev().map(|&(x, lo, _)| (x, clamp_y(lo))))
                        .collect();
                    chart.draw_series(std::iter::once(Polygon::new(poly, color.filled())))?;
                }
            }
            Layer::Line {
                label,
                pts,
                color,
                width,
            } => {
                let style = color.stroke_width(*width);
                let mut first = true;
                for seg in segments(pts) {
                    let seg = dedupe_pixels(&chart, seg.iter().map(|&(x, y)| (x, clamp_y(y))));
                    if bitmap && *width > 1 {
                        // plotters fills thick bitmap paths as one polygon, which turns dense,
                        // wiggly records into jagged, holey bands: stack shifted 1-px lines.
                        let area = chart.plotting_area();
                        let (bx, by) = area.get_base_pixel();
                        let px_area = area.strip_coord_spec();
                        let px: Vec<(i32, i32)> = seg
                            .iter()
                            .map(|p| {
                                let (x, y) = area.map_coordinate(p);
                                (x - bx, y - by)
                            })
                            .collect();
                        let w = *width as i32;
                        for (dx, dy) in (0..w)
                            .flat_map(|i| (0..w).map(move |j| (i, j)))
                            .filter(|&(i, j)| i == 0 || j == 0)
                        {
                            px_area.draw(&PathElement::new(
                                px.iter()
                                    .map(|&(x, y)| (x + dx, y + dy))
                                    .collect::<Vec<_>>(),
                                color.stroke_width(1),
                            ))?;
                        }
                    }
                    let shown = if bitmap && *width > 1 {
                        Vec::new()
                    } else {
                        seg
                    };
                    let anno = chart.draw_series(LineSeries::new(shown, style))?;
                    if first {
                        if let Some(l) = label {
                            legend = true;
                            let st = color.stroke_width(3);
                            anno.label(l.as_str()).legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 24, y)], st)
                            });
                        }
                        first = false;
                    }
                }
            }
            Layer::Dots {
                label,
                pts,
                color,
                radius,
            } => {
                let style = color.filled();
                let r = *radius;
                let anno = chart.draw_series(
                    pts.iter()
                        .flatten()
                        .filter(|(x, _)| inside_x(*x))
                        .map(|&(x, y)| Circle::new((x, clamp_y(y)), r, style)),
                )?;
                if let Some(l) = label {
                    legend = true;
                    anno.label(l.as_str())
                        .legend(move |(x, y)| Circle::new((x + 12, y), r.max(3), style));
                }
            }
        }
    }

    // Horizontal thresholds: dashed line, label right-aligned above it.
    for (i, (label, t)) in c.thresholds.iter().enumerate() {
        if !t.is_finite() {
            continue;
        }
        let col = threshold_color(i);
        chart.draw_series(DashedLineSeries::new(
            vec![(xr0, *t), (xr1, *t)],
            10,
            6,
            col.stroke_width(2),
        ))?;
        let style = (FONT, f.note)
            .into_font()
            .color(&col)
            .pos(Pos::new(HPos::Right, VPos::Bottom));
        chart.draw_series(std::iter::once(
            EmptyElement::at((xr1, *t)) + Text::new(label.clone(), (-6, -4), style),
        ))?;
    }

    // Vertical markers: dashed grey line, labels at the top, staggered to avoid overlap.
    let note_style = (FONT, f.note).into_font().color(&RGBColor(60, 60, 60));
    let mut levels: Vec<i32> = Vec::new(); // right edge (px) of the last label per level
    let mut visible: Vec<&(String, f64)> = c
        .markers
        .iter()
        .filter(|(_, v)| v.is_finite() && inside_x(*v))
        .collect();
    visible.sort_by(|a, b| a.1.total_cmp(&b.1));
    let top = y1;
    for (label, v) in visible {
        let mcol = RGBAColor(90, 90, 90, 0.9);
        chart.draw_series(DashedLineSeries::new(
            vec![(*v, y0), (*v, y1)],
            6,
            5,
            mcol.stroke_width(1),
        ))?;
        let (px, _) = chart.backend_coord(&(*v, top));
        let (w, _) = chart
            .plotting_area()
            .estimate_text_size(label, &note_style)?;
        let left = px + 3;
        let level = match levels.iter().position(|&right| right + 4 < left) {
            Some(k) => k,
            None => {
                levels.push(i32::MIN);
                levels.len() - 1
            }
        };
        levels[level] = left + w as i32;
        let style = note_style.pos(Pos::new(HPos::Left, VPos::Top));
        chart.draw_series(std::iter::once(
            EmptyElement::at((*v, top))
                + Text::new(
                    label.clone(),
                    (3, 4 + level as i32 * (f.note as i32 + 4)),
                    style,
                ),
        ))?;
    }

    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .margin(10)
            .label_font((FONT, f.note).into_font().color(&BLACK))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK.mix(0.3))
            .draw()?;
    }
    Ok(())
}

fn threshold_color(i: usize) -> RGBAColor {
    const C: [(u8, u8, u8); 4] = [
        (214, 39, 40),
        (255, 127, 14),
        (148, 103, 189),
        (44, 160, 44),
    ];
    let (r, g, b) = C[i % C.len()];
    RGBAColor(r, g, b, 1.0)
}

/// Maximal runs of consecutive `Some` values.
fn segments<T: Copy>(pts: &[Option<T>]) -> Vec<Vec<T>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for p in pts {
        match p {
            Some(v) => cur.push(*v),
            None => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Drop points of a polyline that land on the same pixel as the previously kept one (keeps the
/// last point), so that very long records stay fast and SVG files small.
fn dedupe_pixels<DB, Y>(
    chart: &ChartContext<'_, DB, Cartesian2d<RangedCoordf64, Y>>,
    pts: impl Iterator<Item = (f64, f64)>,
) -> Vec<(f64, f64)>
where
    DB: DrawingBackend,
    Y: Ranged<ValueType = f64>,
{
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut last_px = None;
    let mut pending = None;
    for p in pts {
        let px = chart.backend_coord(&p);
        if Some(px) == last_px {
            pending = Some(p);
            continue;
        }
        out.push(p);
        last_px = Some(px);
        pending = None;
    }
    if let Some(p) = pending {
        out.push(p);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_tick_labels() {
        let f = tick_formatter(&[0.0, 10.0, 20.0, 30.0]);
        assert_eq!(f(&10.0), "10");
        let f = tick_formatter(&[0.0, 0.5, 1.0, 1.5]);
        assert_eq!(f(&1.0), "1.0");
        assert_eq!(f(&-0.0), "0.0");
        let f = tick_formatter(&[0.1, 0.2, 0.30000000000000004]);
        assert_eq!(f(&0.30000000000000004), "0.3");
        let f = tick_formatter(&[0.0, 2e-4, 4e-4]);
        assert_eq!(f(&2e-4), "2e-4");
        let f = tick_formatter(&[0.0, 5e5, 1e6]);
        assert_eq!(f(&1e6), "1e6");
        assert_eq!(log_tick(&1e-3), "1e-3");
        assert_eq!(log_tick(&0.01), "0.01");
        assert_eq!(log_tick(&100.0), "100");
        assert_eq!(log_tick(&2.0), "");
    }

    #[test]
    fn plot_ranges_pad() {
        assert_eq!(pad(0.0, 0.0, 0.05), (-1.0, 1.0));
        let (a, b) = pad(3.0, 3.0, 0.05);
        assert!(a < 3.0 && b > 3.0);
        let (a, b) = pad(0.0, 10.0, 0.05);
        assert!((a + 0.5).abs() < 1e-12 && (b - 10.5).abs() < 1e-12);
        let mut c = Chart::new("t", "x", "y");
        c.layers.push(Layer::Line {
            label: None,
            pts: zip_pts(&[f64::NAN, 1.0], &[1.0, f64::INFINITY]),
            color: palette(0),
            width: 1,
        });
        assert!(ranges(&c).is_none());
    }
}
