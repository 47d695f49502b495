//! One record's row of the closed-loop benchmark (`CL_OUT` JSON): the draw, its visibility
//! and the closed loop's answer.

use gearwear::closed_loop::sidebands::SidebandCheck;
use gearwear::closed_loop::{BandEvidence, CalibrationReport, Candidate};

use super::draw::Draw;
use super::run::Indicators;

/// A candidate of the report as a row keeps it: name, ΔBIC, eligible, fingerprint share, RMS
/// error (dB), why it was refused, a pair's member shares.
pub type CandidateRow = (
    String,
    f64,
    bool,
    f64,
    f64,
    Vec<String>,
    Vec<f64>,
    Option<BandEvidence>,
);

/// One record of the benchmark.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// The record's base seed and index in its set (`CL_SEED`, `CL_INDICES`).
    pub seed: u64,
    pub index: usize,
    pub kind: String,
    pub truth: Vec<String>,
    /// The effect's size measure (resonance peak gain, modulation depth, planetary error,
    /// stiffness loss, tone level, …).
    pub size: f64,
    pub ea: f64,
    pub omega1: f64,
    pub snr_db: f64,
    /// The one-draw measure (module docs) and its two figures.
    pub visible: bool,
    pub v_effect: f64,
    pub v_noise: f64,
    /// The K-draw measure: `vis_d > √2 vis_s`.
    pub visible_k: bool,
    pub vis_d: f64,
    pub vis_s: f64,
    pub named: Vec<String>,
    /// Unexplained features: the residual's lines and the level-over-time features.
    pub unexplained: usize,
    pub guesses: Vec<String>,
    /// The kinds of the level-over-time features among them (`unexplained_in_time`).
    pub in_time: Vec<String>,
    pub error_before: f64,
    pub error_after: f64,
    pub ea_before: f64,
    pub ea_after: f64,
    pub ea_lower: f64,
    pub ea_upper: f64,
    pub ea_before_lower: f64,
    pub ea_before_upper: f64,
    /// The refit's own profile-likelihood estimate `(ea, lower, upper)` (`wear_profile`;
    /// `None`: nothing claimed) and `wear_after`'s method.
    pub ea_profile: Option<(f64, f64, f64)>,
    /// The refit `wear_after` was decided from (`wear_refit`: `(ea, lower, upper)`).
    pub ea_refit: Option<(f64, f64, f64)>,
    pub method: String,
    /// Fitted resonance frequency over the truth (resonance records with the effect named).
    pub rho_ratio: Option<f64>,
    pub zeta_ratio: Option<f64>,
    pub seconds: f64,
    pub error: Option<String>,
    /// The selection's null spread and claim margin, and every candidate's (name, ΔBIC,
    /// eligible, fingerprint share, error dB, refusals, member shares, band evidence) — what
    /// `scripts/closed_loop_replay.py` replays the selection from.
    pub null_spread: f64,
    pub claim_margin: f64,
    pub null_deviances: Vec<f64>,
    pub candidates: Vec<CandidateRow>,
    /// The record's tacho-less condition indicators (the diagnosis's): FM4 of the difference
    /// signal, kurtosis of the record.
    pub fm4: f64,
    pub kurtosis: f64,
    /// FM4 of each shaft's TSA difference signal (the diagnosis's order analysis, where the
    /// record holds enough revolutions).
    pub tsa_fm4: Vec<(String, f64)>,
    /// Standard deviation / mean of the per-revolution shaft rate from the diagnosis's order
    /// tracking (NaN without one): the speed variation a constant-speed model cannot make.
    pub speed_std: f64,
    /// Speed wander: its rate over f1 (the size is its depth).
    pub wander_rate: Option<f64>,
    /// Shaft modulation / tooth damage: the rate over f1 of the shaft the rig put it on.
    pub truth_shaft: Option<f64>,
    /// A pair's members, each visible on its own (the record against the same record without
    /// that member) or not.
    pub member_visible: Vec<(String, bool)>,
    /// The same by the K-draw measure.
    pub member_visible_k: Vec<(String, bool)>,
    /// The claimed shaft modulation's / tooth damage's shaft rate over f1.
    pub named_shaft: Option<f64>,
    /// The report's sideband checks: (shaft, spacing over f1, prominence dB, off the rate,
    /// prominence of the sidebands at the shaft's rate dB, the strongest at the rate).
    pub sidebands: Vec<(String, f64, f64, bool, f64, bool)>,
}

