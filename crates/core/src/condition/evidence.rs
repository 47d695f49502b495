//! Speed-free evidence of one record (one channel), per shaft, mesh and bearing.
//!
//! The record is resampled to `P` samples per revolution of the input shaft from its measured
//! angle ([`crate::signal::order::angular_resample`]), over a whole number of revolutions `R`;
//! its Hann amplitude spectrum is then a spectrum in **orders** (multiples of the input rate)
//! with resolution `1/R`, and a line of a shaft or a mesh sits at the same order at every
//! speed. Every feature is a natural logarithm, so a change reads as a ratio
//! (`Δ = 0.115` ≈ 1 dB of amplitude):
//!
//! | feature | what it is | what raises it |
//! | --- | --- | --- |
//! | `mesh<i>.h<k>` | amplitude of the k-th harmonic of stage i's mesh | wear, load |
//! | `mesh<i>.h<k>.sb.<s>` | RMS of the sidebands `k·O_i ± j·r_s` at the first three multiples j of shaft s's rate that only s makes | a gear on s modulating the mesh: local damage, eccentricity |
//! | `shaft.<s>.1x`, `.2x` | amplitude at 1× and 2× shaft s's rate | imbalance, bent shaft (1×), misalignment (2×) |
//! | `tsa.<s>.fm4`, `na4`, `m6a`, `kurtosis`, `er` | metrics of s's time-synchronous average ([`crate::signal::tsa`]) | a once-per-revolution impact of a damaged tooth on s |
//! | `env.<s>` | envelope spectrum at the first three multiples of r_s that only s makes | impacts once per revolution of s |
//! | `bearing.<b>.<defect>` | envelope spectrum at 1..3 × the defect order (±1 %, rolling elements slip) | a bearing defect: `bpfo` outer race, `bpfi` inner race, `bsf` ball, `ftf` cage |
//! | `env.level` | RMS of the envelope band | any impacting |
//! | `stat.rms`, `stat.kurtosis` | of the raw record | anything |
//!
//! A line counts for a shaft only where no faster shaft also puts one ([`specific_to`]: in a
//! train of commensurate rates, a slower shaft's comb contains the faster shafts' harmonics),
//! and a sideband that falls on a mesh harmonic is left out (it would be counted for the
//! wrong part). A bearing harmonic that a bearing of another shaft shares is left out of that
//! bearing's sum for the same reason. The envelope band
//! spans from 3.5 × the highest mesh order (above the mesh harmonics that dominate the raw
//! spectrum) to 0.45 × the sample rate.

use std::collections::BTreeMap;

use rustfft::num_complex::Complex64;

use super::parts::Parts;
use crate::Result;
use crate::signal::order::{ShaftAngle, angular_resample, samples_per_rev_for};
use crate::signal::tsa::OrderAnalysis;
use crate::signal::{PlanCache, Spectrum, Window, amplitude_spectrum, kurtosis, rms};

/// Sideband orders j = 1..=SIDEBANDS around a mesh harmonic.
const SIDEBANDS: usize = 3;
/// Mesh harmonics k = 1..=MESH_HARMONICS.
const MESH_HARMONICS: usize = 3;
/// Highest order kept, relative to the record's Nyquist order.
const NYQUIST_SHARE: f64 = 0.9;

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
/// (a fast FFT length with a power-of-two `P`).
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

