//! Closing the loop with measured data: fit the model to a record, look at the residual,
//! attribute it to an effect the model lacks (or say it is unexplained), add the effect and
//! refit. See `docs/closed-loop.md`.
//!
//! [`calibrate`] in steps:
//! 1. **Diagnose** ([`crate::diagnosis::diagnose`]): f1, Ω1 and the table posterior of `ea`.
//! 2. **Measured spectrum** `M_j` on the normalised grid ([`spectrum`]).
//! 3. **Fit before**: simulate the model at (ea, Ω1, planetary 0.1) → `S_j`; fit the sensor
//!    gain `g` and the flat measurement-noise floor `n` by Levenberg–Marquardt on
//!    `F_j = 10 log10(g² S_j² |H_j|² + n²)` (dB; `H ≡ 1` without a path stage).
//! 4. **The model's own scatter** ([`model_scatter`]): the plain model at its best wear
//!    (least squares) is simulated from [`CalibrateOptions::model_seeds`] more initial states;
//!    their spread per grid point, the record's Welch scatter where the noise floor dominates
//!    and a line-position term give a per-point `σ_j`. Every later fit and score uses the
//!    standardised residual `u_j = (M_j − F_j)/σ_j` with Huber's ρ ([`fit::Weights`]).
//! 5. **Candidates**: no effect (ea profiled over 0.1, 0.2, …, 1.0, the table's value and ±0.05
//!    around the best), a
//!    path resonance searched over the whole band ([`fit::search_resonance`]), each element
//!    effect (shaft modulation on either shaft of the reference mesh, planetary wear, a damaged
//!    tooth on either gear of the reference mesh: the modulation amplitude scaled from the
//!    residual at its sideband lines, the planetary error and the tooth's stiffness loss by
//!    their score over a grid; ea profiled locally, amplitude again), and the pairs (an element
//!    effect with a resonance searched again over the band on top of the element's spectrum,
//!    or with the single resonance's, whichever fits better). Scored by
//!    `BIC = J ln(Σρ/J) + k ln J` (J grid points).
//! 6. **Selection**: only candidates whose improvement falls on their fingerprint
//!    ([`SUPPORT_SHARE`], see [`Candidate::fingerprint_share`]) and that lower the plain RMS
//!    error are eligible (as measured at the record's own resolution, [`sidebands`]: shaft
//!    modulation only where the record's strongest sidebands are at its shaft's rate, tooth
//!    damage not where they are off it; a shaft modulation alone whose shaft's sidebands stand
//!    [`SM_SIDEBAND_PROMINENCE_DB`] up is eligible below the share if it beats "no effect" by
//!    [`SM_SIDEBAND_MARGIN_FACTOR`] margins; a path resonance whose own half-power band holds
//!    its improvement ([`BandEvidence`]) stands on that band instead of the lines, alone at
//!    [`BAND_MARGIN_FACTOR`] margins; [`Candidate::refused`] says why a candidate was
//!    not); the lowest BIC of the eligible single effects wins if
//!    it beats "no effect" by `bic_margin + null_z · null_spread` (`null_spread`: the standard deviation of
//!    the plain model's deviance over the model seeds — what luck alone gives; times
//!    [`TOOTH_MARGIN_FACTOR`] for tooth damage); a pair replaces
//!    it only if it beats the best single by that margin and each member is supported: eligible
//!    on its own with a BIC below "no effect"'s, or, given the other member, with the pair's
//!    improvement over the other member's best single falling on its fingerprint.
//! 7. **Refit**: a path resonance alone — the record de-coloured by the fitted `|H|`
//!    ([`held::decolour_with`]) and diagnosed again: the table's posterior is the wear
//!    (`table-posterior-decoloured`). With an element effect, the table's posterior with the
//!    effects held fixed: the record's line features minus what the effects change in the
//!    model's (simulated with and without them at the profile's best ea), on the de-coloured record
//!    when a path stage is claimed too (`table-posterior-effects-held`,
//!    [`table_posterior_held`]). Beside it, the chosen model's ea is profiled
//!    (`wear_profile`): a parabola fitted to the profile's deviance near its minimum gives the
//!    vertex and the interval (the χ²₁ likelihood interval of the parabola widened by the
//!    vertex's uncertainty from the simulations' scatter, [`fit::profile_interval_noisy`]);
//!    it is the refit only when the held posterior cannot be computed. An element refit
//!    inside the table's credible interval leaves the table's estimate standing
//!    (`table-posterior-confirmed`, [`confirm_or_move`]). With no effect
//!    claimed (or a refit that does not lower the plain error) the model is unchanged and
//!    `wear_after` is the table's estimate.
//! 8. **Unexplained**: runs of the final residual beyond ±[`CalibrateOptions::unexplained_db`],
//!    each with a plain-words guess ([`residual::annotate`]); and, from the record's level
//!    over time, bursts, impacts at a shaft's rate the fit did not claim, or a level drift
//!    ([`level`]: the spectrum averages them away).

pub mod effects;
pub mod fit;
pub mod held;
pub mod level;
pub mod residual;
pub mod sidebands;
pub mod spectrum;
pub mod virtual_rig;

use std::collections::{BTreeMap, HashMap};
use std::sync::Mutex;

use rayon::prelude::*;
use std::f64::consts::TAU;

use serde::Serialize;

use crate::diagnosis::{DiagnoseOptions, diagnose, diagnose_shifted};
use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signal::lines::measure_lines;
use crate::signature::precompute::{SimOptions, random_initial, simulate_sensor};
use crate::signature::{LineDef, line_ratios};
use crate::signature::{SignatureTable, SplitMix64, mix_seed};
use crate::solver::Dopri5Options;
use effects::{
    Effect, ElementParams, MeshGear, PATH_RESONANCE, PLANETARY_WEAR, Resonance, SHAFT_MODULATION,
    TOOTH_DAMAGE, build_model, reference_gears, shaft_rates, shaft_ratio,
};
use fit::{
    Weights, effective_points, fit_sensor, profile_interval_noisy, search_resonance, sensor_model,
};
use level::{TimeFeature, level_features};
use residual::{annotate, fingerprint_gap, residual_features};
use sidebands::{SidebandCheck, SidebandScan, refusal, refuses};
use spectrum::{grid, grid_index, log_spectrum, rms_distance, running_median};

/// Tuning of [`calibrate`].
#[derive(Debug, Clone, Serialize)]
pub struct CalibrateOptions {
    /// Options of the underlying diagnosis (shaft rate, table likelihood).
    pub diagnose: DiagnoseOptions,
    /// Length of each model simulation in f1 periods (32 samples a period).
    pub sim_periods: usize,
    /// Seed of the model simulations' initial state.
    pub sim_seed: u64,
    /// BIC improvement (over J = 314 grid points, against the plain model from its best initial
    /// state) an effect must bring to be claimed, before the null part `null_z · null_spread`.
    /// 50 was set on the tuning seed of `benches/closed_loop.rs` (seed 1; see
    /// `docs/closed-loop.md`): the classical 10 let effects fit the model's own scatter.
    pub bic_margin: f64,
    /// A residual run beyond ± this many dB is reported (unexplained if the final model has it).
    pub unexplained_db: f64,
    /// Extra model seeds (other initial states) simulated at the plain model's operating point
    /// to measure the model's own scatter ([`model_scatter`]).
    pub model_seeds: usize,
    /// The claim margin grows by this many times the seed-to-seed spread of the plain model's
    /// deviance (`null_spread` of the report): an effect must beat the model's own scatter.
    pub null_z: f64,
    /// Score every candidate from the same initial states as "no effect" (the loop's own and
    /// the [`CalibrateOptions::model_seeds`] others) and keep its best, as "no effect" is
    /// scored; otherwise a candidate is scored from the loop's own initial state only. The
    /// attribution checks (fingerprint share, error, band) stay at the loop's own state. About
    /// `model_seeds` more simulations per candidate.
    pub candidate_seeds: bool,
    /// Score every candidate, "no effect" included, on its **mean** log spectrum over the same
    /// initial states (the loop's own and the [`CalibrateOptions::model_seeds`] others): the
    /// expected spectrum, which is what the benchmark's visibility measure compares, instead of
    /// one chaotic draw (or the best of several). The attribution checks stay at the loop's
    /// own state; overrides `candidate_seeds`; about `model_seeds` more simulations per
    /// candidate. Experimental, off: on seeds 44–51 of `benches/closed_loop.rs` it named 104
    /// of 116 visible effects against 103 without, at 1.38× the time, with one clean and
    /// three non-library records fewer kept out (`docs/closed-loop.md`, § Session 16).
    pub mean_seeds: bool,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        CalibrateOptions {
            diagnose: DiagnoseOptions::default(),
            sim_periods: 640,
            sim_seed: 0xC105ED,
            bic_margin: 50.0,
            unexplained_db: 10.0,
            model_seeds: 6,
            null_z: 0.5,
            candidate_seeds: false,
            mean_seeds: false,
        }
    }
}

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
    /// The weighted robust score `Σ ρ(u_j)` the selection uses (see [`fit::Weights`]).
    pub score: f64,
    /// RMS log-spectral distance (dB).
    pub error_db: f64,
    pub bic: f64,
    /// BIC minus the BIC of `none` (negative: better).
    pub delta_bic: f64,
    /// Share of its RSS improvement over `none` that falls on its fingerprint points (it is
    /// eligible only from [`SUPPORT_SHARE`] on; 1 for `none`).
    pub fingerprint_share: f64,
    /// Why it is not eligible whatever its share and score: the resonance colours too few of
    /// the gearbox's lines, the damaged gear's TSA is not impulsive, the record's sidebands
    /// are not at (shaft modulation) or lie off (tooth damage) its shaft's rate. Empty when
    /// nothing refuses it.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub refused: Vec<String>,
    /// A pair: for each member (in `effects` order), the share of the pair's improvement over
    /// the other member's best single that falls on this member's fingerprint (a member is
    /// supported given the other from [`SUPPORT_SHARE`] on). Empty for a single effect.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub member_shares: Vec<f64>,
    /// A candidate with a path resonance: how its improvement lies over the resonance's own
    /// half-power band (see [`BandEvidence`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub band: Option<BandEvidence>,
    /// Whether it could be claimed: fingerprint share reached and the plain RMS error of the
    /// table's estimate lowered (and, for tooth damage, the damaged gear's TSA impulsive where
    /// the record has one, see [`TOOTH_TSA_FM4`], and the record's sidebands not off its
    /// shaft's rate; for shaft modulation, the record's strongest sidebands at its shaft's
    /// rate, see [`sidebands`]; a shaft modulation alone may stand on those sidebands instead of
    /// its share, see [`SM_SIDEBAND_PROMINENCE_DB`]; a path resonance on its own band instead of
    /// the plain model's lines, see [`BandEvidence`]).
    pub eligible: bool,
    /// Tooth damage: FM4 of the damaged gear's shaft's TSA difference signal (the diagnosis's
    /// order analysis); absent when the record holds too few revolutions of that shaft.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tsa_fm4: Option<f64>,
}

