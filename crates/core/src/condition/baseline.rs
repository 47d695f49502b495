//! A baseline that knows operating states: healthy records, each with its measured speed and
//! load, and what they expect of a record **at its state**.
//!
//! # Reference at a state (chosen before looking at any score)
//! The candidates are the baseline records of the record's load (all records when the record
//! or the baseline has no load). Among them, by measured input-shaft rate `f`:
//! 1. records within [`SAME_STATE`] (3 %) of `f` → their mean, feature by feature;
//! 2. else, two records on either side of `f` no more than [`MAX_GAP`] apart (ratio 1.5) →
//!    linear interpolation in `ln f`;
//! 3. else the nearest record if within [`NEAR`] (8 %);
//! 4. else the state is **not covered**, and the answer says which state is missing.
//!
//! Nearest healthy records, not a fitted curve of speed: a line's amplitude crosses
//! resonances as the speed changes, which no low-order curve follows, and a baseline usually
//! holds one or two records per state (the PHM 2009 data: one per speed and load).
//!
//! # Scale and threshold
//! A record at a baseline state is judged with the repeatability of that state — its
//! records' own noise (from their segments) and the spread between runs — and a record between
//! states with the spread of the baseline's leave-state-out predictions as well
//! ([`super::calibration`] has the equations). A record's `z` per feature is
//! `(value − reference) / scale`, its **score** the RMS of its [`TOP_K`] largest `|z|`; it is
//! anomalous above the threshold.

use serde::{Deserialize, Serialize};

pub use super::calibration::{Departure, MIN_THRESHOLD, TOP_K};
use super::calibration::{Within, across_scales, across_spread, departures, score_of, threshold};
use super::machine_model::{LineLevel, MachineModel, Observed, Refused};
use super::state::{Load, OperatingState};
use crate::{Error, Result};
use std::collections::BTreeMap;

/// Records within this relative speed difference are at the same state.
pub const SAME_STATE: f64 = 0.03;
/// Largest ratio of the two speeds an interpolation may span.
pub const MAX_GAP: f64 = 1.5;
/// A single nearest record counts within this relative speed difference.
pub const NEAR: f64 = 0.08;
/// Fewest baseline records with a state.
pub const MIN_STATE_RECORDS: usize = 3;

/// A healthy record: its state, evidence features and their noise in it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateRecord {
    pub state: OperatingState,
    pub values: BTreeMap<String, f64>,
    /// Each feature's noise in the record ([`super::evidence::Evidence::spread`]).
    #[serde(default)]
    pub spread: BTreeMap<String, f64>,
    /// Its marked lines' levels: what the machine's model is calibrated on.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lines: Vec<LineLevel>,
}

/// What a baseline covers at one load.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoadCoverage {
    /// `null`: records without a load.
    pub load: Option<Load>,
    pub records: usize,
    /// Measured speeds (Hz), sorted.
    pub speeds_hz: Vec<f64>,
    pub min_hz: f64,
    pub max_hz: f64,
}

/// A baseline's coverage of operating states.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Coverage {
    pub records: usize,
    pub loads: Vec<LoadCoverage>,
}

/// The expected features at a state and how they were obtained.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    pub values: BTreeMap<String, f64>,
    /// Speeds (Hz) of the baseline records it comes from.
    pub from_hz: Vec<f64>,
    /// `same-state`, `interpolated`, `nearest` or `model`.
    pub how: &'static str,
    /// The model's prediction uncertainty of the features it moved (ln units; `model` only):
    /// their scale is this and the state's repeatability in quadrature.
    pub uncertainty: BTreeMap<String, f64>,
}

/// A record judged against its state's reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StateScore {
    pub score: f64,
    pub threshold: f64,
    pub anomalous: bool,
    /// `same-state`, `interpolated`, `nearest` or `model`.
    pub reference: &'static str,
    /// Baseline speeds (Hz) the reference comes from.
    pub reference_hz: Vec<f64>,
    /// Every feature's departure, largest `|z|` first.
    #[serde(skip)]
    pub departures: Vec<Departure>,
    /// The [`TOP_K`] largest, for people.
    pub top: Vec<Departure>,
}

