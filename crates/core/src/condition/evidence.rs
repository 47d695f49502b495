//! Speed-free evidence of one record (one channel), per line class and region of the order
//! spectrum ([`super::lines`]), per bearing and per shaft.
//!
//! The record is resampled to `p` samples per revolution of the input shaft from its measured
//! angle ([`crate::signal::order::angular_resample`]), over a whole number of common periods
//! ([`super::lines::LineMap::layout`]); its Hann amplitude spectrum is then a spectrum in
//! **orders** on which every shaft's harmonics fall on bins. Every feature is a natural
//! logarithm of an amplitude (the square root of a class's energy), so a change reads as a
//! ratio (`Δ = 0.115` ≈ 1 dB):
//!
//! | feature | what it is | what raises it |
//! | --- | --- | --- |
//! | `lines.<class>.<region>` | energy of a line class in a region ([`super::lines`]) | `own.S`: a fault once per revolution of `S`; `shared`: any shaft; `mesh`: load, wear, path; `none`: non-synchronous vibration |
//! | `shaft.<S>.1x`, `.2x` | the shaft's 1× and 2× lines | imbalance, bent shaft (1×), misalignment (2×) |
//! | `env.own.<S>`, `env.shared`, `env.none` | the same classes in the envelope spectrum's low orders | impacts once per revolution of `S`; non-synchronous impacts |
//! | `env.level` | RMS of the envelope band | any impacting |
//! | `bearing.<b>.<defect>` | envelope spectrum at 1..3 × the defect order (±1 %, rolling elements slip) | a bearing defect: `bpfo` outer race, `bpfi` inner race, `bsf` ball |
//! | `tsa.<S>.fm4`, `na4`, `m6a`, `kurtosis`, `er` | metrics of `S`'s time-synchronous average ([`crate::signal::tsa`]) | a local tooth fault (impulsiveness) |
//! | `stat.rms`, `stat.kurtosis` | of the raw record | anything |
//!
//! A bearing harmonic that a bearing of another shaft shares is left out of both bearings'
//! sums (it would name the wrong one). The envelope band spans from just above the mesh
//! regions ([`super::lines::MESH_REGION_ORDERS`] × the highest mesh order, where the mesh
//! harmonics dominate) to 0.45 × the sample rate.
//!
//! # Repeatability within the record
//! The same features are computed on the record's quarters (each a whole number of common
//! periods; halves when fewer than four periods fit): their spread is the record's own
//! repeatability, from which a baseline scales a feature's change at a state
//! ([`super::calibration`]).

use std::collections::BTreeMap;

use rustfft::num_complex::Complex64;

use super::lines::{Layout, LineMap};
use super::machine_model::LineLevel;
use super::marked::{lines_top, marked_lines};
use super::parts::Parts;
use crate::Result;
use crate::signal::order::{ShaftAngle, angular_resample, samples_per_rev_for};
use crate::signal::tsa::{OrderAnalysis, ShaftTrain, order_analysis_at};
use crate::signal::{PlanCache, Spectrum, Window, amplitude_spectrum, kurtosis, rms};

/// Highest order kept, relative to the record's Nyquist order.
const NYQUIST_SHARE: f64 = 0.9;
/// Relative tolerance of a bearing line (its rolling elements slip).
pub(super) const BEARING_SLIP: f64 = 0.01;
/// Version of the features' definitions: a baseline fits only records of its own version.
pub const EVIDENCE_VERSION: u32 = 2;

/// A channel's evidence: the features of the whole record and each feature's noise in it,
/// from its spread over the record's segments (ln units).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Evidence {
    pub values: BTreeMap<String, f64>,
    pub spread: BTreeMap<String, f64>,
    /// The level of each marked line (mesh harmonics, their sidebands, shaft lines): what a
    /// machine's model is calibrated on ([`super::machine_model`]).
    pub lines: Vec<LineLevel>,
    /// Why the record's own resolution stood in for the common period, when it did.
    pub note: Option<String>,
}