/// Share of a candidate's improvement that must fall on its fingerprint (see [`calibrate`]).
pub const SUPPORT_SHARE: f64 = 0.25;

/// Shaft modulation is also eligible below [`SUPPORT_SHARE`] where the record's strongest
/// sidebands are at its shaft's rate and stand this far (dB) above the scanned window's median
/// ([`sidebands::SidebandCheck::shaft_prominence_db`]) …
pub const SM_SIDEBAND_PROMINENCE_DB: f64 = 6.0;
/// … and it beats "no effect" by this many claim margins. A strong modulation changes the
/// chaotic model's whole response, not only its ± 1-order sidebands (seed 22 of the benchmark,
/// record 13: ΔBIC −285, share 0.09, the input shaft's sidebands at its rate 6.4 dB up). Set in
/// session 14 by replaying the selection over the stored candidates of seeds 22–27
/// (`scripts/closed_loop_replay.py`): two more modulations named, no other answer changed.
pub const SM_SIDEBAND_MARGIN_FACTOR: f64 = 2.0;

/// The sideband orders `k` (`l ± k s` around every line `l`) a shaft modulation's fingerprint
/// covers.
const SM_ORDERS: [f64; 3] = [1.0, 2.0, 3.0];

/// Lines of the plain model (peaks 6 dB above its noise floor) a path resonance must move by
/// more than 3 dB relative to f1 to be eligible (otherwise the candidate says so in
/// [`Candidate::refused`]). It was 3 until session 14; replaying the selection over the stored
/// candidates of seeds 22–27 at 2 named six more true path resonances (two of them visible)
/// and claimed one path on a planetary-wear record.
pub const MIN_COLOURED_LINES: usize = 2;

/// How a path resonance's improvement lies over its own half-power band
/// `|r − ρ| ≤ max(ζ ρ, 1/GRID_PERIODS)`: against the plain model at the candidate's ea (a
/// single) or the other member's best single (a pair).
///
/// A resonance lifts everything the gearbox makes in its band — the lines and the chaotic
/// continuum between them, which the plain model may hold below its noise floor — so a strong
/// mode between the lines improves the fit over a run of neighbouring points without moving
/// [`MIN_COLOURED_LINES`] lines (seed 32 of the benchmark, record 23: a peaking mode at 2.16 f1,
/// ζ 0.023, gain 8.2; ΔBIC −685, 95 % of the improvement off the lines). The band's width alone
/// does not keep tones out: over seeds 32–43 the resonance candidates of the 144 tone and
/// mains-hum records had bands of 0–173 points (median 5 and 2), 33 of them 8 or more; none beat
/// "no effect" by [`BAND_MARGIN_FACTOR`] margins (the best by 1.2), which is what keeps them out.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BandEvidence {
    /// Grid points in the band.
    pub points: usize,
    /// Of those, the points whose residual the candidate lowers.
    pub improved: usize,
    /// Share of the candidate's improvement (over the whole grid) that lies in the band.
    pub share: f64,
}

impl BandEvidence {
    /// The band holds a resonance of its own: at least [`BAND_MIN_POINTS`] points,
    /// [`BAND_IMPROVED_FRACTION`] of them improved, and [`SUPPORT_SHARE`] of the improvement.
    pub fn holds(&self) -> bool {
        self.points >= BAND_MIN_POINTS
            && self.improved as f64 >= BAND_IMPROVED_FRACTION * self.points as f64
            && self.share >= SUPPORT_SHARE
    }
}

/// Grid points a resonance's half-power band must span for [`BandEvidence`] (8 points:
/// ζ ρ ≥ 0.03, e.g. ζ 0.03 at f1; the benchmark's modes are drawn with Q 2–30).
pub const BAND_MIN_POINTS: usize = 8;
/// Share of the band's points the resonance must improve.
pub const BAND_IMPROVED_FRACTION: f64 = 0.8;
/// A path resonance alone that its band supports (below [`SUPPORT_SHARE`] on the lines, or
/// colouring fewer than [`MIN_COLOURED_LINES`]) must beat "no effect" by this many claim
/// margins. Set in session 15 by replaying the selection over the band figures of seeds 32–35
/// (`scripts/closed_loop_replay.py`): at 1 and at 2 the same answers changed.
pub const BAND_MARGIN_FACTOR: f64 = 2.0;

/// A candidate holding tooth damage must beat "no effect" (and a pair the best single) by this
/// many claim margins. Its fingerprint, the shaft's whole order comb, covers most of the grid
/// (all of it for a gear of many teeth), so the attribution check hardly tests it, and two
/// variants (one per gear) are tried. First set to 1.5 on seeds 4 and 5 of the benchmark (1.0:
/// speed wander and noise bursts claimed as tooth damage; 2.0 and more: fewer true ones
/// named), when a line-skirt artefact of the grid spectrum (fixed in session 12) gave the
/// 100-tooth gear's sidebands something to fit on every record. Re-set in session 13 from the
/// stored candidates of seeds 14–21 (528 records; the selection replayed at each factor
/// reproduces every answer at 1.5): 2.5 names one visible effect fewer (103 of 122 against
/// 104) and makes 2 fewer false claims on library records (9 against 11); on seeds 22–23 it
/// names the same 25 of 34 and makes 3 fewer false claims (1 against 4), one of them on a
/// clean record. Checked on the fresh seeds 24 and 25 (`docs/closed-loop.md` § Session 13).
pub const TOOTH_MARGIN_FACTOR: f64 = 2.5;

/// A damaged tooth makes its shaft's time-synchronous average impulsive: where the diagnosis's
/// order analysis has a TSA of that shaft, tooth damage is eligible only if the FM4 of its
/// difference signal (kurtosis; 3 for a Gaussian signal) reaches this. Set on seeds 4–7 of the
/// benchmark and the tests' pinion record: a damaged pinion gave its shaft's TSA an FM4 of
/// 3–16 (6 of 9 above 6; the test's 0.6 stiffness loss at 20 dB SNR 5.4), speed wander at
/// most 3.9, clean records 2.4–6.4 (the chaotic model's own impacts), shaft modulation up to
/// 6.7 — so it keeps out what is not impulsive, not all that is.
/// Where the record is too short for a TSA of the shaft (under
/// [`crate::novelty::MIN_TSA_REVS`] revolutions) the spectrum alone decides.
pub const TOOTH_TSA_FM4: f64 = 5.0;

/// Stiffness losses a damaged-tooth candidate is scored at (then refined between neighbours).
const TOOTH_SCAN: [f64; 7] = [0.05, 0.1, 0.2, 0.35, 0.5, 0.7, 0.9];

/// Shaft-modulation sideband amplitudes (units of b) a slow shaft's modulation is scored at
/// (then refined between neighbours): the benchmark draws 0.0025–0.25.
const MODULATION_SCAN: [f64; 8] = [0.005, 0.01, 0.02, 0.04, 0.08, 0.15, 0.3, 0.6];

/// Planetary error amplitudes (units of b) a planetary-wear candidate is scored at (those
/// above the gearbox's baseline; then refined between neighbours).
const PLANETARY_SCAN: [f64; 7] = [0.2, 0.35, 0.6, 1.0, 1.7, 3.0, 5.0];

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
    /// A plain-words guess at its cause ([`residual::annotate`]); for the features of the
    /// final model only (empty before).
    pub guess: String,
}

/// The spectra behind the report, dB re the measured f1 line, on [`spectrum::grid`].
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

/// The answer of [`calibrate`] (and the JSON of `gearwear calibrate`).
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
    /// drift ([`level`]).
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
    /// RMS log-spectral distance before / after (dB, see [`spectrum`]).
    pub error_before: f64,
    pub error_after: f64,
    pub wear_before: WearEstimate,
    pub wear_after: WearEstimate,
    /// The refit of the wear with the claimed effects (`None`: nothing claimed): the table's
    /// posterior with them held fixed (`table-posterior-effects-held` /
    /// `table-posterior-decoloured`), or the profile when that could not be computed.
    /// `wear_after` is this refit, except that an element refit inside the table's credible
    /// interval leaves the table's estimate standing ([`confirm_or_move`]).
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
    /// ([`sidebands`]; empty when the record is too short to tell).
    pub sideband_checks: Vec<SidebandCheck>,
    pub spectra: Spectra,
    pub diagnosis_warnings: Vec<String>,
    pub options: CalibrateOptions,
}

/// Cache key of a simulated spectrum: the element parameters and the initial state's seed.
type SpectrumKey = ([u64; 6], u64);

/// Samples per stage-1 mesh period of the closed loop's simulations.
const SIM_SPP: usize = 32;

/// Simulated model spectra, cached by parameters and seed.
struct Simulator<'a> {
    gb: &'a Gearbox,
    omega1: f64,
    periods: usize,
    seed: u64,
    cache: Mutex<HashMap<SpectrumKey, Vec<f64>>>,
}

/// One point of a wear profile: the element parameters, the fitted sensor and the score.
type ProfilePoint = (ElementParams, SensorFit, f64);

