//! The answer of [`diagnose`](super::diagnose) and the steps that assemble it from the
//! posterior: the wear degree, the fit, the nearest table entries, the planetary check and the
//! matched lines.

use serde::{Deserialize, Serialize};

use super::inputs::Evaluation;
use super::matcher::{Matcher, Posterior, feature_index, posterior};
use super::options::{DiagnoseOptions, nan_or_above};
use crate::signal::features::ConditionIndicators;
use crate::signal::lines::LineMeasurement;
use crate::signal::mesh_search::F1Detection;
use crate::signal::tsa::OrderAnalysis;
use crate::signature::{LineDef, SignatureTable};

/// The wear estimate. It serialises as `null` when [`WearDegree::withheld`] says why it is not
/// shown (a record the model does not fit): a number read off a model that does not explain
/// the record is not a wear figure.
#[derive(Debug, Clone)]
pub struct WearDegree {
    /// Posterior median of ea (units of b = 5 µm).
    pub estimate: f64,
    /// Lower end of the credible interval.
    pub lower: f64,
    /// Upper end.
    pub upper: f64,
    /// Credible level of `[lower, upper]`.
    pub level: f64,
    /// Posterior mode.
    pub mode: f64,
    /// Why the figure is withheld from the answer (`None`: shown).
    pub withheld: Option<Withheld>,
}

/// Why a wear figure is not shown: what the pages and the API read (the `note` is for people).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WithheldReason {
    /// The model (through the machine's calibration, when it has one) does not fit the record.
    PoorFit,
    /// Most of the record's change is one part's (a gear's local damage, a shaft, a bearing),
    /// not the wear every tooth shares.
    OnePart,
    /// The record ran at a speed outside the machine's calibration.
    OutsideCalibration,
    /// The table at the record's speed is being computed; the record is read again when it is
    /// ready.
    TableInProgress,
    /// No table covers the record's speed and none will (the gearbox's table failed, or the
    /// speed would need more simulations than the service allows).
    OutsideTable,
}

impl WithheldReason {
    /// The word the API writes.
    pub fn as_str(self) -> &'static str {
        match self {
            WithheldReason::PoorFit => "poor-fit",
            WithheldReason::OnePart => "one-part",
            WithheldReason::OutsideCalibration => "outside-calibration",
            WithheldReason::TableInProgress => "table-in-progress",
            WithheldReason::OutsideTable => "outside-table",
        }
    }
}

/// A withheld wear figure: the reason, and the sentence that explains it.
#[derive(Debug, Clone, PartialEq)]
pub struct Withheld {
    pub reason: WithheldReason,
    pub note: String,
}

impl WearDegree {
    /// Withhold the figure (the diagnosis's `wear_note` and `wear_withheld` say it too, through
    /// [`Diagnosis::withhold`]).
    pub fn withhold(&mut self, reason: WithheldReason, note: impl Into<String>) {
        self.withheld = Some(Withheld {
            reason,
            note: note.into(),
        });
    }

    /// The reason it is withheld, if it is.
    pub fn withheld_reason(&self) -> Option<WithheldReason> {
        self.withheld.as_ref().map(|w| w.reason)
    }
}

impl Serialize for WearDegree {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        #[derive(Serialize)]
        struct Shown {
            estimate: f64,
            lower: f64,
            upper: f64,
            level: f64,
            mode: f64,
        }
        if self.withheld.is_some() {
            return s.serialize_none();
        }
        Shown {
            estimate: self.estimate,
            lower: self.lower,
            upper: self.upper,
            level: self.level,
            mode: self.mode,
        }
        .serialize(s)
    }
}

/// One measured line.
#[derive(Debug, Clone, Serialize)]
pub struct MatchedLine {
    pub name: String,
    /// Frequency over f1.
    pub normalised_frequency: f64,
    pub frequency_hz: f64,
    /// Peak amplitude (unit of the record).
    pub amplitude: f64,
    /// 20 log10(A / A_f1).
    pub level_db: f64,
    /// What the table expects at the estimate (dB re f1, after clipping), and its spread.
    pub expected_db: Option<f64>,
    pub expected_std_db: Option<f64>,
}

/// A table entry near the answer.
#[derive(Debug, Clone, Serialize)]
pub struct NearEntry {
    pub ea: f64,
    pub omega1: f64,
    /// Log-likelihood of the record at this entry (tempered).
    pub log_likelihood: f64,
    pub motion_state: String,
}

/// The planetary-stage check.
#[derive(Debug, Clone, Serialize)]
pub struct PlanetaryCheck {
    /// Measured ln(A_f3/A_f1) after clipping.
    pub f3_log_ratio: f64,
    /// Expected at the estimate with planetary error 0.1, and the combined spread.
    pub expected: f64,
    pub sigma: f64,
    pub z: f64,
    pub threshold: f64,
}

/// The paper's single-ratio method.
#[derive(Debug, Clone, Serialize)]
pub struct Baseline {
    pub method: &'static str,
    pub ea: f64,
}