/// A state-aware baseline (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct StateBaseline {
    records: Vec<StateRecord>,
    /// The repeatability at a state.
    within: Within,
    /// Threshold of a record at a baseline state.
    within_threshold: f64,
    /// The scores its threshold was checked against (records predicted by others of their
    /// state).
    within_scores: Vec<f64>,
    /// Scales of a record between baseline states.
    across: BTreeMap<String, f64>,
    across_threshold: f64,
    /// The machine's model calibrated on the records' line levels (`None`: no record carries
    /// them).
    model: Option<Result<MachineModel, Refused>>,
}

fn candidates<'a>(records: &'a [StateRecord], load: Option<&Load>) -> Vec<&'a StateRecord> {
    let with_load = |r: &&StateRecord| match (load, &r.state.load) {
        (Some(a), Some(b)) => a.same(b),
        _ => true,
    };
    let mut v: Vec<&StateRecord> = records.iter().filter(with_load).collect();
    v.sort_by(|a, b| a.state.shaft_hz.total_cmp(&b.state.shaft_hz));
    v
}

fn mean_of(recs: &[&StateRecord]) -> BTreeMap<String, f64> {
    let mut sum: BTreeMap<String, (f64, usize)> = BTreeMap::new();
    for r in recs {
        for (k, v) in &r.values {
            let e = sum.entry(k.clone()).or_default();
            e.0 += v;
            e.1 += 1;
        }
    }
    sum.into_iter()
        .filter(|(_, (_, n))| *n == recs.len())
        .map(|(k, (s, n))| (k, s / n as f64))
        .collect()
}

/// The reference at speed `f` from sorted candidates; `any_distance`: fall back to the nearest
/// whatever its distance (leave-one-out).
fn reference(cands: &[&StateRecord], f: f64, any_distance: bool) -> Option<Reference> {
    let rel = |r: &StateRecord| (r.state.shaft_hz / f - 1.0).abs();
    let same: Vec<&StateRecord> = cands
        .iter()
        .copied()
        .filter(|r| rel(r) <= SAME_STATE)
        .collect();
    if !same.is_empty() {
        return Some(Reference {
            values: mean_of(&same),
            from_hz: same.iter().map(|r| r.state.shaft_hz).collect(),
            how: "same-state",
            uncertainty: BTreeMap::new(),
        });
    }
    let below = cands.iter().rev().find(|r| r.state.shaft_hz < f);
    let above = cands.iter().find(|r| r.state.shaft_hz > f);
    if let (Some(a), Some(b)) = (below, above)
        && b.state.shaft_hz / a.state.shaft_hz <= MAX_GAP
    {
        let (fa, fb) = (a.state.shaft_hz.ln(), b.state.shaft_hz.ln());
        let w = (f.ln() - fa) / (fb - fa);
        let values = a
            .values
            .iter()
            .filter_map(|(k, va)| b.values.get(k).map(|vb| (k.clone(), va + w * (vb - va))))
            .collect();
        return Some(Reference {
            values,
            from_hz: vec![a.state.shaft_hz, b.state.shaft_hz],
            how: "interpolated",
            uncertainty: BTreeMap::new(),
        });
    }
    let nearest = cands.iter().min_by(|a, b| rel(a).total_cmp(&rel(b)))?;
    (any_distance || rel(nearest) <= NEAR).then(|| Reference {
        values: nearest.values.clone(),
        from_hz: vec![nearest.state.shaft_hz],
        how: "nearest",
        uncertainty: BTreeMap::new(),
    })
}

