//! The lines a record's order spectrum is read at, each named by the part that makes it: every
//! mesh harmonic with a region of its own, its sidebands at ±1 and ±2 × each shaft's rate, each
//! shaft's 1× and 2× — what the record page marks ([`super::plot`]) and what a machine's model
//! is calibrated on ([`super::machine_model`], through [`super::evidence`]).

use serde::Serialize;

use super::lines::{Class, LineMap};
use super::parts::Parts;

/// Sidebands marked either side of a mesh harmonic, in multiples of each shaft's rate.
const SIDEBANDS: [i32; 4] = [-2, -1, 1, 2];
/// Levels are floored here (dB re 1 unit): an empty bin.
const FLOOR_DB: f64 = -200.0;

/// A marked line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Line {
    /// Input-shaft orders.
    pub order: f64,
    /// `mesh`, `sideband`, `shaft`, `bearing` or `shaft-rate`.
    pub kind: &'static str,
    /// Short, on the chart: `GM1 ×2`, `+1 idler`, `1× in`, `BPFI in ×1`.
    pub label: String,
    /// The part it belongs to, in words.
    pub part: String,
    /// The evidence feature it feeds (a finding's `evidence[].feature`).
    pub feature: String,
    /// The record's level at the line (dB re 1 unit).
    pub level_db: f64,
}

/// The highest order of the marked lines: the end of the last mesh region, or of the record's
/// usable orders.
pub(super) fn lines_top(map: &LineMap, max_order: f64) -> f64 {
    let meshes_top = map
        .regions
        .iter()
        .rev()
        .find(|r| r.centre.is_some())
        .map_or(map.top_order(), |r| r.hi);
    meshes_top.min(max_order)
}

/// The mesh harmonics, their sidebands and the shafts' 1×/2× below order `top`, each read
/// from the order spectrum `amp` (`bpo` bins to an order).
pub(super) fn marked_lines(
    map: &LineMap,
    parts: &Parts,
    amp: &[f64],
    bpo: f64,
    top: f64,
) -> Vec<Line> {
    let at = |o: f64| level_at(amp, o * bpo, 1.0);
    let mut lines = mesh_lines(map, parts, top, &at);
    lines.extend(shaft_lines(map, top, &at));
    lines
}

/// `20 log10(a)` rounded to 0.1 dB, floored at [`FLOOR_DB`].
pub(super) fn db(a: f64) -> f64 {
    let v = if a > 0.0 { 20.0 * a.log10() } else { FLOOR_DB };
    (v.max(FLOOR_DB) * 10.0).round() / 10.0
}

/// The largest amplitude within `half` bins of the (fractional) bin `c`, in dB.
pub(super) fn level_at(amp: &[f64], c: f64, half: f64) -> f64 {
    let lo = (c - half).round().max(1.0) as usize;
    let hi = ((c + half).round() as usize).min(amp.len().saturating_sub(1));
    db(amp
        .get(lo..=hi.max(lo))
        .map_or(0.0, |s| s.iter().fold(0.0f64, |m, &v| m.max(v))))
}

/// "in 16T / idler 48T": a stage's gears.
fn mesh_part(parts: &Parts, stage: usize) -> String {
    let g: Vec<String> = parts
        .gears
        .iter()
        .filter(|g| g.stage == stage)
        .map(|g| format!("{} {}T", g.shaft, g.teeth))
        .collect();
    format!("mesh {stage} ({})", g.join(" / "))
}

/// The mesh harmonics with a region of their own and their sidebands at each shaft's rate.
fn mesh_lines(map: &LineMap, parts: &Parts, top: f64, at: &dyn Fn(f64) -> f64) -> Vec<Line> {
    let mut out: Vec<Line> = Vec::new();
    for r in &map.regions {
        let Some(c) = r.centre.filter(|&c| c < top) else {
            continue;
        };
        // Every stage whose harmonic this is (mesh 1 at twice mesh 2 shares its lines).
        let of: Vec<(usize, f64)> = map
            .meshes
            .iter()
            .enumerate()
            .filter_map(|(i, &m)| {
                let k = (c / m).round();
                (k >= 1.0 && (c - k * m).abs() <= 1e-6 * c).then_some((i + 1, k))
            })
            .collect();
        let label: Vec<String> = of.iter().map(|(s, k)| format!("GM{s} ×{k}")).collect();
        let part: Vec<String> = of
            .iter()
            .map(|(s, k)| format!("{} harmonic {k}", mesh_part(parts, *s)))
            .collect();
        out.push(Line {
            order: c,
            kind: "mesh",
            label: label.join(" = "),
            part: part.join("; "),
            feature: format!("lines.mesh.{}", r.name),
            level_db: at(c),
        });
        for s in &map.shafts {
            for k in SIDEBANDS {
                let o = c + k as f64 * s.rate;
                let taken = out.iter().any(|l| (l.order - o).abs() < 1e-6 * o.max(1.0));
                if taken || o <= r.lo || o >= r.hi || o >= top {
                    continue;
                }
                let Some((class, feature)) = map.feature_at(o, true) else {
                    continue;
                };
                if class == Class::Mesh {
                    continue;
                }
                out.push(Line {
                    order: o,
                    kind: "sideband",
                    label: format!("{k:+} {}", s.name),
                    part: format!(
                        "sideband {k:+} × the {} shaft's rate around {}",
                        s.name,
                        label.join(" = ")
                    ),
                    feature,
                    level_db: at(o),
                });
            }
        }
    }
    out.sort_by(|a, b| a.order.total_cmp(&b.order));
    out
}

/// Each shaft's 1× and 2× line (where it is a line of that shaft's own class).
fn shaft_lines(map: &LineMap, top: f64, at: &dyn Fn(f64) -> f64) -> Vec<Line> {
    let mut out = Vec::new();
    for s in &map.shafts {
        for h in [1u8, 2] {
            let o = h as f64 * s.rate;
            if o >= top {
                continue;
            }
            if let Some((Class::ShaftLine { .. }, feature)) = map.feature_at(o, true) {
                out.push(Line {
                    order: o,
                    kind: "shaft",
                    label: format!("{h}× {}", s.name),
                    part: format!("the {} shaft, {h}× its rate", s.name),
                    feature,
                    level_db: at(o),
                });
            }
        }
    }
    out
}
