//! Time-synchronous average (TSA) and the gear condition metrics computed on it.
//!
//! The TSA of a shaft is the mean, over whole revolutions, of the record resampled to `P`
//! samples per revolution of that shaft ([`super::order::angular_resample`]): whatever is not
//! synchronous with the shaft averages out. Bin `k` of its `P`-point DFT is shaft order `k`.
//!
//! # Signals (McFadden 1987; Decker & Lewicki 2003; MATLAB `tsaregular`, `tsaresidual`,
//! `tsadifference`)
//!
//! With `M` the mesh orders of the gears on the shaft and their harmonics (`k·z ≤ P/2`), `S`
//! the low shaft orders `1 ..= SHAFT_HARMONICS` and `B` the first-order sidebands `m ± 1` of
//! every `m ∈ M`, each signal is the TSA (mean removed) keeping only some orders (an exact
//! FFT mask, the TSA being periodic):
//!
//! * **regular** `g`: orders `M ∪ B` — the mesh harmonics and their first-order sidebands;
//! * **residual** `r`: everything but `M ∪ S` — the TSA minus its shaft and mesh harmonics;
//! * **difference** `d`: everything but `M ∪ B ∪ S` — the TSA minus the regular signal (and the
//!   low shaft orders, as McFadden's "regular meshing components" include them).
//!
//! # Metrics (population moments, `N = P`; a Gaussian signal gives 3 for the 4th-order ones)
//!
//! * `FM0 = (max x − min x) / Σ_{m ∈ M} A_m` (TSA peak-to-peak over the mesh-harmonic
//!   amplitudes, peak scaling `A_k = 2|X_k|/P`);
//! * `FM4 = N Σ (d − d̄)⁴ / (Σ (d − d̄)²)²`;
//! * `M6A = N² Σ (d − d̄)⁶ / (Σ (d − d̄)²)³`, `M8A = N³ Σ (d − d̄)⁸ / (Σ (d − d̄)²)⁴`;
//! * `NA4 = N Σ (r − r̄)⁴ / (Σ (r − r̄)²)²` — for one record; the literature divides by the
//!   residual variance averaged over the run's earlier records, which a baseline does here;
//! * `NB4 = N Σ (e − ē)⁴ / (Σ (e − ē)²)²`, `e` the envelope (analytic-signal magnitude) of the
//!   TSA band-passed to orders `z ± ⌊z/2⌋` around the first mesh order;
//! * `ER = rms(d) / rms(g)` (energy ratio, Swansson);
//! * `SLF = (A_{z−1} + A_{z+1}) / std(TSA)` (sideband level factor, first mesh order `z`).
//!
//! A metric whose denominator vanishes (e.g. FM4 of a pure mesh tone: its difference signal is
//! zero to rounding) is `None`, never NaN.
//!
//! # Every shaft of a gear train ([`order_analysis`])
//!
//! The input shaft is tracked from the phase of the stage-1 mesh line
//! ([`super::order::track_mesh_phase_with`]); every shaft of the train that turns at least
//! [`MIN_TSA_REVS`] times in the record and carries a gear with a whole mesh order under the
//! record's Nyquist frequency is resampled to its own revolutions, averaged and measured, and
//! the RMS of the input shaft's TSA over that of its resampled record is the synchronous share.

use std::collections::BTreeMap;

use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::order::{
    MeshTrackOptions, ShaftAngle, TrackSummary, angular_resample, samples_per_rev_for,
    track_mesh_phase_with,
};
use super::{PlanCache, Spectrum, check_min_len, check_samples};
use crate::{Error, Result};

/// Low shaft orders removed from the residual and difference signals.
pub const SHAFT_HARMONICS: usize = 2;

/// The time-synchronous average: the mean of the `samples_per_rev`-sample revolutions.
///
/// Errors: `samples_per_rev` = 0, fewer samples than one revolution, non-finite samples.
pub fn tsa(resampled: &[f64], samples_per_rev: usize) -> Result<Vec<f64>> {
    if samples_per_rev == 0 {
        return Err(Error::param(
            "samples_per_rev",
            0.0,
            "at least one sample per revolution",
        ));
    }
    check_samples(resampled)?;
    check_min_len(resampled, samples_per_rev, "a TSA")?;
    let revs = resampled.len() / samples_per_rev;
    let mut out = vec![0.0; samples_per_rev];
    for r in resampled.chunks_exact(samples_per_rev).take(revs) {
        for (o, v) in out.iter_mut().zip(r) {
            *o += v;
        }
    }
    for o in &mut out {
        *o /= revs as f64;
    }
    Ok(out)
}

