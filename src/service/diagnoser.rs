//! The seam between the HTTP layer and the diagnosis core: the service holds an
//! `Arc<dyn Diagnoser>` built once at start-up (signature table loaded, matcher prepared) and
//! calls it from `spawn_blocking`.

use serde_json::Value;

/// A decoded record plus what the request said about it.
#[derive(Debug, Clone)]
pub struct Input {
    /// The samples and their rate (owned: the diagnosis reads them in place, no copy).
    pub record: crate::record::Record,
    pub shaft_hz: Option<f64>,
    pub sensor: Option<String>,
    /// The machine's stored calibration, if it has one: the diagnosis then uses it.
    pub calibration: Option<MachineCalibration>,
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

impl MachineCalibration {
    /// A stored calibration as the diagnoser holds it.
    pub fn from_row(c: &crate::store::CalibrationRow) -> Self {
        MachineCalibration {
            id: c.id.clone(),
            calibrated_at: crate::time::rfc3339(c.created_at),
            effects: serde_json::from_str(&c.effects).unwrap_or(Value::Array(vec![])),
        }
    }
}

/// What the service stores and answers for one diagnosis.
#[derive(Debug, Clone)]
pub struct Output {
    /// The same JSON as `gearwear diagnose`.
    pub diagnosis: Value,
    pub ea_estimate: f64,
    pub ea_lower: f64,
    pub ea_upper: f64,
    pub motion_state: String,
    pub f1_hz: f64,
    /// Named lines to mark on the spectrum: `(name, f / f1)`.
    pub marks: Vec<(String, f64)>,
    /// Features stored with the record (lines, condition indicators).
    pub features: Value,
    /// The record's Hann amplitude spectrum, when the diagnosis computed it for the samples as
    /// received (not for a calibration-corrected copy): the plot is drawn from it.
    pub spectrum: Option<crate::signal::Spectrum>,
    /// The diagnosis's order analysis of the samples as received (not of a
    /// calibration-corrected copy), tracked with the table's gearbox: the record's baseline
    /// features reuse it.
    pub order: Option<crate::novelty::OrderAnalysis>,
}

/// Diagnose one record. Errors are the library's, mapped to problem+json by the caller.
pub trait Diagnoser: Send + Sync + 'static {
    fn diagnose(&self, input: &Input) -> crate::Result<Output>;
    /// Close the loop on one record ([`crate::closed_loop::calibrate`]): the report JSON.
    fn calibrate(&self, input: &Input) -> crate::Result<Value>;
    /// Identity of the loaded table (its model hash), for `/readyz`.
    fn table_id(&self) -> String;
}
