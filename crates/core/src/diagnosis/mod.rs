//! Diagnosis: from one accelerometer record to a wear degree with a credible interval.
//!
//! Steps of [`diagnose`]:
//! 1. **Validate** the record (non-empty, finite, a usable sample rate).
//! 2. **Locate f1** (stage-1 mesh frequency, Hz). With a shaft rate: `f1 = z1 × shaft_hz`
//!    (29 × on the paper's rig), refined to the spectral peak within ±0.3 %. Without
//!    (tacho-less): every prominent peak of the record's spectrum inside the table's speed band
//!    is scored by its own prominence plus the prominence of its kinematic partners
//!    (`f2 = 0.36 f1`, `2f2`, `f1 − f2`, `f3 = 0.0875 f1`, `f1 + f2`, `2 f1`); the best
//!    candidate wins and is refined to the maximum of the record's Hann DTFT. `Ω1 = f1 / f_ref`.
//! 3. **Measure** the model's lines and the gain-invariant features
//!    ([`crate::signal::lines::measure_lines`]; the same code made the table).
//! 4. **Match**: a Gaussian likelihood in the clipped log-ratio features with the table's
//!    per-grid-point mean and spread plus a measurement floor, bilinearly interpolated in
//!    `(ea, Ω1)`, tempered, marginalised over `Ω1` with a narrow Gaussian prior around the
//!    measured value; uniform prior on `ea` over the table's range. The posterior gives the
//!    estimate (median), the 90 % credible interval (5 % and 95 % quantiles), the motion state
//!    the table expects there and the nearest table entries.
//! 5. **Planetary flag**: the z-score of the measured `ln(A_f3/A_f1)` against what the table
//!    (planetary error 0.1) expects at the estimate; above `planetary_z` → elevated.
//! 6. **Condition indicators** (RMS, kurtosis, crest factor, FM0, FM4, NA4; tacho-less, see
//!    [`crate::signal::features`]).
//! 7. **Baseline** (the paper's method): the single ratio `A_f2/A_f1` matched to the table's
//!    mean curve at the measured Ω1; reported for comparison.

mod inputs;
pub mod machine_path;
pub mod machine_physics;
mod matcher;
mod options;
mod report;

pub use crate::signal::mesh_search::F1Detection;
pub use matcher::{Matcher, Posterior, posterior};
pub use options::{BAND_EDGE_TOLERANCE, DiagnoseOptions};
pub use report::{
    Baseline, Diagnosis, Fit, MatchedLine, NearEntry, PlanetaryCheck, RecordInfo, WearDegree,
    Withheld, WithheldReason,
};

use crate::error::{Error, Result};
use crate::record::Record;
use crate::signal::Spectrum;
use crate::signal::tsa::order_analysis;
use crate::signature::SignatureTable;
use inputs::Inputs;
use options::nan_or_above;
use report::{
    coarse_density, fit_and_inflate, matched_lines, motion_state_at, nearest, nearest_entries,
    planetary_check, wear_degree,
};

