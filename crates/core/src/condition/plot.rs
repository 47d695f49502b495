//! What a record's page draws to show its evidence ([`super::evidence`]): the deciding
//! channel's order spectrum and envelope spectrum as the evidence reads them (resampled to the
//! input shaft's measured angle over whole common periods), with the lines the findings rest
//! on marked and named by part, each carrying the feature it feeds — so a finding's evidence
//! (`lines.own.idler.near.m16`, `shaft.in.1x`, `bearing.in.bpfi`, …) finds its lines.
//!
//! | spectrum | lines | feature |
//! | --- | --- | --- |
//! | orders | each mesh harmonic with a region of its own | `lines.mesh.<region>` |
//! | orders | its sidebands at ±1 and ±2 × each shaft's rate | `lines.own.<S>.near.<region>` (or `lines.shared.<region>`) |
//! | orders | each shaft's 1× and 2× | `shaft.<S>.1x`, `.2x` |
//! | envelope | each bearing's defect orders, 1–3 × (BPFO, BPFI, 2 × BSF) | `bearing.<b>.<defect>` |
//! | envelope | each shaft's rate, 1× and 2× | `env.own.<S>` (or `env.shared`) |
//!
//! Levels are in dB re 1 unit of the record's samples (the channel's unit), so a record and a
//! healthy record of the same machine compare directly. The traces are reduced to at most
//! [`MAX_TRACE_POINTS`] points by keeping the largest bin of each group (lines survive); each
//! line's level is read at its own bin.

use serde::Serialize;

use super::evidence::{Angular, BEARING_SLIP, bearing_lines, envelope, envelope_band};
use super::lines::{Class, LineMap};
pub use super::marked::Line;
use super::marked::{db, level_at, lines_top, marked_lines};
use super::parts::Parts;
use crate::Result;
use crate::signal::order::ShaftAngle;
use crate::signal::{Window, amplitude_spectrum};

/// Largest number of points of a trace.
pub const MAX_TRACE_POINTS: usize = 3000;
/// The envelope spectrum is drawn up to this much above its highest marked line.
const ENVELOPE_MARGIN: f64 = 1.1;

/// A spectrum on a uniform order axis: point `i` is at order `start + i · step`, the largest
/// bin of its group.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Trace {
    pub start: f64,
    pub step: f64,
    /// dB re 1 unit of the record's samples, 0.1 dB steps.
    pub level_db: Vec<f32>,
}

/// A shaft and its rate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlotShaft {
    pub name: String,
    /// Its rate in input-shaft orders.
    pub order: f64,
}

/// A region of the order axis (`low`, `m<h>`, `high`): a finding on a whole line class of a
/// region (`lines.none.m16`) points at it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlotRegion {
    pub name: String,
    pub lo: f64,
    pub hi: f64,
}

/// The envelope spectrum and its lines.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnvelopePlot {
    /// The band demodulated, in orders.
    pub band: [f64; 2],
    pub trace: Trace,
    pub lines: Vec<Line>,
}

/// What the record page draws (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvidencePlot {
    /// The channel drawn (the deciding one).
    pub channel: String,
    pub input_shaft: String,
    /// The measured mean input-shaft rate (Hz): order × this = Hz.
    pub shaft_hz: f64,
    /// Input revolutions analysed.
    pub revolutions: usize,
    pub shafts: Vec<PlotShaft>,
    pub regions: Vec<PlotRegion>,
    /// The order spectrum up to the last mesh region.
    pub orders: Trace,
    pub lines: Vec<Line>,
    /// `None` when the record's band above the meshes is too narrow for an envelope.
    pub envelope: Option<EnvelopePlot>,
}