/// The evidence features of one channel (see the [module docs](self)): `x` sampled at `fs`,
/// `angle` the input shaft's measured angle over the same samples, `order` the channel's
/// per-shaft TSA from that angle when computed.
///
/// Errors: a record and an angle of different lengths, or under two revolutions.
pub fn evidence(
    x: &[f64],
    fs: f64,
    angle: &ShaftAngle,
    parts: &Parts,
    order: Option<&OrderAnalysis>,
) -> Result<BTreeMap<String, f64>> {
    let f_in = angle.summary.mean_hz;
    let p = samples_per_rev_for(fs, f_in);
    let mut res = angular_resample(x, angle, 1.0, p)?;
    let r = smooth_revolutions(res.revolutions);
    res.samples.truncate(r * p);
    let max_order = NYQUIST_SHARE * 0.5 * fs / f_in;
    let spec = Orders::new(&res.samples, p, max_order)?;
    let mut out = BTreeMap::new();
    let mut put = |k: String, v: Option<f64>| {
        if let Some(v) = v.and_then(ln) {
            out.insert(k, v);
        }
    };
    mesh_features(&spec, parts, &mut put);
    for (s, &rate) in &parts.shafts {
        put(format!("shaft.{s}.1x"), spec.peak(rate, 0.0));
        put(format!("shaft.{s}.2x"), spec.peak(2.0 * rate, 0.0));
    }
    envelope_features(&res.samples, p, parts, max_order, &mut put)?;
    if let Some(a) = order {
        for s in &a.shafts {
            let m = &s.metrics;
            for (k, v) in [
                ("fm4", m.fm4),
                ("na4", m.na4),
                ("m6a", m.m6a),
                ("kurtosis", m.kurtosis),
                ("er", m.er),
            ] {
                put(format!("tsa.{}.{k}", s.shaft), v);
            }
        }
    }
    let m = x.iter().sum::<f64>() / x.len() as f64;
    let xc: Vec<f64> = x.iter().map(|v| v - m).collect();
    put("stat.rms".into(), Some(rms(&xc)));
    put("stat.kurtosis".into(), Some(kurtosis(&xc)));
    Ok(out)
}

/// Is an offset `delta` (orders) a multiple of shaft `s`'s rate that **only** `s` makes? In
/// a train whose rates are commensurate, a faster shaft's harmonics are also harmonics of a
/// slower one (1 × the input rate is 3 × the idler's when they turn 3:1): a once-per-revolution
/// impact on the slower shaft raises lines at every multiple of its rate, an impact on the
/// faster one only at its own multiples. So a line counts for `s` when it is not (within 1.5
/// bins) a multiple of any faster shaft's rate; the fastest shaft keeps all its multiples.
fn specific_to(parts: &Parts, s: &str, delta: f64, bin: f64) -> bool {
    let rs = parts.shafts[s];
    parts
        .shafts
        .iter()
        .filter(|(t, rt)| t.as_str() != s && **rt > rs * (1.0 + 1e-9))
        .all(|(_, &rt)| {
            let m = (delta / rt).round();
            m < 1.0 || (delta - m * rt).abs() > 1.5 * bin
        })
}

/// The first `n` multiples of shaft `s`'s rate that are [`specific_to`] it and, when read
/// around `centre` (a mesh harmonic) as sidebands, do not land on a mesh harmonic.
fn specific_offsets(parts: &Parts, s: &str, centre: f64, bin: f64, n: usize) -> Vec<f64> {
    let rs = parts.shafts[s];
    let on_mesh = |o: f64| {
        centre > 0.0
            && parts.meshes.iter().any(|&om| {
                (1..=MESH_HARMONICS + 1).any(|k| {
                    let h = k as f64 * om;
                    (h - (centre + o)).abs() < 1.5 * bin || (h - (centre - o)).abs() < 1.5 * bin
                })
            })
    };
    (1..=4 * n)
        .map(|j| j as f64 * rs)
        .filter(|&d| specific_to(parts, s, d, bin) && !on_mesh(d))
        .take(n)
        .collect()
}

/// `mesh<i>.h<k>` and `mesh<i>.h<k>.sb.<s>` for every stage and every shaft carrying one of
/// its gears.
fn mesh_features(spec: &Orders, parts: &Parts, put: &mut impl FnMut(String, Option<f64>)) {
    for (i, &om) in parts.meshes.iter().enumerate() {
        let stage = i + 1;
        let mut shafts: Vec<&str> = parts
            .gears
            .iter()
            .filter(|g| g.stage == stage)
            .map(|g| g.shaft.as_str())
            .collect();
        shafts.dedup();
        for k in 1..=MESH_HARMONICS {
            let c = k as f64 * om;
            put(format!("mesh{stage}.h{k}"), spec.peak(c, 0.0));
            for s in &shafts {
                let orders: Vec<f64> = specific_offsets(parts, s, c, spec.bin(), SIDEBANDS)
                    .into_iter()
                    .flat_map(|d| [c - d, c + d])
                    .collect();
                put(format!("mesh{stage}.h{k}.sb.{s}"), spec.rms_of(orders, 0.0));
            }
        }
    }
}

