//! The internal chart description every public figure maps onto (layers, labels, markers,
//! thresholds) and its axis ranges.

use plotters::style::RGBAColor;

pub(crate) type Pt = Option<(f64, f64)>;

pub(crate) enum Layer {
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

pub(crate) struct Chart {
    pub(crate) title: String,
    pub(crate) x_label: String,
    pub(crate) y_label: String,
    pub(crate) layers: Vec<Layer>,
    /// Fixed x range; otherwise from the data.
    pub(crate) x_range: Option<(f64, f64)>,
    /// Linear y axis starts at zero when the data are non-negative.
    pub(crate) y_from_zero: bool,
    pub(crate) log_y: bool,
    /// Vertical dashed markers (label, x).
    pub(crate) markers: Vec<(String, f64)>,
    /// Horizontal dashed threshold lines (label, y).
    pub(crate) thresholds: Vec<(String, f64)>,
    /// Smaller fonts and margins (multi-panel figures).
    pub(crate) compact: bool,
}

impl Chart {
    pub(crate) fn new(title: &str, x_label: &str, y_label: &str) -> Self {
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
pub(crate) fn zip_pts(x: &[f64], y: &[f64]) -> Vec<Pt> {
    x.iter()
        .zip(y)
        .map(|(&a, &b)| (a.is_finite() && b.is_finite()).then_some((a, b)))
        .collect()
}

/// Matplotlib's "tab10" palette.
pub(crate) fn palette(i: usize) -> RGBAColor {
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
/// Font sizes (px) for one chart.
pub(crate) struct Fonts {
    pub(crate) title: f64,
    pub(crate) axis: f64,
    pub(crate) tick: f64,
    pub(crate) note: f64,
}

impl Fonts {
    pub(crate) fn of(compact: bool) -> Self {
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
pub(crate) fn ranges(c: &Chart) -> Option<((f64, f64), (f64, f64))> {
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
pub(crate) struct MinMax(Option<(f64, f64)>);

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
pub(crate) fn pad(a: f64, b: f64, frac: f64) -> (f64, f64) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