/// An order spectrum: amplitude per bin, `bins_per_order` bins per order.
struct Orders {
    spectrum: Spectrum,
    bins_per_order: f64,
    max_order: f64,
}

impl Orders {
    fn new(x: &[f64], samples_per_rev: usize, max_order: f64) -> Result<Orders> {
        let spectrum = amplitude_spectrum(x, samples_per_rev as f64, Window::Hann)?;
        let bins_per_order = x.len() as f64 / samples_per_rev as f64;
        Ok(Orders {
            spectrum,
            bins_per_order,
            max_order,
        })
    }

    /// Largest amplitude within `o ± max(1 bin, rel·o)`; `None` above the usable orders.
    fn peak(&self, o: f64, rel: f64) -> Option<f64> {
        if !(o > 0.0 && o < self.max_order) {
            return None;
        }
        let c = o * self.bins_per_order;
        let half = (rel * c).max(1.0);
        let lo = (c - half).round().max(1.0) as usize;
        let hi = ((c + half).round() as usize).min(self.spectrum.amplitude.len() - 1);
        (lo <= hi).then(|| {
            self.spectrum.amplitude[lo..=hi]
                .iter()
                .fold(0.0f64, |a, &b| a.max(b))
        })
    }

    /// RMS of the peaks at the given orders (those in range); `None` when none is.
    fn rms_of(&self, orders: impl IntoIterator<Item = f64>, rel: f64) -> Option<f64> {
        let v: Vec<f64> = orders
            .into_iter()
            .filter_map(|o| self.peak(o, rel))
            .collect();
        (!v.is_empty()).then(|| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt())
    }

    fn bin(&self) -> f64 {
        1.0 / self.bins_per_order
    }
}

/// `ln v` of a positive finite value.
fn ln(v: f64) -> Option<f64> {
    (v.is_finite() && v > 0.0).then(|| v.ln())
}

/// The largest whole number of revolutions ≤ `r` whose only prime factors are 2, 3 and 5
/// (a fast FFT length with a power-of-two `p`): the layout without a common period.
fn smooth_revolutions(r: usize) -> usize {
    (1..=r)
        .rev()
        .find(|&m| {
            let mut k = m;
            for p in [2, 3, 5] {
                while k % p == 0 {
                    k /= p;
                }
            }
            k == 1
        })
        .unwrap_or(1)
}

/// The evidence of one channel (see the [module docs](self)): `x` sampled at `fs`, `angle`
/// the input shaft's measured angle over the same samples, `order` the channel's per-shaft
/// TSA from that angle when computed.
///
/// Errors: a record and an angle of different lengths, or under two revolutions.
pub fn evidence(
    x: &[f64],
    fs: f64,
    angle: &ShaftAngle,
    parts: &Parts,
    order: Option<&OrderAnalysis>,
) -> Result<Evidence> {
    let map = LineMap::of(parts);
    let Angular {
        samples,
        p,
        layout,
        max_order,
    } = Angular::of(x, fs, angle, &map)?;
    let (mut values, spec) = angular_features(&samples, p, &layout, &map, parts, max_order)?;
    let bpo = layout.revolutions as f64;
    let top = lines_top(&map, max_order);
    let amp = &spec.amplitude[..((top * bpo) as usize + 1).min(spec.amplitude.len())];
    let lines = marked_lines(&map, parts, amp, bpo, top)
        .iter()
        .filter_map(LineLevel::of)
        .collect();
    if let Some(a) = order {
        tsa_features(a, &mut values);
    }
    stat_features(x, &mut values);
    let spread = spread(x, fs, angle, &samples, p, &layout, &map, parts, max_order)?;
    Ok(Evidence {
        values,
        spread,
        lines,
        note: map.resolution_note(&layout),
    })
}

