//! The answer of [`calibrate`](super::calibrate) ([`CalibrationReport`] and its parts), and
//! its last step: the residual features the final model leaves, each with a plain-words guess
//! ([`residual::annotate`](super::residual::annotate)), and from the record's level over time
//! bursts, impacts at a shaft's rate the fit did not claim, or a level drift
//! ([`level`](super::level): the spectrum averages them away).

use serde::Serialize;

use super::CalibrateOptions;
use super::attribution::BandEvidence;
use super::effects::{Effect, Resonance, TOOTH_DAMAGE, shaft_rates};
use super::level::{TimeFeature, level_features};
use super::measured::{Before, Measured};
use super::refit::After;
use super::residual::{annotate, residual_features};
use super::scatter::Null;
use super::sidebands::SidebandCheck;
use super::spectrum::{self, grid_index, rms_distance, running_median};
use crate::error::{Error, Result};

/// A wear state of the model.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct WearEstimate {
    /// Fixed-axis wear degree (units of b = 5 µm).
    pub ea: f64,
    /// Interval of `ea` at the diagnosis's credible level: the table posterior's (before, and
    /// after when no effect was claimed) or the profile likelihood's of the refit.
    pub ea_lower: f64,
    pub ea_upper: f64,
    /// Planetary composite-error amplitude (units of b; baseline 0.1).
    pub planetary: f64,
    /// Where `ea` and its interval come from: `table-posterior` (nothing claimed),
    /// `table-posterior-decoloured` (a path stage alone claimed: the table's posterior on the
    /// record divided by the fitted `|H|`), `table-posterior-effects-held` (element effects
    /// claimed: the table's posterior with their simulated feature change subtracted, on the
    /// de-coloured record when a path stage is claimed too), `profile-likelihood` (the
    /// refit's own profile, when the held posterior could not be computed) or
    /// `table-posterior-confirmed` (element effects claimed, and their refit lies inside the
    /// table's credible interval: the table's estimate and interval stand).
    pub method: &'static str,
}

/// The fitted sensor: gain and flat noise floor (dB of the record's unit, the gain relative to
/// the model's dimensionless ẍ̄1).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SensorFit {
    pub gain_db: f64,
    pub noise_db: f64,
    pub resonance: Option<Resonance>,
}

/// One candidate model of the selection.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Effects, joined by `+` (`none` for the plain model).
    pub name: String,
    pub effects: Vec<Effect>,
    /// Fitted parameters k (gain, noise, ea, plus the effects').
    pub parameters: usize,
    /// Residual sum of squares (dB²) over the grid.
    pub rss: f64,
    /// The weighted robust score `Σ ρ(u_j)` the selection uses (see
    /// [`fit::Weights`](super::fit::Weights)).
    pub score: f64,
    /// RMS log-spectral distance (dB).
    pub error_db: f64,
    pub bic: f64,
    /// BIC minus the BIC of `none` (negative: better).
    pub delta_bic: f64,
    /// Share of its RSS improvement over `none` that falls on its fingerprint points (it is
    /// eligible only from [`SUPPORT_SHARE`](super::SUPPORT_SHARE) on; 1 for `none`).
    pub fingerprint_share: f64,
    /// Why it is not eligible whatever its share and score: the resonance colours too few of
    /// the gearbox's lines, the damaged gear's TSA is not impulsive, the record's sidebands
    /// are not at (shaft modulation) or lie off (tooth damage) its shaft's rate. Empty when
    /// nothing refuses it.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub refused: Vec<String>,
    /// A pair: for each member (in `effects` order), the share of the pair's improvement over
    /// the other member's best single that falls on this member's fingerprint (a member is
    /// supported given the other from [`SUPPORT_SHARE`](super::SUPPORT_SHARE) on). Empty for a
    /// single effect.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub member_shares: Vec<f64>,
    /// A candidate with a path resonance: how its improvement lies over the resonance's own
    /// half-power band (see [`BandEvidence`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub band: Option<BandEvidence>,
    /// Whether it could be claimed: fingerprint share reached and the plain RMS error of the
    /// table's estimate lowered (and, for tooth damage, the damaged gear's TSA impulsive where
    /// the record has one, see [`TOOTH_TSA_FM4`](super::TOOTH_TSA_FM4), and the record's
    /// sidebands not off its shaft's rate; for shaft modulation, the record's strongest
    /// sidebands at its shaft's rate, see [`sidebands`](super::sidebands); a shaft modulation
    /// alone may stand on those sidebands instead of its share, see
    /// [`SM_SIDEBAND_PROMINENCE_DB`](super::SM_SIDEBAND_PROMINENCE_DB); a path resonance on its
    /// own band instead of the plain model's lines, see [`BandEvidence`]).
    pub eligible: bool,
    /// Tooth damage: FM4 of the damaged gear's shaft's TSA difference signal (the diagnosis's
    /// order analysis); absent when the record holds too few revolutions of that shaft.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tsa_fm4: Option<f64>,
}