/// The signals derived from a TSA (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct TsaSignals {
    pub regular: Vec<f64>,
    pub residual: Vec<f64>,
    pub difference: Vec<f64>,
    /// Band-passed around the first mesh order, envelope.
    pub envelope: Vec<f64>,
    /// Peak amplitude of shaft order `k`, `k = 0 ..= P/2` (`A_0` = |mean|).
    pub order_amplitudes: Vec<f64>,
}

/// The mesh harmonics `k·z ≤ P/2` of every mesh order, sorted, deduplicated.
fn mesh_set(mesh_orders: &[usize], p: usize) -> Vec<usize> {
    let mut v: Vec<usize> = mesh_orders
        .iter()
        .filter(|&&z| z > 0)
        .flat_map(|&z| (1..).map(move |k| k * z).take_while(|&m| m <= p / 2))
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// Split a TSA into its regular, residual and difference signals and the envelope of its first
/// mesh band.
///
/// Errors: fewer than 8 samples, non-finite samples, no mesh order in `1 ..= P/2`.
pub fn tsa_signals(x: &[f64], mesh_orders: &[usize]) -> Result<TsaSignals> {
    check_samples(x)?;
    check_min_len(x, 8, "TSA signals")?;
    let p = x.len();
    let mesh = mesh_set(mesh_orders, p);
    let z = *mesh_orders
        .iter()
        .filter(|&&z| z > 0 && z <= p / 2)
        .min()
        .ok_or_else(|| Error::NoMeshOrder {
            orders: mesh_orders.to_vec(),
            max_order: p / 2,
        })?;
    let mut spec: Vec<Complex64> = x.iter().map(|&v| Complex64::new(v, 0.0)).collect();
    PlanCache::global().complex(p, false).process(&mut spec);
    let order_amplitudes: Vec<f64> = (0..=p / 2)
        .map(|k| {
            let s = if k == 0 || 2 * k == p { 1.0 } else { 2.0 };
            s * spec[k].norm() / p as f64
        })
        .collect();
    let in_mesh = |k: usize| mesh.binary_search(&k).is_ok();
    let in_side = |k: usize| !in_mesh(k) && (in_mesh(k + 1) || (k > 0 && in_mesh(k - 1)));
    let in_shaft = |k: usize| (1..=SHAFT_HARMONICS).contains(&k);
    // Keep the orders `keep(k)` (and their negative-frequency mirrors) of the mean-free TSA.
    let filtered = |keep: &dyn Fn(usize) -> bool| -> Vec<f64> {
        let mut b: Vec<Complex64> = (0..p)
            .map(|i| {
                let k = if i <= p / 2 { i } else { p - i };
                if k != 0 && keep(k) {
                    spec[i]
                } else {
                    Complex64::new(0.0, 0.0)
                }
            })
            .collect();
        PlanCache::global().complex(p, true).process(&mut b);
        b.iter().map(|c| c.re / p as f64).collect()
    };
    let regular = filtered(&|k| in_mesh(k) || in_side(k));
    let residual = filtered(&|k| !(in_mesh(k) || in_shaft(k)));
    let difference = filtered(&|k| !(in_mesh(k) || in_side(k) || in_shaft(k)));
    // Analytic signal of the band z ± ⌊z/2⌋: positive orders only, doubled.
    let (blo, bhi) = (z - z / 2, (z + z / 2).min(p / 2));
    let mut b: Vec<Complex64> = (0..p)
        .map(|i| {
            if i >= blo.max(1) && i <= bhi && 2 * i != p {
                2.0 * spec[i]
            } else {
                Complex64::new(0.0, 0.0)
            }
        })
        .collect();
    PlanCache::global().complex(p, true).process(&mut b);
    let envelope = b.iter().map(|c| c.norm() / p as f64).collect();
    Ok(TsaSignals {
        regular,
        residual,
        difference,
        envelope,
        order_amplitudes,
    })
}

/// Gear condition metrics of one TSA (definitions in the [module docs](self)). `None`: the
/// metric's denominator is zero to rounding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GearMetrics {
    pub fm0: Option<f64>,
    pub fm4: Option<f64>,
    pub na4: Option<f64>,
    pub nb4: Option<f64>,
    pub m6a: Option<f64>,
    pub m8a: Option<f64>,
    pub er: Option<f64>,
    pub slf: Option<f64>,
    /// RMS of the mean-free TSA (unit of the record).
    pub rms: f64,
    /// Kurtosis of the TSA itself.
    pub kurtosis: Option<f64>,
    /// rms(residual) / rms(TSA): the share the mesh and shaft harmonics do not explain.
    pub residual_ratio: Option<f64>,
    /// First mesh order (tooth count of the shaft's gear) the metrics refer to.
    pub mesh_order: usize,
}