/// A record resampled to the input shaft's angle as the evidence reads it: `p` samples per
/// revolution over the [`Layout`]'s revolutions, and the highest order kept.
pub(super) struct Angular {
    pub samples: Vec<f64>,
    pub p: usize,
    pub layout: Layout,
    pub max_order: f64,
}

impl Angular {
    /// `x` sampled at `fs`, resampled from the input shaft's measured `angle` over a whole
    /// number of common periods of `map` (or a 2-3-5-smooth number of revolutions).
    pub fn of(x: &[f64], fs: f64, angle: &ShaftAngle, map: &LineMap) -> Result<Angular> {
        let f_in = angle.summary.mean_hz;
        let p = samples_per_rev_for(fs, f_in);
        let max_order = NYQUIST_SHARE * 0.5 * fs / f_in;
        let mut res = angular_resample(x, angle, 1.0, p)?;
        let mut layout = map.layout(res.revolutions);
        if layout.periods.is_none() {
            layout.revolutions = smooth_revolutions(res.revolutions);
        }
        res.samples.truncate(layout.revolutions * p);
        Ok(Angular {
            samples: res.samples,
            p,
            layout,
            max_order,
        })
    }
}

/// Segments a record's repeatability is measured on: quarters, each a whole number of
/// common periods when the record holds at least four; else halves.
const SEGMENTS: usize = 4;

/// `sqrt(median(χ²_{K−1} / (K − 1)))`: the median of the standard deviation of `K` normal
/// values over their standard deviation (K = 2, 3, 4).
fn sd_median_factor(k: usize) -> f64 {
    match k {
        2 => 0.6745,
        3 => 0.8326,
        _ => 0.8881,
    }
}

/// Each feature's noise in the whole record, from its spread over the record's segments: the
/// standard deviation `sd` of its values on `K` segments (each a whole number of common
/// periods on a grid, else an equal share of the revolutions), over `√K` (a segment holds
/// `1/K` of the record, so `K` times its variance) and over the median-unbiasing factor
/// [`sd_median_factor`] (a baseline takes the median over its records). TSA metrics come
/// from each segment's own averages. Empty when the record holds fewer than two segments.
#[allow(clippy::too_many_arguments)]
fn spread(
    x: &[f64],
    fs: f64,
    angle: &ShaftAngle,
    resampled: &[f64],
    p: usize,
    layout: &Layout,
    map: &LineMap,
    parts: &Parts,
    max_order: f64,
) -> Result<BTreeMap<String, f64>> {
    let (k, seg) = match layout.periods {
        Some(n) if n >= 2 => {
            let k = SEGMENTS.min(n);
            let per = layout.revolutions / n;
            (
                k,
                Layout {
                    revolutions: per * (n / k),
                    periods: Some(n / k),
                },
            )
        }
        Some(_) => return Ok(BTreeMap::new()),
        None if layout.revolutions >= 2 * SEGMENTS => (
            SEGMENTS,
            Layout {
                revolutions: smooth_revolutions(layout.revolutions / SEGMENTS),
                periods: None,
            },
        ),
        None => return Ok(BTreeMap::new()),
    };
    let len = seg.revolutions * p;
    let train = train_of(parts);
    let mut sides = Vec::with_capacity(k);
    for i in 0..k {
        let part = &resampled[i * len..(i + 1) * len];
        let (mut v, _) = angular_features(part, p, &seg, map, parts, max_order)?;
        // The samples of the same revolutions, for the TSA and the statistics.
        let (a, b) = sample_span(angle, i * seg.revolutions, (i + 1) * seg.revolutions);
        if b > a + 1 {
            let sub = sub_angle(angle, a, b);
            if let Ok(oa) = order_analysis_at(&x[a..b], fs, &train, &sub) {
                tsa_features(&oa, &mut v);
            }
            stat_features(&x[a..b], &mut v);
        }
        sides.push(v);
    }
    let norm = (k as f64).sqrt() * sd_median_factor(k);
    Ok(sides[0]
        .keys()
        .filter_map(|f| {
            let v: Vec<f64> = sides.iter().filter_map(|s| s.get(f).copied()).collect();
            (v.len() == k).then(|| {
                let m = v.iter().sum::<f64>() / k as f64;
                let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k - 1) as f64;
                (f.clone(), var.sqrt() / norm)
            })
        })
        .collect())
}

