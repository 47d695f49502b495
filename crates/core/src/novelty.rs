//! A machine's own healthy baseline and a novelty score against it.
//!
//! A model never matches a real gearbox exactly; a machine's own healthy records do. This
//! module turns one record (one channel) into named scalar features ([`record_features`]),
//! learns their healthy spread from a few records ([`MachineBaseline::fit`]) and scores a new
//! record against it ([`MachineBaseline::score`]).
//!
//! # Features
//!
//! Every feature is a logarithm (ln) of a positive, mostly gain-free quantity, so that a
//! relative change reads the same whatever the sensor's sensitivity:
//!
//! * always (no description needed): `stat.ln_rms`, `stat.ln_kurtosis`, `stat.ln_crest` of the
//!   mean-free record, and `band.<f>hz`: the share of the record's power in the 1/3-octave band
//!   centred on `f = 10^(k/10)` Hz (a fixed grid from 100 Hz to 0.45 × the sample rate), from a
//!   Welch spectrum (Hann, 4096-sample segments, half overlap);
//! * with a gearbox description and a speed hint ([`order_analysis`]): the input shaft is
//!   tracked from the phase of the stage-1 mesh line ([`crate::signal::order`]); every shaft the
//!   description names that turns at least [`MIN_TSA_REVS`] times in the record and carries a
//!   gear with a whole mesh order gets a time-synchronous average and its metrics
//!   ([`crate::signal::tsa`]); features `tsa.<shaft>.ln_fm0 … ln_slf`, `ln_kurtosis`,
//!   `ln_residual_ratio`, `mesh<k>` (ln of the k-th mesh harmonic over the TSA's RMS) and
//!   `sb<k>` (ln of the summed first-order sidebands over their mesh harmonic), k = 1..3; and
//!   `order.ln_sync_share` (RMS of the input shaft's TSA over that of the resampled record).
//!
//! A broken or cracked tooth makes a once-per-revolution impulse in the TSA of its shaft
//! (FM4, NA4, M6A, M8A, kurtosis, FM0 up) and spreads energy into shaft-order sidebands around
//! the mesh harmonics (SLF, `sb<k>`, ER up); distributed wear raises the mesh harmonics and
//! their sidebands together. The description-free features catch what is not synchronous.
//!
//! # Baseline and score
//!
//! Per feature, location = median and scale = max(1.4826 × MAD, [`SCALE_FLOOR`]) over the
//! baseline records that have it (at least [`MIN_BASELINE_RECORDS`]; records of one
//! [`RecordFeatures::group`] enter as their group's median, one value per group); the floor (0.1 ln units,
//! a 10 % change) keeps three near-identical records from giving a zero spread. A record's
//! `z` per feature is `(value − location) / scale`, over the features both have (features
//! missing on either side are ignored); its **score** is the root mean square of its
//! [`TOP_K`] largest `|z|`: a fault moves a few related features far, while the healthy
//! scatter of many features stays small.
//!
//! # Threshold (calibrated by leave-one-out)
//!
//! Each baseline record is scored against a baseline fitted without it — without its whole
//! group when records carry a [`RecordFeatures::group`] (segments of one file, records of one
//! operating point), so that a held-out record is new the way a future record is. The
//! threshold is the largest of these leave-one-out scores (and at least [`MIN_THRESHOLD`]).
//!
//! **False-alarm rate targeted:** if a new healthy record's group and the `u` baseline groups
//! are exchangeable, the new group's score exceeds the largest of the `u` leave-one-out scores
//! with probability at most `1 / (u + 1)` — and less in practice, since a new record is scored
//! against all `u` groups while each leave-one-out score comes from `u − 1` (a smaller baseline
//! scatters more). So: at most 25 % with the minimum of three records, 9 % with ten, 1/(u+1) in
//! general; more healthy records (or groups, e.g. operating points) lower it.
//!
//! (A log-normal 99 % prediction bound on the leave-one-out scores was tried first; with four
//! groups its Student-t factor put the threshold far above every score, healthy or broken, of
//! the real records of `docs/real-data.md`, so it was replaced by this rule.)

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use crate::gearbox::Gearbox;
use crate::record::Record;
pub use crate::signal::tsa::{MAX_SAMPLES_PER_REV, MIN_TSA_REVS, OrderAnalysis, ShaftTsa};
use crate::signal::{Window, kurtosis, median, welch};
use crate::{Error, Result};