impl Simulator<'_> {
    fn new<'a>(gb: &'a Gearbox, omega1: f64, opts: &CalibrateOptions) -> Simulator<'a> {
        Simulator {
            gb,
            omega1,
            periods: opts.sim_periods,
            seed: opts.sim_seed,
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// The first `n` initial-state seeds: the loop's own, then the model seeds derived from it
    /// (the model's scatter and the held refit's shift use the same ones).
    fn seeds(&self, n: u64) -> Vec<u64> {
        (0..n)
            .map(|k| {
                if k == 0 {
                    self.seed
                } else {
                    mix_seed(&[self.seed, k, 0x5EED])
                }
            })
            .collect()
    }

    /// Model spectrum (dB, dimensionless ẍ̄1) on the grid.
    fn spectrum(&self, p: &ElementParams) -> Result<Vec<f64>> {
        self.spectrum_seeded(p, self.seed)
    }

    /// [`Simulator::spectrum`] from the initial state of another seed.
    fn spectrum_seeded(&self, p: &ElementParams, seed: u64) -> Result<Vec<f64>> {
        let key = (p.key(), seed);
        if let Some(s) = self.cache.lock().expect("cache lock").get(&key) {
            return Ok(s.clone());
        }
        let s = log_spectrum(&self.series(p, seed)?, SIM_SPP as f64, 1.0)?;
        self.cache
            .lock()
            .expect("cache lock")
            .insert(key, s.clone());
        Ok(s)
    }

    /// [`Simulator::spectrum_seeded`] from each of `seeds`' initial states, in parallel.
    fn spectra_seeded(&self, p: &ElementParams, seeds: &[u64]) -> Result<Vec<Vec<f64>>> {
        seeds
            .par_iter()
            .map(|&sd| self.spectrum_seeded(p, sd))
            .collect()
    }

    /// The model's accelerometer series (dimensionless ẍ̄1, [`SIM_SPP`] samples per mesh period
    /// of stage 1) from the initial state of `seed`, after the transient.
    fn series(&self, p: &ElementParams, seed: u64) -> Result<Vec<f64>> {
        let model = build_model(self.gb, p)?;
        let mut rng = SplitMix64::new(seed);
        let initial = random_initial(model.n(), 2.0, self.omega1, &mut rng);
        let period = TAU / self.omega1;
        let rec = simulate_sensor(
            &model,
            &initial,
            &SimOptions {
                omega1: self.omega1,
                transient_tau: 400.0_f64.max(30.0 * period),
                dt_tau: period / SIM_SPP as f64,
                samples: self.periods * SIM_SPP,
                sensor: crate::signature::SensorQuantity::Accel,
                poincare_every: 0,
                solver: Dopri5Options::default(),
            },
        )?;
        Ok(rec.series)
    }

    /// The signature table's unclipped features ([`LineMeasurement::features`] of `lines`) of
    /// the model at `p`, one vector per initial state of `seeds` (in parallel).
    ///
    /// [`LineMeasurement::features`]: crate::signal::lines::LineMeasurement::features
    fn line_features(
        &self,
        p: &ElementParams,
        seeds: &[u64],
        lines: &[LineDef],
    ) -> Result<Vec<Vec<f64>>> {
        let ratios = line_ratios(lines);
        seeds
            .par_iter()
            .map(|&s| {
                let x = self.series(p, s)?;
                Ok(measure_lines(&x, SIM_SPP as f64, 1.0, &ratios)?.features(lines))
            })
            .collect()
    }

    /// The residual score (of `w`) over `eas` with everything else of `base` held: at each ea
    /// the model is simulated and the sensor fitted (a path resonance `res`, when given,
    /// re-fitted from there; `fixed_res` held fixed instead). In parallel (rayon), sorted by ea.
    #[allow(clippy::too_many_arguments)]
    fn profile(
        &self,
        m: &[f64],
        r: &[f64],
        base: ElementParams,
        eas: &[f64],
        res: Option<Resonance>,
        fixed_res: Option<Resonance>,
        w: &Weights,
    ) -> Result<Vec<ProfilePoint>> {
        let mut out: Vec<ProfilePoint> = eas
            .par_iter()
            .map(|&ea| {
                let p = ElementParams { ea, ..base };
                let s = self.spectrum(&p)?;
                Ok(match fixed_res {
                    Some(h) => {
                        let hs: Vec<f64> =
                            s.iter().zip(r).map(|(a, b)| a + h.gain_db(*b)).collect();
                        let (mut sens, rss) = fit_sensor(m, &hs, r, None, w);
                        sens.resonance = Some(h);
                        (p, sens, rss)
                    }
                    None => {
                        let (sens, rss) = fit_sensor(m, &s, r, res, w);
                        (p, sens, rss)
                    }
                })
            })
            .collect::<Result<Vec<_>>>()?;
        out.sort_by(|a, b| a.0.ea.total_cmp(&b.0.ea));
        Ok(out)
    }
}

impl Simulator<'_> {
    /// [`Simulator::profile`] over the coarse grid 0.1, 0.2, …, 1.0 plus `base.ea`, then the
    /// points 0.05 either side of the best one (the profile's minimum and the interval are
    /// read from this adaptive set).
    fn profile_adaptive(
        &self,
        m: &[f64],
        r: &[f64],
        base: ElementParams,
        res: Option<Resonance>,
        fixed_res: Option<Resonance>,
        w: &Weights,
    ) -> Result<Vec<ProfilePoint>> {
        let mut eas: Vec<f64> = (1..=10).map(|k| 0.1 * k as f64).collect();
        if eas.iter().all(|x| (x - base.ea).abs() > 1e-9) && base.ea.is_finite() {
            eas.push(base.ea);
        }
        let mut prof = self.profile(m, r, base, &eas, res, fixed_res, w)?;
        let best = best_point(&prof).0.ea;
        let more: Vec<f64> = [best - 0.05, best + 0.05]
            .into_iter()
            .filter(|x| (0.1 - 1e-9..=1.0 + 1e-9).contains(x))
            .filter(|x| prof.iter().all(|p| (p.0.ea - x).abs() > 1e-9))
            .collect();
        if !more.is_empty() {
            prof.extend(self.profile(m, r, base, &more, res, fixed_res, w)?);
            prof.sort_by(|a, b| a.0.ea.total_cmp(&b.0.ea));
        }
        Ok(prof)
    }
}

/// The lowest-RSS point of a profile.
fn best_point(prof: &[ProfilePoint]) -> ProfilePoint {
    *prof
        .iter()
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .expect("non-empty profile")
}

/// Number of points of the ea refinement grid 0.1, 0.15, …, 1.0.
const EA_GRID_N: usize = 19;

/// The full wear grid 0.1, 0.15, …, 1.0 plus `start`.
fn ea_grid(start: f64) -> Vec<f64> {
    let mut v: Vec<f64> = (0..EA_GRID_N).map(|k| 0.1 + 0.05 * k as f64).collect();
    if v.iter().all(|x| (x - start).abs() > 1e-9) && start.is_finite() {
        v.push(start);
    }
    v
}

/// The grid points within ±0.05 of `centre`, plus `centre` (a local profile).
fn ea_window(centre: f64) -> Vec<f64> {
    let mut v: Vec<f64> = ea_grid(centre)
        .into_iter()
        .filter(|x| (x - centre).abs() <= 0.05 + 1e-9)
        .collect();
    if v.iter().all(|x| (x - centre).abs() > 1e-9) {
        v.push(centre);
    }
    v
}

struct Fitted {
    name: String,
    effects: Vec<Effect>,
    params: ElementParams,
    sensor: SensorFit,
    rss: f64,
    k: usize,
}

fn effect_shaft(e: f64, shaft: &MeshGear) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("sideband_amplitude_b".into(), e);
    p.insert("shaft_ratio".into(), shaft.shaft_ratio);
    let mut l = BTreeMap::new();
    l.insert("shaft".into(), shaft.shaft.clone());
    Effect {
        name: SHAFT_MODULATION.into(),
        kind: "element",
        parameters: p,
        labels: l,
    }
}

/// Share of the improvement from model `from` to model `to` (dB² of the record `m`'s
/// residual, summed over the grid, unweighted: where the improvement lies — the 25 % of
/// [`SUPPORT_SHARE`] was set so) that falls on the `mask`ed points; 0 when nothing improves.
fn improvement_share(m: &[f64], from: &[f64], to: &[f64], mask: &[bool]) -> f64 {
    let (mut tot, mut inside) = (0.0, 0.0);
    for j in 0..m.len() {
        let d = (m[j] - from[j]).powi(2) - (m[j] - to[j]).powi(2);
        tot += d;
        if mask[j] {
            inside += d;
        }
    }
    if tot > 0.0 { inside / tot } else { 0.0 }
}

fn effect_resonance(res: &Resonance, f1: f64) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("frequency_ratio".into(), res.rho);
    p.insert("frequency_hz".into(), res.rho * f1);
    p.insert("damping_ratio".into(), res.zeta);
    if let Some(g) = res.peak_gain {
        p.insert("peak_gain".into(), g);
    }
    let mut l = BTreeMap::new();
    l.insert("form".into(), res.form().to_string());
    Effect {
        name: PATH_RESONANCE.into(),
        kind: "sensor-stage",
        parameters: p,
        labels: l,
    }
}

fn effect_planetary(pl: f64) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("planetary_error_b".into(), pl);
    Effect {
        name: PLANETARY_WEAR.into(),
        kind: "element",
        parameters: p,
        labels: BTreeMap::new(),
    }
}

fn effect_tooth(depth: f64, gear: &MeshGear) -> Effect {
    let mut p = BTreeMap::new();
    p.insert("stiffness_loss".into(), depth);
    p.insert("shaft_ratio".into(), gear.shaft_ratio);
    p.insert("teeth".into(), gear.teeth as f64);
    let mut l = BTreeMap::new();
    l.insert("gear".into(), format!("stage-1 {}", gear.member));
    l.insert("shaft".into(), gear.shaft.clone());
    Effect {
        name: TOOTH_DAMAGE.into(),
        kind: "element",
        parameters: p,
        labels: l,
    }
}

/// The effects of an element parameter set (given the gears and shafts they name).
fn element_effects(
    p: &ElementParams,
    baseline: f64,
    gears: &[MeshGear],
    input: &MeshGear,
) -> Vec<Effect> {
    let mut v = Vec::new();
    if p.eccentricity > 0.0 {
        let sh = gears
            .iter()
            .find(|g| p.ecc_shaft > 0.0 && (g.shaft_ratio - p.ecc_shaft).abs() < 1e-12)
            .unwrap_or(input);
        v.push(effect_shaft(p.eccentricity, sh));
    }
    if p.planetary > baseline + 1e-12 {
        v.push(effect_planetary(p.planetary));
    }
    if p.tooth_depth > 0.0
        && let Some(g) = gears
            .iter()
            .find(|g| (g.shaft_ratio - p.tooth_shaft).abs() < 1e-12)
    {
        v.push(effect_tooth(p.tooth_depth, g));
    }
    v
}