/// The shaft train of a gearbox's parts (what the TSA needs).
fn train_of(parts: &Parts) -> ShaftTrain {
    ShaftTrain {
        input_shaft: parts.input_shaft.clone(),
        mesh_order: parts.meshes.first().copied().unwrap_or(1.0),
        shafts: parts.shafts.clone(),
        meshes: parts.meshes.clone(),
    }
}

/// The samples `[a, b)` over which the input shaft turns from revolution `r0` to `r1` of the
/// angle's usable part.
fn sample_span(angle: &ShaftAngle, r0: usize, r1: usize) -> (usize, usize) {
    let (lo, hi) = angle.usable;
    let start = angle.revs[lo];
    let at = |r: usize| {
        let target = start + r as f64;
        lo + angle.revs[lo..=hi].partition_point(|&v| v < target)
    };
    (at(r0), at(r1).min(hi + 1))
}

/// The angle over samples `[a, b)`, as a track of its own.
fn sub_angle(angle: &ShaftAngle, a: usize, b: usize) -> ShaftAngle {
    let r0 = angle.revs[a];
    let revs: Vec<f64> = angle.revs[a..b].iter().map(|r| r - r0).collect();
    let span = revs.last().copied().unwrap_or(0.0);
    let mut summary = angle.summary.clone();
    summary.revolutions = span;
    if b > a + 1 {
        summary.mean_hz = span * angle.sample_rate / (b - a - 1) as f64;
    }
    ShaftAngle {
        revs,
        sample_rate: angle.sample_rate,
        usable: (0, b - a - 1),
        summary,
    }
}

/// The features read from the record in the input shaft's angle: line classes, shaft lines,
/// the envelope's classes, level and bearing lines; and the order spectrum they were read from.
fn angular_features(
    samples: &[f64],
    p: usize,
    layout: &Layout,
    map: &LineMap,
    parts: &Parts,
    max_order: f64,
) -> Result<(BTreeMap<String, f64>, Spectrum)> {
    let spec = amplitude_spectrum(samples, p as f64, Window::Hann)?;
    let mut out = BTreeMap::new();
    for (k, e) in map.energies(&spec.amplitude, layout, max_order, true) {
        if let Some(v) = ln(e.sqrt()) {
            out.insert(k, v);
        }
    }
    envelope_features(samples, p, layout, map, parts, max_order, &mut out)?;
    Ok((out, spec))
}

/// `tsa.<S>.<metric>` from a per-shaft TSA.
fn tsa_features(a: &OrderAnalysis, out: &mut BTreeMap<String, f64>) {
    for s in &a.shafts {
        let m = &s.metrics;
        for (k, v) in [
            ("fm4", m.fm4),
            ("na4", m.na4),
            ("m6a", m.m6a),
            ("kurtosis", m.kurtosis),
            ("er", m.er),
        ] {
            if let Some(v) = v.and_then(ln) {
                out.insert(format!("tsa.{}.{k}", s.shaft), v);
            }
        }
    }
}

/// `stat.rms` and `stat.kurtosis` of the raw record.
fn stat_features(x: &[f64], out: &mut BTreeMap<String, f64>) {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    let xc: Vec<f64> = x.iter().map(|v| v - m).collect();
    for (k, v) in [("stat.rms", rms(&xc)), ("stat.kurtosis", kurtosis(&xc))] {
        if let Some(v) = ln(v) {
            out.insert(k.into(), v);
        }
    }
}

