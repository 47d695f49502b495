//! Wear read against the model **calibrated to a machine**: the signature table's simulated
//! line ratios seen through the machine's own transfer path, learnt from its healthy records.
//!
//! # Why
//! The table's features are gain-free ratios `y_ℓ = ln(A_ℓ / A_f1)` of the model's lines (at
//! `r_ℓ · f1`). A real sensor sees the gears through a path `H(f)` (housing, mounting,
//! amplifier) the lumped model does not contain, so a measured ratio is the model's plus the
//! path's colouring,
//!
//! ```text
//! y_ℓ = μ_ℓ(ea, Ω1) + P(r_ℓ f1) − P(f1),     P(f) = ln |H(f)|
//! ```
//!
//! and a healthy record already departs from the table by `P(r_ℓ f1) − P(f1)` — which is why
//! the table does not fit real records. Records of the healthy machine at several speeds sample
//! that difference at many frequencies (the lines move with the speed, the path does not).
//!
//! # Calibration ([`PathCalibration::fit`])
//! With the healthy machine taken at the table's **lowest wear** `ea₀` (clearance growth is read
//! from an unworn gearbox), each healthy record's residual `d_ℓ = y_ℓ − μ_ℓ(ea₀, Ω1)` is fitted
//! by a path `P` piecewise linear in `log10 Hz` ([`KNOTS_PER_DECADE`] knots a decade, second
//! differences penalised by `λ`), each residual weighted by the table's spread of that feature
//! there (the chaotic model's own scatter). Features at the clipping floor carry no path and are
//! left out. `λ` is chosen by leaving each speed out; the same left-out residuals give each
//! feature's calibration uncertainty `σ_ℓ` (their RMS).
//!
//! # Reading wear ([`PathCalibration::diagnose`])
//! The record is diagnosed once to find its f1; then again with each feature's path colouring
//! `P(r_ℓ f1) − P(f1)` subtracted and `σ_ℓ²` added to its variance
//! ([`super::diagnose_shifted`]): the table's posterior of a record seen through a known path,
//! with its credible interval, and no figure (`wear_note`) when even the de-coloured record does
//! not fit the model — a local fault or a bearing makes lines the wear model cannot.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::{DiagnoseOptions, Diagnosis, Matcher, diagnose, diagnose_shifted};
use crate::error::{Error, Result};
use crate::record::Record;
use crate::signature::SignatureTable;

/// Knots of the path per decade of frequency.
pub const KNOTS_PER_DECADE: f64 = 24.0;
/// Fewest healthy records (at two speeds or more) a calibration needs.
pub const MIN_RECORDS: usize = 4;
/// A feature within this much (ln units, ≈ 6 dB) of the clipping floor carries no path.
const FLOOR_MARGIN: f64 = 0.7;
/// Path smoothness weights tried.
const LAMBDAS: [f64; 5] = [0.1, 1.0, 10.0, 100.0, 1000.0];
/// Records within this relative f1 of each other are one speed.
const SAME_SPEED: f64 = 0.03;
/// Smallest calibration uncertainty of a feature (ln units).
const MIN_SIGMA: f64 = 0.05;

/// A machine's transfer path as the table's features see it (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PathCalibration {
    /// The healthy machine's wear degree (the table's lowest).
    pub healthy_ea: f64,
    pub records: usize,
    /// Speeds (f1, Hz) calibrated on.
    pub f1_hz: Vec<f64>,
    /// `log10 Hz` of the knots and the path there (dB).
    knots: Vec<f64>,
    path_db: Vec<f64>,
    /// The path's smoothness weight chosen.
    pub lambda: f64,
    /// Each feature's calibration uncertainty (ln units; table feature order).
    pub sigma: Vec<f64>,
    /// RMS of the healthy records' residuals (dB) before and after the path, left-out speeds.
    pub residual_before_db: f64,
    pub residual_after_db: f64,
}

/// One healthy residual: feature `k` of a record at speed group `g`, its line at `log10 Hz`
/// `x`, f1 at `x1`, the residual `d` (ln) and its weight.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Residual {
    pub(crate) k: usize,
    pub(crate) g: usize,
    pub(crate) x: f64,
    pub(crate) x1: f64,
    pub(crate) d: f64,
    pub(crate) w: f64,
}