/// A residual feature: a run of grid points beyond the threshold.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualFeature {
    /// `extra` (measured above the model: a line the model lacks) or `missing` (a model line the
    /// measurement lacks).
    pub kind: &'static str,
    /// Frequency of the extreme point over f1.
    pub frequency_ratio: f64,
    pub frequency_hz: f64,
    /// Residual (measured − fitted) at the extreme point (dB).
    pub size_db: f64,
    /// Measured level there, dB re the measured f1 line.
    pub level_db: f64,
    /// Width of the run (units of f1).
    pub width_ratio: f64,
    /// A plain-words guess at its cause ([`residual::annotate`](super::residual::annotate)); for
    /// the features of the final model only (empty before).
    pub guess: String,
}

/// The spectra behind the report, dB re the measured f1 line, on
/// [`spectrum::grid`](super::spectrum::grid).
#[derive(Debug, Clone, Serialize)]
pub struct Spectra {
    pub frequency_ratio: Vec<f64>,
    pub measured_db: Vec<f64>,
    pub fitted_before_db: Vec<f64>,
    pub fitted_after_db: Vec<f64>,
    pub residual_before_db: Vec<f64>,
    pub residual_after_db: Vec<f64>,
    /// Running median (±0.1 f1) of the residual after: the smooth trend left over.
    pub trend_after_db: Vec<f64>,
}

/// The answer of [`calibrate`](super::calibrate) (and the JSON of `gearwear calibrate`).
#[derive(Debug, Clone, Serialize)]
pub struct CalibrationReport {
    pub f1_hz: f64,
    pub omega1: f64,
    /// The effects added to the model (empty: none claimed).
    pub effects: Vec<Effect>,
    /// Residual features the final model leaves (frequencies and sizes).
    pub unexplained: Vec<ResidualFeature>,
    /// What the record's level over time shows and a steady model does not make: bursts,
    /// impacts once per revolution of a shaft the fit claimed no damaged tooth on, a level
    /// drift ([`level`](super::level)).
    pub unexplained_in_time: Vec<TimeFeature>,
    /// Residual features of the plain model (before).
    pub residual_features_before: Vec<ResidualFeature>,
    /// Effective number of independent grid points of the plain model's standardised residual
    /// (the `J_eff` of the deviance, the BIC and the wear interval).
    pub effective_points: f64,
    /// Standard deviation of the plain model's deviance `J ln(score/J)` over model seeds
    /// (other initial states) at its best wear: the model's own scatter, the null level.
    pub null_spread: f64,
    /// The ΔBIC an effect had to beat: `bic_margin + null_z · null_spread`.
    pub claim_margin: f64,
    /// The plain model's deviance `J ln(score/J)`: its wear profile's best point, then at the
    /// operating point from each extra model seed. "No effect" is scored by the lowest (the
    /// model may settle on another attractor from another initial state: an effect must beat
    /// the plain model from every initial state tried).
    pub null_deviances: Vec<f64>,
    /// RMS log-spectral distance before / after (dB, see [`spectrum`](super::spectrum)).
    pub error_before: f64,
    pub error_after: f64,
    pub wear_before: WearEstimate,
    pub wear_after: WearEstimate,
    /// The refit of the wear with the claimed effects (`None`: nothing claimed): the table's
    /// posterior with them held fixed (`table-posterior-effects-held` /
    /// `table-posterior-decoloured`), or the profile when that could not be computed.
    /// `wear_after` is this refit, except that an element refit inside the table's credible
    /// interval leaves the table's estimate standing
    /// ([`confirm_or_move`](super::refit::confirm_or_move)).
    pub wear_refit: Option<WearEstimate>,
    /// The chosen model's own profile-likelihood estimate of `ea` (`None`: nothing claimed),
    /// reported beside the refit for comparison.
    pub wear_profile: Option<WearEstimate>,
    pub sensor_before: SensorFit,
    pub sensor_after: SensorFit,
    /// Smooth residual trend after: RMS of the running median (dB).
    pub trend_rms_db: f64,
    pub candidates: Vec<Candidate>,
    /// Where the record's sidebands lie against each shaft an element effect was tried on
    /// ([`sidebands`](super::sidebands); empty when the record is too short to tell).
    pub sideband_checks: Vec<SidebandCheck>,
    pub spectra: Spectra,
    pub diagnosis_warnings: Vec<String>,
    pub options: CalibrateOptions,
}