/// Fewest records a baseline is fitted from.
pub const MIN_BASELINE_RECORDS: usize = 3;
/// The scoring constants both baselines share (the state-aware one of [`crate::condition`] and
/// this pooled one).
pub use crate::condition::calibration::{MIN_THRESHOLD, TOP_K};
/// Smallest robust scale of a feature (ln units: a 10 % change).
pub const SCALE_FLOOR: f64 = 0.1;

/// What a baseline is made of: the features of one record (one channel).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct RecordFeatures {
    /// Named scalar features (order-spectrum levels, TSA metrics, …); the baseline's inputs.
    pub values: BTreeMap<String, f64>,
    /// For people: order tracking summary (tracked shaft, its mean rate in Hz, speed variation,
    /// method) and the TSA metrics per shaft. Any JSON.
    pub indicators: serde_json::Value,
    /// Records of one group (segments of one file, one operating point) are left out together
    /// when the threshold is calibrated. `None`: the record is its own group.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// The record's measured operating state, when its speed was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<crate::condition::OperatingState>,
    /// Order-domain evidence ([`crate::condition::evidence`]): what a state-aware baseline
    /// compares.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub evidence: BTreeMap<String, f64>,
    /// Each evidence feature's noise in the record, from its segments
    /// ([`crate::condition::Evidence::spread`]).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub evidence_spread: BTreeMap<String, f64>,
    /// [`crate::condition::EVIDENCE_VERSION`] of `evidence` (0: before versions): a baseline
    /// fits only records of the current one.
    #[serde(default)]
    pub evidence_version: u32,
    /// The marked lines' levels ([`crate::condition::Evidence::lines`]): what the machine's
    /// model is calibrated on ([`crate::condition::machine_model`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lines: Vec<crate::condition::machine_model::LineLevel>,
    /// The table's plain reading of the record's lines ([`crate::diagnosis::machine_path`]):
    /// what the machine's transfer path is calibrated on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ratios: Option<crate::diagnosis::machine_path::LineRatios>,
}

impl RecordFeatures {
    /// The same features, marked as belonging to `group`.
    pub fn with_group(mut self, group: impl Into<String>) -> Self {
        self.group = Some(group.into());
        self
    }
}

/// The line ratios per channel of records' features (those that carry them; a channel whose
/// records carry none has an empty list): what the machine's own model is fitted to.
pub fn line_ratios(
    per_channel: &BTreeMap<String, Vec<RecordFeatures>>,
) -> BTreeMap<String, Vec<crate::diagnosis::machine_path::LineRatios>> {
    per_channel
        .iter()
        .map(|(c, fs)| {
            (
                c.clone(),
                fs.iter().filter_map(|f| f.ratios.clone()).collect(),
            )
        })
        .collect()
}

/// Track the input shaft from the stage-1 mesh line near `mesh_hz_hint` (searched within
/// `± search`, relative) and compute the TSA and its metrics for every shaft of `gb`
/// ([`crate::signal::tsa::order_analysis`] on [`Gearbox::shaft_train`]).
///
/// Errors: the tracking's ([`crate::signal::order::track_mesh_phase`]); every shaft skipped is not an error.
pub fn order_analysis(
    x: &[f64],
    fs: f64,
    gb: &Gearbox,
    mesh_hz_hint: f64,
    search: f64,
) -> Result<OrderAnalysis> {
    order_analysis_with(x, fs, gb, mesh_hz_hint, search, None)
}