/// Diagnose one record against a signature table. See the [module docs](self).
///
/// Errors (each carries the numbers): [`Error::EmptyRecord`], [`Error::FlatRecord`],
/// [`Error::ClippedRecord`] (see [`crate::record::check_signal`]), [`Error::RecordTooShort`]
/// (fewer f1 periods than one estimator segment), [`Error::NonFiniteSample`], [`Error::SampleRateTooLow`],
/// [`Error::NoMeshLine`], [`Error::SpeedOutOfBand`], [`Error::InvalidParameter`] for a bad
/// shaft rate or sample rate.
pub fn diagnose(
    record: &Record,
    table: &SignatureTable,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis> {
    let matcher = Matcher::new(table, opts)?;
    diagnose_with(record, table, &matcher, opts)
}

/// [`diagnose`] with a prepared [`Matcher`] (what a service keeps between requests).
pub fn diagnose_with(
    record: &Record,
    table: &SignatureTable,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis> {
    diagnose_with_spectrum(record, table, matcher, opts).map(|(d, _)| d)
}

/// [`diagnose_with`], also handing back the spectrum its f1 search computed: the record's
/// Hann-windowed [`amplitude_spectrum`](crate::signal::amplitude_spectrum) (`None` for a record over 2^17 samples, searched on a
/// Welch average). The service plots that spectrum instead of transforming the record again.
pub fn diagnose_with_spectrum(
    record: &Record,
    table: &SignatureTable,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) -> Result<(Diagnosis, Option<Spectrum>)> {
    diagnose_inner(Inputs::new(record, table)?, matcher, opts)
}

/// [`diagnose`] with known effects the table does not hold **held fixed**: `shift[k]` (the
/// change those effects make to unclipped feature `k` of [`LineMeasurement::features`](crate::signal::lines::LineMeasurement::features), same
/// order and length) is subtracted from the record's features before they are clipped and
/// matched, and `shift_var[k]` (that change's own uncertainty, ln-units²) is added to the
/// feature's variance at every table entry ([`Matcher::with_extra_variance`]), so the posterior
/// over `(ea, Ω1)` reads the record as the table's model would make it without the effects,
/// leaning on the features they barely touch. The closed loop computes both from simulations
/// with and without the effects it claimed (`closed_loop::calibrate`'s
/// `table-posterior-effects-held` wear).
///
/// Errors: those of [`diagnose`], and a shift or variance whose length is not the table's
/// feature count or that holds a non-finite value.
pub fn diagnose_shifted(
    record: &Record,
    table: &SignatureTable,
    opts: &DiagnoseOptions,
    shift: &[f64],
    shift_var: &[f64],
) -> Result<Diagnosis> {
    let nf = table.features.lines.len();
    for (what, v) in [("shift", shift), ("shift variance", shift_var)] {
        if v.len() != nf {
            return Err(Error::LengthMismatch {
                what,
                expected: nf,
                found: v.len(),
            });
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(Error::NonFiniteValue {
                analysis: what,
                what: format!("value {i}"),
            });
        }
    }
    let matcher = Matcher::new(table, opts)?.with_extra_variance(shift_var);
    let inp = Inputs {
        shift: Some(shift),
        ..Inputs::new(record, table)?
    };
    diagnose_inner(inp, &matcher, opts).map(|(d, _)| d)
}

fn diagnose_inner(
    inp: Inputs<'_>,
    matcher: &Matcher,
    opts: &DiagnoseOptions,
) -> Result<(Diagnosis, Option<Spectrum>)> {
    let table = inp.table;
    let nominal = inp.nominal_f1(opts.shaft_hz)?;
    let mut warnings = Vec::new();
    let (mut f1, mut detection, spectrum) = inp.locate(nominal, &mut warnings)?;
    let mut ev = inp.evaluate(matcher, opts, f1)?;
    let nfeat = matcher.wear_features.len();
    if detection.method == "spectrum"
        && nan_or_above(
            ev.chi2 / nfeat.max(1) as f64,
            opts.reselect_chi2_per_feature,
        )
    {
        f1 = inp.reselect_f1(matcher, opts, f1, &mut detection, &mut ev, &mut warnings);
    }
    let omega1 = f1 / inp.f_ref;
    let fit = fit_and_inflate(matcher, opts, &mut ev, omega1, &mut warnings);
    let wear = wear_degree(&ev.post, opts.credible_level);
    let i_om = nearest(&table.grid.omega1, omega1);
    let (motion_state, share) =
        motion_state_at(table, nearest(&table.grid.ea, wear.estimate), i_om);
    let near = nearest_entries(table, matcher, &ev.y, i_om, opts);
    let planetary = planetary_check(matcher, &ev.y, wear.estimate, omega1, opts);
    let out_lines = matched_lines(inp.lines, &ev.meas, matcher, wear.estimate, omega1, f1);
    let shaft = f1 * inp.gb.input_shaft_ratio();
    let ci = inp.condition_indicators(f1, shaft)?;
    let x = inp.x;
    let fs = inp.fs;
    // The f1 found above is precise: the tracker searches its line within ±1 %.
    let spectrum = spectrum.into_whole();
    let (order, order_error) = if !opts.track_orders {
        (None, None)
    } else {
        match order_analysis(x, fs, &inp.gb.shaft_train(), f1, 0.01, spectrum.as_ref()) {
            Ok(a) => (Some(a), None),
            Err(e) => (None, Some(e.to_string())),
        }
    };
    let diagnosis = Diagnosis {
        wear_degree: wear,
        wear_note: None,
        wear_withheld: None,
        f1_hz: f1,
        shaft_hz: shaft,
        omega1,
        omega1_posterior: ev.post.omega_mean,
        f1_detection: detection,
        motion_state,
        motion_state_share: share,
        planetary_clearance_elevated: planetary.as_ref().is_some_and(|p| p.z > opts.planetary_z),
        planetary,
        lines: out_lines,
        condition_indicators: ci,
        nearest_entries: near,
        posterior: coarse_density(&ev.post),
        fit,
        baseline_single_ratio: matcher
            .baseline(&ev.y, omega1, opts.ea_step)
            .map(|ea| Baseline {
                method: "paper: ea whose table mean ln(A_f2/A_f1) at the measured Ω1 is closest",
                ea,
            }),
        record: RecordInfo {
            samples: x.len(),
            sample_rate_hz: fs,
            duration_s: x.len() as f64 / fs,
            f1_periods: x.len() as f64 * f1 / fs,
            welch_segments: ev.meas.segments,
            segment_len: ev.meas.segment_len,
        },
        table_model_hash: table.model_hash.clone(),
        sensor: table.sensor.label().into(),
        warnings,
        order,
        order_error,
    };
    Ok((diagnosis, spectrum))
}
