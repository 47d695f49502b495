//! Rendering charts into a PNG or SVG file: the format, the grid of panels, the axes.

use std::path::Path;

use gearwear_core::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::chart::{Chart, Fonts, ranges};
use crate::draw::{DrawResult, fill_chart};
use crate::font::{FONT, ensure_font};

enum Format {
    Png,
    Svg,
}

/// Draw `charts` in a `rows × cols` grid into `path` (format from the extension).
pub(crate) fn render(
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

pub(crate) type Ranges = ((f64, f64), (f64, f64));

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

pub(crate) fn plot_err(path: &Path, reason: impl Into<String>) -> Error {
    Error::Plot {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}