/// The envelope of `x` (samples in the input shaft's angle, `p` per revolution) in the band
/// `lo..hi` (orders): the magnitude of the band's analytic signal.
fn envelope(x: &[f64], p: usize, lo: f64, hi: f64) -> Vec<f64> {
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

/// `env.level`, `env.<s>` and `bearing.<b>.<defect>` from the envelope spectrum.
fn envelope_features(
    x: &[f64],
    p: usize,
    parts: &Parts,
    max_order: f64,
    put: &mut impl FnMut(String, Option<f64>),
) -> Result<()> {
    let top_mesh = parts.meshes.iter().fold(0.0f64, |a, &b| a.max(b));
    let lo = 3.5 * top_mesh;
    if !(lo < 0.5 * max_order) {
        return Ok(());
    }
    let mut env = envelope(x, p, lo, max_order);
    put("env.level".into(), Some(rms(&env)));
    let m = env.iter().sum::<f64>() / env.len() as f64;
    env.iter_mut().for_each(|v| *v -= m);
    let spec = Orders::new(&env, p, max_order)?;
    for s in parts.shafts.keys() {
        let orders = specific_offsets(parts, s, 0.0, spec.bin(), 3);
        put(format!("env.{s}"), spec.rms_of(orders, 0.0));
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
        put(
            format!("bearing.{bearing}.{name}"),
            spec.rms_of(own, BEARING_SLIP),
        );
    }
    Ok(())
}

/// Relative tolerance of a bearing line (its rolling elements slip).
const BEARING_SLIP: f64 = 0.01;

/// A bearing's defect lines: bearing, defect, shaft, orders of harmonics 1..3.
type BearingLine = (String, &'static str, String, Vec<f64>);

/// Every described bearing's defect lines in input-shaft orders; the ball line is read at
/// 2 × BSF (a ball defect strikes both races once per spin).
fn bearing_lines(parts: &Parts) -> Vec<BearingLine> {
    let mut v = Vec::new();
    for b in &parts.bearings {
        let rs = parts.shafts.get(&b.shaft).copied().unwrap_or(0.0);
        let o = &b.orders;
        for (name, d) in [
            ("bpfo", o.bpfo),
            ("bpfi", o.bpfi),
            ("bsf", 2.0 * o.bsf),
            ("ftf", o.ftf),
        ] {
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

    /// Mesh 2 (8 × the input rate) amplitude-modulated at the idler's rate (1/3 order) reads as
    /// idler sidebands around mesh 2 — not around mesh 1, not at the input's rate; the mesh
    /// amplitudes are read exactly (Hann, on-bin).
    #[test]
    fn sidebands_name_the_modulating_shaft() {
        let gb = helical();
        let parts = Parts::of(&gb);
        let (fs, f) = (8192.0, 32.0);
        let n = 8192 * 6;
        let tach: Vec<f64> = (0..n)
            .map(|i| {
                if (i as f64 / fs * f * 4.0).fract() < 0.3 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let angle = track_tachometer(&tach, fs, 4).unwrap();
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let th = TAU * f * i as f64 / fs;
                (1.0 + 0.3 * (th / 3.0).cos()) * (8.0 * th).cos() + 0.5 * (16.0 * th).cos()
            })
            .collect();
        let e = evidence(&x, fs, &angle, &parts, None).unwrap();
        let v = |k: &str| e[k].exp();
        assert!((v("mesh2.h1") - 1.0).abs() < 0.02, "{e:?}");
        assert!((v("mesh1.h1") - 0.5).abs() < 0.02, "{e:?}");
        // j = 1 sidebands of 0.15 each; j = 2 and 4 empty; j = 3 left out (3 × 1/3 is the
        // input shaft's 1×, not the idler's alone): RMS over 6 lines = 0.15/√3.
        let sb = v("mesh2.h1.sb.idler");
        assert!((sb - 0.15 / 3f64.sqrt()).abs() < 0.005, "{sb} {e:?}");
        assert!(v("mesh2.h1.sb.out") < 0.01 * sb, "{e:?}");
        assert!(v("mesh1.h1.sb.in") < 0.01 * sb, "{e:?}");
    }

    #[test]
    fn smooth_revolutions_are_235_smooth() {
        assert_eq!(smooth_revolutions(61), 60);
        assert_eq!(smooth_revolutions(7), 6);
        assert_eq!(smooth_revolutions(1), 1);
    }
}