impl StateBaseline {
    /// Fit from healthy records with their states (at least [`MIN_STATE_RECORDS`]), in any
    /// order: they are put in one (load, speed, values) so that the same records give the same
    /// baseline to the last bit, however a store returns them.
    pub fn fit(mut records: Vec<StateRecord>) -> Result<StateBaseline> {
        records.sort_by(|a, b| {
            let load = |r: &StateRecord| r.state.load.as_ref().map(|l| l.to_string());
            load(a)
                .cmp(&load(b))
                .then(a.state.shaft_hz.total_cmp(&b.state.shaft_hz))
                .then_with(|| {
                    a.values
                        .values()
                        .zip(b.values.values())
                        .map(|(x, y)| x.total_cmp(y))
                        .find(|o| o.is_ne())
                        .unwrap_or(std::cmp::Ordering::Equal)
                })
        });
        if records.len() < MIN_STATE_RECORDS {
            return Err(Error::BaselineTooSmall {
                records: records.len(),
                needed: MIN_STATE_RECORDS,
            });
        }
        let n = records.len();
        let same_state: Vec<_> = (0..n).map(|i| loo_residual(&records, i, false)).collect();
        let other_states: Vec<_> = (0..n).map(|i| loo_residual(&records, i, true)).collect();
        let spreads: Vec<&BTreeMap<String, f64>> = records
            .iter()
            .map(|r| &r.spread)
            .filter(|h| !h.is_empty())
            .collect();
        let spread_across = across_spread(&other_states);
        let within = Within::fit(&spreads, &same_state, &spread_across);
        if within.noise.is_empty() && other_states.iter().all(|r| r.is_empty()) {
            return Err(Error::BaselineUnrepeatable);
        }
        let wscales = within.scales();
        let within_scores: Vec<f64> = same_state
            .iter()
            .filter(|r| !r.is_empty())
            .map(|r| score_of(&departures(r, &zeros(r), |k| wscales.get(k).copied())))
            .collect();
        let within_threshold = threshold(wscales.len(), &within_scores);
        let across = across_scales(&wscales, &spread_across);
        let across_scores: Vec<f64> = other_states
            .iter()
            .filter(|r| !r.is_empty())
            .map(|r| score_of(&departures(r, &zeros(r), |k| across.get(k).copied())))
            .collect();
        let across_threshold = threshold(across.len(), &across_scores);
        let observed: Vec<Observed> = records
            .iter()
            .filter(|r| !r.lines.is_empty())
            .map(|r| Observed {
                state: &r.state,
                lines: &r.lines,
            })
            .collect();
        let model = (!observed.is_empty()).then(|| MachineModel::fit(&observed));
        Ok(StateBaseline {
            records,
            within,
            within_threshold,
            within_scores,
            across,
            across_threshold,
            model,
        })
    }

    /// The records' coverage, by load.
    pub fn coverage(&self) -> Coverage {
        let mut loads: Vec<LoadCoverage> = Vec::new();
        for r in &self.records {
            let f = r.state.shaft_hz;
            match loads.iter_mut().find(|l| match (&l.load, &r.state.load) {
                (Some(a), Some(b)) => a.same(b),
                (None, None) => true,
                _ => false,
            }) {
                Some(l) => {
                    l.records += 1;
                    l.speeds_hz.push(f);
                }
                None => loads.push(LoadCoverage {
                    load: r.state.load.clone(),
                    records: 1,
                    speeds_hz: vec![f],
                    min_hz: f,
                    max_hz: f,
                }),
            }
        }
        for l in &mut loads {
            l.speeds_hz.sort_by(f64::total_cmp);
            l.min_hz = l.speeds_hz[0];
            l.max_hz = l.speeds_hz[l.speeds_hz.len() - 1];
        }
        Coverage {
            records: self.records.len(),
            loads,
        }
    }

    /// The expected features at `state`; `Err` says which state the baseline lacks.
    pub fn reference(&self, state: &OperatingState) -> std::result::Result<Reference, String> {
        let cands = candidates(&self.records, state.load.as_ref());
        let at_load = match &state.load {
            Some(l) => format!("at load {l}"),
            None => "at any load".into(),
        };
        if cands.is_empty() {
            let loads: Vec<String> = self
                .coverage()
                .loads
                .iter()
                .map(|l| l.load.as_ref().map_or("(none)".into(), |l| l.to_string()))
                .collect();
            return Err(format!(
                "the baseline has no healthy record {at_load} (its loads: {}); add healthy \
                 records at this load",
                loads.join(", ")
            ));
        }
        reference(&cands, state.shaft_hz, false)
            .or_else(|| self.model_reference(state))
            .ok_or_else(|| {
            let speeds: Vec<String> = cands
                .iter()
                .map(|r| format!("{:.1}", r.state.shaft_hz))
                .collect();
            format!(
                "the baseline has no healthy record {at_load} near {:.2} Hz (its speeds {at_load}: \
                 {} Hz); add a healthy record at this speed and load",
                state.shaft_hz,
                speeds.join(", ")
            )
        })
    }