/// A smooth curve over `log10 Hz` (ln units), [`KNOTS_PER_DECADE`] knots a decade from `lo`.
#[derive(Debug, Clone)]
pub(crate) struct Path {
    pub(crate) lo: f64,
    pub(crate) values: Vec<f64>,
}

impl Path {
    fn terms(&self, x: f64) -> [(usize, f64); 2] {
        let n = self.values.len();
        let t = ((x - self.lo) * KNOTS_PER_DECADE).clamp(0.0, (n - 1) as f64);
        let j = (t.floor() as usize).min(n.saturating_sub(2));
        let w = (t - j as f64).clamp(0.0, 1.0);
        [(j, 1.0 - w), ((j + 1).min(n - 1), w)]
    }

    pub(crate) fn at(&self, x: f64) -> f64 {
        self.terms(x).iter().map(|&(j, w)| w * self.values[j]).sum()
    }

    /// Fit `P(x) − P(x1) ≈ d` over `rs` (weighted), smoothness `lambda`.
    pub(crate) fn fit(rs: &[&Residual], lo: f64, hi: f64, lambda: f64) -> Option<Path> {
        let n = (((hi - lo) * KNOTS_PER_DECADE).ceil() as usize + 1).max(2);
        let mut p = Path {
            lo,
            values: vec![0.0; n],
        };
        let mut a = DMatrix::<f64>::zeros(n, n);
        let mut b = DVector::<f64>::zeros(n);
        for r in rs {
            let mut row: Vec<(usize, f64)> = p.terms(r.x).to_vec();
            row.extend(p.terms(r.x1).iter().map(|&(j, w)| (j, -w)));
            for &(i, wi) in &row {
                b[i] += r.w * wi * r.d;
                for &(j, wj) in &row {
                    a[(i, j)] += r.w * wi * wj;
                }
            }
        }
        for j in 1..n.saturating_sub(1) {
            let d = [(j - 1, 1.0), (j, -2.0), (j + 1, 1.0)];
            for &(i, wi) in &d {
                for &(k, wk) in &d {
                    a[(i, k)] += lambda * wi * wk;
                }
            }
        }
        for i in 0..n {
            a[(i, i)] += 1e-6;
        }
        p.values = a.cholesky()?.solve(&b).iter().copied().collect();
        Some(p)
    }
}

fn rms_of(e: &[f64]) -> f64 {
    (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt()
}

/// A fitted path: its `λ`, the left-out errors `(feature, ln)` and the path on all records.
struct Fitted {
    lambda: f64,
    errors: Vec<(usize, f64)>,
    path: Path,
}

/// The path fitted to `rs` (speeds `0..groups`) at the `λ` of [`LAMBDAS`] that predicts a
/// left-out speed best, with those left-out errors.
fn calibrate(rs: &[Residual], groups: usize) -> Result<Fitted> {
    let lo = rs
        .iter()
        .map(|r| r.x.min(r.x1))
        .fold(f64::INFINITY, f64::min);
    let hi = rs
        .iter()
        .map(|r| r.x.max(r.x1))
        .fold(f64::NEG_INFINITY, f64::max);
    let left_out = |lambda: f64| -> Vec<(usize, f64)> {
        let mut out = Vec::new();
        for g in 0..groups {
            let train: Vec<&Residual> = rs.iter().filter(|r| r.g != g).collect();
            let Some(p) = Path::fit(&train, lo, hi, lambda) else {
                continue;
            };
            out.extend(
                rs.iter()
                    .filter(|r| r.g == g)
                    .map(|r| (r.k, r.d - (p.at(r.x) - p.at(r.x1)))),
            );
        }
        out
    };
    let score = |e: &[(usize, f64)]| rms_of(&e.iter().map(|x| x.1).collect::<Vec<_>>());
    let (lambda, errors) = LAMBDAS
        .iter()
        .map(|&l| (l, left_out(l)))
        .min_by(|a, b| score(&a.1).total_cmp(&score(&b.1)))
        .expect("LAMBDAS is not empty");
    let all: Vec<&Residual> = rs.iter().collect();
    let path = Path::fit(&all, lo, hi, lambda).ok_or(Error::BaselineUnrepeatable)?;
    Ok(Fitted {
        lambda,
        errors,
        path,
    })
}

/// What a calibration reads of a healthy record's plain diagnosis: its speed and its lines'
/// levels re f1, in the table's line order — kept with the record's features, so that a
/// stored baseline can be calibrated without diagnosing it again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineRatios {
    pub f1_hz: f64,
    pub omega1: f64,
    /// `[frequency over f1, 20 log10(A / A_f1)]` of every line but f1.
    pub lines: Vec<[f64; 2]>,
}