/// [`order_analysis`] reusing the record's whole-record Hann amplitude spectrum if at hand
/// ([`crate::signal::order::track_mesh_phase_with`]).
pub fn order_analysis_with(
    x: &[f64],
    fs: f64,
    gb: &Gearbox,
    mesh_hz_hint: f64,
    search: f64,
    spectrum: Option<&crate::signal::Spectrum>,
) -> Result<OrderAnalysis> {
    crate::signal::tsa::order_analysis(x, fs, &gb.shaft_train(), mesh_hz_hint, search, spectrum)
}

/// `ln v` for a positive finite `v` (floored at 1e-12), else nothing.
fn ln_pos(v: f64) -> Option<f64> {
    (v.is_finite() && v >= 0.0).then(|| v.max(1e-12).ln())
}

/// Description-free features: statistics and 1/3-octave band shares.
fn plain_features(x: &[f64], fs: f64, out: &mut BTreeMap<String, f64>) -> Result<()> {
    let n = x.len();
    let m = x.iter().sum::<f64>() / n as f64;
    let xc: Vec<f64> = x.iter().map(|v| v - m).collect();
    let rms = (xc.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let peak = xc.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let mut put = |k: &str, v: Option<f64>| {
        if let Some(v) = v.filter(|v| v.is_finite()) {
            out.insert(k.to_string(), v);
        }
    };
    put("stat.ln_rms", ln_pos(rms));
    put("stat.ln_kurtosis", ln_pos(kurtosis(&xc)));
    if rms > 0.0 {
        put("stat.ln_crest", ln_pos(peak / rms));
    }
    let seg = 4096.min(n.next_power_of_two() / 2).max(64).min(n);
    let s = welch(&xc, fs, seg, 0.5, Window::Hann)?;
    let total: f64 = s
        .freq
        .iter()
        .zip(&s.amplitude)
        .filter(|(f, _)| **f >= 10.0)
        .map(|(_, a)| a * a)
        .sum();
    if !(total > 0.0) {
        return Ok(());
    }
    for k in 20..60 {
        let fc = 10f64.powf(k as f64 / 10.0);
        let (lo, hi) = (fc * 2f64.powf(-1.0 / 6.0), fc * 2f64.powf(1.0 / 6.0));
        if hi > 0.45 * fs {
            break;
        }
        let p: f64 = s
            .freq
            .iter()
            .zip(&s.amplitude)
            .filter(|(f, _)| **f >= lo && **f < hi)
            .map(|(_, a)| a * a)
            .sum();
        if let Some(v) = ln_pos(p / total) {
            out.insert(format!("band.{:.0}hz", fc.round()), v);
        }
    }
    Ok(())
}

/// Features of one order analysis.
fn order_features(a: &OrderAnalysis, out: &mut BTreeMap<String, f64>) {
    let mut put = |k: String, v: Option<f64>| {
        if let Some(v) = v.filter(|v| v.is_finite()) {
            out.insert(k, v);
        }
    };
    put("order.ln_sync_share".into(), ln_pos(a.sync_share));
    for s in &a.shafts {
        let m = &s.metrics;
        let p = |k: &str| format!("tsa.{}.{k}", s.shaft);
        for (k, v) in [
            ("ln_fm0", m.fm0),
            ("ln_fm4", m.fm4),
            ("ln_na4", m.na4),
            ("ln_nb4", m.nb4),
            ("ln_m6a", m.m6a),
            ("ln_m8a", m.m8a),
            ("ln_er", m.er),
            ("ln_slf", m.slf),
            ("ln_kurtosis", m.kurtosis),
            ("ln_residual_ratio", m.residual_ratio),
        ] {
            put(p(k), v.and_then(ln_pos));
        }
        let amp = |o: usize| s.mesh_lines.iter().find(|l| l.0 == o).map(|l| l.1);
        let z = m.mesh_order;
        for k in 1..=3 {
            let (Some(lo), Some(c), Some(hi)) = (amp(k * z - 1), amp(k * z), amp(k * z + 1)) else {
                continue;
            };
            if m.rms > 0.0 {
                put(p(&format!("mesh{k}")), ln_pos(c / m.rms));
            }
            if c > 0.0 {
                put(p(&format!("sb{k}")), ln_pos((lo + hi) / c));
            }
        }
    }
}

/// The features of one record (see the [module docs](self)).
///
/// `gearbox: None` = no description known: only the description-free features (statistics and
/// log band levels on a fixed grid), so that a baseline still works for an unknown machine.
/// `input_shaft_hz`: the nominal input-shaft rate if known (hint for finding the tracked mesh
/// line, searched within ±3 %); without it the description's `nominal_input_hz` (±15 %); with
/// neither, no order tracking. A failed tracking is not an error: the record keeps its
/// description-free features and `indicators.order_tracking.error` says why.
///
/// Errors: an empty record, a non-finite sample or a bad sample rate.
pub fn record_features(
    rec: &Record,
    gearbox: Option<&Gearbox>,
    input_shaft_hz: Option<f64>,
) -> Result<RecordFeatures> {
    record_features_with(rec, gearbox, input_shaft_hz, None)
}

/// [`record_features`] with the record's order analysis already done for the same gearbox
/// (the diagnosis's [`crate::diagnosis::Diagnosis::order`], tracked from the f1 it found):
/// its features are taken as they are instead of tracking the record a second time. Without
/// `gearbox` it is ignored.
pub fn record_features_with(
    rec: &Record,
    gearbox: Option<&Gearbox>,
    input_shaft_hz: Option<f64>,
    order: Option<&OrderAnalysis>,
) -> Result<RecordFeatures> {
    let x = &rec.samples;
    let fs = rec.sample_rate;
    crate::record::check_sample_rate(fs)?;
    crate::record::check_signal(x)?;
    let mut values = BTreeMap::new();
    plain_features(x, fs, &mut values)?;
    let mut indicators = serde_json::Map::new();
    if let (Some(_), Some(a)) = (gearbox, order) {
        order_features(a, &mut values);
        indicators.insert(
            "order_tracking".into(),
            serde_json::to_value(a).unwrap_or_default(),
        );
    } else if let Some(gb) = gearbox {
        let hint = input_shaft_hz
            .filter(|h| h.is_finite() && *h > 0.0)
            .map(|h| (h, 0.03))
            .or_else(|| gb.description.nominal_input_hz.map(|h| (h, 0.15)));
        match hint {
            Some((h, search)) => match order_analysis(x, fs, gb, gb.f1_hz(h), search) {
                Ok(a) => {
                    order_features(&a, &mut values);
                    indicators.insert(
                        "order_tracking".into(),
                        serde_json::to_value(&a).unwrap_or_default(),
                    );
                }
                Err(e) => {
                    indicators.insert(
                        "order_tracking".into(),
                        serde_json::json!({ "error": e.to_string() }),
                    );
                }
            },
            None => {
                indicators.insert(
                    "order_tracking".into(),
                    serde_json::json!({ "error": "no speed hint: give the input-shaft rate or \
                        the description's nominal_input_hz" }),
                );
            }
        }
    }
    let stats: BTreeMap<&String, &f64> = values
        .iter()
        .filter(|(k, _)| k.starts_with("stat."))
        .collect();
    indicators.insert(
        "statistics".into(),
        serde_json::to_value(stats).unwrap_or_default(),
    );
    Ok(RecordFeatures {
        values,
        indicators: serde_json::Value::Object(indicators),
        ..Default::default()
    })
}

/// Split a record into `parts` equal consecutive records (the tail that does not divide is
/// dropped).
pub fn split_record(rec: &Record, parts: usize) -> Vec<Record> {
    let parts = parts.max(1);
    let len = rec.samples.len() / parts;
    (0..parts)
        .map(|k| Record {
            samples: rec.samples[k * len..(k + 1) * len].to_vec(),
            sample_rate: rec.sample_rate,
        })
        .collect()
}

/// Robust location and scale of one feature over the baseline.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FeatureStats {
    /// Median.
    pub location: f64,
    /// max(1.4826 × MAD, [`SCALE_FLOOR`]).
    pub scale: f64,
    /// Baseline records that have the feature.
    pub records: usize,
}