/// `Σ (x − x̄)^k / N` for k = 2, 4, 6, 8.
fn central(x: &[f64]) -> [f64; 4] {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let mut s = [0.0; 4];
    for v in x {
        let d2 = (v - m) * (v - m);
        let d4 = d2 * d2;
        s[0] += d2;
        s[1] += d4;
        s[2] += d4 * d2;
        s[3] += d4 * d4;
    }
    s.map(|v| v / n)
}

/// `Some(v)` for a finite `v`, else `None`.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// The metrics of a TSA whose shaft carries gears of `mesh_orders` teeth.
///
/// Errors: as [`tsa_signals`].
pub fn gear_metrics(x: &[f64], mesh_orders: &[usize]) -> Result<GearMetrics> {
    gear_metrics_and_signals(x, mesh_orders).map(|(m, _)| m)
}

/// [`gear_metrics`] and the [`TsaSignals`] they were computed from.
pub fn gear_metrics_and_signals(
    x: &[f64],
    mesh_orders: &[usize],
) -> Result<(GearMetrics, TsaSignals)> {
    let s = tsa_signals(x, mesh_orders)?;
    let p = x.len();
    let z = *mesh_orders
        .iter()
        .filter(|&&z| z > 0 && z <= p / 2)
        .min()
        .expect("tsa_signals checked a mesh order");
    let [v2, v4, _, _] = central(x);
    // "Zero to rounding": below 1e-20 of the TSA's own variance (or exactly zero).
    let tiny = 1e-20 * v2;
    let ratio_moment = |m: [f64; 4], k: usize| -> Option<f64> {
        if !(m[0] > tiny) {
            return None;
        }
        finite(m[k] / m[0].powi(k as i32 + 1))
    };
    let md = central(&s.difference);
    let mr = central(&s.residual);
    let me = central(&s.envelope);
    let mesh = mesh_set(mesh_orders, p);
    let mesh_sum: f64 = mesh.iter().map(|&k| s.order_amplitudes[k]).sum();
    let (mx, mn) = x
        .iter()
        .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), &v| {
            (a.max(v), b.min(v))
        });
    let rms_of = |m: [f64; 4]| m[0].sqrt();
    let mg = central(&s.regular);
    let sd = v2.sqrt();
    let a = |k: usize| s.order_amplitudes.get(k).copied().unwrap_or(0.0);
    let metrics = GearMetrics {
        fm0: (mesh_sum > 0.0)
            .then(|| (mx - mn) / mesh_sum)
            .and_then(finite),
        fm4: ratio_moment(md, 1),
        na4: ratio_moment(mr, 1),
        nb4: ratio_moment(me, 1),
        m6a: ratio_moment(md, 2),
        m8a: ratio_moment(md, 3),
        er: (mg[0] > tiny)
            .then(|| rms_of(md) / rms_of(mg))
            .and_then(finite),
        slf: (v2 > 0.0)
            .then(|| (a(z - 1) + a(z + 1)) / sd)
            .and_then(finite),
        rms: sd,
        kurtosis: (v2 > 0.0).then(|| v4 / (v2 * v2)).and_then(finite),
        residual_ratio: (v2 > 0.0).then(|| rms_of(mr) / sd).and_then(finite),
        mesh_order: z,
    };
    Ok((metrics, s))
}

