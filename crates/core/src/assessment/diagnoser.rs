//! A signature table ready to diagnose records: the table, its prepared [`Matcher`] and the
//! options, built once (the service keeps one per gearbox table, `gearwear diagnose` one per
//! run). [`TableDiagnoser::read`] diagnoses one channel, with the machine's calibration when it
//! has one: a path stage is divided out of the record first, and the calibrated effects are
//! held fixed in a refit of the wear.

use serde::Serialize;
use serde_json::Value;

use crate::closed_loop::held::{HeldEffects, MAX_CORRECTION_DB, refit_moves_wear};
use crate::closed_loop::{CalibrateOptions, HeldRefit, calibrate, refit_held};
use crate::diagnosis::machine_path::LineRatios;
use crate::diagnosis::{
    DiagnoseOptions, Diagnosis, Matcher, diagnose_with, diagnose_with_spectrum,
};
use crate::record::Record;
use crate::signature::SignatureTable;

/// Table + matcher + the options every diagnosis with it uses.
pub struct TableDiagnoser {
    table: SignatureTable,
    matcher: Matcher,
    opts: DiagnoseOptions,
}

/// A machine's current calibration as later diagnoses hold it.
#[derive(Debug, Clone)]
pub struct MachineCalibration {
    pub id: String,
    /// RFC 3339.
    pub calibrated_at: String,
    /// The accepted effects, `[{name, kind, parameters}]` as stored.
    pub effects: Value,
}

/// The `calibration` object of a calibrated machine's diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrationUse {
    pub id: String,
    pub calibrated_at: String,
    pub effects: Value,
    /// The path stage divided out of the record, when the calibration has one.
    pub path_correction: Option<PathCorrection>,
    /// The wear of the record as measured (no path correction), beside a path correction.
    pub uncorrected_wear_degree: Option<WearInterval>,
    /// The wear refitted with the calibrated effects held fixed; `None` without effects to
    /// hold or when the refit failed (a warning says why).
    pub wear_refit: Option<HeldRefit>,
    /// Element effects are not in the signature table: the machine's wear (and so its alert
    /// level) is the refit's when it lies outside the table's credible interval (inside it,
    /// the table's reading stands, as in the calibration's `table-posterior-confirmed`); a
    /// path stage alone is in the de-coloured `wear_degree`. `wear_refit` or `wear_degree`.
    pub alert_follows: &'static str,
}

/// A calibrated transmission-path resonance.
#[derive(Debug, Clone, Serialize)]
pub struct PathCorrection {
    pub frequency_hz: f64,
    pub damping_ratio: f64,
    pub peak_gain: Option<f64>,
    pub max_correction_db: f64,
}

/// A wear degree (units of the backlash b) with its credible interval.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct WearInterval {
    pub estimate: f64,
    pub lower: f64,
    pub upper: f64,
}

/// One channel read with the table.
#[derive(Debug, Clone)]
pub struct TableReading {
    /// The table's diagnosis (of the de-coloured record under a path calibration), its
    /// warnings followed by the calibration's.
    pub diagnosis: Diagnosis,
    /// How the machine's calibration entered, when it has one.
    pub calibration: Option<CalibrationUse>,
    /// The wear the alert level and the stored trend follow: the diagnosis's, or the refit's
    /// when the calibration holds an element effect that moves it (see
    /// [`CalibrationUse::alert_follows`]).
    pub wear: WearInterval,
    /// The record's Hann amplitude spectrum, when the diagnosis computed it for the samples as
    /// received (not for a calibration-corrected copy): a plot is drawn from it.
    pub spectrum: Option<crate::signal::Spectrum>,
    /// The diagnosis's order analysis of the samples as received (not of a
    /// calibration-corrected copy), tracked with the table's gearbox: the record's baseline
    /// features reuse it.
    pub order: Option<crate::novelty::OrderAnalysis>,
    /// The plain table's line ratios of the record as received, before a calibrated path
    /// re-read it: what a baseline record keeps for the path's calibration.
    pub ratios: Option<LineRatios>,
}

