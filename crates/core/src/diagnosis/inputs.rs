//! The record and the table's facts that the steps of the diagnosis share: validation, the f1
//! search, the line measurement and the match at one f1, the tacho-less re-selection.

use super::F1Detection;
use super::matcher::{Matcher, Posterior, posterior};
use super::options::{BAND_EDGE_TOLERANCE, DiagnoseOptions};
use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signal::features::{ConditionIndicators, condition_indicators};
use crate::signal::lines::{
    LineMeasurement, SEGMENT_PERIODS, highest_ratio, measure_lines, segment_len,
};
use crate::signal::mesh_search::{SearchSpectrum, locate_f1, refine_near};
use crate::signature::{LineDef, SignatureTable, line_ratios};

/// Kinematic partners (name, ratio) used to recognise the stage-1 mesh line.
///
/// Every other stage's mesh line `fk` and, for a stage the wear acts on, `2fk` and `f1−fk`;
/// then `f1+fk` of the wear stages; then `2f1` (and `3f1` for a single-stage gearbox, which has
/// no other partner). For the first paper's rig: f2, 2f2, f1−f2, f3, f1+f2, 2f1.
fn partners(gb: &Gearbox) -> Vec<(String, f64)> {
    let wear = gb.wear_stages();
    let others: Vec<(usize, f64, bool)> = gb
        .mesh_ratios
        .iter()
        .enumerate()
        .skip(1)
        .map(|(i, r)| (i + 1, *r, wear.contains(&(i + 1))))
        .collect();
    let mut v = Vec::new();
    for &(k, r, w) in &others {
        v.push((format!("f{k}"), r));
        if w {
            v.push((format!("2f{k}"), 2.0 * r));
            if r < 1.0 {
                v.push((format!("f1-f{k}"), 1.0 - r));
            }
        }
    }
    for &(k, r, w) in &others {
        if w {
            v.push((format!("f1+f{k}"), 1.0 + r));
        }
    }
    v.push(("2f1".into(), 2.0));
    if others.is_empty() {
        v.push(("3f1".into(), 3.0));
    }
    v
}

/// The record and the table's facts that the steps of [`diagnose_with_spectrum`] share.
pub(super) struct Inputs<'a> {
    pub(super) table: &'a SignatureTable,
    /// Subtracted from the unclipped features before matching ([`diagnose_shifted`]).
    pub(super) shift: Option<&'a [f64]>,
    pub(super) x: &'a [f64],
    pub(super) fs: f64,
    pub(super) gb: &'a Gearbox,
    pub(super) f_ref: f64,
    pub(super) lines: &'a [LineDef],
    /// The lines' ratios to f1, in their order.
    pub(super) ratios: Vec<f64>,
    /// Highest line ratio: the sample rate must exceed `2 top f1`.
    pub(super) top: f64,
    /// The table's Ω1 band, and the same in Hz of f1.
    pub(super) omega_band: (f64, f64),
    pub(super) band_hz: (f64, f64),
}

/// The lines measured at one f1 and what the matcher makes of them (steps 3 and 4).
pub(super) struct Evaluation {
    pub(super) meas: LineMeasurement,
    /// The clipped features.
    pub(super) y: Vec<f64>,
    pub(super) post: Posterior,
    /// χ² of the wear features at the posterior mode.
    pub(super) chi2: f64,
}

impl<'a> Inputs<'a> {
    /// Step 1: validate the record (sample rate, samples) and gather the table's facts.
    pub(super) fn new(record: &'a Record, table: &'a SignatureTable) -> Result<Self> {
        let x = &record.samples;
        let fs = record.sample_rate;
        crate::record::check_sample_rate(fs)?;
        crate::record::check_signal(x)?;
        let gb = table.gearbox();
        let f_ref = gb.reference_frequency_hz();
        let lines = &table.features.lines;
        let (olo, ohi) = table.omega_band();
        let ratios = line_ratios(lines);
        Ok(Inputs {
            table,
            shift: None,
            x,
            fs,
            gb,
            f_ref,
            lines,
            top: highest_ratio(&ratios),
            ratios,
            omega_band: (olo, ohi),
            band_hz: (olo * f_ref, ohi * f_ref),
        })
    }

