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
//! 4. **The model's own scatter** ([`model_scatter`](scatter::model_scatter)): the plain
//!    model at its best wear (least squares) is simulated from
//!    [`CalibrateOptions::model_seeds`] more initial states; their spread per grid point, the
//!    record's Welch scatter where the noise floor dominates and a line-position term give a
//!    per-point `σ_j`. Every later fit and score uses the
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
//!    [`table_posterior_held`](refit::table_posterior_held)). Beside it, the chosen model's ea
//!    is profiled (`wear_profile`): a parabola fitted to the profile's deviance near its minimum gives the
//!    vertex and the interval (the χ²₁ likelihood interval of the parabola widened by the
//!    vertex's uncertainty from the simulations' scatter, [`fit::profile_interval_noisy`]);
//!    it is the refit only when the held posterior cannot be computed. An element refit
//!    inside the table's credible interval leaves the table's estimate standing
//!    (`table-posterior-confirmed`, [`confirm_or_move`](refit::confirm_or_move)). With no effect
//!    claimed (or a refit that does not lower the plain error) the model is unchanged and
//!    `wear_after` is the table's estimate.
//! 8. **Unexplained**: runs of the final residual beyond ±[`CalibrateOptions::unexplained_db`],
//!    each with a plain-words guess ([`residual::annotate`]); and, from the record's level
//!    over time, bursts, impacts at a shaft's rate the fit did not claim, or a level drift
//!    ([`level`]: the spectrum averages them away).
//!
//! Each step is a stage of its own: [`measured`] (1–3), [`scatter`] (4), [`candidates`] and
//! [`elements`] (5), [`scoring`], [`attribution`] and [`selection`] (6), [`refit`] (7),
//! [`report`] (8); [`simulator`] runs the model for all of them.

pub mod effects;
pub mod fit;
pub mod held;
pub mod level;
pub mod residual;
pub mod sidebands;
pub mod spectrum;
pub mod virtual_rig;

mod attribution;
mod candidates;
mod elements;
mod measured;
mod options;
mod refit;
mod report;
mod scatter;
mod scoring;
mod selection;
mod simulator;

pub use attribution::SUPPORT_SHARE;
pub use attribution::{
    BAND_IMPROVED_FRACTION, BAND_MIN_POINTS, BandEvidence, MIN_COLOURED_LINES, TOOTH_TSA_FM4,
};
pub use options::CalibrateOptions;
pub use refit::{HeldRefit, refit_held};
pub use report::{CalibrationReport, Candidate, ResidualFeature, SensorFit, Spectra, WearEstimate};
pub use selection::{
    BAND_MARGIN_FACTOR, SM_SIDEBAND_MARGIN_FACTOR, SM_SIDEBAND_PROMINENCE_DB, TOOTH_MARGIN_FACTOR,
};

use crate::error::Result;
use crate::record::Record;
use crate::signature::SignatureTable;
use attribution::Attribution;
use candidates::Candidates;
use measured::{Before, Measured};
use scatter::Null;
use scoring::{Scores, rescore_over_seeds};
use selection::Selection;
use simulator::Simulator;

/// Close the loop on one record; see the [module docs](self).
pub fn calibrate(
    record: &Record,
    table: &SignatureTable,
    opts: &CalibrateOptions,
) -> Result<CalibrationReport> {
    let ms = Measured::new(record, table, opts)?;
    let sim = Simulator::new(ms.gb, ms.omega1, opts);
    let before = Before::fit(&ms, &sim)?;
    let null = Null::measure(&ms, &sim, &before)?;
    let mut cands = Candidates::fit(&ms, &sim, before.params, &null)?;
    rescore_over_seeds(&ms, &sim, &null.weights, &mut cands.list)?;
    let attr = Attribution::measure(&ms, &sim, &null.weights, &cands)?;
    let scores = Scores::new(&ms, &null, &cands.list, &attr.fitted);
    let selection = Selection::new(&ms, &cands, &attr, &scores, before.rss);
    let chosen = selection.choose();
    let candidates = selection.report(ms.j_n);
    let after = refit::refit(&ms, &sim, &before, &null, &cands, chosen)?;
    report::assemble(
        &ms,
        &before,
        &null,
        after,
        candidates,
        scores.claim_margin,
        cands.sideband_checks,
    )
}