/// The lower edge (orders) of the envelope band: just above the mesh regions; `None` when
/// that leaves no band below `max_order`.
pub(super) fn envelope_band(map: &LineMap, max_order: f64) -> Option<f64> {
    let top_mesh = map.meshes.iter().fold(0.0f64, |a, &b| a.max(b));
    let lo = (super::lines::MESH_REGION_ORDERS + 0.5) * top_mesh;
    (lo < 0.5 * max_order).then_some(lo)
}

/// The envelope of `x` (samples in the input shaft's angle, `p` per revolution) in the band
/// `lo..hi` (orders): the magnitude of the band's analytic signal.
pub(super) fn envelope(x: &[f64], p: usize, lo: f64, hi: f64) -> Vec<f64> {
    let n = x.len();
    let mut buf: Vec<Complex64> = x.iter().map(|&v| Complex64::new(v, 0.0)).collect();
    PlanCache::global().complex(n, false).process(&mut buf);
    let orders_per_bin = p as f64 / n as f64;
    for (k, c) in buf.iter_mut().enumerate() {
        let o = k as f64 * orders_per_bin;
        *c = if k > 0 && k < n / 2 && o >= lo && o <= hi {
            *c * 2.0
        } else {
            Complex64::new(0.0, 0.0)
        };
    }
    PlanCache::global().complex(n, true).process(&mut buf);
    let inv_n = 1.0 / n as f64;
    buf.iter().map(|c| c.norm() * inv_n).collect()
}

/// `env.level`, `env.own.<S>`, `env.shared`, `env.none` and `bearing.<b>.<defect>` from the
/// envelope spectrum.
fn envelope_features(
    x: &[f64],
    p: usize,
    layout: &Layout,
    map: &LineMap,
    parts: &Parts,
    max_order: f64,
    out: &mut BTreeMap<String, f64>,
) -> Result<()> {
    let Some(lo) = envelope_band(map, max_order) else {
        return Ok(());
    };
    let mut env = envelope(x, p, lo, max_order);
    if let Some(v) = ln(rms(&env)) {
        out.insert("env.level".into(), v);
    }
    let m = env.iter().sum::<f64>() / env.len() as f64;
    env.iter_mut().for_each(|v| *v -= m);
    let spec = Orders::new(&env, p, max_order)?;
    for (k, e) in map.energies(&spec.spectrum.amplitude, layout, max_order, false) {
        if let Some(class) = k
            .strip_prefix("lines.")
            .and_then(|k| k.strip_suffix(".low"))
            && let Some(v) = ln(e.sqrt())
        {
            out.insert(format!("env.{class}"), v);
        }
    }
    let lines = bearing_lines(parts);
    for (i, (bearing, name, shaft, orders)) in lines.iter().enumerate() {
        // A harmonic that a bearing of another shaft also puts there (ER-10K bearings on
        // shafts turning 3:1 share 3 · BPFI · r_idler = BPFI · r_in) would name the wrong one.
        let own: Vec<f64> = orders
            .iter()
            .copied()
            .filter(|&o| {
                lines.iter().enumerate().all(|(j, other)| {
                    j == i
                        || other.2 == *shaft
                        || other
                            .3
                            .iter()
                            .all(|&p| (p - o).abs() > (BEARING_SLIP * o).max(1.5 * spec.bin()))
                })
            })
            .collect();
        if let Some(v) = spec.rms_of(own, BEARING_SLIP).and_then(ln) {
            out.insert(format!("bearing.{bearing}.{name}"), v);
        }
    }
    Ok(())
}

