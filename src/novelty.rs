//! A machine's own healthy baseline and the novelty of a record against it.
//!
//! * [`record_features`] — the named scalar features of one record (one channel);
//! * [`MachineBaseline::fit`] — robust location (median) and scale (MAD·1.4826, with a floor)
//!   of each feature over the records marked healthy, and a threshold calibrated by
//!   leave-one-out on those records;
//! * [`MachineBaseline::score`] — the record's novelty: the root mean square of its robust
//!   z-scores, with the features that drive it.
//!
//! Description-free features (log band levels on a fixed logarithmic grid, kurtosis, crest
//! factor) work for a machine whose gearbox is not described.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signal::{Window, amplitude_spectrum, crest_factor, kurtosis};

/// What a baseline is made of: the features of one record (one channel).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RecordFeatures {
    /// Named scalar features; the baseline's inputs.
    pub values: BTreeMap<String, f64>,
    /// For people: how the features were obtained. Any JSON.
    pub indicators: serde_json::Value,
}

/// Fewest healthy records a baseline is fitted from.
pub const MIN_BASELINE_RECORDS: usize = 3;

/// Scale floor of a feature, in its own units (the features are natural logs or
/// dimensionless statistics of order 1): three records must not give a zero spread.
const SCALE_FLOOR: f64 = 0.15;
/// The threshold is this factor over the largest leave-one-out score of the baseline.
const LOO_MARGIN: f64 = 1.25;
/// ... and never below this score.
const MIN_THRESHOLD: f64 = 2.0;
/// Number of logarithmic bands between [`BAND_LO_HZ`] and 0.45·fs.
const BANDS: usize = 24;
const BAND_LO_HZ: f64 = 20.0;

/// The features of one record. `gearbox` and `input_shaft_hz` are hints; without them the
/// features are description-free.
pub fn record_features(
    rec: &Record,
    _gearbox: Option<&Gearbox>,
    _input_shaft_hz: Option<f64>,
) -> Result<RecordFeatures> {
    let sp = amplitude_spectrum(&rec.samples, rec.sample_rate, Window::Hann)?;
    let hi = 0.45 * rec.sample_rate;
    let mut values = BTreeMap::new();
    let ratio = (hi / BAND_LO_HZ).powf(1.0 / BANDS as f64);
    let total: f64 = sp
        .amplitude
        .iter()
        .map(|a| a * a)
        .sum::<f64>()
        .max(f64::MIN_POSITIVE);
    for b in 0..BANDS {
        let (lo, up) = (
            BAND_LO_HZ * ratio.powi(b as i32),
            BAND_LO_HZ * ratio.powi(b as i32 + 1),
        );
        let p: f64 = sp
            .freq
            .iter()
            .zip(&sp.amplitude)
            .filter(|(f, _)| **f >= lo && **f < up)
            .map(|(_, a)| a * a)
            .sum();
        values.insert(
            format!("band_{:05.0}hz", lo),
            ((p + 1e-12 * total) / total).ln(),
        );
    }
    values.insert("kurtosis".into(), kurtosis(&rec.samples).ln());
    values.insert("crest_factor".into(), crest_factor(&rec.samples).ln());
    values.retain(|_, v| v.is_finite());
    Ok(RecordFeatures {
        values,
        indicators: serde_json::json!({
            "method": "description-free: log relative power in 24 logarithmic bands, ln kurtosis, ln crest factor",
        }),
    })
}

/// Robust location and scale of each feature over a machine's healthy records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MachineBaseline {
    /// `name → (median, scale)`.
    pub features: BTreeMap<String, (f64, f64)>,
    pub threshold: f64,
    pub records: usize,
    /// How the threshold was set.
    pub threshold_rule: String,
}

/// The novelty of one record against a baseline.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Novelty {
    pub score: f64,
    pub threshold: f64,
    pub anomalous: bool,
    pub baseline_records: usize,
    pub top_features: Vec<FeatureZ>,
}

/// One feature's robust z-score.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FeatureZ {
    pub name: String,
    pub z: f64,
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn location_scale(records: &[&RecordFeatures]) -> BTreeMap<String, (f64, f64)> {
    let mut names: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for r in records {
        for (k, v) in &r.values {
            if v.is_finite() {
                names.entry(k).or_default().push(*v);
            }
        }
    }
    names
        .into_iter()
        .filter(|(_, v)| v.len() * 2 > records.len())
        .map(|(k, mut v)| {
            let m = median(&mut v);
            let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
            let s = (1.4826 * median(&mut dev)).max(SCALE_FLOOR);
            (k.to_string(), (m, s))
        })
        .collect()
}

fn zscores(features: &BTreeMap<String, (f64, f64)>, f: &RecordFeatures) -> Vec<FeatureZ> {
    features
        .iter()
        .filter_map(|(k, (m, s))| {
            let v = f.values.get(k)?;
            v.is_finite().then(|| FeatureZ {
                name: k.clone(),
                z: (v - m) / s,
            })
        })
        .collect()
}

fn rms_score(z: &[FeatureZ]) -> f64 {
    if z.is_empty() {
        return 0.0;
    }
    (z.iter().map(|z| z.z * z.z).sum::<f64>() / z.len() as f64).sqrt()
}

impl MachineBaseline {
    /// Fit from at least [`MIN_BASELINE_RECORDS`] healthy records.
    pub fn fit(records: &[RecordFeatures]) -> Result<MachineBaseline> {
        if records.len() < MIN_BASELINE_RECORDS {
            return Err(Error::Signal(format!(
                "a baseline needs at least {MIN_BASELINE_RECORDS} healthy records, got {}",
                records.len()
            )));
        }
        let all: Vec<&RecordFeatures> = records.iter().collect();
        let features = location_scale(&all);
        if features.is_empty() {
            return Err(Error::Signal(
                "the baseline records share no feature: were they recorded on the same channel?"
                    .into(),
            ));
        }
        // Leave one out: each healthy record scored against the others.
        let mut loo: f64 = 0.0;
        for i in 0..records.len() {
            let rest: Vec<&RecordFeatures> = all
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, r)| *r)
                .collect();
            let fs = location_scale(&rest);
            loo = loo.max(rms_score(&zscores(&fs, &records[i])));
        }
        let threshold = (LOO_MARGIN * loo).max(MIN_THRESHOLD);
        Ok(MachineBaseline {
            features,
            threshold,
            records: records.len(),
            threshold_rule: format!(
                "{LOO_MARGIN} × the largest leave-one-out score of the baseline records, at least {MIN_THRESHOLD}"
            ),
        })
    }

    /// The novelty of a record.
    pub fn score(&self, f: &RecordFeatures) -> Novelty {
        let mut z = zscores(&self.features, f);
        let score = rms_score(&z);
        z.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
        z.truncate(5);
        Novelty {
            score,
            threshold: self.threshold,
            anomalous: score > self.threshold,
            baseline_records: self.records,
            top_features: z,
        }
    }

    /// Number of records it was fitted from.
    pub fn records(&self) -> usize {
        self.records
    }
}