    /// The expected features at `state` predicted by the machine's calibrated model: its
    /// nearest healthy record at the state's load, each feature the model's lines feed moved
    /// by the model's change from that record's state to `state` ([`MachineModel::shift`])
    /// and judged with the model's uncertainty and the state's repeatability; the rest as
    /// that record holds them, judged with the spread between states. `None` without an accepted model or outside its calibrated
    /// range.
    pub fn model_reference(&self, state: &OperatingState) -> Option<Reference> {
        let model = self.model.as_ref()?.as_ref().ok()?;
        if !model.covers(state) {
            return None;
        }
        let f = state.shaft_hz;
        let cands = candidates(&self.records, state.load.as_ref());
        let nearest = cands
            .iter()
            .filter(|r| !r.lines.is_empty())
            .min_by(|a, b| {
                (a.state.shaft_hz / f)
                    .ln()
                    .abs()
                    .total_cmp(&(b.state.shaft_hz / f).ln().abs())
            })?;
        let shift = model.shift(&nearest.state, state);
        let values = nearest
            .values
            .iter()
            .map(|(k, v)| (k.clone(), v + shift.get(k).map_or(0.0, |s| s.change)))
            .collect();
        Some(Reference {
            values,
            from_hz: vec![nearest.state.shaft_hz],
            how: "model",
            uncertainty: shift.into_iter().map(|(k, s)| (k, s.sigma)).collect(),
        })
    }

    /// The machine's calibrated model, or why it was refused (`None`: the records carry no
    /// line levels).
    pub fn model(&self) -> Option<&Result<MachineModel, Refused>> {
        self.model.as_ref()
    }

    /// Judge a record's features at its state; `Err` as [`StateBaseline::reference`].
    pub fn score(
        &self,
        state: &OperatingState,
        values: &BTreeMap<String, f64>,
    ) -> std::result::Result<StateScore, String> {
        Ok(self.score_against(values, self.reference(state)?))
    }

    /// Judge a record's features against a given reference (the same-state repeatability for
    /// a same-state reference, else the spread between states).
    pub fn score_against(&self, values: &BTreeMap<String, f64>, r: Reference) -> StateScore {
        let same = r.how == "same-state" && !self.within.noise.is_empty();
        let n = r.from_hz.len();
        let (d, threshold) = if same {
            let d = departures(values, &r.values, |k| self.within.scale(k, n));
            (d, self.within_threshold)
        } else {
            // A feature the model moved: the nearest record's repeatability and the model's
            // uncertainty; the rest: the spread between states.
            let scale = |k: &str| match (r.uncertainty.get(k), self.within.scale(k, 1)) {
                (Some(u), Some(w)) => Some(w.hypot(*u)),
                _ => self.across.get(k).copied(),
            };
            (departures(values, &r.values, scale), self.across_threshold)
        };
        let score = score_of(&d);
        StateScore {
            score,
            threshold,
            anomalous: score > threshold,
            reference: r.how,
            reference_hz: r.from_hz,
            top: d.iter().take(TOP_K).cloned().collect(),
            departures: d,
        }
    }

    /// The threshold of a record at a baseline state.
    pub fn threshold(&self) -> f64 {
        self.within_threshold
    }

    /// The healthy comparisons the same-state threshold was checked against (records predicted
    /// by others of their state).
    pub fn loo_scores(&self) -> &[f64] {
        &self.within_scores
    }

    pub fn records(&self) -> usize {
        self.records.len()
    }

    /// Per feature: a record's own noise `σ`, the between-run spread where measured and the
    /// scale between states (ln units) — what the yardstick is made of, for people.
    pub fn spreads(&self) -> Vec<(String, f64, Option<f64>, Option<f64>)> {
        self.within
            .noise
            .iter()
            .map(|(k, h)| {
                (
                    k.clone(),
                    *h,
                    self.within.between.get(k).copied(),
                    self.across.get(k).copied(),
                )
            })
            .collect()
    }
}

/// A map of zeros with the keys of `r` (the reference of a residual).
fn zeros(r: &BTreeMap<String, f64>) -> BTreeMap<String, f64> {
    r.keys().map(|k| (k.clone(), 0.0)).collect()
}