/// How well the best table point explains the record.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    /// `Σ_d (y_d − μ_d)² / (σ_d² + feature_sigma²)` over the wear features at (mode, Ω1).
    pub chi2: f64,
    /// Number of features in the sum.
    pub features: usize,
    /// `chi2 / features`; ≈ 1 for a record the model explains. Above
    /// [`DiagnoseOptions::max_chi2_per_feature`] a warning says the record does not look like
    /// this model's output (another gearbox, another sensor position, a fault the model lacks).
    pub chi2_per_feature: f64,
    /// True when the fit was poor and the likelihood was flattened by `chi2_per_feature`.
    pub inflated: bool,
}

fn fit_is_poor(chi2_per_feature: f64, opts: &DiagnoseOptions) -> bool {
    nan_or_above(chi2_per_feature, opts.max_chi2_per_feature)
}

/// Record facts.
#[derive(Debug, Clone, Serialize)]
pub struct RecordInfo {
    pub samples: usize,
    pub sample_rate_hz: f64,
    pub duration_s: f64,
    pub f1_periods: f64,
    pub welch_segments: usize,
    pub segment_len: usize,
}

/// The answer of [`diagnose`](super::diagnose) (also the JSON of `gearwear diagnose`).
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub wear_degree: WearDegree,
    /// Why `wear_degree` is `null`, when it is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_note: Option<String>,
    /// The reason `wear_degree` is `null`, as a code the pages read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wear_withheld: Option<WithheldReason>,
    /// Stage-1 mesh frequency (Hz).
    pub f1_hz: f64,
    /// Input-shaft rate implied by f1 (Hz), `f1 / z1`.
    pub shaft_hz: f64,
    /// Ω1 = f1 / f_ref of the measured f1.
    pub omega1: f64,
    /// Posterior mean of Ω1.
    pub omega1_posterior: f64,
    pub f1_detection: F1Detection,
    /// Motion state of x1 the table expects at (estimate, Ω1).
    pub motion_state: String,
    /// Share of the table's seeds in that state at the nearest entry.
    pub motion_state_share: f64,
    pub planetary_clearance_elevated: bool,
    /// Absent for a gearbox without a planetary stage that the wear leaves out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planetary: Option<PlanetaryCheck>,
    pub lines: Vec<MatchedLine>,
    pub condition_indicators: ConditionIndicators,
    pub nearest_entries: Vec<NearEntry>,
    /// Posterior density over ea on a 0.01 grid: `(ea, density)`.
    pub posterior: Vec<(f64, f64)>,
    /// The paper's single-ratio method; absent for a gearbox with no second wear stage (its
    /// line `f2` is what the method reads).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baseline_single_ratio: Option<Baseline>,
    pub fit: Fit,
    pub record: RecordInfo,
    /// Table identity.
    pub table_model_hash: String,
    pub sensor: String,
    pub warnings: Vec<String>,
    /// Order tracking of the input shaft from the phase of the f1 line, the time-synchronous
    /// average of every shaft it reaches and the gear condition metrics on it (FM0, FM4, NA4,
    /// NB4, M6A, M8A, ER, SLF; [`crate::signal::tsa::order_analysis`]). Absent when the tracking
    /// fails (`order_error` says why).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order: Option<OrderAnalysis>,
    /// Why there is no `order` (e.g. a record of fewer than 16 revolutions).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order_error: Option<String>,
}

impl Diagnosis {
    /// Withhold the wear figure: `wear_degree` becomes `null`, `wear_note` says why in words
    /// and `wear_withheld` as a code.
    pub fn withhold(&mut self, reason: WithheldReason, note: impl Into<String>) {
        let note = note.into();
        self.wear_degree.withhold(reason, note.clone());
        self.wear_note = Some(note);
        self.wear_withheld = Some(reason);
    }
}

/// The fit at the best table point. A poor one flattens the likelihood (Birge-ratio
/// inflation: every variance scaled by χ²/D so the interval reflects the misfit instead of the
/// then meaningless nominal spread), recomputes `ev.post` and warns.
pub(super) fn fit_and_inflate(
    matcher: &Matcher,
    opts: &DiagnoseOptions,
    ev: &mut Evaluation,
    omega1: f64,
    warnings: &mut Vec<String>,
) -> Fit {
    let nfeat = matcher.wear_features.len();
    let fit = Fit {
        chi2: ev.chi2,
        features: nfeat,
        chi2_per_feature: ev.chi2 / nfeat.max(1) as f64,
        inflated: fit_is_poor(ev.chi2 / nfeat.max(1) as f64, opts),
    };
    if fit.inflated {
        let inflated = DiagnoseOptions {
            temperature: opts.temperature * fit.chi2_per_feature,
            ..opts.clone()
        };
        ev.post = posterior(matcher, &ev.y, omega1, &inflated);
        warnings.push(format!(
            "poor fit: χ² per feature {:.1} at the best table point (threshold {}); the record \
             does not look like this model's output (another gearbox, sensor or fault?). The \
             likelihood was flattened by that factor; treat the wear degree and the planetary \
             flag as unreliable",
            fit.chi2_per_feature, opts.max_chi2_per_feature
        ));
    }
    fit
}