/// Fewest revolutions of a shaft for its TSA.
pub const MIN_TSA_REVS: f64 = 8.0;
/// Largest samples per revolution of a TSA (a slow shaft in a fast-sampled record).
pub const MAX_SAMPLES_PER_REV: usize = 16_384;

/// The TSA of one shaft.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShaftTsa {
    pub shaft: String,
    /// Rate over the tracked shaft's.
    pub rate_ratio: f64,
    /// Mean rate (Hz).
    pub mean_hz: f64,
    pub samples_per_rev: usize,
    /// Revolutions averaged.
    pub revolutions: usize,
    /// Tooth counts of the gears on this shaft (whole mesh orders).
    pub mesh_orders: Vec<usize>,
    pub metrics: GearMetrics,
    /// Peak amplitudes (unit of the record) of the first mesh order's harmonics k = 1..3 and
    /// their first-order sidebands: `(order, amplitude)`.
    pub mesh_lines: Vec<(usize, f64)>,
}

/// Order tracking and the TSA of every shaft it reaches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderAnalysis {
    pub tracked_shaft: String,
    pub tracking: TrackSummary,
    /// RMS of the tracked shaft's TSA over the RMS of the resampled record: the synchronous
    /// share.
    pub sync_share: f64,
    pub shafts: Vec<ShaftTsa>,
    /// Shafts without a TSA and why.
    pub skipped: Vec<(String, String)>,
}

/// The shafts and meshes of a gear train as [`order_analysis`] needs them, every rate per unit
/// input-shaft rate (`crate::gearbox::Gearbox::shaft_train` makes it from a description).
#[derive(Debug, Clone, PartialEq)]
pub struct ShaftTrain {
    /// The input shaft: the one tracked from the stage-1 mesh line.
    pub input_shaft: String,
    /// Stage-1 mesh frequency over the input-shaft rate (the tooth count of the input shaft's
    /// stage-1 gear): the tracked line's mesh order.
    pub mesh_order: f64,
    /// Every shaft's rate over the input shaft's (magnitudes), by name.
    pub shafts: BTreeMap<String, f64>,
    /// Every mesh frequency over the input-shaft rate, in stage order.
    pub meshes: Vec<f64>,
}

/// Track the input shaft of `train` from the stage-1 mesh line near `mesh_hz_hint` (searched
/// within `± search`, relative) and compute the TSA and its metrics for every shaft, reusing
/// the record's whole-record Hann amplitude spectrum if at hand
/// ([`super::order::track_mesh_phase_with`]).
///
/// Errors: the tracking's ([`super::order::track_mesh_phase`]); every shaft skipped is not an
/// error.
pub fn order_analysis(
    x: &[f64],
    fs: f64,
    train: &ShaftTrain,
    mesh_hz_hint: f64,
    search: f64,
    spectrum: Option<&Spectrum>,
) -> Result<OrderAnalysis> {
    let angle = track_mesh_phase_with(
        x,
        fs,
        mesh_hz_hint,
        train.mesh_order,
        &MeshTrackOptions {
            search,
            ..Default::default()
        },
        spectrum,
    )?;
    order_analysis_at(x, fs, train, &angle)
}