/// The report of the loop: the residual before and after, the features the final model leaves
/// unexplained, and the spectra behind them (dB re the measured f1 line).
pub(super) fn assemble(
    ms: &Measured,
    before: &Before,
    null: &Null,
    after: After,
    candidates: Vec<Candidate>,
    claim_margin: f64,
    sideband_checks: Vec<SidebandCheck>,
) -> Result<CalibrationReport> {
    let (m, r, f1, opts) = (&ms.m, &ms.r, ms.f1, ms.opts);
    let error_before = before.error_db(ms.j_n);
    let error_after = rms_distance(m, &after.fitted);
    let i1 = grid_index(1.0).unwrap_or(0);
    let ref_db = m[i1];
    let rel = |v: &[f64]| v.iter().map(|x| x - ref_db).collect::<Vec<f64>>();
    let res_before: Vec<f64> = m.iter().zip(&before.fitted).map(|(a, b)| a - b).collect();
    let res_after: Vec<f64> = m.iter().zip(&after.fitted).map(|(a, b)| a - b).collect();
    let trend = running_median(&res_after, (0.1 * spectrum::GRID_PERIODS) as usize);
    let trend_rms_db = rms_distance(&trend, &vec![0.0; trend.len()]);
    let m_rel = rel(m);
    let (unexplained, unexplained_in_time) =
        unexplained(ms, &res_after, &m_rel, &after.effects, &sideband_checks);
    let residual_features_before =
        residual_features(&res_before, &m_rel, r, f1, opts.unexplained_db);
    if !(error_before.is_finite() && error_after.is_finite()) {
        return Err(Error::NonFiniteValue {
            analysis: "the closed-loop fit",
            what: "the fit error".into(),
        });
    }
    Ok(CalibrationReport {
        f1_hz: f1,
        omega1: ms.omega1,
        effects: after.effects,
        unexplained,
        unexplained_in_time,
        residual_features_before,
        effective_points: null.j_eff,
        null_spread: null.spread,
        claim_margin,
        null_deviances: null.deviances.clone(),
        error_before,
        error_after,
        wear_before: before.wear,
        wear_after: after.wear,
        wear_refit: after.refit,
        wear_profile: after.profile,
        sensor_before: before.sensor,
        sensor_after: after.sensor,
        trend_rms_db,
        candidates,
        sideband_checks,
        spectra: Spectra {
            frequency_ratio: r.clone(),
            measured_db: m_rel,
            fitted_before_db: rel(&before.fitted),
            fitted_after_db: rel(&after.fitted),
            residual_before_db: res_before,
            residual_after_db: res_after,
            trend_after_db: trend,
        },
        diagnosis_warnings: ms.diagnosis.warnings.clone(),
        options: opts.clone(),
    })
}

/// What the final model leaves: runs of its residual `res_after` beyond
/// ±[`CalibrateOptions::unexplained_db`], each with a plain-words guess; and the features of
/// the record's level over time (impacts at the rate of a shaft the claimed `effects` put a
/// damaged tooth on are explained).
fn unexplained(
    ms: &Measured,
    res_after: &[f64],
    m_rel: &[f64],
    effects: &[Effect],
    sideband_checks: &[SidebandCheck],
) -> (Vec<ResidualFeature>, Vec<TimeFeature>) {
    let f1 = ms.f1;
    let mut unexplained = residual_features(res_after, m_rel, &ms.r, f1, ms.opts.unexplained_db);
    annotate(&mut unexplained, ms.gb, f1, sideband_checks);
    let claimed_tooth = effects
        .iter()
        .find(|e| e.name == TOOTH_DAMAGE)
        .and_then(|e| e.parameters.get("shaft_ratio").copied());
    let unexplained_in_time = level_features(
        &ms.record.samples,
        ms.fs,
        f1,
        &shaft_rates(ms.gb),
        claimed_tooth,
    );
    (unexplained, unexplained_in_time)
}