impl LineRatios {
    /// The ratios of a plain diagnosis.
    pub fn of(d: &Diagnosis) -> LineRatios {
        LineRatios {
            f1_hz: d.f1_hz,
            omega1: d.omega1,
            lines: d
                .lines
                .iter()
                .filter(|l| l.name != "f1")
                .map(|l| [l.normalised_frequency, l.level_db])
                .collect(),
        }
    }

    /// The measured unclipped features `(ratio, ln)` (the power fraction is left out: it is
    /// not a line ratio).
    fn features(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.lines
            .iter()
            .map(|[r, db]| (*r, db * std::f64::consts::LN_10 / 20.0))
    }
}

impl PathCalibration {
    /// Calibrate from the diagnoses of the machine's healthy records (see the
    /// [module docs](self)).
    ///
    /// Errors: fewer than [`MIN_RECORDS`] records or fewer than two speeds; a diagnosis made
    /// with another table's lines; a path that predicts a left-out speed no better than the
    /// plain model ([`Error::PathNoBetter`]).
    pub fn fit(
        table: &SignatureTable,
        opts: &DiagnoseOptions,
        healthy: &[LineRatios],
    ) -> Result<PathCalibration> {
        let matcher = Matcher::new(table, opts)?;
        let healthy_ea = table.grid.ea[0];
        let floor = opts.floor_db * std::f64::consts::LN_10 / 20.0;
        let nf = table.features.names.len();
        let mut f1s: Vec<f64> = healthy.iter().map(|d| d.f1_hz).collect();
        f1s.sort_by(f64::total_cmp);
        let mut centres: Vec<f64> = Vec::new();
        for &f in &f1s {
            if centres.last().is_none_or(|&c| f / c - 1.0 > SAME_SPEED) {
                centres.push(f);
            }
        }
        if healthy.len() < MIN_RECORDS || centres.len() < 2 {
            return Err(Error::BaselineTooSmall {
                records: healthy.len().min(centres.len()),
                needed: MIN_RECORDS,
            });
        }
        let group = |f: f64| {
            centres
                .iter()
                .rposition(|&c| f >= c * (1.0 - 1e-9))
                .unwrap_or(0)
        };
        let mut rs = Vec::new();
        for d in healthy {
            if d.lines.len() + 1 != nf {
                return Err(Error::LengthMismatch {
                    what: "a healthy record's lines",
                    expected: nf - 1,
                    found: d.lines.len(),
                });
            }
            for (k, (ratio, y)) in d.features().enumerate() {
                let (m, v) = matcher.stats_at(k, healthy_ea, d.omega1);
                if m <= floor + FLOOR_MARGIN || y <= floor + FLOOR_MARGIN {
                    continue;
                }
                rs.push(Residual {
                    k,
                    g: group(d.f1_hz),
                    x: (ratio * d.f1_hz).log10(),
                    x1: d.f1_hz.log10(),
                    d: y - m,
                    w: 1.0 / (v + opts.feature_sigma * opts.feature_sigma),
                });
            }
        }
        let Fitted {
            lambda,
            errors,
            path,
        } = calibrate(&rs, centres.len())?;
        let mut sigma = vec![MIN_SIGMA; nf];
        for (k, s) in sigma.iter_mut().enumerate() {
            let e: Vec<f64> = errors
                .iter()
                .filter(|x| x.0 == k)
                .map(|x| x.1 * x.1)
                .collect();
            if !e.is_empty() {
                *s = (e.iter().sum::<f64>() / e.len() as f64)
                    .sqrt()
                    .max(MIN_SIGMA);
            }
        }
        let db = 20.0 / std::f64::consts::LN_10;
        let before: Vec<f64> = rs.iter().map(|r| r.d).collect();
        let after: Vec<f64> = errors.iter().map(|x| x.1).collect();
        let (path_db, plain_db) = (rms_of(&after) * db, rms_of(&before) * db);
        if path_db >= plain_db {
            return Err(Error::PathNoBetter { path_db, plain_db });
        }
        Ok(PathCalibration {
            healthy_ea,
            records: healthy.len(),
            f1_hz: centres,
            knots: (0..path.values.len())
                .map(|j| path.lo + j as f64 / KNOTS_PER_DECADE)
                .collect(),
            path_db: path.values.iter().map(|v| v * db).collect(),
            lambda,
            sigma,
            residual_before_db: plain_db,
            residual_after_db: path_db,
        })
    }