impl TableReading {
    /// `(estimate, poor_fit, chi2_per_feature)`: what the alert policy reads of the wear.
    pub fn alert_wear(&self) -> (f64, bool, f64) {
        let fit = &self.diagnosis.fit;
        (self.wear.estimate, fit.inflated, fit.chi2_per_feature)
    }

    /// Named lines to mark on the spectrum: `(name, f / f1)`.
    pub fn marks(&self) -> Vec<(String, f64)> {
        self.diagnosis
            .lines
            .iter()
            .map(|l| (l.name.clone(), l.normalised_frequency))
            .collect()
    }
}

/// The effects of a stored calibration (name + parameters of each).
fn held_effects(cal: &MachineCalibration) -> crate::Result<HeldEffects> {
    let list = cal.effects.as_array().cloned().unwrap_or_default();
    let parsed: Vec<(String, std::collections::BTreeMap<String, f64>)> = list
        .iter()
        .map(|e| {
            let name = e["name"].as_str().unwrap_or("").to_string();
            let params = serde_json::from_value(e["parameters"].clone()).map_err(|err| {
                crate::Error::Stored {
                    what: format!("effect `{name}`"),
                    reason: err.to_string(),
                }
            })?;
            Ok((name, params))
        })
        .collect::<crate::Result<_>>()?;
    HeldEffects::from_effects(parsed.iter().map(|(n, p)| (n.as_str(), p)))
}

impl TableDiagnoser {
    pub fn new(table: SignatureTable, opts: DiagnoseOptions) -> crate::Result<Self> {
        let matcher = Matcher::new(&table, &opts)?;
        Ok(TableDiagnoser {
            table,
            matcher,
            opts,
        })
    }

    pub fn table(&self) -> &SignatureTable {
        &self.table
    }

    /// Identity of the loaded table (its model hash).
    pub fn table_id(&self) -> String {
        self.table.model_hash.clone()
    }

    /// The diagnosis options at `shaft_hz`.
    pub fn options(&self, shaft_hz: Option<f64>) -> DiagnoseOptions {
        let mut opts = self.opts.clone();
        opts.shaft_hz = shaft_hz;
        opts
    }

    /// How a calibration enters a diagnosis, warnings to add, and the refit the wear follows
    /// when it moves it. `rec` is the record as measured, `d` the diagnosis of the
    /// (de-coloured) record.
    fn calibration_use(
        &self,
        cal: &MachineCalibration,
        held: &HeldEffects,
        rec: &Record,
        d: &Diagnosis,
        opts: &DiagnoseOptions,
    ) -> crate::Result<(CalibrationUse, Vec<String>, Option<HeldRefit>)> {
        let mut warnings = Vec::new();
        let (path_correction, uncorrected) = match held.path_resonance {
            Some((fr, zeta)) => {
                let d0 = diagnose_with(rec, &self.table, &self.matcher, opts)?;
                (
                    Some(PathCorrection {
                        frequency_hz: fr,
                        damping_ratio: zeta,
                        peak_gain: held.path_peak_gain,
                        max_correction_db: MAX_CORRECTION_DB,
                    }),
                    Some(WearInterval {
                        estimate: d0.wear_degree.estimate,
                        lower: d0.wear_degree.lower,
                        upper: d0.wear_degree.upper,
                    }),
                )
            }
            None => (None, None),
        };
        let mut held_refit = None;
        if !held.is_empty() {
            let copts = CalibrateOptions {
                diagnose: opts.clone(),
                ..CalibrateOptions::default()
            };
            match refit_held(
                rec,
                &self.table,
                &copts,
                d.f1_hz,
                d.omega1,
                d.wear_degree.estimate,
                held,
            ) {
                Ok(r) => {
                    if r.error_db >= r.error_plain_db {
                        warnings.push(format!(
                            "the calibrated effects do not lower this record's model error \
                             ({:.2} dB with them, {:.2} dB without): the calibration may no longer \
                             apply; recalibrate the machine",
                            r.error_db, r.error_plain_db
                        ));
                    }
                    held_refit = Some(r);
                }
                Err(e) => {
                    warnings.push(format!(
                        "the refit with the calibrated effects failed ({e}); wear_refit is null"
                    ));
                }
            }
        }
        let wd = &d.wear_degree;
        let moved = held_refit
            .filter(|r| held.has_element_effect() && refit_moves_wear((wd.lower, wd.upper), r.ea));
        Ok((
            CalibrationUse {
                id: cal.id.clone(),
                calibrated_at: cal.calibrated_at.clone(),
                effects: cal.effects.clone(),
                path_correction,
                uncorrected_wear_degree: uncorrected,
                wear_refit: held_refit,
                alert_follows: if moved.is_some() {
                    "wear_refit"
                } else {
                    "wear_degree"
                },
            },
            warnings,
            moved,
        ))
    }