/// A pair's members, each with whether it is visible on its own.
pub type Members = Vec<(String, bool)>;

impl Row {
    /// The row `seen` (the draw `d` and its visibility) with the closed loop's answer `rep`
    /// and the diagnosis's indicators `ind` (`f1`: the true f1, Hz).
    pub fn answered(seen: Row, rep: &CalibrationReport, d: &Draw, f1: f64, ind: Indicators) -> Row {
        let named: Vec<String> = rep.effects.iter().map(|e| e.name.clone()).collect();
        let fitted_resonance = rep.effects.iter().find(|x| x.name == "path-resonance");
        let (rho_ratio, zeta_ratio) = match (d.e.path_peak, fitted_resonance) {
            (Some((rho, zeta, _)), Some(x)) => (
                Some(x.parameters["frequency_hz"] / (rho * f1)),
                Some(x.parameters["damping_ratio"] / zeta),
            ),
            _ => (None, None),
        };
        Row {
            named,
            unexplained: rep.unexplained.len() + rep.unexplained_in_time.len(),
            guesses: rep
                .unexplained
                .iter()
                .map(|u| u.guess.clone())
                .chain(rep.unexplained_in_time.iter().map(|u| u.guess.clone()))
                .collect(),
            in_time: rep
                .unexplained_in_time
                .iter()
                .map(|u| u.kind.to_string())
                .collect(),
            error_before: rep.error_before,
            error_after: rep.error_after,
            ea_before: rep.wear_before.ea,
            ea_after: rep.wear_after.ea,
            ea_lower: rep.wear_after.ea_lower,
            ea_upper: rep.wear_after.ea_upper,
            ea_before_lower: rep.wear_before.ea_lower,
            ea_before_upper: rep.wear_before.ea_upper,
            ea_profile: rep.wear_profile.map(|w| (w.ea, w.ea_lower, w.ea_upper)),
            ea_refit: rep.wear_refit.map(|w| (w.ea, w.ea_lower, w.ea_upper)),
            method: rep.wear_after.method.into(),
            rho_ratio,
            zeta_ratio,
            seconds: 0.0,
            error: None,
            null_spread: rep.null_spread,
            claim_margin: rep.claim_margin,
            null_deviances: rep.null_deviances.clone(),
            candidates: rep.candidates.iter().map(candidate_row).collect(),
            fm4: ind.fm4,
            kurtosis: ind.kurtosis,
            tsa_fm4: ind.tsa_fm4,
            speed_std: ind.speed_std,
            named_shaft: rep
                .effects
                .iter()
                .find_map(|x| x.parameters.get("shaft_ratio").copied()),
            sidebands: rep.sideband_checks.iter().map(sideband_row).collect(),
            ..seen
        }
    }
}

/// A candidate as the row keeps it ([`CandidateRow`]).
fn candidate_row(c: &Candidate) -> CandidateRow {
    (
        c.name.clone(),
        c.delta_bic,
        c.eligible,
        c.fingerprint_share,
        c.error_db,
        c.refused.clone(),
        c.member_shares.clone(),
        c.band,
    )
}

/// A sideband check as the row keeps it: (shaft, spacing over f1, prominence dB, off the rate,
/// prominence of the sidebands at the shaft's rate dB, the strongest at the rate).
fn sideband_row(c: &SidebandCheck) -> (String, f64, f64, bool, f64, bool) {
    (
        c.shaft.clone(),
        c.spacing_ratio,
        c.prominence_db,
        c.off_rate,
        c.shaft_prominence_db,
        c.at_rate,
    )
}