/// Floor of the per-point standard deviation (dB): the model's lines agree across seeds.
const SIGMA_FLOOR_DB: f64 = 0.5;
/// Uncertainty of a line's position (grid points: f1's estimate, interpolation): a steep flank
/// scatters by this much times its slope.
const LINE_JITTER: f64 = 0.2;
/// Huber threshold of the standardised residual.
const HUBER: f64 = 3.0;

/// The model's own scatter at one operating point.
struct Scatter {
    /// Weights of every fit: `σ_j` from the scatter, scaled so that the plain model's
    /// standardised residual has a robust standard deviation of 1.
    weights: Weights,
    /// The plain model's spectra from the extra seeds (not the main one).
    seed_spectra: Vec<Vec<f64>>,
}

/// The point-by-point mean of equal-length rows (spectra on the grid).
fn pointwise_mean(rows: &[Vec<f64>]) -> Vec<f64> {
    let n = rows.len() as f64;
    (0..rows.first().map_or(0, Vec::len))
        .map(|j| rows.iter().map(|row| row[j]).sum::<f64>() / n)
        .collect()
}

/// The model's own seed-to-seed scatter at `p`: the plain model is simulated from
/// `1 + extra` initial states (the main seed's spectrum is cached), each fitted to the record
/// (gain, noise floor), and per grid point
///
/// `v_j = 2 var_k(F_kj) + (LINE_JITTER · dF̄/dj)² + w_j var_Welch + SIGMA_FLOOR_DB²`
///
/// — the record is one more draw of the chaotic model, hence twice the model's variance (the
/// variance smoothed over ±2 points: five draws are few); a line's flank moves with a small
/// error of f1; where the fitted noise floor dominates (share `w_j` of the power) the record's
/// Welch estimate scatters by `(10/ln 10)² ψ'(ν/2)` with `ν ≈ 1.9 × segments` degrees of
/// freedom. `σ_j = τ √v_j` with `τ` the robust scale (median |u| / 0.6745) of the main seed's
/// residual, so the Huber threshold means "`HUBER` standard deviations".
fn model_scatter(
    sim: &Simulator,
    m: &[f64],
    r: &[f64],
    p: ElementParams,
    extra: usize,
    segments: usize,
) -> Result<Scatter> {
    let n = r.len();
    let unit = Weights::unit(n);
    let spectra = sim.spectra_seeded(&p, &sim.seeds(extra as u64 + 1))?;
    let fits: Vec<(SensorFit, Vec<f64>)> = spectra
        .iter()
        .map(|s| {
            let (sens, _) = fit_sensor(m, s, r, None, &unit);
            (sens, sensor_model(s, r, &sens))
        })
        .collect();
    let kk = fits.len() as f64;
    let fitted: Vec<Vec<f64>> = fits.iter().map(|f| f.1.clone()).collect();
    let mean = pointwise_mean(&fitted);
    let var: Vec<f64> = (0..n)
        .map(|j| {
            if kk < 2.0 {
                0.0
            } else {
                fits.iter().map(|f| (f.1[j] - mean[j]).powi(2)).sum::<f64>() / (kk - 1.0)
            }
        })
        .collect();
    let var_s: Vec<f64> = (0..n)
        .map(|j| {
            let (a, b) = (j.saturating_sub(2), (j + 2).min(n - 1));
            var[a..=b].iter().sum::<f64>() / (b - a + 1) as f64
        })
        .collect();
    let nu = (1.9 * segments.max(1) as f64).max(1.0);
    let x = nu / 2.0;
    let trigamma = 1.0 / x + 1.0 / (2.0 * x * x) + 1.0 / (6.0 * x * x * x);
    let var_welch = (10.0 / std::f64::consts::LN_10).powi(2) * trigamma;
    let noise = fits[0].0.noise_db;
    let v: Vec<f64> = (0..n)
        .map(|j| {
            let slope = (mean[(j + 1).min(n - 1)] - mean[j.saturating_sub(1)]) / 2.0;
            let share = 10f64.powf((noise - mean[j]) / 10.0).min(1.0);
            2.0 * var_s[j]
                + (LINE_JITTER * slope).powi(2)
                + share * var_welch
                + SIGMA_FLOOR_DB * SIGMA_FLOOR_DB
        })
        .collect();
    let mut u: Vec<f64> = (0..n)
        .map(|j| ((m[j] - fits[0].1[j]) / v[j].sqrt()).abs())
        .collect();
    u.sort_by(f64::total_cmp);
    let tau = (u[n / 2] / 0.6745).max(1e-6);
    Ok(Scatter {
        weights: Weights {
            inv_sigma: v.iter().map(|vj| 1.0 / (tau * vj.sqrt())).collect(),
            huber: HUBER,
        },
        seed_spectra: spectra.into_iter().skip(1).collect(),
    })
}

/// Number of Welch segments [`spectrum::log_spectrum`] averages for a record.
fn welch_segments(samples: usize, fs: f64, f1: f64) -> usize {
    let len = (spectrum::GRID_PERIODS * fs / f1).round() as usize;
    let hop = ((len as f64 * 0.5).round() as usize).max(1);
    if samples < len {
        0
    } else {
        1 + (samples - len) / hop
    }
}

