//! Drawing one chart's contents on its axes: the mesh, the layers (bands, lines, dots), the
//! threshold lines, the vertical markers and the legend.

use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::chart::{Chart, Fonts, Layer, Pt};
use crate::font::FONT;
use crate::ticks::{log_tick, tick_formatter};

/// What drawing into a plotters area returns: plotters' errors are boxed, and turned into
/// [`gearwear_core::Error::Plot`] with the file's path where the figure is written.
pub(crate) type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// The axes of one chart: x is linear, y linear or logarithmic (`Y`).
type Axes<'a, DB, Y> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>;

/// What every layer is clipped to: the plotted x range and, on a log axis, the y floor.
#[derive(Clone, Copy)]
struct Clip {
    xr0: f64,
    xr1: f64,
    log_y: bool,
    /// The bottom of a log axis (`-∞` on a linear one).
    floor: f64,
}

impl Clip {
    fn inside_x(&self, x: f64) -> bool {
        x >= self.xr0 && x <= self.xr1
    }

    /// `y` raised to the floor of a log axis, unchanged on a linear one.
    fn y(&self, y: f64) -> f64 {
        if self.log_y { y.max(self.floor) } else { y }
    }
}

/// Draw chart `c` on its axes (y range `(y0, y1)`): mesh, layers, thresholds, markers, legend.
pub(crate) fn fill_chart<'a, DB, Y>(
    mut chart: Axes<'a, DB, Y>,
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
    draw_mesh(&mut chart, c, f, (y0, y1), log_y)?;
    let (xr0, xr1) = {
        let r = chart.x_range();
        (r.start, r.end)
    };
    let clip = Clip {
        xr0,
        xr1,
        log_y,
        floor: if log_y { y0 } else { f64::NEG_INFINITY },
    };
    let mut legend = false;
    for layer in &c.layers {
        legend |= draw_layer(&mut chart, bitmap, layer, clip)?;
    }
    draw_thresholds(&mut chart, c, f, clip)?;
    draw_markers(&mut chart, c, f, clip, (y0, y1))?;
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

/// The grid, the axes, their descriptions and tick labels.
fn draw_mesh<'a, DB, Y>(
    chart: &mut Axes<'a, DB, Y>,
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
    Ok(())
}

/// Draw one layer; `true` when it added a legend entry.
fn draw_layer<'a, DB, Y>(
    chart: &mut Axes<'a, DB, Y>,
    bitmap: bool,
    layer: &Layer,
    clip: Clip,
) -> Result<bool, Box<dyn std::error::Error>>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    match layer {
        Layer::Band { pts, color } => {
            for seg in segments(pts) {
                if seg.len() < 2 {
                    continue;
                }
                let poly: Vec<(f64, f64)> = seg
                    .iter()
                    .map(|&(x, _, hi)| (x, clip.y(hi)))
                    .chain(seg.iter().rev().map(|&(x, lo, _)| (x, clip.y(lo))))
                    .collect();
                chart.draw_series(std::iter::once(Polygon::new(poly, color.filled())))?;
            }
            Ok(false)
        }
        Layer::Line {
            label,
            pts,
            color,
            width,
        } => draw_line(chart, bitmap, label.as_deref(), pts, *color, *width, clip),
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
                    .filter(|(x, _)| clip.inside_x(*x))
                    .map(|&(x, y)| Circle::new((x, clip.y(y)), r, style)),
            )?;
            if let Some(l) = label {
                anno.label(l.as_str())
                    .legend(move |(x, y)| Circle::new((x + 12, y), r.max(3), style));
                return Ok(true);
            }
            Ok(false)
        }
    }
}

/// A polyline broken at its `None` points, labelled on its first segment; `true` when it
/// added a legend entry.
fn draw_line<'a, DB, Y>(
    chart: &mut Axes<'a, DB, Y>,
    bitmap: bool,
    label: Option<&str>,
    pts: &[Pt],
    color: RGBAColor,
    width: u32,
    clip: Clip,
) -> Result<bool, Box<dyn std::error::Error>>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let style = color.stroke_width(width);
    let mut legend = false;
    let mut first = true;
    for seg in segments(pts) {
        let seg = dedupe_pixels(chart, seg.iter().map(|&(x, y)| (x, clip.y(y))));
        if bitmap && width > 1 {
            draw_thick_bitmap_line(chart, &seg, color, width)?;
        }
        let shown = if bitmap && width > 1 { Vec::new() } else { seg };
        let anno = chart.draw_series(LineSeries::new(shown, style))?;
        if first {
            if let Some(l) = label {
                legend = true;
                let st = color.stroke_width(3);
                anno.label(l)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], st));
            }
            first = false;
        }
    }
    Ok(legend)
}

/// plotters fills thick bitmap paths as one polygon, which turns dense, wiggly records into
/// jagged, holey bands: stack shifted 1-px lines instead, `width` px each way.
fn draw_thick_bitmap_line<'a, DB, Y>(
    chart: &Axes<'a, DB, Y>,
    seg: &[(f64, f64)],
    color: RGBAColor,
    width: u32,
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
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
    let w = width as i32;
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
    Ok(())
}

/// Horizontal thresholds: dashed line, label right-aligned above it.
fn draw_thresholds<'a, DB, Y>(
    chart: &mut Axes<'a, DB, Y>,
    c: &Chart,
    f: &Fonts,
    clip: Clip,
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let (xr0, xr1) = (clip.xr0, clip.xr1);
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
    Ok(())
}

/// Vertical markers: dashed grey line, labels at the top, staggered to avoid overlap.
fn draw_markers<'a, DB, Y>(
    chart: &mut Axes<'a, DB, Y>,
    c: &Chart,
    f: &Fonts,
    clip: Clip,
    (y0, y1): (f64, f64),
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let note_style = (FONT, f.note).into_font().color(&RGBColor(60, 60, 60));
    let mut levels: Vec<i32> = Vec::new(); // right edge (px) of the last label per level
    let mut visible: Vec<&(String, f64)> = c
        .markers
        .iter()
        .filter(|(_, v)| v.is_finite() && clip.inside_x(*v))
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