/// Record `i`'s residual from a reference made without it: `whole_state` — without every
/// record of its state and load (how a record between baseline speeds is judged; the nearest
/// record at any distance when no interpolation reaches); else without it alone, and only
/// when its state has other records (how a record at a baseline state is judged), divided by
/// `√(1 + 1/m)` for a reference of `m` records (a between-run spread). Empty when there is no
/// such reference.
fn loo_residual(records: &[StateRecord], i: usize, whole_state: bool) -> BTreeMap<String, f64> {
    let me = &records[i];
    let f = me.state.shaft_hz;
    let same_state = |r: &StateRecord| {
        (r.state.shaft_hz / f - 1.0).abs() <= SAME_STATE
            && match (&r.state.load, &me.state.load) {
                (Some(a), Some(b)) => a.same(b),
                _ => true,
            }
    };
    let others: Vec<StateRecord> = records
        .iter()
        .enumerate()
        .filter(|(j, r)| *j != i && (!whole_state || !same_state(r)))
        .map(|(_, r)| r.clone())
        .collect();
    let cands = candidates(&others, me.state.load.as_ref());
    match reference(&cands, f, whole_state) {
        Some(r) if whole_state => residual(&me.values, &r.values, 1.0),
        Some(r) if r.how == "same-state" => {
            let m = r.from_hz.len() as f64;
            residual(&me.values, &r.values, (1.0 + 1.0 / m).sqrt())
        }
        _ => BTreeMap::new(),
    }
}

