//! How far a feature may move between healthy records, and how high a healthy record's score
//! may go: the yardstick of a state-aware baseline ([`super::baseline`]).
//!
//! # Within a state
//! Two sources of spread, per feature `f` (ln units):
//! * **the record's own noise** `σ`, from the spread of the feature over each baseline
//!   record's segments ([`super::evidence`]), the median over every baseline record (the noise
//!   of a logarithm hardly depends on the speed): a record compared with the mean of `n`
//!   records differs by `σ √(1 + 1/n)`;
//! * **between runs** at the same state (a machine warmed up differently, a day apart): when
//!   the baseline has several records of a state, their leave-one-out residuals measure it
//!   (`s_b`, at least [`MIN_BETWEEN`]). With one record per state it cannot be measured, and
//!   `s_b = max(BETWEEN_RUN, RUN_SHARE · σ_a)` stands in for it: a line that moves much from
//!   one speed to the next (a mesh harmonic near a resonance) also moves from one run to the
//!   next, by about half as much (on the PHM 2009 spur train's two healthy runs the RMS
//!   run-to-run change of a line class was 0.6 × its leave-state-out spread, median over the
//!   classes, and never under about 1 dB);
//! * the scale is `√(σ² (1 + 1/n) + s_b²)`.
//!
//! # Between states
//! A record whose reference is interpolated between speeds (or the nearest speed) also carries
//! the error of that interpolation: each baseline state is predicted with its records left
//! out, and the robust spread of those residuals (`1.4826 · MAD`) is the scale when larger.
//!
//! # Threshold
//! A record's score is the RMS of its [`TOP_K`] largest `|z|`. Were every `z` an independent
//! standard normal, the score of a healthy record would exceed [`null_threshold`] with
//! probability [`FALSE_ALARM_RATE`] per channel and record; the threshold is that, at least
//! [`MIN_THRESHOLD`], and at least the largest score of the baseline's own comparisons (its
//! records predicted by others of their state; its leave-state-out residuals between states),
//! so that the healthy records the baseline holds stay quiet.

use std::collections::BTreeMap;
use std::sync::Mutex;

use crate::signal::median;
use crate::signature::SplitMix64;

/// Number of largest |z| the score averages (in square).
pub const TOP_K: usize = 3;
/// Smallest threshold: a record is never anomalous with its top features within 3 scales.
pub const MIN_THRESHOLD: f64 = 3.0;
/// The false-alarm rate per channel and record the threshold is set for, under independent
/// normal features.
pub const FALSE_ALARM_RATE: f64 = 0.001;
/// Smallest between-run spread of a feature when the baseline cannot measure it (ln: 1.5 dB).
pub const BETWEEN_RUN: f64 = 0.1727;
/// Between-run spread as a share of the spread between states, when the baseline cannot
/// measure it.
pub const RUN_SHARE: f64 = 0.6;
/// Smallest between-run spread a baseline may measure (ln: 0.5 dB).
pub const MIN_BETWEEN: f64 = 0.0576;
/// Smallest scale between states (ln: a 10 % change).
pub const ACROSS_FLOOR: f64 = 0.1;
/// Fewest values a spread is estimated from.
pub const MIN_VALUES: usize = 3;

/// `1.4826 · median |v − median v|`.
fn mad(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    let m = median(&mut v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&mut dev)
}

/// Per-feature spread of healthy records at one state.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Within {
    /// A record's own noise `σ`.
    pub noise: BTreeMap<String, f64>,
    /// Between-run spread `s_b`: measured, or from the spread between states.
    pub between: BTreeMap<String, f64>,
}