/// The evidence plot of channel `channel` (`x` sampled at `fs`) from the input shaft's
/// measured `angle` and the gearbox's `parts`.
///
/// Errors: those of the resampling (a record and an angle of different lengths).
pub fn evidence_plot(
    channel: &str,
    x: &[f64],
    fs: f64,
    angle: &ShaftAngle,
    parts: &Parts,
) -> Result<EvidencePlot> {
    let map = LineMap::of(parts);
    let a = Angular::of(x, fs, angle, &map)?;
    let spec = amplitude_spectrum(&a.samples, a.p as f64, Window::Hann)?;
    let bpo = a.layout.revolutions as f64;
    let top = lines_top(&map, a.max_order);
    let amp = &spec.amplitude[..((top * bpo) as usize + 1).min(spec.amplitude.len())];
    let lines = marked_lines(&map, parts, amp, bpo, top);
    let envelope = envelope_plot(&a, &map, parts)?;
    Ok(EvidencePlot {
        channel: channel.to_string(),
        input_shaft: parts.input_shaft.clone(),
        shaft_hz: angle.summary.mean_hz,
        revolutions: a.layout.revolutions,
        shafts: map
            .shafts
            .iter()
            .map(|s| PlotShaft {
                name: s.name.clone(),
                order: s.rate,
            })
            .collect(),
        regions: map
            .regions
            .iter()
            .map(|r| PlotRegion {
                name: r.name.clone(),
                lo: r.lo,
                hi: r.hi,
            })
            .collect(),
        orders: trace(amp, bpo),
        lines,
        envelope,
    })
}

/// `amp` (bins `bpo` to an order) as a [`Trace`] of at most [`MAX_TRACE_POINTS`] points.
fn trace(amp: &[f64], bpo: f64) -> Trace {
    let group = amp.len().div_ceil(MAX_TRACE_POINTS).max(1);
    let level_db = amp
        .chunks(group)
        .map(|g| db(g.iter().fold(0.0f64, |m, &v| m.max(v))) as f32)
        .collect();
    let step = group as f64 / bpo;
    Trace {
        // A group's point sits at its middle bin.
        start: (group - 1) as f64 / 2.0 / bpo,
        step,
        level_db,
    }
}

/// The envelope spectrum of the band above the meshes (as the evidence demodulates it), with
/// each bearing's defect orders and each shaft's rate.
fn envelope_plot(a: &Angular, map: &LineMap, parts: &Parts) -> Result<Option<EnvelopePlot>> {
    let Some(lo) = envelope_band(map, a.max_order) else {
        return Ok(None);
    };
    let mut env = envelope(&a.samples, a.p, lo, a.max_order);
    let m = env.iter().sum::<f64>() / env.len() as f64;
    env.iter_mut().for_each(|v| *v -= m);
    let spec = amplitude_spectrum(&env, a.p as f64, Window::Hann)?;
    let bpo = a.layout.revolutions as f64;
    let amp = &spec.amplitude;
    let mut lines = Vec::new();
    for (bearing, defect, shaft, orders) in bearing_lines(parts) {
        let name = match defect {
            "bsf" => "2BSF".to_string(),
            d => d.to_uppercase(),
        };
        for (h, &o) in orders.iter().enumerate() {
            let c = o * bpo;
            lines.push(Line {
                order: o,
                kind: "bearing",
                label: format!("{name} {bearing} ×{}", h + 1),
                part: format!(
                    "bearing {bearing} (on {shaft}): {} × {}",
                    h + 1,
                    defect_words(defect)
                ),
                feature: format!("bearing.{bearing}.{defect}"),
                level_db: level_at(amp, c, (BEARING_SLIP * c).max(1.0)),
            });
        }
    }
    for s in &map.shafts {
        for h in [1u8, 2] {
            let o = h as f64 * s.rate;
            let feature = match map.feature_at(o, false) {
                Some((Class::Own { .. }, f)) | Some((Class::Shared, f)) => f
                    .strip_prefix("lines.")
                    .and_then(|f| f.strip_suffix(".low"))
                    .map(|f| format!("env.{f}")),
                _ => None,
            };
            lines.push(Line {
                order: o,
                kind: "shaft-rate",
                label: format!("{h}× {}", s.name),
                part: format!("the {} shaft's rate, {h}×", s.name),
                feature: feature.unwrap_or_default(),
                level_db: level_at(amp, o * bpo, 1.0),
            });
        }
    }
    lines.sort_by(|a, b| a.order.total_cmp(&b.order));
    let hi = lines.iter().fold(0.0f64, |m, l| m.max(l.order)) * ENVELOPE_MARGIN;
    let n = ((hi.min(0.5 * a.max_order) * bpo) as usize + 1).min(amp.len());
    lines.retain(|l| l.order * bpo < n as f64);
    Ok(Some(EnvelopePlot {
        band: [lo, a.max_order],
        trace: trace(&amp[..n], bpo),
        lines,
    }))
}

