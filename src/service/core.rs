//! The real [`Diagnoser`]: the signature table loaded once at start-up (and checked against
//! the current model configuration) with its prepared [`Matcher`]; each request runs
//! [`diagnose_with`] — the same code and the same JSON as `gearwear diagnose`.

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use super::diagnoser::{Diagnoser, Input, MachineCalibration, Output};
use crate::closed_loop::held::{HeldEffects, MAX_CORRECTION_DB, refit_moves_wear};
use crate::closed_loop::{CalibrateOptions, HeldRefit, calibrate, refit_held};
use crate::diagnosis::{DiagnoseOptions, Matcher, diagnose_with, diagnose_with_spectrum};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signature::SignatureTable;

/// Table + matcher + the default options.
pub struct TableDiagnoser {
    table: SignatureTable,
    matcher: Matcher,
    opts: DiagnoseOptions,
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
}

/// Load the table at `path`; refuse it if it was computed for another model configuration
/// unless `allow_stale` (then log a warning).
pub fn load(path: &Path, allow_stale: bool) -> anyhow::Result<TableDiagnoser> {
    let table = SignatureTable::load(path).with_context(|| {
        format!(
            "regenerate it with `gearwear precompute --output {}`",
            path.display()
        )
    })?;
    // The paper rig's table must match the committed description; any other table must at
    // least match the description it carries.
    let rig = Gearbox::paper_rig();
    let check = if table.gearbox.name == rig.name() {
        table.check_model(&rig)
    } else {
        table.check_model(table.gearbox())
    };
    if let Err(e) = check {
        if allow_stale {
            tracing::warn!(error = %e, "serving with a stale signature table");
        } else {
            return Err(anyhow::Error::from(e).context("pass --allow-stale-table to serve anyway"));
        }
    }
    Ok(TableDiagnoser::new(table, DiagnoseOptions::default())?)
}

/// The effects of a stored calibration (name + parameters of each).
fn held_effects(cal: &MachineCalibration) -> crate::Result<HeldEffects> {
    let list = cal.effects.as_array().cloned().unwrap_or_default();
    let parsed: Vec<(String, std::collections::BTreeMap<String, f64>)> = list
        .iter()
        .map(|e| {
            let name = e["name"].as_str().unwrap_or("").to_string();
            let params = serde_json::from_value(e["parameters"].clone()).map_err(|err| {
                crate::Error::Signal(format!("stored effect `{name}` unreadable: {err}"))
            })?;
            Ok((name, params))
        })
        .collect::<crate::Result<_>>()?;
    HeldEffects::from_effects(parsed.iter().map(|(n, p)| (n.as_str(), p)))
}

impl TableDiagnoser {
    fn options(&self, input: &Input) -> DiagnoseOptions {
        let mut opts = self.opts.clone();
        opts.shaft_hz = input.shaft_hz;
        opts
    }