fn residual(
    values: &BTreeMap<String, f64>,
    reference: &BTreeMap<String, f64>,
    over: f64,
) -> BTreeMap<String, f64> {
    values
        .iter()
        .filter_map(|(k, v)| reference.get(k).map(|r| (k.clone(), (v - r) / over)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::state::SpeedSource;

    fn rec(f: f64, load: &str, v: f64) -> StateRecord {
        StateRecord {
            state: OperatingState {
                shaft_hz: f,
                source: SpeedSource::Tachometer,
                hint_hz: None,
                speed_variation: 0.0,
                load: Load::parse(load),
            },
            values: BTreeMap::from([("a".to_string(), v), ("b".to_string(), 0.0)]),
            spread: BTreeMap::new(),
            lines: Vec::new(),
        }
    }

    /// [`rec`] with its own noise `d` in both features.
    fn rec_noisy(f: f64, load: &str, v: f64, d: f64) -> StateRecord {
        StateRecord {
            spread: BTreeMap::from([("a".to_string(), d), ("b".to_string(), d)]),
            ..rec(f, load, v)
        }
    }

    /// Feature `a` rises with speed (ln a = ln f) at each load; a record at a covered state
    /// with the same law scores low, one 3 scales up is anomalous, and a state outside the
    /// baseline is refused naming what is missing.
    #[test]
    fn judges_at_the_state_and_names_the_missing_one() {
        let mut recs = Vec::new();
        for f in [30.0, 35.0, 40.0, 45.0, 50.0] {
            for (l, off) in [("High", 0.5), ("Low", 0.0)] {
                recs.push(rec(f, l, f64::ln(f) + off + 0.01 * (f % 7.0)));
            }
        }
        let b = StateBaseline::fit(recs).unwrap();
        let cov = b.coverage();
        assert_eq!(cov.loads.len(), 2);
        assert_eq!(cov.loads[0].speeds_hz, vec![30.0, 35.0, 40.0, 45.0, 50.0]);
        let st = |f: f64, l: &str| rec(f, l, 0.0).state;
        let ok = b
            .score(
                &st(37.5, "high"),
                &BTreeMap::from([("a".into(), f64::ln(37.5) + 0.5)]),
            )
            .unwrap();
        assert!(!ok.anomalous, "{ok:?}");
        assert_eq!(ok.reference, "interpolated");
        let bad = b
            .score(
                &st(40.3, "Low"),
                &BTreeMap::from([("a".into(), f64::ln(40.0) + 1.5)]),
            )
            .unwrap();
        assert!(bad.anomalous, "{bad:?} {}", b.threshold());
        assert_eq!(bad.reference, "same-state");
        let e = b.score(&st(60.0, "Low"), &BTreeMap::new()).unwrap_err();
        assert!(e.contains("near 60.00 Hz") && e.contains("load Low"), "{e}");
        let e = b.score(&st(40.0, "Medium"), &BTreeMap::new()).unwrap_err();
        assert!(e.contains("load Medium") && e.contains("High"), "{e}");
    }

    /// Features from the test lines (`ln` of each feature's RMS amplitude) and the lines.
    fn with_lines(f: f64, run: usize, shift: f64) -> StateRecord {
        let lines = crate::condition::test_util::lines(f, "High", run, 0.3, true);
        let mut energy: BTreeMap<String, (f64, f64)> = BTreeMap::new();
        for l in &lines {
            let e = energy.entry(l.feature.clone()).or_default();
            e.0 += 10f64.powf(l.level_db / 10.0);
            e.1 += 1.0;
        }
        let values: BTreeMap<String, f64> = energy
            .into_iter()
            .enumerate()
            .map(|(i, (k, (e, n)))| (k, 0.5 * (e / n).ln() + if i < 3 { shift } else { 0.0 }))
            .collect();
        StateRecord {
            spread: values.keys().map(|k| (k.clone(), 0.05)).collect(),
            values,
            lines,
            ..rec(f, "High", 0.0)
        }
    }

    /// Records at 20, 22 and 36 Hz leave 30 Hz uncovered (no record within 8 %, the gap
    /// 22–36 Hz too wide to interpolate) but inside the calibrated range: a healthy record
    /// there is judged against the model's reference, a changed one is anomalous, and 40 Hz
    /// (outside the range) is still refused.
    #[test]
    fn an_uncovered_state_inside_the_range_is_judged_against_the_model() {
        let recs: Vec<StateRecord> = [(20.0, 1), (22.0, 2), (36.0, 3), (20.0, 4), (36.0, 5)]
            .into_iter()
            .map(|(f, i)| with_lines(f, i, 0.0))
            .collect();
        let b = StateBaseline::fit(recs).unwrap();
        assert!(matches!(b.model(), Some(Ok(_))), "{:?}", b.model());
        let healthy = with_lines(30.0, 9, 0.0);
        let ok = b.score(&healthy.state, &healthy.values).unwrap();
        assert_eq!(ok.reference, "model");
        assert_eq!(ok.reference_hz, vec![36.0]);
        assert!(!ok.anomalous, "{ok:?}");
        let changed = with_lines(30.0, 9, 3.5);
        let bad = b.score(&changed.state, &changed.values).unwrap();
        assert!(bad.anomalous, "{bad:?}");
        let e = b.score(&rec(40.0, "High", 0.0).state, &BTreeMap::new());
        assert!(e.unwrap_err().contains("near 40.00 Hz"));
    }

    /// Two records per state, a feature that bends with speed (not linear in ln f): a healthy
    /// record between states is judged with the across-state spread (which holds the bend),
    /// one at a state with the repeatability — so neither false-alarms, and a shift that is
    /// small against the bend but large against the repeatability is still caught at a state.
    #[test]
    fn within_and_across_state_calibrations() {
        let mut recs = Vec::new();
        for (k, f) in [30.0, 35.0, 40.0, 45.0, 50.0].iter().enumerate() {
            for run in 0..2 {
                let bend = 0.02 * (f - 40.0f64).powi(2);
                let noise = 0.02 * ((k * 2 + run) as f64 * 1.7).sin();
                let d = 0.02 + 0.01 * ((k * 2 + run) as f64 * 2.3).cos();
                recs.push(rec_noisy(*f, "High", bend + noise, d));
            }
        }
        let b = StateBaseline::fit(recs).unwrap();
        let st = |f: f64| rec(f, "High", 0.0).state;
        let at = |f: f64, v: f64| b.score(&st(f), &BTreeMap::from([("a".into(), v)])).unwrap();
        let between = at(32.5, 0.02 * 7.5f64.powi(2));
        assert_eq!(between.reference, "interpolated");
        assert!(!between.anomalous, "{between:?}");
        let healthy = at(40.0, 0.01);
        assert_eq!(healthy.reference, "same-state");
        assert!(!healthy.anomalous, "{healthy:?}");
        let shifted = at(40.0, 0.6);
        assert!(shifted.anomalous, "{shifted:?}");
    }
}
