//! A record read against the machine's own model: its own table, through its channel's path,
//! with the fit's uncertainty in the interval.

use super::MachinePhysics;
use crate::diagnosis::{DiagnoseOptions, Diagnosis, WithheldReason, diagnose_shifted};
use crate::error::Result;
use crate::record::Record;
use crate::signature::SignatureTable;

/// z of the two-sided 90 % interval.
const Z90: f64 = 1.6449;

impl MachinePhysics {
    /// Read `record` (measured by `channel`) against `table` — the table of the machine's own
    /// gearbox ([`MachinePhysics::gearbox`]) — from its `plain` diagnosis, which gives the
    /// speed: its features de-coloured by the channel's path, their variance raised by the
    /// path's scatter and the factors' uncertainty ([`MachinePhysics::shift_at`]), and the
    /// interval widened by the wear stages' common error factor's uncertainty
    /// ([`MachinePhysics::wear_scale_sigma`], in quadrature on `ln ea`). The figure is withheld
    /// (`poor-fit`) when the model is not predictive ([`MachinePhysics::predictive`]),
    /// (`outside-calibration`) at a speed the fit did not cover, and (`poor-fit`) where the
    /// machine's own model does not fit the record. `None` for a channel the fit did not see.
    pub fn reread(
        &self,
        record: &Record,
        channel: &str,
        table: &SignatureTable,
        opts: &DiagnoseOptions,
        plain: &Diagnosis,
    ) -> Result<Option<Diagnosis>> {
        if !self.channels.contains_key(channel) {
            return Ok(None);
        }
        if !self.predictive() {
            let mut d = plain.clone();
            d.withhold(
                WithheldReason::PoorFit,
                format!(
                    "no wear figure: the machine's own model misses its healthy records' lines at a \
                     left-out speed by {:.1} dB (RMS), more than the {:.1} dB it may: its physics \
                     are not this machine's, and a wear degree read against them would not be \
                     either",
                    self.left_out_db, self.predictive_limit_db
                ),
            );
            return Ok(Some(d));
        }
        if !self.covers(plain.f1_hz) {
            let mut d = plain.clone();
            d.withhold(
                WithheldReason::OutsideCalibration,
                format!(
                    "no wear figure: f1 = {:.1} Hz lies outside the speeds the machine's own \
                     model was fitted at ({:.1}–{:.1} Hz); healthy records at this speed extend it",
                    plain.f1_hz,
                    self.f1_hz[0],
                    self.f1_hz[self.f1_hz.len() - 1]
                ),
            );
            return Ok(Some(d));
        }
        let Some((shift, var)) = self.shift_at(channel, table, plain.f1_hz) else {
            return Ok(None);
        };
        let held = DiagnoseOptions {
            shaft_hz: Some(plain.shaft_hz),
            track_orders: false,
            ..opts.clone()
        };
        let mut d = diagnose_shifted(record, table, &held, &shift, &var)?;
        let wear_stages = table.gearbox().wear_stages();
        let s = Z90 * self.wear_scale_sigma(&wear_stages);
        let (lo_ea, hi_ea) = (table.grid.ea[0], table.grid.ea[table.grid.ea.len() - 1]);
        let w = &mut d.wear_degree;
        if s > 0.0 && w.estimate > 0.0 {
            let down = (w.estimate / w.lower.max(1e-9)).ln();
            let up = (w.upper.max(1e-9) / w.estimate).ln();
            w.lower = (w.estimate * (-(down.hypot(s))).exp()).max(lo_ea);
            w.upper = (w.estimate * up.hypot(s).exp()).min(hi_ea);
        }
        d.warnings.push(format!(
            "wear read against the machine's own model: its physics fitted to {} healthy \
             records (a left-out speed's lines to {:.1} dB, against {} for the description's \
             physics through a calibrated path)",
            self.records,
            self.left_out_db,
            self.yardstick_db
                .map_or("no figure".into(), |y| format!("{y:.1} dB"))
        ));
        if d.fit.inflated {
            let why = format!(
                "no wear figure: the machine's own model does not fit this record (χ² per \
                 feature {:.1} over {} features): a change the wear model does not make (local \
                 damage, a bearing, another path)",
                d.fit.chi2_per_feature, d.fit.features
            );
            d.withhold(WithheldReason::PoorFit, why);
        }
        Ok(Some(d))
    }
}