/// The TSA and its metrics for every shaft of `train`, with the input shaft's angle already
/// known (a tachometer's, or a track shared by the channels of one record).
///
/// Errors: `x` and the track of different lengths; every shaft skipped is not an error.
pub fn order_analysis_at(
    x: &[f64],
    fs: f64,
    train: &ShaftTrain,
    angle: &ShaftAngle,
) -> Result<OrderAnalysis> {
    let input = train.input_shaft.clone();
    let usable_revs = angle.summary.revolutions;
    let mut shafts = Vec::new();
    let mut skipped = Vec::new();
    let mut sync_share = f64::NAN;
    // The input shaft first, then the others in name order.
    let mut names: Vec<&String> = train.shafts.keys().collect();
    names.sort_by_key(|s| (**s != input, (*s).clone()));
    for name in names {
        let ratio = train.shafts[name];
        if !(ratio > 0.0) {
            skipped.push((name.clone(), "does not turn".into()));
            continue;
        }
        let revs = usable_revs * ratio;
        if revs < MIN_TSA_REVS {
            skipped.push((
                name.clone(),
                format!("{revs:.1} revolutions in the record (a TSA needs {MIN_TSA_REVS})"),
            ));
            continue;
        }
        let mut orders: Vec<usize> = train
            .meshes
            .iter()
            .filter_map(|m| {
                let o = m / ratio;
                let r = o.round();
                ((o - r).abs() <= 1e-6 * o && r >= 1.0).then_some(r as usize)
            })
            .collect();
        orders.sort_unstable();
        orders.dedup();
        let mean_hz = angle.summary.mean_hz * ratio;
        let p = samples_per_rev_for(fs, mean_hz);
        if p > MAX_SAMPLES_PER_REV {
            skipped.push((
                name.clone(),
                format!("{p} samples per revolution needed (at most {MAX_SAMPLES_PER_REV})"),
            ));
            continue;
        }
        orders.retain(|&z| z < p / 2);
        if orders.is_empty() {
            skipped.push((
                name.clone(),
                "no gear on it with a whole mesh order under the record's Nyquist frequency".into(),
            ));
            continue;
        }
        let res = angular_resample(x, angle, ratio, p)?;
        let avg = tsa(&res.samples, p)?;
        let (metrics, signals) = gear_metrics_and_signals(&avg, &orders)?;
        if *name == input {
            let r_all = {
                let m = res.samples.iter().sum::<f64>() / res.samples.len() as f64;
                (res.samples.iter().map(|v| (v - m).powi(2)).sum::<f64>()
                    / res.samples.len() as f64)
                    .sqrt()
            };
            sync_share = metrics.rms / r_all;
        }
        let amps = signals.order_amplitudes;
        let z = metrics.mesh_order;
        let mut lines = Vec::new();
        for k in 1..=3 {
            for o in [k * z - 1, k * z, k * z + 1] {
                if let Some(&a) = amps.get(o) {
                    lines.push((o, a));
                }
            }
        }
        shafts.push(ShaftTsa {
            shaft: name.clone(),
            rate_ratio: ratio,
            mean_hz,
            samples_per_rev: p,
            revolutions: res.revolutions,
            mesh_orders: orders,
            metrics,
            mesh_lines: lines,
        });
    }
    Ok(OrderAnalysis {
        tracked_shaft: input,
        tracking: angle.summary.clone(),
        sync_share,
        shafts,
        skipped,
    })
}

#[cfg(test)]
mod tests {
    use super::super::test_util::lcg;
    use super::*;
    use std::f64::consts::TAU;

    /// Approximately Gaussian samples (sum of 12 uniforms − 6, variance 1).
    fn gauss(n: usize, seed: u64) -> Vec<f64> {
        let u = lcg(12 * n, seed);
        u.chunks(12).map(|c| c.iter().sum::<f64>() * 0.5).collect()
    }

    fn tone(p: usize, z: usize, a: f64) -> Vec<f64> {
        (0..p)
            .map(|i| a * (TAU * (z * i) as f64 / p as f64).cos())
            .collect()
    }