/// Close the loop on one record; see the [module docs](self).
pub fn calibrate(
    record: &Record,
    table: &SignatureTable,
    opts: &CalibrateOptions,
) -> Result<CalibrationReport> {
    let gb = table.gearbox();
    let d = diagnose(record, table, &opts.diagnose)?;
    let f1 = d.f1_hz;
    let (olo, ohi) = table.omega_band();
    let omega1 = d.omega1.clamp(olo, ohi);
    let fs = record.sample_rate;
    let r = grid();
    let m = log_spectrum(&record.samples, fs, f1)?;
    let j_n = m.len() as f64;

    let baseline_planetary = gb.planetary_baseline().unwrap_or(0.0);
    let wear_before = WearEstimate {
        ea: d.wear_degree.estimate,
        ea_lower: d.wear_degree.lower,
        ea_upper: d.wear_degree.upper,
        planetary: baseline_planetary,
        method: "table-posterior",
    };
    let sim = Simulator::new(gb, omega1, opts);
    let unit = Weights::unit(r.len());
    let p0 = ElementParams::plain(wear_before.ea, baseline_planetary);
    // Before: the plain model at the table's estimate (the diagnosis as it stands).
    let s0 = sim.spectrum(&p0)?;
    let (sens0, rss0) = fit_sensor(&m, &s0, &r, None, &unit);
    let f0 = sensor_model(&s0, &r, &sens0);

    // The plain model's operating point (least squares), the model's own scatter there (other
    // seeds) and from it the weights of every later fit and score.
    let prof_plain = sim.profile_adaptive(&m, &r, p0, None, None, &unit)?;
    let scatter = model_scatter(
        &sim,
        &m,
        &r,
        best_point(&prof_plain).0,
        opts.model_seeds,
        welch_segments(record.samples.len(), fs, f1),
    )?;
    let w = &scatter.weights;

    // Candidate "none": the plain model, ea profiled over the whole grid.
    let prof_none = sim.profile_adaptive(&m, &r, p0, None, None, w)?;
    let (pn, sn, rn) = best_point(&prof_none);
    let u_none = w.standardised(&m, &sensor_model(&sim.spectrum(&pn)?, &r, &sn));
    let j_eff = effective_points(&u_none);
    // Deviance of a score, the per-point scale profiled out, over the J grid points. (The null
    // spread below is measured in the same units, so the null part of the claim margin does
    // not depend on how many of the points count as independent; `J_eff` from the plain
    // model's residual is dominated by the very structure an effect would explain — a smooth
    // colouring gives J_eff ≈ 10 — and is used for the wear interval only.)
    let dev = |score: f64| j_n * (score / j_n).max(1e-300).ln();
    // The null: the same plain model from other initial states, fitted to the record.
    let null_dev: Vec<f64> = std::iter::once(dev(rn))
        .chain(
            scatter
                .seed_spectra
                .iter()
                .map(|s| dev(fit_sensor(&m, s, &r, None, w).1)),
        )
        .collect();
    let null_spread = {
        let k = null_dev.len() as f64;
        let mu = null_dev.iter().sum::<f64>() / k;
        if k > 1.0 {
            (null_dev.iter().map(|d| (d - mu).powi(2)).sum::<f64>() / (k - 1.0)).sqrt()
        } else {
            0.0
        }
    };
    let mut cands: Vec<Fitted> = vec![Fitted {
        name: "none".into(),
        effects: vec![],
        params: pn,
        sensor: sn,
        rss: rn,
        k: 3,
    }];

    // Path resonance (sensor stage): searched over the band at the plain model's best ea,
    // ea profiled over the whole grid with the resonance re-fitted (the plain model's
    // simulations, cached), searched again at the new ea, profiled again.
    let mut res_start = search_resonance(&m, &sim.spectrum(&pn)?, &r, w)
        .0
        .resonance
        .expect("fitted resonance");
    let mut prof_res = sim.profile_adaptive(&m, &r, p0, Some(res_start), None, w)?;
    let (pr1, _, _) = best_point(&prof_res);
    if (pr1.ea - pn.ea).abs() > 1e-9 {
        let (again, _) = search_resonance(&m, &sim.spectrum(&pr1)?, &r, w);
        res_start = again.resonance.expect("fitted resonance");
        let prof2 = sim.profile_adaptive(&m, &r, p0, Some(res_start), None, w)?;
        if best_point(&prof2).2 < best_point(&prof_res).2 {
            prof_res = prof2;
        }
    }
    let (pr, sr_, rr) = best_point(&prof_res);
    let res_best = sr_.resonance.expect("fitted");
    cands.push(Fitted {
        name: PATH_RESONANCE.into(),
        effects: vec![effect_resonance(&res_best, f1)],
        params: pr,
        sensor: sr_,
        rss: rr,
        k: if res_best.peak_gain.is_some() { 6 } else { 5 },
    });

    // Element effects: amplitude from the gap at the fingerprint lines (one probe simulation),
    // ea profiled locally, amplitude re-fitted at the refined ea.
    let gears = reference_gears(gb);
    let input = MeshGear {
        member: "pinion",
        shaft: gb.description.input_shaft.clone(),
        teeth: (1.0 / shaft_ratio(gb)).round() as u32,
        shaft_ratio: shaft_ratio(gb),
    };
    let mut shafts: Vec<MeshGear> = vec![input.clone()];
    for g in &gears {
        if (g.shaft_ratio - input.shaft_ratio).abs() > 1e-9 {
            shafts.push(g.clone());
        }
    }
    // Where the record's sidebands lie, at its own resolution ([`sidebands`]): shaft
    // modulation is eligible only where the strongest are at its shaft's rate, tooth damage
    // not where they are off it ([`refuses`]).
    let scan = SidebandScan::new(&record.samples, fs, f1, spectrum::BAND_HI);
    let sideband_checks: Vec<SidebandCheck> = shafts
        .iter()
        .filter_map(|g| scan.as_ref()?.check(&g.shaft, g.shaft_ratio))
        .collect();
    let f3 = gb.planetary_ratio();
    let fam: Vec<f64> = f3
        .map(|f3| vec![f3, 2.0 * f3, 1.0 - f3, 1.0 + f3])
        .unwrap_or_default();
    let fit_amp = |make: &dyn Fn(f64) -> ElementParams,
                   probe: f64,
                   ratios: &[f64],
                   lo: f64,
                   hi: f64|
     -> Result<f64> {
        let sp = sim.spectrum(&make(probe))?;
        let (sens, _) = fit_sensor(&m, &sp, &r, None, w);
        let fp = sensor_model(&sp, &r, &sens);
        Ok(match fingerprint_gap(&m, &fp, sens.noise_db, ratios, 6.0) {
            Some(gap) => (probe * 10f64.powf(gap.clamp(-40.0, 40.0) / 20.0)).clamp(lo, hi),
            None => lo,
        })
    };
    // An element effect: `set(base, amplitude)` puts the amplitude in.
    let element_fit = |base: ElementParams,
                       set: &(dyn Fn(ElementParams, f64) -> ElementParams + Sync),
                       probe: f64,
                       ratios: &[f64],
                       lo: f64,
                       hi: f64|
     -> Result<ElementParams> {
        let a1 = fit_amp(&|a| set(base, a), probe, ratios, lo, hi)?;
        let first = set(base, a1);
        let prof = sim.profile(&m, &r, first, &ea_window(first.ea), None, None, w)?;
        let (refined, _, _) = best_point(&prof);
        let a2 = fit_amp(&|a| set(refined, a), a1, ratios, lo, hi)?;
        Ok(set(refined, a2))
    };
    // An element effect whose lines the grid cannot measure one by one (a damaged tooth on a
    // gear of many teeth puts its sidebands 1.3 grid steps apart, inside the mesh line's own
    // main lobe; the planetary family sits far below f1): the amplitude by its score, not by
    // a gap at lines. Every amplitude of `grid` simulated at `base` (rayon, cached), the best
    // kept; ea profiled within ±0.05; then the best amplitude's neighbours on a grid twice as
    // fine, at the refined ea.
    let element_scan = |base: ElementParams,
                        set: &(dyn Fn(ElementParams, f64) -> ElementParams + Sync),
                        grid: &[f64]|
     -> Result<ElementParams> {
        // The index of the best-scoring amplitude of `amps` at `b`.
        let scan = |b: ElementParams, amps: &[f64]| -> Result<usize> {
            let scores: Vec<f64> = amps
                .par_iter()
                .map(|&a| Ok(fit_sensor(&m, &sim.spectrum(&set(b, a))?, &r, None, w).1))
                .collect::<Result<_>>()?;
            Ok((0..scores.len())
                .min_by(|&x, &y| scores[x].total_cmp(&scores[y]))
                .expect("a non-empty amplitude grid"))
        };
        let i = scan(base, grid)?;
        let a1 = grid[i];
        let first = set(base, a1);
        let prof = sim.profile(&m, &r, first, &ea_window(first.ea), None, None, w)?;
        let (refined, _, _) = best_point(&prof);
        let mut local = vec![a1];
        if i > 0 {
            local.push(0.5 * (grid[i - 1] + a1));
        }
        if i + 1 < grid.len() {
            local.push(0.5 * (grid[i + 1] + a1));
        }
        Ok(set(refined, local[scan(refined, &local)?]))
    };
    let mut singles: Vec<(String, ElementParams)> = Vec::new();
    for sh in &shafts {
        let s = sh.shaft_ratio;
        let sb: Vec<f64> = [1.0, 2.0].iter().flat_map(|c| [c - s, c + s]).collect();
        let set = move |b: ElementParams, e: f64| ElementParams {
            eccentricity: e,
            ecc_shaft: s,
            ..b
        };
        // Sidebands within 3 grid steps of their carrier sit in its main lobe on the grid
        // (a gear of many teeth: the stage-1 gear shaft at f1/100 is 1.3 steps out), where the
        // gap at the sideband lines measures the carrier: the amplitude by score instead.
        let p = if s * spectrum::GRID_PERIODS < 3.0 {
            element_scan(pn, &set, &MODULATION_SCAN)?
        } else {
            // The gap at the sideband lines, and the scan by score as a guard: on a chaotic
            // record the gap can read the trajectory's own lines as sidebands and put in an
            // amplitude far worse than none (seed 25 of the benchmark, record 27: ΔBIC +433).
            // The better-scoring of the two is kept.
            let by_gap = element_fit(pn, &set, 0.05, &sb, 1e-3, 2.0)?;
            let by_scan = element_scan(pn, &set, &MODULATION_SCAN)?;
            let score = |q: &ElementParams| -> Result<f64> {
                Ok(fit_sensor(&m, &sim.spectrum(q)?, &r, None, w).1)
            };
            if score(&by_scan)? < score(&by_gap)? {
                by_scan
            } else {
                by_gap
            }
        };
        singles.push((SHAFT_MODULATION.into(), p));
    }
    if f3.is_some() {
        let set = |b: ElementParams, p: f64| ElementParams { planetary: p, ..b };
        let grid: Vec<f64> = PLANETARY_SCAN
            .iter()
            .copied()
            .filter(|p| *p > baseline_planetary)
            .collect();
        let p = if grid.is_empty() {
            element_fit(pn, &set, 1.0, &fam, baseline_planetary, 5.0)?
        } else {
            element_scan(pn, &set, &grid)?
        };
        singles.push((PLANETARY_WEAR.into(), p));
    }
    for g in &gears {
        let s = g.shaft_ratio;
        let set = move |b: ElementParams, dep: f64| ElementParams {
            tooth_depth: dep,
            tooth_shaft: s,
            ..b
        };
        let p = element_scan(pn, &set, &TOOTH_SCAN)?;
        singles.push((TOOTH_DAMAGE.into(), p));
    }
    let make = |name: String, p: ElementParams, res: Option<Resonance>| -> Result<Fitted> {
        let s = sim.spectrum(&p)?;
        let (sens, rss) = fit_sensor(&m, &s, &r, res, w);
        let mut effects = element_effects(&p, baseline_planetary, &gears, &input);
        if let Some(res) = sens.resonance {
            effects.push(effect_resonance(&res, f1));
        }
        // gain, noise, ea + one amplitude per element effect + ρ, ζ (and g) of a resonance.
        let k = 3 + effects
            .iter()
            .map(|e| match e.name.as_str() {
                PATH_RESONANCE => 2 + e.parameters.contains_key("peak_gain") as usize,
                _ => 1,
            })
            .sum::<usize>();
        Ok(Fitted {
            name,
            effects,
            params: p,
            sensor: sens,
            rss,
            k,
        })
    };
    for (name, p) in &singles {
        cands.push(make(name.clone(), *p, None)?);
    }
    // Pairs: the best variant of each element effect with the resonance, and with each other.
    let n_single = cands.len();
    // (A variant the record's sidebands refuse cannot be claimed: the pairs take the best of
    // the others.)
    let mut best_variant: Vec<(String, ElementParams)> = Vec::new();
    for (k, (name, p)) in singles.iter().enumerate() {
        let shaft = match name.as_str() {
            SHAFT_MODULATION => p.ecc_shaft,
            _ => p.tooth_shaft,
        };
        if refuses(&sideband_checks, name, shaft) {
            continue;
        }
        let rss = cands[n_single - singles.len() + k].rss;
        match best_variant.iter().position(|(n, _)| n == name) {
            Some(i) => {
                let j = singles
                    .iter()
                    .position(|(n, q)| n == name && *q == best_variant[i].1);
                let old = j.map_or(f64::INFINITY, |j| cands[n_single - singles.len() + j].rss);
                if rss < old {
                    best_variant[i].1 = *p;
                }
            }
            None => best_variant.push((name.clone(), *p)),
        }
    }
    for (name, p) in &best_variant {
        // The resonance of a pair is searched again over the whole band on top of the element
        // effect's spectrum: the one found on the plain model may be a stand-in for the
        // element's own lines. The better of that and the single resonance's is kept.
        let pair = format!("{name}+{PATH_RESONANCE}");
        let from_single = make(pair.clone(), *p, Some(res_best))?;
        let searched = search_resonance(&m, &sim.spectrum(p)?, &r, w).0.resonance;
        let from_search = make(pair, *p, searched)?;
        cands.push(if from_search.rss < from_single.rss {
            from_search
        } else {
            from_single
        });
    }
    for (i, (na, pa)) in best_variant.iter().enumerate() {
        for (nb, pb) in best_variant.iter().skip(i + 1) {
            let p = ElementParams {
                eccentricity: pa.eccentricity.max(pb.eccentricity),
                ecc_shaft: if pa.eccentricity > 0.0 {
                    pa.ecc_shaft
                } else {
                    pb.ecc_shaft
                },
                planetary: pa.planetary.max(pb.planetary),
                tooth_depth: pa.tooth_depth.max(pb.tooth_depth),
                tooth_shaft: if pa.tooth_depth > 0.0 {
                    pa.tooth_shaft
                } else {
                    pb.tooth_shaft
                },
                ea: pa.ea,
            };
            cands.push(make(format!("{na}+{nb}"), p, None)?);
        }
    }

    // A chaotic model's score from one initial state scatters by `null_spread`; "no effect"
    // takes the best of `1 + model_seeds`, so a candidate from one state is handicapped by
    // that scatter. Optionally every candidate is scored from the same initial states: on its
    // mean spectrum over them, "no effect" included ([`CalibrateOptions::mean_seeds`]), or by
    // the best of them like "no effect" ([`CalibrateOptions::candidate_seeds`]).
    let seeds = sim.seeds(opts.model_seeds as u64 + 1);
    if opts.mean_seeds {
        for c in cands.iter_mut() {
            let mean = pointwise_mean(&sim.spectra_seeded(&c.params, &seeds)?);
            c.rss = fit_sensor(&m, &mean, &r, c.sensor.resonance, w).1;
        }
    } else if opts.candidate_seeds {
        for c in cands.iter_mut().skip(1) {
            c.rss = sim
                .spectra_seeded(&c.params, &seeds[1..])?
                .iter()
                .map(|s| fit_sensor(&m, s, &r, c.sensor.resonance, w).1)
                .fold(c.rss, f64::min);
        }
    }

    // Attribution check: an effect is claimed only where its fingerprint is. The share of a
    // candidate's RSS improvement over the plain model at the same ea (so that a wear
    // correction, which moves every line, does not count) that falls on its fingerprint points
    // (the plain model's own lines for a path stage — a resonance colours what the gearbox
    // makes; the sidebands ± k s (k = 1, 2, 3, [`SM_ORDERS`]) of its shaft around every line
    // of the plain model (and 1, 2 f1) for shaft modulation; the shaft's order comb m s (all m) for tooth damage;
    // a f1 ± c f3 (a = 0, 1, 2; c = 1, 2) for
    // planetary wear; ±1 grid point) must reach [`SUPPORT_SHARE`]; otherwise the candidate is
    // not eligible.
    // Every candidate's fitted spectrum, and the plain model at its ea fitted to the record (its
    // reference for the fingerprint share and the band).
    let fitted: Vec<Vec<f64>> = cands
        .iter()
        .map(|c| Ok(sensor_model(&sim.spectrum(&c.params)?, &r, &c.sensor)))
        .collect::<Result<_>>()?;
    let f_none = &fitted[0];
    let near = |ratios: &[f64], mask: &mut [bool]| {
        for &x in ratios {
            if let Some(j) = grid_index(x) {
                for k in j.saturating_sub(1)..=(j + 1).min(mask.len() - 1) {
                    mask[k] = true;
                }
            }
        }
    };
    let mut line_mask: Vec<bool> = vec![false; r.len()];
    for (j, v) in f_none.iter().enumerate() {
        if *v > cands[0].sensor.noise_db + 3.0 {
            for k in j.saturating_sub(1)..=(j + 1).min(r.len() - 1) {
                line_mask[k] = true;
            }
        }
    }
    // The plain model's lines: local maxima 6 dB above its noise floor.
    let line_peaks: Vec<f64> = (1..r.len() - 1)
        .filter(|&j| {
            f_none[j] > cands[0].sensor.noise_db + 6.0
                && f_none[j] >= f_none[j - 1]
                && f_none[j] >= f_none[j + 1]
        })
        .map(|j| r[j])
        .collect();
    let fam_wide: Vec<f64> = f3
        .map(|f3| {
            [0.0, 1.0, 2.0]
                .iter()
                .flat_map(|a| [-2.0, -1.0, 1.0, 2.0].map(|c| (a + c * f3).abs()))
                .collect()
        })
        .unwrap_or_default();
    // Tooth damage: the TSA of the damaged gear's shaft, where the diagnosis has one.
    let tsa_fm4: Vec<Option<f64>> = cands
        .iter()
        .map(|c| {
            let shaft = c
                .effects
                .iter()
                .find(|e| e.name == TOOTH_DAMAGE)?
                .labels
                .get("shaft")?;
            d.order
                .as_ref()?
                .shafts
                .iter()
                .find(|t| &t.shaft == shaft)?
                .metrics
                .fm4
        })
        .collect();
    // An effect's fingerprint: the grid points its improvement must fall on.
    let fingerprint = |e: &Effect, mask: &mut [bool]| {
        let s = e.parameters.get("shaft_ratio").copied().unwrap_or(0.0);
        match e.name.as_str() {
            PATH_RESONANCE => {
                for (mk, l) in mask.iter_mut().zip(&line_mask) {
                    *mk |= *l;
                }
            }
            SHAFT_MODULATION => {
                // Orders ± 1 to ± 3: the mesh's nonlinear response to a strong modulation
                // carries it to the higher sideband orders (± 1 only until session 14; the
                // selection replayed over seeds 22–27 named three more modulations with the
                // three orders, and let one speed wander through).
                let sb: Vec<f64> = line_peaks
                    .iter()
                    .chain(&[1.0, 2.0])
                    .flat_map(|l| SM_ORDERS.map(|k| [l - k * s, l + k * s]))
                    .flatten()
                    .collect();
                near(&sb, mask)
            }
            TOOTH_DAMAGE => {
                // A pulse one mesh period long, once a revolution: shaft-order sidebands
                // of about equal size out to ± z/2 orders around every mesh harmonic,
                // i.e. the shaft's whole order comb m s over the band (for a gear of many
                // teeth that is every grid point: then only the score, the error and the
                // TSA test decide).
                if s > 0.0 {
                    let top = (r[r.len() - 1] / s).ceil() as usize;
                    let comb: Vec<f64> = (1..=top).map(|k| k as f64 * s).collect();
                    near(&comb, mask);
                }
            }
            _ => near(&fam_wide, mask),
        }
    };
    let plain_at: Vec<Vec<f64>> = cands
        .iter()
        .map(|c| {
            let plain = sim.spectrum(&ElementParams::plain(c.params.ea, baseline_planetary))?;
            let (sp, _) = fit_sensor(&m, &plain, &r, None, w);
            Ok(sensor_model(&plain, &r, &sp))
        })
        .collect::<Result<_>>()?;
    let mut support: Vec<f64> = vec![1.0; cands.len()];
    let mut refused: Vec<Vec<String>> = vec![Vec::new(); cands.len()];
    // The colour rule's refusal, kept aside: the resonance's own band may stand for it.
    let mut few_lines: Vec<Option<String>> = vec![None; cands.len()];
    for (ci, c) in cands.iter().enumerate().skip(1) {
        let mut mask = vec![false; r.len()];
        for e in &c.effects {
            fingerprint(e, &mut mask);
        }
        support[ci] = improvement_share(&m, &plain_at[ci], &fitted[ci], &mask);
        // A path stage colours what the gearbox makes: it must move at least
        // [`MIN_COLOURED_LINES`] of the plain model's lines by more than 3 dB relative to f1.
        // A narrow mode that lifts one weak line next to a tone is a tone, not a path.
        if let Some(h) = c.sensor.resonance {
            let h1 = h.gain_db(1.0);
            let coloured = line_peaks
                .iter()
                .filter(|&&x| (h.gain_db(x) - h1).abs() > 3.0)
                .count();
            if coloured < MIN_COLOURED_LINES {
                few_lines[ci] = Some(format!(
                    "the resonance moves {coloured} of the plain model's lines by more than \
                     3 dB ({MIN_COLOURED_LINES} needed)"
                ));
            }
        }
        if let Some(fm4) = tsa_fm4[ci]
            && fm4 < TOOTH_TSA_FM4
        {
            refused[ci].push(format!(
                "the damaged gear's TSA is not impulsive (FM4 {fm4:.1} < {TOOTH_TSA_FM4})"
            ));
        }
        refused[ci].extend(c.effects.iter().filter_map(|e| {
            let s = *e.parameters.get("shaft_ratio")?;
            refusal(&sideband_checks, &e.name, s)
        }));
    }

    // Selection: a BIC on the deviance of the weighted robust score, `J_eff ln(score/J) +
    // k ln J_eff`; an effect must beat "none" by `bic_margin + null_z · null_spread` (the
    // model's own seed-to-seed scatter) and lower the plain RMS error of the table's estimate.
    let rss_unw: Vec<f64> = fitted.iter().map(|fc| unit.score(&m, fc)).collect();
    let bic = |score: f64, k: usize| dev(score) + k as f64 * j_n.ln();
    let scores: Vec<f64> = cands.iter().map(|c| bic(c.rss, c.k)).collect();
    // "No effect" from the best of its initial states (its profile's best point, each seed).
    let none_ref = null_dev.iter().copied().fold(f64::INFINITY, f64::min);
    let bic0 = if opts.mean_seeds {
        // "No effect" is scored on its mean spectrum like every candidate.
        scores[0]
    } else {
        scores[0].min(none_ref + 3.0 * j_n.ln())
    };
    let claim_margin = opts.bic_margin + opts.null_z * null_spread;
    // Shaft modulation alone whose record shows sidebands at its shaft's rate (the strongest
    // spacing, [`SM_SIDEBAND_PROMINENCE_DB`] above the scanned window's median): that is
    // evidence of its own, and the candidate is eligible below [`SUPPORT_SHARE`] if it beats
    // "no effect" by [`SM_SIDEBAND_MARGIN_FACTOR`] claim margins.
    let sideband_evidence = |c: &Fitted| match c.effects.as_slice() {
        [e] if e.name == SHAFT_MODULATION => e.parameters.get("shaft_ratio").is_some_and(|&s| {
            sideband_checks.iter().any(|k| {
                (k.shaft_ratio - s).abs() < 1e-9
                    && k.at_rate
                    && !k.off_rate
                    && k.shaft_prominence_db >= SM_SIDEBAND_PROMINENCE_DB
            })
        }),
        _ => false,
    };
    // The best-scoring single candidate of an effect (of its variants).
    let best_single = |name: &str| {
        (1..n_single)
            .filter(|&k| cands[k].effects.len() == 1 && cands[k].effects[0].name == name)
            .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
    };
    // A path resonance's own band ([`BandEvidence`]), against the plain model at its ea (a
    // single) or the other member's best single (a pair).
    let band: Vec<Option<BandEvidence>> = (0..cands.len())
        .map(|i| {
            let c = &cands[i];
            let h = c.sensor.resonance.filter(|_| i > 0)?;
            let fref = match c.effects.iter().find(|e| e.name != PATH_RESONANCE) {
                None => &plain_at[i],
                Some(other) => &fitted[best_single(&other.name)?],
            };
            let fc = &fitted[i];
            let half = (h.zeta * h.rho).max(1.0 / spectrum::GRID_PERIODS);
            let mask: Vec<bool> = r.iter().map(|x| (x - h.rho).abs() <= half).collect();
            let improved = (0..r.len())
                .filter(|&j| mask[j] && (m[j] - fc[j]).powi(2) < (m[j] - fref[j]).powi(2))
                .count();
            Some(BandEvidence {
                points: mask.iter().filter(|b| **b).count(),
                improved,
                share: improvement_share(&m, fref, fc, &mask),
            })
        })
        .collect();
    // A path resonance alone stands on its band if it beats "no effect" by
    // [`BAND_MARGIN_FACTOR`] claim margins; a pair's resonance on its band alone (the pair
    // must still beat the best single by the margin).
    let band_stands = |i: usize| {
        band[i].is_some_and(|b| b.holds())
            && (cands[i].effects.len() > 1 || scores[i] < bic0 - BAND_MARGIN_FACTOR * claim_margin)
    };
    for (i, why) in few_lines.into_iter().enumerate() {
        if let Some(why) = why
            && !band_stands(i)
        {
            refused[i].insert(0, why);
        }
    }
    let attributed = |i: usize| {
        support[i] >= SUPPORT_SHARE
            || (sideband_evidence(&cands[i])
                && scores[i] < bic0 - SM_SIDEBAND_MARGIN_FACTOR * claim_margin)
            || (cands[i].effects.len() == 1 && band_stands(i))
    };
    let eligible = |i: usize| attributed(i) && refused[i].is_empty() && rss_unw[i] <= rss0;
    let best_of = |pred: &dyn Fn(usize) -> bool| {
        (0..cands.len())
            .filter(|&i| pred(i) && eligible(i))
            .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
    };
    // A pair's member must be eligible on its own and better than "no effect" (its BIC below
    // the null's); the pair as a whole must then beat the best single by the claim margin.
    let supported = |name: &str| {
        cands.iter().zip(&scores).enumerate().any(|(i, (c, b))| {
            c.effects.len() == 1 && c.effects[0].name == name && *b < bic0 && eligible(i)
        })
    };
    // Or, in a pair, supported given the other member: the pair's improvement over the best
    // single of the other member falls on this member's fingerprint (share ≥
    // [`SUPPORT_SHARE`]). A resonance the element's lines hide from a search on the plain
    // model, or an element the resonance's colouring hides, is then judged where both are
    // fitted. (The pair's own checks — its fingerprint share, the coloured lines of its
    // resonance, the sidebands, the TSA — still apply.)
    let given_share = |pair: usize, member: &Effect| -> f64 {
        let other = cands[pair].effects.iter().find(|e| e.name != member.name);
        let Some(o) = other.and_then(|other| best_single(&other.name)) else {
            return 0.0;
        };
        let mut mask = vec![false; r.len()];
        fingerprint(member, &mut mask);
        improvement_share(&m, &fitted[o], &fitted[pair], &mask)
    };
    let member_shares: Vec<Vec<f64>> = cands
        .iter()
        .enumerate()
        .map(|(i, c)| {
            if c.effects.len() < 2 {
                return Vec::new();
            }
            c.effects.iter().map(|e| given_share(i, e)).collect()
        })
        .collect();
    let margin_of = |c: &Fitted| {
        if c.effects.iter().any(|e| e.name == TOOTH_DAMAGE) {
            TOOTH_MARGIN_FACTOR * claim_margin
        } else {
            claim_margin
        }
    };
    let mut chosen = 0;
    // The best single effect that beats "no effect" by its margin.
    if let Some(single) =
        best_of(&|i| cands[i].effects.len() == 1 && scores[i] < bic0 - margin_of(&cands[i]))
    {
        chosen = single;
        if let Some(pair) = best_of(&|i| cands[i].effects.len() == 2) {
            // A pair needs every member supported on its own, and to beat the best single.
            let mut members_ok = true;
            for (e, given) in cands[pair].effects.iter().zip(&member_shares[pair]) {
                members_ok &= supported(&e.name)
                    || *given >= SUPPORT_SHARE
                    || (e.name == PATH_RESONANCE && band_stands(pair));
            }
            if members_ok && scores[pair] < scores[single] - margin_of(&cands[pair]) {
                chosen = pair;
            }
        }
    }
    let candidates: Vec<Candidate> = cands
        .iter()
        .zip(&scores)
        .enumerate()
        .map(|(i, (c, b))| Candidate {
            name: c.name.clone(),
            effects: c.effects.clone(),
            parameters: c.k,
            rss: rss_unw[i],
            score: c.rss,
            error_db: (rss_unw[i] / j_n).sqrt(),
            bic: *b,
            delta_bic: b - bic0,
            fingerprint_share: support[i],
            refused: refused[i].clone(),
            member_shares: member_shares[i].clone(),
            band: band[i],
            eligible: i > 0 && eligible(i),
            tsa_fm4: tsa_fm4[i],
        })
        .collect();

    // The refit: the chosen model's ea profiled over the whole grid (continuous minimum and a
    // profile-likelihood interval widened by the simulations' own scatter). No effect claimed:
    // the model is unchanged. A refit whose best point does not lower the plain model's error
    // is not claimed either.
    let level = opts.diagnose.credible_level;
    let error_before = (rss0 / j_n).sqrt();
    let refit = if chosen == 0 {
        None
    } else {
        let ch = &cands[chosen];
        let prof = sim.profile_adaptive(&m, &r, ch.params, ch.sensor.resonance, None, w)?;
        let pts: Vec<(f64, f64)> = prof.iter().map(|p| (p.0.ea, p.2)).collect();
        let (ea, lo, hi) = profile_interval_noisy(&pts, j_eff, level, null_spread * j_eff / j_n);
        let (pb, sb, _) = best_point(&prof);
        let profile = WearEstimate {
            ea,
            ea_lower: lo,
            ea_upper: hi,
            planetary: pb.planetary,
            method: "profile-likelihood",
        };
        let fa = sensor_model(&sim.spectrum(&pb)?, &r, &sb);
        if rms_distance(&m, &fa) > error_before {
            None
        } else {
            let element = ch.effects.iter().any(|e| e.name != PATH_RESONANCE);
            let path = ch.effects.iter().any(|e| e.name == PATH_RESONANCE);
            let held = table_posterior_held(
                &sim,
                record,
                table,
                &opts.diagnose,
                (path, element),
                (pb, sb.resonance),
                baseline_planetary,
                f1,
            )?;
            let mut effects = element_effects(&pb, baseline_planetary, &gears, &input);
            if let Some(res) = sb.resonance {
                effects.push(effect_resonance(&res, f1));
            }
            let refit = held.unwrap_or(profile);
            Some((
                confirm_or_move(&wear_before, refit, element),
                Some(refit),
                Some(profile),
                sb,
                fa,
                effects,
            ))
        }
    };
    let (wear_after, wear_refit, wear_profile, sensor_after, f_after, effects) =
        refit.unwrap_or_else(|| (wear_before, None, None, sens0, f0.clone(), Vec::new()));
    let error_after = rms_distance(&m, &f_after);

    let i1 = grid_index(1.0).unwrap_or(0);
    let ref_db = m[i1];
    let rel = |v: &[f64]| v.iter().map(|x| x - ref_db).collect::<Vec<f64>>();
    let res_before: Vec<f64> = m.iter().zip(&f0).map(|(a, b)| a - b).collect();
    let res_after: Vec<f64> = m.iter().zip(&f_after).map(|(a, b)| a - b).collect();
    let trend = running_median(&res_after, (0.1 * spectrum::GRID_PERIODS) as usize);
    let trend_rms_db = rms_distance(&trend, &vec![0.0; trend.len()]);
    let m_rel = rel(&m);
    let mut unexplained = residual_features(&res_after, &m_rel, &r, f1, opts.unexplained_db);
    annotate(&mut unexplained, gb, f1, &sideband_checks);
    let claimed_tooth = effects
        .iter()
        .find(|e| e.name == TOOTH_DAMAGE)
        .and_then(|e| e.parameters.get("shaft_ratio").copied());
    let unexplained_in_time =
        level_features(&record.samples, fs, f1, &shaft_rates(gb), claimed_tooth);
    let residual_features_before =
        residual_features(&res_before, &m_rel, &r, f1, opts.unexplained_db);
    if !(error_before.is_finite() && error_after.is_finite()) {
        return Err(Error::Signal(
            "the closed-loop fit produced a non-finite error".into(),
        ));
    }
    Ok(CalibrationReport {
        f1_hz: f1,
        omega1,
        effects,
        unexplained,
        unexplained_in_time,
        residual_features_before,
        effective_points: j_eff,
        null_spread,
        claim_margin,
        null_deviances: null_dev.clone(),
        error_before,
        error_after,
        wear_before,
        wear_after,
        wear_refit,
        wear_profile,
        sensor_before: sens0,
        sensor_after,
        trend_rms_db,
        candidates,
        sideband_checks,
        spectra: Spectra {
            frequency_ratio: r.clone(),
            measured_db: m_rel.clone(),
            fitted_before_db: rel(&f0),
            fitted_after_db: rel(&f_after),
            residual_before_db: res_before,
            residual_after_db: res_after,
            trend_after_db: trend,
        },
        diagnosis_warnings: d.warnings.clone(),
        options: opts.clone(),
    })
}