fn defect_words(defect: &str) -> &'static str {
    match defect {
        "bpfo" => "the outer-race defect order (BPFO)",
        "bpfi" => "the inner-race defect order (BPFI)",
        _ => "the ball defect order (twice BSF)",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gearbox::Gearbox;
    use crate::signal::order::track_tachometer;
    use std::f64::consts::TAU;

    fn helical() -> Gearbox {
        Gearbox::parse(
            include_str!("../../../../configs/gearboxes/phm09-helical.toml"),
            "test",
        )
        .unwrap()
    }

    /// A 16θ mesh tone modulated once per idler revolution, an input-shaft 1× line and an
    /// impact train at the input bearing's BPFI, 32 Hz, 8 s at 8192 Hz.
    fn record(fs: f64, f: f64, n: usize) -> (Vec<f64>, ShaftAngle) {
        let parts = Parts::of(&helical());
        let bpfi = parts.bearings[0].orders.bpfi;
        let tach: Vec<f64> = (0..n)
            .map(|i| f64::from((i as f64 / fs * f * 4.0).fract() < 0.3))
            .collect();
        let angle = track_tachometer(&tach, fs, 4).unwrap();
        let x = (0..n)
            .map(|i| {
                let th = TAU * f * i as f64 / fs;
                let since = (th * bpfi / TAU).fract() / (f * bpfi);
                (1.0 + 0.3 * (th / 3.0).cos()) * (16.0 * th).cos()
                    + 0.2 * th.cos()
                    + 2.0 * (-since * 600.0).exp() * (TAU * 2500.0 * since).sin()
            })
            .collect();
        (x, angle)
    }

    #[test]
    fn the_lines_sit_on_the_records_peaks_and_name_their_features() {
        let (fs, f) = (8192.0, 32.0);
        let (x, angle) = record(fs, f, 8192 * 8);
        let parts = Parts::of(&helical());
        let p = evidence_plot("a1", &x, fs, &angle, &parts).unwrap();
        assert!((p.shaft_hz - f).abs() < 0.01, "{}", p.shaft_hz);
        assert!(p.orders.level_db.len() <= MAX_TRACE_POINTS);
        // Sideband labels repeat around each harmonic: the first at or above 10 orders.
        let line = |kind: &str, label: &str| {
            p.lines
                .iter()
                .filter(|l| l.kind != "sideband" || l.order > 10.0)
                .chain(p.envelope.iter().flat_map(|e| &e.lines))
                .find(|l| l.kind == kind && l.label == label)
                .unwrap_or_else(|| panic!("no {kind} {label}: {:?}", p.lines))
                .clone()
        };
        // The carrier (amplitude 1: 0 dB), its idler sidebands (0.15: −16.5 dB), the 1× line
        // (0.2: −14 dB); the output shaft's sidebands are absent (far below).
        let mesh = line("mesh", "GM1 ×1 = GM2 ×2");
        assert_eq!(mesh.feature, "lines.mesh.m16");
        assert!(mesh.level_db.abs() < 0.5, "{mesh:?}");
        let sb = line("sideband", "+1 idler");
        assert_eq!(sb.feature, "lines.own.idler.near.m16");
        assert!((sb.level_db + 16.5).abs() < 0.5, "{sb:?}");
        assert!(line("sideband", "+1 out").level_db < sb.level_db - 30.0);
        let one = line("shaft", "1× in");
        assert_eq!(one.feature, "shaft.in.1x");
        assert!((one.level_db + 14.0).abs() < 0.5, "{one:?}");
        // The impacts: the input bearing's BPFI line stands out in the envelope, above the
        // outer race's.
        let bpfi = line("bearing", "BPFI in ×1");
        assert_eq!(bpfi.feature, "bearing.in.bpfi");
        assert!(bpfi.level_db > line("bearing", "BPFO in ×1").level_db + 10.0);
        assert_eq!(line("shaft-rate", "1× idler").feature, "env.own.idler");
        // The trace keeps the peaks its points group.
        let o = &p.orders;
        let i = ((16.0 - o.start) / o.step).round() as usize;
        let near = o.level_db[i.saturating_sub(1)..=i + 1]
            .iter()
            .fold(f32::MIN, |m, &v| m.max(v));
        assert!((f64::from(near) - mesh.level_db).abs() < 0.2, "{near}");
    }
}