impl Within {
    /// From the baseline records' own noise ([`super::evidence::Evidence::spread`]), the
    /// residuals of records predicted by others of their state (each already divided by
    /// `√(1 + 1/m)`, `m` the records of the reference) and, where those are missing, the
    /// spread between states ([`across_spread`]).
    pub fn fit(
        spreads: &[&BTreeMap<String, f64>],
        residuals: &[BTreeMap<String, f64>],
        across: &BTreeMap<String, f64>,
    ) -> Within {
        let mut between: BTreeMap<String, f64> = across
            .iter()
            .map(|(k, a)| (k.clone(), (RUN_SHARE * a).max(BETWEEN_RUN)))
            .collect();
        between.extend(per_feature(residuals.iter(), |v| mad(v).max(MIN_BETWEEN)));
        Within {
            noise: per_feature(spreads.iter().copied(), |v| median(&mut v.to_vec())),
            between,
        }
    }

    /// The scale of feature `f` against a reference of `n` records; `None` without a measure
    /// of its noise.
    pub fn scale(&self, f: &str, n: usize) -> Option<f64> {
        let s = self.noise.get(f)?;
        let b = self.between.get(f).copied().unwrap_or(BETWEEN_RUN);
        Some((s * s * (1.0 + 1.0 / n.max(1) as f64) + b * b).sqrt())
    }

    /// Every scale against a one-record reference.
    pub fn scales(&self) -> BTreeMap<String, f64> {
        self.noise
            .keys()
            .filter_map(|k| Some((k.clone(), self.scale(k, 1)?)))
            .collect()
    }
}

/// `spread(values)` of every feature with at least [`MIN_VALUES`] values.
fn per_feature<'a>(
    maps: impl Iterator<Item = &'a BTreeMap<String, f64>>,
    spread: impl Fn(&[f64]) -> f64,
) -> BTreeMap<String, f64> {
    let mut per: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for m in maps {
        for (k, v) in m {
            per.entry(k.clone()).or_default().push(*v);
        }
    }
    per.into_iter()
        .filter(|(_, v)| v.len() >= MIN_VALUES)
        .map(|(k, v)| (k, spread(&v)))
        .collect()
}

/// Per-feature robust spread (`1.4826 · MAD`) of leave-state-out residuals: how far a
/// feature moves between neighbouring states.
pub fn across_spread(residuals: &[BTreeMap<String, f64>]) -> BTreeMap<String, f64> {
    per_feature(residuals.iter(), mad)
}

/// Per-feature scales of leave-state-out residuals: the within scale or the residuals' robust
/// spread, whichever is larger (at least [`ACROSS_FLOOR`]); a feature with only one of them
/// takes that one.
pub fn across_scales(
    within: &BTreeMap<String, f64>,
    spread: &BTreeMap<String, f64>,
) -> BTreeMap<String, f64> {
    let mut out = spread.clone();
    for (k, w) in within {
        let e = out.entry(k.clone()).or_insert(0.0);
        *e = e.max(*w);
    }
    out.values_mut().for_each(|v| *v = v.max(ACROSS_FLOOR));
    out
}

/// One feature's departure from the reference.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Departure {
    pub feature: String,
    /// `value − reference` (ln units: a ratio).
    pub change: f64,
    pub z: f64,
    /// The reference's value (ln).
    #[serde(skip)]
    pub reference: f64,
    /// The scale the change was divided by (ln).
    #[serde(skip)]
    pub scale: f64,
}

/// Departures of `values` from `reference` at `scale` (features with all three), largest `|z|`
/// first.
pub fn departures(
    values: &BTreeMap<String, f64>,
    reference: &BTreeMap<String, f64>,
    scale: impl Fn(&str) -> Option<f64>,
) -> Vec<Departure> {
    let mut d: Vec<Departure> = values
        .iter()
        .filter_map(|(k, v)| {
            let r = *reference.get(k)?;
            let s = scale(k)?;
            Some(Departure {
                feature: k.clone(),
                change: v - r,
                z: (v - r) / s,
                reference: r,
                scale: s,
            })
        })
        .collect();
    d.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    d
}

/// RMS of the [`TOP_K`] largest `|z|` (0 without departures).
pub fn score_of(d: &[Departure]) -> f64 {
    let top: Vec<f64> = d.iter().take(TOP_K).map(|x| x.z * x.z).collect();
    if top.is_empty() {
        return 0.0;
    }
    (top.iter().sum::<f64>() / top.len() as f64).sqrt()
}