/// The wear after a claim: the refit `refit`, unless it re-reads `element` effects (not a path
/// stage alone) and lands inside the table's credible interval `[before.ea_lower,
/// before.ea_upper]`; then the table's estimate and interval stand
/// (`table-posterior-confirmed`). A de-coloured record is the record without a linear sensor
/// stage (exact, no simulation in it), so its posterior is always taken; an element effect
/// enters through simulations of a fitted effect whose size is itself uncertain, and its
/// refits moved good table estimates either way by less than their interval (tuning seed 6 of
/// `benches/closed_loop.rs`, 66 records: wear error after ≤ before on 54 taking every refit, 56
/// taking the profile's vertex as session 8 did, 60 with this rule; fresh seeds in
/// `docs/closed-loop.md` § Session 9). The refit is still reported (`wear_refit`).
fn confirm_or_move(before: &WearEstimate, refit: WearEstimate, element: bool) -> WearEstimate {
    if element && !held::refit_moves_wear((before.ea_lower, before.ea_upper), refit.ea) {
        WearEstimate {
            planetary: refit.planetary,
            method: "table-posterior-confirmed",
            ..*before
        }
    } else {
        refit
    }
}

/// Seeds whose simulations give the feature change of claimed element effects
/// ([`table_posterior_held`]): the closed loop's own seed and the first model seeds.
const HELD_SHIFT_SEEDS: u64 = 4;