/// One feature's deviation from the baseline, in robust scales.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FeatureZ {
    pub name: String,
    pub z: f64,
}

/// A record's novelty against a machine's baseline.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Novelty {
    pub score: f64,
    pub threshold: f64,
    pub anomalous: bool,
    pub baseline_records: usize,
    /// The features with the largest |z|, largest first (at most 5).
    pub top_features: Vec<FeatureZ>,
    /// Features the score used (present in the record and in the baseline).
    pub features_used: usize,
}

/// A machine's healthy baseline (see the [module docs](self)).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MachineBaseline {
    pub features: BTreeMap<String, FeatureStats>,
    /// Calibrated threshold on the score.
    pub threshold: f64,
    /// Records fitted.
    pub n: usize,
    /// Leave-one-out units (groups, or records).
    pub units: usize,
    /// The leave-one-out scores of the baseline records, in their order.
    pub loo_scores: Vec<f64>,
    /// The threshold rule, in words.
    pub rule: String,
}

/// Location and scale of every feature that at least `min_records` records have
/// ([`MIN_BASELINE_RECORDS`] for a baseline; one less for its leave-one-out fits, so that a
/// baseline of exactly three records is still calibrated).
/// Records of one group are near-duplicates (segments of one file): each group enters through
/// the median of its records, so that the spread is the spread *between* groups.
fn feature_stats(
    records: &[&RecordFeatures],
    min_records: usize,
) -> BTreeMap<String, FeatureStats> {
    // feature → group → values
    let mut by: BTreeMap<&str, BTreeMap<String, Vec<f64>>> = BTreeMap::new();
    for (i, r) in records.iter().enumerate() {
        let g = r.group.clone().unwrap_or_else(|| format!("#{i}"));
        for (k, v) in &r.values {
            if v.is_finite() {
                by.entry(k)
                    .or_default()
                    .entry(g.clone())
                    .or_default()
                    .push(*v);
            }
        }
    }
    by.into_iter()
        .filter(|(_, g)| g.values().map(Vec::len).sum::<usize>() >= min_records)
        .map(|(k, groups)| {
            let n = groups.values().map(Vec::len).sum();
            let mut v: Vec<f64> = groups.into_values().map(|mut g| median(&mut g)).collect();
            let loc = median(&mut v);
            let mut dev: Vec<f64> = v.iter().map(|x| (x - loc).abs()).collect();
            let mad = median(&mut dev);
            (
                k.to_string(),
                FeatureStats {
                    location: loc,
                    scale: (1.4826 * mad).max(SCALE_FLOOR),
                    records: n,
                },
            )
        })
        .collect()
}