/// The score that `n` independent standard-normal `z` exceed with probability
/// [`FALSE_ALARM_RATE`]: the `1 − α` quantile of the RMS of their [`TOP_K`] largest `|z|`,
/// from 20 000 seeded draws (deterministic; cached per `n`).
pub fn null_threshold(n: usize) -> f64 {
    static CACHE: Mutex<BTreeMap<usize, f64>> = Mutex::new(BTreeMap::new());
    if n == 0 {
        return 0.0;
    }
    if let Some(v) = CACHE.lock().expect("cache lock").get(&n) {
        return *v;
    }
    const DRAWS: usize = 20_000;
    let mut rng = SplitMix64::new(0x5EED ^ n as u64);
    let mut scores: Vec<f64> = (0..DRAWS)
        .map(|_| {
            let mut top = [0.0f64; TOP_K];
            for _ in 0..n {
                let z = rng.normal().abs();
                if z > top[TOP_K - 1] {
                    top[TOP_K - 1] = z;
                    top.sort_by(|a, b| b.total_cmp(a));
                }
            }
            let k = TOP_K.min(n);
            (top[..k].iter().map(|z| z * z).sum::<f64>() / k as f64).sqrt()
        })
        .collect();
    scores.sort_by(f64::total_cmp);
    let v = scores[((1.0 - FALSE_ALARM_RATE) * DRAWS as f64) as usize];
    CACHE.lock().expect("cache lock").insert(n, v);
    v
}

/// A threshold: the null quantile for `n` features, the largest of `scores`, at least
/// [`MIN_THRESHOLD`].
pub fn threshold(n: usize, scores: &[f64]) -> f64 {
    scores
        .iter()
        .fold(null_threshold(n).max(MIN_THRESHOLD), |a, &b| a.max(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The null quantile grows slowly with the number of features and matches an independent
    /// estimate: for one feature the score is |z|, whose 99.9 % quantile is 3.29.
    #[test]
    fn the_null_threshold_is_a_quantile_of_the_top_k_score() {
        assert!(
            (null_threshold(1) - 3.29).abs() < 0.1,
            "{}",
            null_threshold(1)
        );
        let (a, b) = (null_threshold(20), null_threshold(100));
        assert!(a > 2.7 && a < 3.3 && b > a && b < 3.8, "{a} {b}");
        assert_eq!(null_threshold(100), b);
    }

    /// Records whose own noise is 0.1, 0.2 and 0.3: the median 0.2; a one-record reference
    /// then scales by √(2 · 0.2² + 1.5 dB²) where no between-run spread was measured.
    #[test]
    fn scales_combine_the_records_noise_and_the_between_run_spread() {
        let spreads: Vec<BTreeMap<String, f64>> = [0.1, 0.2, 0.3f64]
            .iter()
            .map(|v| BTreeMap::from([("a".to_string(), *v)]))
            .collect();
        let refs: Vec<&BTreeMap<String, f64>> = spreads.iter().collect();
        let w = Within::fit(&refs, &[], &BTreeMap::new());
        assert!((w.noise["a"] - 0.2).abs() < 1e-12);
        let s = w.scale("a", 1).unwrap();
        assert!((s - (2.0 * 0.04 + BETWEEN_RUN * BETWEEN_RUN).sqrt()).abs() < 1e-12);
        assert!(w.scale("a", 4).unwrap() < s);
        // A feature that moves 0.8 between states moves RUN_SHARE × 0.8 between runs.
        let across = BTreeMap::from([("a".to_string(), 0.8)]);
        let w = Within::fit(&refs, &[], &across);
        let s = w.scale("a", 1).unwrap();
        let b = RUN_SHARE * 0.8;
        assert!((s - (2.0 * 0.04 + b * b).sqrt()).abs() < 1e-12);
        assert_eq!(w.scale("b", 1), None);
    }
}