/// The table's posterior with the chosen effects held fixed (`None` when that diagnosis
/// fails, or the set holds neither kind; the caller then keeps the profile). `has_path`,
/// `has_element`: whether the chosen set holds a path stage, an element effect. A path stage
/// in the set de-colours the record by
/// the fitted `|H|` (Hz); element effects (shaft modulation, planetary wear, tooth damage)
/// shift the record's line features by what they change in the model at `pb` (the chosen
/// model's profile minimum, where the model with the effects fits the record; at the table's
/// own estimate, which an effect biases, the shift was the wrong one — the eccentricity test
/// read 0.474 for a truth of 0.3 that way, 0.300 this way): `Δy = ȳ(pb) −
/// ȳ(pb without its effects)`, each the mean over
/// [`HELD_SHIFT_SEEDS`] initial states (the same seeds with and without, so the periodic
/// regime's Δy is exact and the chaotic one's is a difference of long-run means). A feature is
/// `ln(A_ℓ/A_f1)`, which a linear sensor stage shifts alike with and without the effects, so
/// Δy does not depend on the sensor. Each feature's variance is raised by `Δy² + se²` (se: the
/// paired differences' standard error), so the features an effect dominates hardly count.
///
/// A path stage alone changes no element of the gearbox: the table represents the model exactly
/// once the record is de-coloured, so its posterior there is the wear (over the 21 records of
/// seeds 4–7 where a resonance alone was named, wear MAE 0.068 this way against 0.106 for the
/// profile's vertex and 0.076 for the coloured record's table estimate).
#[allow(clippy::too_many_arguments)]
fn table_posterior_held(
    sim: &Simulator<'_>,
    record: &Record,
    table: &SignatureTable,
    dopts: &DiagnoseOptions,
    (has_path, has_element): (bool, bool),
    (pb, resonance): (ElementParams, Option<Resonance>),
    baseline_planetary: f64,
    f1: f64,
) -> Result<Option<WearEstimate>> {
    let decoloured;
    let rec = match resonance {
        Some(h) if has_path => {
            let hz = Resonance {
                rho: h.rho * f1,
                ..h
            };
            decoloured = Record {
                samples: held::decolour_with(&record.samples, record.sample_rate, &hz)?,
                sample_rate: record.sample_rate,
            };
            &decoloured
        }
        _ => record,
    };
    let (d, method) = if has_element {
        let lines = &table.features.lines;
        let seeds = sim.seeds(HELD_SHIFT_SEEDS);
        let without = ElementParams::plain(pb.ea, baseline_planetary);
        let yw = sim.line_features(&pb, &seeds, lines)?;
        let y0 = sim.line_features(&without, &seeds, lines)?;
        // Paired differences (same seed with and without): their mean is the shift, their
        // standard error the simulations' part of its uncertainty; the fitted effect's own
        // uncertainty is taken as the whole shift (a feature the effect changes a lot is
        // nearly left out, one it barely touches keeps its weight).
        let n = seeds.len() as f64;
        let (shift, shift_var): (Vec<f64>, Vec<f64>) = (0..lines.len())
            .map(|k| {
                let d: Vec<f64> = yw.iter().zip(&y0).map(|(a, b)| a[k] - b[k]).collect();
                let mean = d.iter().sum::<f64>() / n;
                let se2 =
                    d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0) / n;
                (mean, mean * mean + se2)
            })
            .unzip();
        let dd = diagnose_shifted(rec, table, dopts, &shift, &shift_var);
        (dd, "table-posterior-effects-held")
    } else if has_path {
        (diagnose(rec, table, dopts), "table-posterior-decoloured")
    } else {
        return Ok(None);
    };
    Ok(d.ok().map(|dd| WearEstimate {
        ea: dd.wear_degree.estimate,
        ea_lower: dd.wear_degree.lower,
        ea_upper: dd.wear_degree.upper,
        planetary: pb.planetary,
        method,
    }))
}