    /// Diagnose one channel, with the machine's calibration when it has one.
    pub fn read(
        &self,
        rec: &Record,
        shaft_hz: Option<f64>,
        calibration: Option<&MachineCalibration>,
    ) -> crate::Result<TableReading> {
        self.read_with(rec, shaft_hz, calibration, true)
    }

    /// [`TableDiagnoser::read`]; `track_orders: false` leaves the order analysis to the caller
    /// (who has the shaft's angle from a tachometer).
    pub fn read_with(
        &self,
        rec: &Record,
        shaft_hz: Option<f64>,
        calibration: Option<&MachineCalibration>,
        track_orders: bool,
    ) -> crate::Result<TableReading> {
        let mut opts = self.options(shaft_hz);
        opts.track_orders = track_orders;
        let held = calibration
            .map(|c| held_effects(c).map(|h| (c, h)))
            .transpose()?;
        // A path stage is divided out of the spectrum before the ordinary feature extraction.
        let corrected = match held
            .as_ref()
            .and_then(|(_, h)| h.decolour(&rec.samples, rec.sample_rate))
        {
            Some(x) => Some(Record {
                samples: x?,
                sample_rate: rec.sample_rate,
            }),
            None => None,
        };
        let (mut d, spectrum) = diagnose_with_spectrum(
            corrected.as_ref().unwrap_or(rec),
            &self.table,
            &self.matcher,
            &opts,
        )?;
        // The spectrum (and the order analysis) of a corrected copy is not the record's: the
        // plot shows the record, and its features track the record itself.
        let spectrum = spectrum.filter(|_| corrected.is_none());
        let order = d.order.clone().filter(|_| corrected.is_none());
        let mut wear = WearInterval {
            estimate: d.wear_degree.estimate,
            lower: d.wear_degree.lower,
            upper: d.wear_degree.upper,
        };
        let mut calibration = None;
        if let Some((cal, h)) = &held {
            let (c, warnings, refit) = self.calibration_use(cal, h, rec, &d, &opts)?;
            calibration = Some(c);
            d.warnings.extend(warnings);
            // The alert level (and the stored wear) follow the refit when it holds an
            // element effect.
            if let Some(r) = refit {
                wear = WearInterval {
                    estimate: r.ea,
                    lower: r.ea_lower,
                    upper: r.ea_upper,
                };
            }
        }
        let ratios = corrected.is_none().then(|| LineRatios::of(&d));
        Ok(TableReading {
            ratios,
            diagnosis: d,
            calibration,
            wear,
            spectrum,
            order,
        })
    }

    /// Close the loop on one record ([`crate::closed_loop::calibrate`]): the report JSON.
    pub fn calibrate(&self, rec: &Record, shaft_hz: Option<f64>) -> crate::Result<Value> {
        let opts = CalibrateOptions {
            diagnose: self.options(shaft_hz),
            ..CalibrateOptions::default()
        };
        let report = calibrate(rec, &self.table, &opts)?;
        serde_json::to_value(&report).map_err(|e| crate::Error::Stored {
            what: "closed-loop report".into(),
            reason: e.to_string(),
        })
    }
}