    /// The path's colouring of each feature at `f1` (ln units, table feature order; 0 for
    /// the power fraction) and its variance.
    pub fn shift_at(&self, table: &SignatureTable, f1_hz: f64) -> (Vec<f64>, Vec<f64>) {
        let path = Path {
            lo: self.knots.first().copied().unwrap_or(0.0),
            values: self
                .path_db
                .iter()
                .map(|v| v * std::f64::consts::LN_10 / 20.0)
                .collect(),
        };
        let x1 = f1_hz.log10();
        let mut shift: Vec<f64> = table
            .features
            .lines
            .iter()
            .filter(|l| l.name != "f1")
            .map(|l| path.at((l.ratio * f1_hz).log10()) - path.at(x1))
            .collect();
        shift.push(0.0);
        let var = self.sigma.iter().map(|s| s * s).collect();
        (shift, var)
    }

    /// Whether `f1` lies within the calibrated speeds (± 3 %).
    pub fn covers(&self, f1_hz: f64) -> bool {
        let lo = self.f1_hz.first().copied().unwrap_or(f64::NAN);
        let hi = self.f1_hz.last().copied().unwrap_or(f64::NAN);
        f1_hz >= lo * (1.0 - SAME_SPEED) && f1_hz <= hi * (1.0 + SAME_SPEED)
    }

    /// Diagnose `record` through the calibrated path (see the [module docs](self)); a speed
    /// outside the calibrated ones keeps the plain diagnosis with a warning.
    pub fn diagnose(
        &self,
        record: &Record,
        table: &SignatureTable,
        opts: &DiagnoseOptions,
    ) -> Result<Diagnosis> {
        let mut plain = diagnose(record, table, opts)?;
        match self.reread(record, table, opts, &plain)? {
            Some(d) => Ok(d),
            None => {
                plain.warnings.push(self.outside(plain.f1_hz));
                Ok(plain)
            }
        }
    }

    /// Why a record at `f1_hz` is read against the plain model.
    pub fn outside(&self, f1_hz: f64) -> String {
        format!(
            "f1 = {f1_hz:.1} Hz lies outside the speeds the machine's transfer path was \
             calibrated at ({:.1}–{:.1} Hz): read against the plain model",
            self.f1_hz[0],
            self.f1_hz[self.f1_hz.len() - 1]
        )
    }

    /// `record` read through the calibrated path, from its `plain` diagnosis (which gives the
    /// speed); `None` outside the calibrated speeds.
    pub fn reread(
        &self,
        record: &Record,
        table: &SignatureTable,
        opts: &DiagnoseOptions,
        plain: &Diagnosis,
    ) -> Result<Option<Diagnosis>> {
        if !self.covers(plain.f1_hz) {
            return Ok(None);
        }
        let (shift, var) = self.shift_at(table, plain.f1_hz);
        let held = DiagnoseOptions {
            shaft_hz: Some(plain.shaft_hz),
            ..opts.clone()
        };
        let mut d = diagnose_shifted(record, table, &held, &shift, &var)?;
        d.warnings.push(format!(
            "wear read through the machine's transfer path calibrated on its {} healthy records \
             (left-out residual {:.1} dB against {:.1} dB for the plain model)",
            self.records, self.residual_after_db, self.residual_before_db
        ));
        if d.fit.inflated {
            let why = format!(
                "no wear figure: the model seen through the machine's calibrated path does not \
                 fit this record (χ² per feature {:.1} over {} features): a change the wear \
                 model does not make (local damage, a bearing, another path)",
                d.fit.chi2_per_feature, d.fit.features
            );
            d.withhold(super::WithheldReason::PoorFit, why);
        }
        Ok(Some(d))
    }

    /// The path (Hz, dB relative to its own level) at its knots.
    pub fn path(&self) -> Vec<[f64; 2]> {
        self.knots
            .iter()
            .zip(&self.path_db)
            .map(|(x, p)| [10f64.powf(*x), *p])
            .collect()
    }
}