/// Sorted |z| list and the score of `f` against `stats`.
fn score_against(
    stats: &BTreeMap<String, FeatureStats>,
    f: &RecordFeatures,
) -> (f64, Vec<FeatureZ>) {
    let mut zs: Vec<FeatureZ> = f
        .values
        .iter()
        .filter(|(_, v)| v.is_finite())
        .filter_map(|(k, v)| {
            let s = stats.get(k)?;
            let z = ((v - s.location) / s.scale).clamp(-1e6, 1e6);
            z.is_finite().then(|| FeatureZ { name: k.clone(), z })
        })
        .collect();
    zs.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    let k = zs.len().min(TOP_K);
    let score = if k == 0 {
        0.0
    } else {
        (zs[..k].iter().map(|z| z.z * z.z).sum::<f64>() / k as f64).sqrt()
    };
    (score, zs)
}

impl MachineBaseline {
    /// Fit a baseline; Err ([`Error::BaselineTooSmall`]) with fewer than
    /// [`MIN_BASELINE_RECORDS`] records. The threshold is calibrated by leave-one-out on the
    /// baseline records (rule and targeted false-alarm rate in the [module docs](self)).
    pub fn fit(records: &[RecordFeatures]) -> Result<MachineBaseline> {
        if records.len() < MIN_BASELINE_RECORDS {
            return Err(Error::BaselineTooSmall {
                records: records.len(),
                needed: MIN_BASELINE_RECORDS,
            });
        }
        let all: Vec<&RecordFeatures> = records.iter().collect();
        let features = feature_stats(&all, MIN_BASELINE_RECORDS);
        // Leave-one-out units: the groups, unless there are fewer than three of them.
        let groups: BTreeSet<&str> = records.iter().filter_map(|r| r.group.as_deref()).collect();
        let grouped =
            groups.len() >= MIN_BASELINE_RECORDS && records.iter().all(|r| r.group.is_some());
        let unit_of = |i: usize| -> String {
            if grouped {
                records[i].group.clone().unwrap_or_default()
            } else {
                format!("#{i}")
            }
        };
        let units: BTreeSet<String> = (0..records.len()).map(unit_of).collect();
        let mut loo = Vec::with_capacity(records.len());
        for i in 0..records.len() {
            let u = unit_of(i);
            let rest: Vec<&RecordFeatures> = (0..records.len())
                .filter(|&j| unit_of(j) != u)
                .map(|j| &records[j])
                .collect();
            let st = feature_stats(&rest, MIN_BASELINE_RECORDS - 1);
            loo.push(score_against(&st, &records[i]).0);
        }
        let u = units.len();
        let max_loo = loo.iter().copied().fold(0.0, f64::max);
        let threshold = if max_loo.is_finite() {
            max_loo.max(MIN_THRESHOLD)
        } else {
            MIN_THRESHOLD
        };
        Ok(MachineBaseline {
            features,
            threshold,
            n: records.len(),
            units: u,
            loo_scores: loo,
            rule: format!(
                "score = RMS of the {TOP_K} largest |z|; threshold = max({MIN_THRESHOLD}, the \
                 largest leave-one-{} score over {u} units): at most 1/(u+1) false alarms for \
                 exchangeable records",
                if grouped { "group-out" } else { "out" }
            ),
        })
    }