/// A bearing's defect lines: bearing, defect, shaft, orders of harmonics 1..3.
pub(super) type BearingLine = (String, &'static str, String, Vec<f64>);

/// Every described bearing's defect lines in input-shaft orders; the ball line is read at
/// 2 × BSF (a ball defect strikes both races once per spin). The cage's own frequency (FTF,
/// ≈ 0.4 × the shaft rate) is not read: it sits among the shafts' first lines, within the
/// rolling elements' slip of them, and a cage defect shows as a modulation of the other lines.
pub(super) fn bearing_lines(parts: &Parts) -> Vec<BearingLine> {
    let mut v = Vec::new();
    for b in &parts.bearings {
        let rs = parts.shafts.get(&b.shaft).copied().unwrap_or(0.0);
        let o = &b.orders;
        for (name, d) in [("bpfo", o.bpfo), ("bpfi", o.bpfi), ("bsf", 2.0 * o.bsf)] {
            let orders = (1..=3).map(|h| h as f64 * d * rs).collect();
            v.push((b.name.clone(), name, b.shaft.clone(), orders));
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gearbox::Gearbox;
    use crate::signal::order::track_tachometer;
    use std::f64::consts::TAU;

    fn helical() -> Gearbox {
        Gearbox::parse(
            "format = \"gearwear-gearbox\"\nversion = 1\nname = \"h\"\ninput_shaft = \"in\"\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"in\", teeth = 16 }\n\
             gear = { shaft = \"idler\", teeth = 48 }\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"idler\", teeth = 24 }\n\
             gear = { shaft = \"out\", teeth = 40 }\n",
            "test",
        )
        .unwrap()
    }

    fn tach(n: usize, fs: f64, f: f64) -> ShaftAngle {
        let t: Vec<f64> = (0..n)
            .map(|i| {
                if (i as f64 / fs * f * 4.0).fract() < 0.3 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        track_tachometer(&t, fs, 4).unwrap()
    }

    /// Mesh 2 (8 × the input rate) amplitude-modulated at the idler's rate (1/3 order) puts
    /// its sidebands in the idler's own lines near mesh 2 — none in the output's, none in the
    /// `none` class beyond the window's leakage; the carriers read as mesh lines.
    #[test]
    fn sidebands_land_in_the_modulating_shafts_own_lines() {
        let parts = Parts::of(&helical());
        let (fs, f) = (8192.0, 32.0);
        let n = 8192 * 8; // 256 revolutions: 17 common periods of 15
        let angle = tach(n, fs, f);
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let th = TAU * f * i as f64 / fs;
                (1.0 + 0.3 * (th / 3.0).cos()) * (8.0 * th).cos() + 0.5 * (16.0 * th).cos()
            })
            .collect();
        let e = evidence(&x, fs, &angle, &parts, None).unwrap();
        let v = |k: &str| e.values.get(k).map_or(0.0, |v| v.exp());
        // Each sideband 0.15 over its three bins (1 + 2 × 0.25 of the energy): 2 × 1.5 × 0.0225.
        let sb = v("lines.own.idler.near.m8");
        assert!((sb - (2.0 * 1.5 * 0.0225f64).sqrt()).abs() < 0.01, "{e:?}");
        assert!(v("lines.own.out.near.m8") < 0.01 * sb, "{e:?}");
        assert!(v("lines.own.idler.far.m8") < 0.01 * sb, "{e:?}");
        // The carrier of mesh 2 (1) and mesh 1 (0.5) over three bins each.
        assert!((v("lines.mesh.m8") - 1.5f64.sqrt()).abs() < 0.02, "{e:?}");
        assert!(
            (v("lines.mesh.m16") - (0.25 * 1.5f64).sqrt()).abs() < 0.02,
            "{e:?}"
        );
        assert!(e.note.is_none());
        // The quarters of a stationary record agree.
        let d = e.spread["lines.own.idler.near.m8"];
        assert!(d.abs() < 0.01, "{d}");
    }

    #[test]
    fn smooth_revolutions_are_235_smooth() {
        assert_eq!(smooth_revolutions(61), 60);
        assert_eq!(smooth_revolutions(7), 6);
        assert_eq!(smooth_revolutions(1), 1);
    }
}