    /// The `calibration` object of a calibrated machine's diagnosis, and warnings to add.
    /// `rec` is the record as measured, `d` the diagnosis of the (de-coloured) record.
    fn calibration_json(
        &self,
        cal: &MachineCalibration,
        held: &HeldEffects,
        rec: &Record,
        d: &crate::diagnosis::Diagnosis,
        opts: &DiagnoseOptions,
    ) -> crate::Result<(serde_json::Value, Vec<String>, Option<HeldRefit>)> {
        let mut warnings = Vec::new();
        let (path_correction, uncorrected) = match held.path_resonance {
            Some((fr, zeta)) => {
                let d0 = diagnose_with(rec, &self.table, &self.matcher, opts)?;
                (
                    json!({"frequency_hz": fr, "damping_ratio": zeta,
                           "peak_gain": held.path_peak_gain,
                           "max_correction_db": MAX_CORRECTION_DB}),
                    json!({"estimate": d0.wear_degree.estimate, "lower": d0.wear_degree.lower,
                           "upper": d0.wear_degree.upper}),
                )
            }
            None => (serde_json::Value::Null, serde_json::Value::Null),
        };
        let mut held_refit = None;
        let refit = if held.is_empty() {
            serde_json::Value::Null
        } else {
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
                    serde_json::to_value(r).unwrap_or_default()
                }
                Err(e) => {
                    warnings.push(format!(
                        "the refit with the calibrated effects failed ({e}); wear_refit is null"
                    ));
                    serde_json::Value::Null
                }
            }
        };
        let wd = &d.wear_degree;
        let moved = held_refit
            .filter(|r| held.has_element_effect() && refit_moves_wear((wd.lower, wd.upper), r.ea));
        Ok((
            json!({
                "id": cal.id,
                "calibrated_at": cal.calibrated_at,
                "effects": cal.effects,
                "path_correction": path_correction,
                "uncorrected_wear_degree": uncorrected,
                "wear_refit": refit,
                // Element effects are not in the signature table: the machine's wear (and so
                // its alert level) is the refit's when it lies outside the table's credible
                // interval (inside it, the table's reading stands, as in the calibration's
                // `table-posterior-confirmed`); a path stage alone is in the de-coloured
                // `wear_degree`.
                "alert_follows": if moved.is_some() { "wear_refit" } else { "wear_degree" },
            }),
            warnings,
            moved,
        ))
    }
}

impl Diagnoser for TableDiagnoser {
    fn diagnose(&self, input: &Input) -> crate::Result<Output> {
        let rec = &input.record;
        let opts = self.options(input);
        let held = input
            .calibration
            .as_ref()
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
        let (d, spectrum) = diagnose_with_spectrum(
            corrected.as_ref().unwrap_or(rec),
            &self.table,
            &self.matcher,
            &opts,
        )?;
        // The spectrum (and the order analysis) of a corrected copy is not the record's: the
        // plot shows the record, and its features track the record itself.
        let spectrum = spectrum.filter(|_| corrected.is_none());
        let order = d.order.clone().filter(|_| corrected.is_none());
        let mut diagnosis =
            serde_json::to_value(&d).map_err(|e| crate::Error::Signal(e.to_string()))?;
        let mut wear = (
            d.wear_degree.estimate,
            d.wear_degree.lower,
            d.wear_degree.upper,
        );
        if let Some((cal, h)) = &held {
            let (c, warnings, refit) = self.calibration_json(cal, h, rec, &d, &opts)?;
            diagnosis["calibration"] = c;
            if let Some(w) = diagnosis["warnings"].as_array_mut() {
                w.extend(warnings.into_iter().map(Into::into));
            }
            // The alert level (and the stored wear) follow the refit when it holds an
            // element effect.
            if let Some(r) = refit {
                wear = (r.ea, r.ea_lower, r.ea_upper);
            }
        }
        Ok(Output {
            ea_estimate: wear.0,
            ea_lower: wear.1,
            ea_upper: wear.2,
            motion_state: d.motion_state.clone(),
            f1_hz: d.f1_hz,
            marks: d
                .lines
                .iter()
                .map(|l| (l.name.clone(), l.normalised_frequency))
                .collect(),
            features: json!({
                "lines": diagnosis["lines"],
                "condition_indicators": diagnosis["condition_indicators"],
                "f1_hz": d.f1_hz,
                "omega1": d.omega1,
            }),
            diagnosis,
            spectrum,
            order,
        })
    }

    fn calibrate(&self, input: &Input) -> crate::Result<serde_json::Value> {
        let opts = CalibrateOptions {
            diagnose: self.options(input),
            ..CalibrateOptions::default()
        };
        let report = calibrate(&input.record, &self.table, &opts)?;
        serde_json::to_value(&report).map_err(|e| crate::Error::Signal(e.to_string()))
    }

    fn table_id(&self) -> String {
        self.table.model_hash.clone()
    }
}