    /// Score a record: never NaN; features missing on either side are ignored.
    pub fn score(&self, f: &RecordFeatures) -> Novelty {
        let (score, zs) = score_against(&self.features, f);
        Novelty {
            score,
            threshold: self.threshold,
            anomalous: score > self.threshold,
            baseline_records: self.n,
            features_used: zs.len(),
            top_features: zs.into_iter().take(5).collect(),
        }
    }

    /// Records the baseline was fitted from.
    pub fn records(&self) -> usize {
        self.n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feats(pairs: &[(&str, f64)]) -> RecordFeatures {
        RecordFeatures {
            values: pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            indicators: serde_json::Value::Null,
            ..Default::default()
        }
    }

    #[test]
    fn too_few_records_is_a_clear_error() {
        let e = MachineBaseline::fit(&[feats(&[("a", 1.0)]), feats(&[("a", 1.1)])]).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("2") && s.contains("3"), "{s}");
        assert!(matches!(
            e,
            Error::BaselineTooSmall {
                records: 2,
                needed: 3
            }
        ));
    }

    /// Scale floor, missing features, NaN: the score stays finite and ignores what is missing.
    #[test]
    fn missing_features_and_floor() {
        let base: Vec<RecordFeatures> = (0..5)
            .map(|i| {
                let mut f = feats(&[("a", 1.0), ("b", 2.0 + 0.01 * i as f64)]);
                if i % 2 == 0 {
                    f.values.insert("c".into(), 0.5);
                }
                f
            })
            .collect();
        let b = MachineBaseline::fit(&base).unwrap();
        assert_eq!(b.records(), 5);
        assert_eq!(b.features["a"].scale, SCALE_FLOOR);
        assert!(b.threshold >= MIN_THRESHOLD && b.threshold.is_finite());
        // A record without `a` and with a NaN `b`: only `c` counts.
        let mut f = feats(&[("b", f64::NAN), ("c", 0.5 + 10.0 * SCALE_FLOOR)]);
        f.values.insert("unknown".into(), 5.0);
        let nv = b.score(&f);
        assert_eq!(nv.features_used, 1);
        assert!((nv.score - 10.0).abs() < 1e-9, "{nv:?}");
        assert!(nv.anomalous);
        // Nothing in common: score 0, not NaN.
        let nv = b.score(&feats(&[("zz", 1.0)]));
        assert_eq!((nv.score, nv.anomalous, nv.features_used), (0.0, false, 0));
        // A healthy-looking record is not anomalous.
        assert!(
            !b.score(&feats(&[("a", 1.0), ("b", 2.02), ("c", 0.5)]))
                .anomalous
        );
    }