    /// Refuse a record shorter than one estimator segment at `f1`.
    fn check_length(&self, f1: f64) -> Result<()> {
        let needed = segment_len(self.fs, f1).max(16);
        if self.x.len() < needed {
            return Err(Error::RecordTooShort {
                samples: self.x.len(),
                periods: self.x.len() as f64 * f1 / self.fs,
                f1_hz: f1,
                needed_periods: SEGMENT_PERIODS as usize,
                needed_samples: needed,
            });
        }
        Ok(())
    }

    /// True when `2 top f1` reaches the sample rate.
    fn rate_too_low_for(&self, f1: f64) -> bool {
        2.0 * self.top * f1 >= self.fs
    }

    fn rate_too_low(&self, f1: f64) -> Error {
        Error::SampleRateTooLow {
            sample_rate: self.fs,
            highest_line_hz: self.top * f1,
            needed: 2.0 * self.top * f1,
        }
    }

    /// True when `omega1` is more than `tol` outside the table's Ω1 band.
    fn outside_band(&self, omega1: f64, tol: f64) -> bool {
        omega1 < self.omega_band.0 - tol || omega1 > self.omega_band.1 + tol
    }

    /// True when `omega1` is more than half a grid step outside the table's Ω1 band (a
    /// one-column table: [`BAND_EDGE_TOLERANCE`]): a record that close to an edge is read at
    /// the edge's column (the matcher clamps), whose lines differ from its own by less than
    /// from the next column's.
    fn beyond_half_step(&self, omega1: f64) -> bool {
        let o = &self.table.grid.omega1;
        let (lo, hi) = match o.len() {
            0 | 1 => (self.edge(), self.edge()),
            n => (0.5 * (o[1] - o[0]), 0.5 * (o[n - 1] - o[n - 2])),
        };
        omega1 < self.omega_band.0 - lo.max(self.edge())
            || omega1 > self.omega_band.1 + hi.max(self.edge())
    }

    fn out_of_band(&self, f1: f64, omega1: f64) -> Error {
        Error::SpeedOutOfBand {
            f1_hz: f1,
            omega1,
            min: self.omega_band.0,
            max: self.omega_band.1,
            min_hz: self.band_hz.0,
            max_hz: self.band_hz.1,
        }
    }

    /// How far a refined f1 may stand outside the band (Ω1 units).
    fn edge(&self) -> f64 {
        BAND_EDGE_TOLERANCE * self.omega_band.0
    }

    /// Step 1, the shaft rate: the f1 it implies, refused outside the table's band, above what
    /// the sample rate carries or with too short a record. Without a shaft rate, the sample rate
    /// must carry the lines at the band's lowest f1.
    pub(super) fn nominal_f1(&self, shaft_hz: Option<f64>) -> Result<Option<f64>> {
        match shaft_hz {
            Some(s) => {
                if !(s.is_finite() && s > 0.0) {
                    return Err(Error::param(
                        "shaft_hz",
                        s,
                        "the input-shaft rate must be a positive number of Hz",
                    ));
                }
                let f1 = self.gb.f1_hz(s);
                let om = f1 / self.f_ref;
                if self.beyond_half_step(om) {
                    return Err(self.out_of_band(f1, om));
                }
                if self.rate_too_low_for(f1) {
                    return Err(self.rate_too_low(f1));
                }
                self.check_length(f1)?;
                Ok(Some(f1))
            }
            None => {
                if self.rate_too_low_for(self.band_hz.0) {
                    return Err(self.rate_too_low(self.band_hz.0));
                }
                Ok(None)
            }
        }
    }