    /// A pure mesh tone: FM0 = peak-to-peak / amplitude = 2A / A = 2 exactly; its difference
    /// signal is zero, so FM4, M6A, M8A and ER are undefined (`None`, not NaN); no sidebands:
    /// SLF = 0; TSA kurtosis = 1.5 (a sine).
    #[test]
    fn pure_mesh_tone() {
        let x = tone(512, 32, 1.7);
        let m = gear_metrics(&x, &[32]).unwrap();
        assert!((m.fm0.unwrap() - 2.0).abs() < 1e-12, "{m:?}");
        assert_eq!((m.fm4, m.m6a, m.m8a), (None, None, None));
        assert!(m.er.unwrap_or(0.0) < 1e-9, "{m:?}");
        assert!(m.slf.unwrap().abs() < 1e-12);
        assert!((m.kurtosis.unwrap() - 1.5).abs() < 1e-12);
        assert!((m.rms - 1.7 / 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(m.mesh_order, 32);
    }

    /// FM0 checked by hand with two mesh harmonics and a sideband pair: x = 1.0 cos(32θ) +
    /// 0.5 cos(64θ) + 0.25 (cos 31θ + cos 33θ). Peak-to-peak: max 2.0 at θ = 0, min found by
    /// brute force below; FM0 = pp / (1.0 + 0.5). SLF = (0.25 + 0.25) / std, std² = (1 + 0.25
    /// + 2 · 0.0625) / 2.
    #[test]
    fn fm0_and_slf_by_hand() {
        let p = 512;
        let x: Vec<f64> = (0..p)
            .map(|i| {
                let th = TAU * i as f64 / p as f64;
                (32.0 * th).cos()
                    + 0.5 * (64.0 * th).cos()
                    + 0.25 * ((31.0 * th).cos() + (33.0 * th).cos())
            })
            .collect();
        let pp = x.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - x.iter().cloned().fold(f64::INFINITY, f64::min);
        let m = gear_metrics(&x, &[32]).unwrap();
        assert!((m.fm0.unwrap() - pp / 1.5).abs() < 1e-12, "{m:?}");
        let sd = ((1.0 + 0.25 + 2.0 * 0.0625) / 2.0f64).sqrt();
        assert!((m.slf.unwrap() - 0.5 / sd).abs() < 1e-12, "{m:?}");
        // Everything is regular: the difference signal is empty, the residual holds the sidebands.
        assert_eq!(m.fm4, None);
        assert!(m.na4.is_some());
    }

    /// A TSA of a mesh tone plus one impulsive tooth per revolution (a broken tooth): FM4, NA4,
    /// M6A and M8A large; the same mesh tone plus Gaussian noise: FM4 and NA4 ≈ 3.
    #[test]
    fn impulsive_tooth_vs_gaussian() {
        let p = 1024;
        let z = 32;
        let mut x = tone(p, z, 1.0);
        // One tooth (p/z = 32 samples) carries a short impulse of height 3 on 3 samples.
        for i in 500..503 {
            x[i] += 3.0;
        }
        let broken = gear_metrics(&x, &[z]).unwrap();
        let (fm4, na4) = (broken.fm4.unwrap(), broken.na4.unwrap());
        assert!(fm4 > 30.0 && na4 > 30.0, "{broken:?}");
        assert!(broken.m6a.unwrap() > fm4 && broken.m8a.unwrap() > broken.m6a.unwrap());
        assert!(broken.nb4.unwrap() > 3.0, "{broken:?}");
        let g = gauss(p, 11);
        let y: Vec<f64> = tone(p, z, 1.0)
            .iter()
            .zip(&g)
            .map(|(a, b)| a + 0.3 * b)
            .collect();
        let healthy = gear_metrics(&y, &[z]).unwrap();
        for (name, v) in [("fm4", healthy.fm4.unwrap()), ("na4", healthy.na4.unwrap())] {
            assert!((v - 3.0).abs() < 0.6, "{name} = {v} ({healthy:?})");
        }
        // Gaussian M6A ≈ 15, M8A ≈ 105 (the 6th and 8th standardised moments).
        assert!((healthy.m6a.unwrap() - 15.0).abs() < 6.0, "{healthy:?}");
        // ER: difference (≈ the noise, 0.3) over regular (the tone, 1/√2): ≈ 0.42.
        let er = healthy.er.unwrap();
        assert!((er - 0.3 * 2f64.sqrt()).abs() < 0.1, "{er}");
    }

    #[test]
    fn tsa_averages_revolutions() {
        let rev: Vec<f64> = (0..16).map(|i| i as f64).collect();
        let mut x = Vec::new();
        for k in 0..5 {
            x.extend(rev.iter().map(|v| v + if k % 2 == 0 { 1.0 } else { -1.0 }));
        }
        let t = tsa(&x, 16).unwrap();
        for (a, b) in t.iter().zip(&rev) {
            assert!((a - (b + 0.2)).abs() < 1e-12);
        }
        assert!(tsa(&x, 0).is_err());
        assert!(tsa(&x[..10], 16).is_err());
        assert!(gear_metrics(&tone(64, 8, 1.0), &[40]).is_err());
    }
}