    /// Gaussian features: the calibrated threshold keeps the false-alarm rate on new healthy
    /// records under its 1/(u+1) target (12 records: 7.7 %) and flags a 6-scale shift of three
    /// features.
    #[test]
    fn threshold_false_alarms_and_detection() {
        let mut s: u64 = 99;
        let mut gauss = move || {
            let mut acc = 0.0;
            for _ in 0..12 {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                acc += (s >> 11) as f64 / (1u64 << 53) as f64;
            }
            acc - 6.0
        };
        let d = 20;
        let mut rec = |shift: f64| {
            let pairs: Vec<(String, f64)> = (0..d)
                .map(|j| {
                    let v = 0.3 * gauss() + if j < 3 { shift } else { 0.0 };
                    (format!("f{j}"), v)
                })
                .collect();
            RecordFeatures {
                values: pairs.into_iter().collect(),
                indicators: serde_json::Value::Null,
                ..Default::default()
            }
        };
        let base: Vec<RecordFeatures> = (0..12).map(|_| rec(0.0)).collect();
        let b = MachineBaseline::fit(&base).unwrap();
        let alarms = (0..500).filter(|_| b.score(&rec(0.0)).anomalous).count();
        assert!(
            alarms <= 500 / 13,
            "{alarms} false alarms of 500 (threshold {})",
            b.threshold
        );
        let hits = (0..100)
            .filter(|_| b.score(&rec(6.0 * 0.3)).anomalous)
            .count();
        assert!(
            hits >= 80,
            "{hits} of 100 detected (threshold {})",
            b.threshold
        );
    }

    /// Three records: each leave-one-out fit has two, and still calibrates the threshold.
    #[test]
    fn three_records_are_calibrated() {
        let base = [
            feats(&[("a", 0.0)]),
            feats(&[("a", 0.05)]),
            feats(&[("a", 1.0)]),
        ];
        let b = MachineBaseline::fit(&base).unwrap();
        // The third, against (0, 0.05): location 0.025, scale at the 0.1 floor: z = 9.75.
        assert!((b.threshold - 9.75).abs() < 1e-9, "{:?}", b.loo_scores);
    }

    #[test]
    fn groups_are_left_out_together() {
        // Two copies per group: leave-one-record-out would see its twin and score 0.
        let base: Vec<RecordFeatures> = (0..4)
            .flat_map(|g| {
                let f = feats(&[("a", g as f64)]).with_group(format!("g{g}"));
                [f.clone(), f]
            })
            .collect();
        let b = MachineBaseline::fit(&base).unwrap();
        assert_eq!(b.units, 4);
        assert!(b.loo_scores.iter().all(|s| *s > 0.0), "{:?}", b.loo_scores);
        let json = serde_json::to_string(&b).unwrap();
        let back: MachineBaseline = serde_json::from_str(&json).unwrap();
        assert_eq!(back.threshold, b.threshold);
    }
}