    /// Step 2: locate f1 in the search band (the table's, limited by what the sample rate can
    /// carry), refuse it outside the band or with too short a record, and warn about a weak f1
    /// line or one without kinematic partners. Also returns the spectrum the search used.
    pub(super) fn locate(
        &self,
        nominal: Option<f64>,
        warnings: &mut Vec<String>,
    ) -> Result<(f64, F1Detection, SearchSpectrum)> {
        let (x, fs) = (self.x, self.fs);
        let search = (
            self.band_hz.0,
            self.band_hz.1.min(0.999 * fs / (2.0 * self.top)),
        );
        // Length check against the most lenient f1 of the band (the exact check follows).
        self.check_length(search.1)?;
        let spectrum = SearchSpectrum::new(x, fs)?;
        let (f1, detection) = locate_f1(x, fs, &spectrum, &partners(self.gb), search, nominal)?;
        let omega1 = f1 / self.f_ref;
        // Refinement may move a peak found at the band edge a hair outside it.
        if self.beyond_half_step(omega1) {
            return Err(self.out_of_band(f1, omega1));
        }
        self.check_length(f1)?;
        if detection.prominence_db < 10.0 {
            warnings.push(format!(
                "the f1 line at {f1:.2} Hz stands only {:.1} dB over the local floor",
                detection.prominence_db
            ));
        }
        if detection.method == "spectrum" && detection.partners_found.len() < 2 {
            warnings.push(format!(
                "tacho-less f1 = {f1:.2} Hz has only {} kinematic partner line(s) of this rig \
                 ({:?}); the record may come from another gearbox or f1 may be wrong",
                detection.partners_found.len(),
                detection.partners_found
            ));
        }
        Ok((f1, detection, spectrum))
    }

    /// Steps 3 and 4 at one f1: measure the lines, clip the features, the posterior over
    /// `(ea, Ω1)` and the χ² at its mode.
    pub(super) fn evaluate(
        &self,
        matcher: &Matcher,
        opts: &DiagnoseOptions,
        f1: f64,
    ) -> Result<Evaluation> {
        let meas = measure_lines(self.x, self.fs, f1, &self.ratios)?;
        let mut raw = meas.features(self.lines);
        if let Some(shift) = self.shift {
            raw.iter_mut().zip(shift).for_each(|(v, d)| *v -= d);
        }
        let y = matcher.clip(&raw);
        let post = posterior(matcher, &y, f1 / self.f_ref, opts);
        let (chi2, _) = matcher.chi2(&y, post.mode(), post.omega_mean, opts);
        Ok(Evaluation {
            meas,
            y,
            post,
            chi2,
        })
    }

    /// Tacho-less and the model explains the record worse than it explains its own
    /// simulations: maybe the wrong peak won (a harmonic or subharmonic of f1). Try the other
    /// spectral candidates and keep the one the model explains best: `ev`, `detection` and a
    /// warning are updated when one is chosen. Returns the f1 kept.
    pub(super) fn reselect_f1(
        &self,
        matcher: &Matcher,
        opts: &DiagnoseOptions,
        f1: f64,
        detection: &mut F1Detection,
        ev: &mut Evaluation,
        warnings: &mut Vec<String>,
    ) -> f64 {
        let (x, fs) = (self.x, self.fs);
        let nfeat = matcher.wear_features.len();
        let df = fs / x.len().min(1 << 17) as f64;
        let first = ev.chi2;
        let mut chosen = None;
        for &(cand, _, _) in detection.candidates.iter() {
            if (cand - detection.initial_hz).abs() < 0.5 * df {
                continue;
            }
            let fc = refine_near(x, fs, cand, 1.5 * df);
            if self.outside_band(fc / self.f_ref, self.edge())
                || self.check_length(fc).is_err()
                || self.rate_too_low_for(fc)
            {
                continue;
            }
            // Switch only to a candidate the model actually explains: when every candidate
            // fits badly the record is not this gearbox's, and the spectral choice stands.
            if let Ok(r) = self.evaluate(matcher, opts, fc)
                && r.chi2 < ev.chi2
                && r.chi2 <= opts.max_chi2_per_feature * nfeat as f64
            {
                *ev = r;
                chosen = Some((cand, fc));
            }
        }
        let Some((cand, fc)) = chosen else {
            return f1;
        };
        warnings.push(format!(
            "tacho-less f1 re-selected by model fit: the strongest candidate {f1:.2} Hz gave \
             χ² {first:.1}, the candidate {cand:.2} Hz (refined {fc:.2} Hz) gives {:.1}",
            ev.chi2
        ));
        detection.method = "spectrum, re-selected by model fit";
        detection.initial_hz = cand;
        fc
    }

    /// Step 6: the condition indicators, every model line but f1 and 2f1 counted as "other".
    pub(super) fn condition_indicators(&self, f1: f64, shaft: f64) -> Result<ConditionIndicators> {
        let other: Vec<f64> = self
            .lines
            .iter()
            .filter(|l| l.name != "f1" && l.name != "2f1")
            .map(|l| l.ratio * f1)
            .collect();
        condition_indicators(self.x, self.fs, f1, shaft, &other)
    }
}