/// Step 4, the answer: the posterior median, the credible interval at `level` and the mode.
pub(super) fn wear_degree(post: &Posterior, level: f64) -> WearDegree {
    let c = level.clamp(0.0, 1.0);
    WearDegree {
        estimate: post.quantile(0.5),
        lower: post.quantile(0.5 * (1.0 - c)),
        upper: post.quantile(0.5 * (1.0 + c)),
        level: c,
        mode: post.mode(),
        withheld: None,
    }
}

/// The majority motion state of the table entry `(i_ea, i_om)` and the share of its seeds in
/// that state.
pub(super) fn motion_state_at(table: &SignatureTable, i_ea: usize, i_om: usize) -> (String, f64) {
    let entry = table.entry(i_ea, i_om);
    let motion_state = entry.majority_motion();
    let share = entry.motion.iter().filter(|m| **m == motion_state).count() as f64
        / entry.motion.len().max(1) as f64;
    (motion_state, share)
}

/// The five entries of highest likelihood among the Ω1 columns next to `i_om`.
pub(super) fn nearest_entries(
    table: &SignatureTable,
    matcher: &Matcher,
    y: &[f64],
    i_om: usize,
    opts: &DiagnoseOptions,
) -> Vec<NearEntry> {
    let mut near: Vec<NearEntry> = Vec::new();
    let no = table.grid.omega1.len();
    for j in i_om.saturating_sub(1)..(i_om + 2).min(no) {
        for i in 0..table.grid.ea.len() {
            let k = i * no + j;
            near.push(NearEntry {
                ea: table.grid.ea[i],
                omega1: table.grid.omega1[j],
                log_likelihood: matcher.entry_log_likelihood(y, k, opts),
                motion_state: table.entries[k].majority_motion(),
            });
        }
    }
    near.sort_by(|a, b| b.log_likelihood.total_cmp(&a.log_likelihood));
    near.truncate(5);
    near
}

/// Step 5: the z-score of the measured `ln(A_f3/A_f1)` against what the table expects at
/// `(ea, omega1)`.
pub(super) fn planetary_check(
    matcher: &Matcher,
    y: &[f64],
    ea: f64,
    omega1: f64,
    opts: &DiagnoseOptions,
) -> Option<PlanetaryCheck> {
    let f3 = matcher.f3_feature?;
    let (m3, v3) = matcher.stats_at(f3, ea, omega1);
    let s3 = (v3 + opts.feature_sigma.powi(2)).sqrt();
    Some(PlanetaryCheck {
        f3_log_ratio: y[f3],
        expected: m3,
        sigma: s3,
        z: (y[f3] - m3) / s3,
        threshold: opts.planetary_z,
    })
}

/// Every measured line with its level re f1 and what the table expects at `(ea, omega1)`.
pub(super) fn matched_lines(
    lines: &[LineDef],
    meas: &LineMeasurement,
    matcher: &Matcher,
    ea: f64,
    omega1: f64,
    f1: f64,
) -> Vec<MatchedLine> {
    let i1 = LineMeasurement::index(lines, "f1").unwrap_or(0);
    let a1 = meas.amplitudes[i1];
    let to_db = 20.0 / std::f64::consts::LN_10;
    lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let expected = feature_index(lines, &l.name).map(|d| {
                let (m, v) = matcher.stats_at(d, ea, omega1);
                (m * to_db, v.sqrt() * to_db)
            });
            MatchedLine {
                name: l.name.clone(),
                normalised_frequency: l.ratio,
                frequency_hz: l.ratio * f1,
                amplitude: meas.amplitudes[i],
                level_db: 20.0 * (meas.amplitudes[i] / a1).log10(),
                expected_db: if l.name == "f1" {
                    Some(0.0)
                } else {
                    expected.map(|e| e.0)
                },
                expected_std_db: if l.name == "f1" {
                    Some(0.0)
                } else {
                    expected.map(|e| e.1)
                },
            }
        })
        .collect()
}

/// The posterior density over ea on a 0.01 grid (per unit ea), rounded to 4 decimals.
pub(super) fn coarse_density(post: &Posterior) -> Vec<(f64, f64)> {
    let step = post.ea.get(1).map(|e| e - post.ea[0]).unwrap_or(1.0);
    let per = ((0.01 / step).round() as usize).max(1);
    post.ea
        .chunks(per)
        .zip(post.p.chunks(per))
        .map(|(e, p)| {
            let mass: f64 = p.iter().sum();
            let round = |v: f64| (v * 1e4).round() / 1e4;
            (round(e[0]), round(mass / (step * p.len() as f64)))
        })
        .collect()
}

pub(super) fn nearest(axis: &[f64], v: f64) -> usize {
    axis.iter()
        .enumerate()
        .min_by(|a, b| (a.1 - v).abs().total_cmp(&(b.1 - v).abs()))
        .map(|(i, _)| i)
        .unwrap_or(0)
}