/// The wear re-estimated with a machine's calibrated effects held fixed ([`refit_held`]).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct HeldRefit {
    /// Fixed-axis wear `ea`: the minimum of the profile over 0.1, 0.2, …, 1.0, the start and
    /// ±0.05 around the best (parabola through the best three points; continuous).
    pub ea: f64,
    /// Profile-likelihood interval of `ea` at the diagnosis's credible level.
    pub ea_lower: f64,
    pub ea_upper: f64,
    /// Planetary error and shaft-modulation amplitude the model held (units of b).
    pub planetary_error_b: f64,
    pub eccentricity_b: f64,
    /// Tooth-damage stiffness loss the model held (0: none).
    pub tooth_stiffness_loss: f64,
    /// RMS log-spectral distance (dB) of the model with the held effects at the best simulated
    /// ea.
    pub error_db: f64,
    /// The same for the plain model at the start value (the uncalibrated diagnosis).
    pub error_plain_db: f64,
    pub f1_hz: f64,
    pub omega1: f64,
}

/// Re-estimate the wear of `record` with `held` in the model: element effects in the
/// assembly, a path resonance as a fixed sensor stage (its Hz frequency mapped to `f1`).
/// `ea` is profiled like [`calibrate`]'s refit (gain and noise floor by
/// Levenberg–Marquardt at each point; nothing about the effects re-fitted), with the same
/// continuous minimum and profile-likelihood interval.
pub fn refit_held(
    record: &Record,
    table: &SignatureTable,
    opts: &CalibrateOptions,
    f1: f64,
    omega1: f64,
    ea_start: f64,
    held: &held::HeldEffects,
) -> Result<HeldRefit> {
    let gb = table.gearbox();
    let (olo, ohi) = table.omega_band();
    let omega1 = omega1.clamp(olo, ohi);
    let r = grid();
    let m = log_spectrum(&record.samples, record.sample_rate, f1)?;
    let j_n = m.len() as f64;
    let sim = Simulator::new(gb, omega1, opts);
    let baseline = gb.planetary_baseline().unwrap_or(0.0);
    let p0 = ElementParams::plain(ea_start, baseline);
    let unit = Weights::unit(r.len());
    let s0 = sim.spectrum(&p0)?;
    let (sens0, rss0) = fit_sensor(&m, &s0, &r, None, &unit);
    let error_plain_db = (rss0 / j_n).sqrt();
    let resid0: Vec<f64> = {
        let f = sensor_model(&s0, &r, &sens0);
        m.iter().zip(&f).map(|(a, b)| a - b).collect()
    };
    let j_eff = effective_points(&resid0);
    let res = held.resonance_at(f1);
    let base = ElementParams {
        planetary: held.planetary_error_b.unwrap_or(baseline),
        eccentricity: held.eccentricity_b,
        ecc_shaft: held.eccentricity_shaft_ratio.unwrap_or(0.0),
        tooth_depth: held.tooth.map_or(0.0, |t| t.0),
        tooth_shaft: held.tooth.map_or(0.0, |t| t.1),
        ..p0
    };
    let prof = sim.profile_adaptive(&m, &r, base, None, res, &unit)?;
    let pts: Vec<(f64, f64)> = prof.iter().map(|p| (p.0.ea, p.2)).collect();
    // No model seeds here (cost per diagnosis): the points' scatter about the parabola stands
    // for the simulations' noise.
    let (ea, ea_lower, ea_upper) =
        profile_interval_noisy(&pts, j_eff, opts.diagnose.credible_level, 0.0);
    let (_, _, rss) = best_point(&prof);
    let error_db = (rss / j_n).sqrt();
    if !(error_db.is_finite() && error_plain_db.is_finite() && ea.is_finite()) {
        return Err(Error::Signal(
            "the refit with the calibrated effects produced a non-finite error".into(),
        ));
    }
    Ok(HeldRefit {
        ea,
        ea_lower,
        ea_upper,
        planetary_error_b: base.planetary,
        eccentricity_b: base.eccentricity,
        tooth_stiffness_loss: base.tooth_depth,
        error_db,
        error_plain_db,
        f1_hz: f1,
        omega1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn est(ea: f64, lo: f64, hi: f64, method: &'static str) -> WearEstimate {
        WearEstimate {
            ea,
            ea_lower: lo,
            ea_upper: hi,
            planetary: 0.1,
            method,
        }
    }

    #[test]
    fn an_element_refit_moves_the_wear_only_outside_the_tables_interval() {
        let before = est(0.50, 0.40, 0.53, "table-posterior");
        // Inside: the table's estimate and interval stand, named as confirmed.
        let inside = confirm_or_move(
            &before,
            est(0.45, 0.30, 0.60, "table-posterior-effects-held"),
            true,
        );
        assert_eq!(inside.method, "table-posterior-confirmed");
        assert_eq!(
            (inside.ea, inside.ea_lower, inside.ea_upper),
            (0.50, 0.40, 0.53)
        );
        // Outside (the eccentricity test's case): the refit is the wear.
        let refit = est(0.30, 0.27, 0.51, "table-posterior-effects-held");
        let outside = confirm_or_move(&before, refit, true);
        assert_eq!((outside.ea, outside.method), (0.30, refit.method));
        // A path stage alone is always taken, even inside, and whatever its method (the profile
        // stands in when the de-coloured diagnosis fails).
        for m in ["table-posterior-decoloured", "profile-likelihood"] {
            let r = confirm_or_move(&before, est(0.45, 0.35, 0.55, m), false);
            assert_eq!((r.ea, r.method), (0.45, m));
        }
        // The interval's ends count as inside.
        assert!(!held::refit_moves_wear((0.40, 0.53), 0.40));
        assert!(held::refit_moves_wear((0.40, 0.53), 0.5301));
    }
}
