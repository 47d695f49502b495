//! Steps 1–3 of [`calibrate`](super::calibrate): the diagnosis, the record's spectrum on the
//! normalised grid ([`Measured`]) and the plain model at the table's estimate fitted to it
//! ([`Before`]).

use super::effects::ElementParams;
use super::fit::{Weights, fit_sensor, sensor_model};
use super::simulator::Simulator;
use super::spectrum::{grid, log_spectrum};
use super::{CalibrateOptions, SensorFit, WearEstimate};
use crate::diagnosis::{Diagnosis, diagnose};
use crate::error::Result;
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signature::SignatureTable;

/// The record as the loop sees it: its diagnosis and its log spectrum `M_j` on the grid.
pub(super) struct Measured<'a> {
    pub record: &'a Record,
    pub table: &'a SignatureTable,
    pub opts: &'a CalibrateOptions,
    pub gb: &'a Gearbox,
    /// The ordinary diagnosis: f1, Ω1 and the table posterior of `ea`.
    pub diagnosis: Diagnosis,
    /// Stage-1 mesh frequency (Hz).
    pub f1: f64,
    /// Ω1, clamped to the table's band.
    pub omega1: f64,
    /// The record's sample rate (Hz).
    pub fs: f64,
    /// The normalised grid (`f/f1`, [`grid`]).
    pub r: Vec<f64>,
    /// The record's log spectrum on the grid (dB).
    pub m: Vec<f64>,
    /// J, the number of grid points.
    pub j_n: f64,
    /// The gearbox's planetary error baseline (units of b; 0 without a planetary stage).
    pub baseline_planetary: f64,
}

impl<'a> Measured<'a> {
    /// Diagnose `record` and measure its spectrum.
    pub(super) fn new(
        record: &'a Record,
        table: &'a SignatureTable,
        opts: &'a CalibrateOptions,
    ) -> Result<Measured<'a>> {
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
        Ok(Measured {
            record,
            table,
            opts,
            gb,
            diagnosis: d,
            f1,
            omega1,
            fs,
            r,
            m,
            j_n,
            baseline_planetary,
        })
    }

    /// Deviance of a score, the per-point scale profiled out, over the J grid points. (The null
    /// spread is measured in the same units, so the null part of the claim margin does not
    /// depend on how many of the points count as independent; `J_eff` from the plain model's
    /// residual is dominated by the very structure an effect would explain — a smooth
    /// colouring gives J_eff ≈ 10 — and is used for the wear interval only.)
    pub(super) fn deviance(&self, score: f64) -> f64 {
        self.j_n * (score / self.j_n).max(1e-300).ln()
    }

    /// `BIC = J ln(score/J) + k ln J` of a score with `k` fitted parameters.
    pub(super) fn bic(&self, score: f64, k: usize) -> f64 {
        self.deviance(score) + k as f64 * self.j_n.ln()
    }
}

/// Before: the plain model at the table's estimate (the diagnosis as it stands), its sensor
/// fitted by least squares.
pub(super) struct Before {
    /// The table posterior's estimate (`table-posterior`).
    pub wear: WearEstimate,
    /// The plain model at that estimate.
    pub params: ElementParams,
    pub sensor: SensorFit,
    /// Residual sum of squares (dB²) over the grid.
    pub rss: f64,
    /// The fitted spectrum `F_j` (dB).
    pub fitted: Vec<f64>,
}

impl Before {
    pub(super) fn fit(ms: &Measured, sim: &Simulator) -> Result<Before> {
        let d = &ms.diagnosis;
        let wear = WearEstimate {
            ea: d.wear_degree.estimate,
            ea_lower: d.wear_degree.lower,
            ea_upper: d.wear_degree.upper,
            planetary: ms.baseline_planetary,
            method: "table-posterior",
        };
        let unit = Weights::unit(ms.r.len());
        let params = ElementParams::plain(wear.ea, ms.baseline_planetary);
        let s0 = sim.spectrum(&params)?;
        let (sensor, rss) = fit_sensor(&ms.m, &s0, &ms.r, None, &unit);
        let fitted = sensor_model(&s0, &ms.r, &sensor);
        Ok(Before {
            wear,
            params,
            sensor,
            rss,
            fitted,
        })
    }

    /// RMS log-spectral distance before (dB).
    pub(super) fn error_db(&self, j_n: f64) -> f64 {
        (self.rss / j_n).sqrt()
    }
}
