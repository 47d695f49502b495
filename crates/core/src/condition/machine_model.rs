//! A machine's healthy line levels as a model **calibrated to that machine**: the gearbox's
//! kinematic sources seen through a transfer path smooth in frequency, fitted to the healthy
//! baseline's records at all their states at once, so that it predicts a healthy record at a
//! speed the baseline does not hold.
//!
//! # The model
//! Every marked line `i` of a channel ([`super::plot`]: a mesh harmonic, a sideband at ±1 or ±2
//! × a shaft's rate around one, a shaft's 1× or 2×), at input-shaft order `o_i`, of a record at
//! measured input rate `f` (Hz) and load `ℓ`, has the level (dB re 1 unit)
//!
//! ```text
//! L_i(f, ℓ) = a_i + P(log10(o_i · f)) + γ_c(i) · log10(f / f_ref) + g_ℓ,c(i)
//! ```
//!
//! - `a_i`: the line's source at the reference speed — a mesh harmonic's transmission-error
//!   amplitude, a sideband's modulation depth, a shaft's imbalance or misalignment;
//! - `P`: the transfer path from the gears to the sensor (housing, mounting, amplifier gain) as
//!   one curve over **frequency in Hz** shared by every line — piecewise linear in `log10 Hz`,
//!   knots every [`KNOTS_PER_DECADE`]⁻¹ decade, its second differences penalised by `λ`. A
//!   line's order is fixed and its frequency moves with the speed, so records at several
//!   speeds sample the path at many frequencies: that is what calibrates it;
//! - `γ_c` (dB per decade of speed) how a family's sources grow with speed against the mesh
//!   lines' (`γ_mesh = 0`: the path's slope carries the common part); `g_ℓ,c` a load's offset
//!   per family (`0` at the first load).
//!
//! The fit is linear least squares on every baseline line of every record at once. `λ` is
//! chosen by leaving out each baseline **speed** (every record within [`SAME_SPEED`] of it, all
//! loads) and predicting its lines from the rest; the same errors give each family's
//! prediction uncertainty `σ_c` (their RMS, at least [`MIN_SIGMA_DB`]).
//!
//! # Refusal
//! The same leave-one-speed-out prediction is made by a **smooth curve with no kinematics**
//! (each family's level a smooth curve of the line's frequency in Hz, plus the load's offset).
//! A calibration whose median error on the mesh harmonics and sidebands is not below that
//! curve's is refused, with both figures: it has learnt nothing the gearbox explains.
//!
//! # Use
//! [`MachineModel::shift`] gives how each evidence feature fed by the marked lines changes
//! between two states (ln units): a state-aware baseline transports its nearest healthy
//! record to an uncovered state with it ([`super::baseline`], reference `model`).

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::marked::Line;
use super::state::{Load, OperatingState};

/// Knots of the path per decade of frequency.
pub const KNOTS_PER_DECADE: f64 = 32.0;
/// Records within this relative speed of each other are one speed (left out together).
pub const SAME_SPEED: f64 = 0.03;
/// Fewest distinct baseline speeds a calibration needs (one left out, two left to fit).
pub const MIN_SPEEDS: usize = 3;
/// Smallest prediction uncertainty of a line (dB).
pub const MIN_SIGMA_DB: f64 = 1.0;
/// A line takes part when at least this many baseline records hold it.
const MIN_LINE_RECORDS: usize = 3;
/// Levels at or below this are empty bins, not lines (dB).
const EMPTY_DB: f64 = -190.0;
/// Path smoothness weights tried.
const LAMBDAS: [f64; 6] = [0.1, 0.3, 1.0, 3.0, 10.0, 30.0];
/// Ridge on every parameter: fixes the constant shared by the sources and the path.
const RIDGE: f64 = 1e-6;
/// A state inside the calibrated range may lie this far (relative) beyond its extreme speeds.
const RANGE_MARGIN: f64 = 0.03;

/// What kind of marked line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LineKind {
    Mesh,
    Sideband,
    Shaft,
}

impl LineKind {
    pub const ALL: [LineKind; 3] = [LineKind::Mesh, LineKind::Sideband, LineKind::Shaft];

    fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            LineKind::Mesh => "mesh",
            LineKind::Sideband => "sideband",
            LineKind::Shaft => "shaft",
        }
    }
}

/// One marked line's level in a record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineLevel {
    /// Input-shaft orders.
    pub order: f64,
    pub kind: LineKind,
    /// The evidence feature it feeds.
    pub feature: String,
    /// dB re 1 unit of the record's samples.
    pub level_db: f64,
}

impl LineLevel {
    /// A plotted line's level (mesh, sideband and shaft lines with a level).
    pub(super) fn of(l: &Line) -> Option<LineLevel> {
        let kind = match l.kind {
            "mesh" => LineKind::Mesh,
            "sideband" => LineKind::Sideband,
            "shaft" => LineKind::Shaft,
            _ => return None,
        };
        (l.level_db > EMPTY_DB).then(|| LineLevel {
            order: l.order,
            kind,
            feature: l.feature.clone(),
            level_db: l.level_db,
        })
    }

    fn key(&self) -> LineKey {
        (self.kind, (self.order * 1e6).round() as i64)
    }
}

/// A line's identity across records: its kind and its order (µ-orders).
type LineKey = (LineKind, i64);

/// One baseline record as the calibration reads it.
#[derive(Debug, Clone, Copy)]
pub struct Observed<'a> {
    pub state: &'a OperatingState,
    pub lines: &'a [LineLevel],
}

/// A line's predicted healthy level.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Predicted {
    pub order: f64,
    pub kind: LineKind,
    pub feature: String,
    pub level_db: f64,
    /// One standard deviation of the prediction (dB).
    pub sigma_db: f64,
}

/// A feature's predicted change between two states and its uncertainty (ln units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shift {
    pub change: f64,
    pub sigma: f64,
}

/// Median absolute error (dB) per family; `None` where a family had no line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct FamilyErrors {
    pub mesh_db: Option<f64>,
    pub sideband_db: Option<f64>,
    pub shaft_db: Option<f64>,
    /// Mesh harmonics and sidebands together: what the refusal compares.
    pub mesh_and_sideband_db: Option<f64>,
}

impl FamilyErrors {
    fn of(errors: &[(LineKind, f64)]) -> FamilyErrors {
        let med = |f: &dyn Fn(LineKind) -> bool| {
            median(
                errors
                    .iter()
                    .filter(|(k, _)| f(*k))
                    .map(|(_, e)| e.abs())
                    .collect(),
            )
        };
        FamilyErrors {
            mesh_db: med(&|k| k == LineKind::Mesh),
            sideband_db: med(&|k| k == LineKind::Sideband),
            shaft_db: med(&|k| k == LineKind::Shaft),
            mesh_and_sideband_db: med(&|k| k != LineKind::Shaft),
        }
    }
}

/// The fit at one baseline record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StateFit {
    pub shaft_hz: f64,
    pub load: Option<Load>,
    /// In-sample error (the record took part in the fit).
    pub fit: FamilyErrors,
    /// Error when its speed was left out of the fit.
    pub left_out: FamilyErrors,
    /// The smooth curve's error when its speed was left out.
    pub smooth_left_out: FamilyErrors,
}

/// How a calibration went, for people and for the refusal.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationReport {
    pub records: usize,
    pub lines: usize,
    /// Distinct speeds (Hz) and loads calibrated on.
    pub speeds_hz: Vec<f64>,
    pub loads: Vec<Option<Load>>,
    pub states: Vec<StateFit>,
    /// Leave-one-speed-out, every record: the calibrated model and the smooth curve.
    pub left_out: FamilyErrors,
    pub smooth_left_out: FamilyErrors,
    /// The path's smoothness weight chosen.
    pub lambda: f64,
    /// Prediction uncertainty per family (dB, one σ): mesh, sideband, shaft.
    pub sigma_db: [f64; 3],
    /// How the sidebands' and the shaft lines' sources grow with speed against the mesh
    /// harmonics' (dB per decade).
    pub speed_growth_db_per_decade: [f64; 3],
    /// Each load's mean offset of its sources per family (dB; the first load 0).
    pub load_offsets_db: Vec<[f64; 3]>,
    /// The transfer path (relative dB) at its knots (Hz).
    pub path: Vec<[f64; 2]>,
}

/// A machine's calibrated model (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct MachineModel {
    fit: Fitted,
    lines: Vec<(LineKey, f64, String)>,
    /// Speed range (Hz) per load.
    ranges: Vec<(Option<Load>, f64, f64)>,
    pub report: CalibrationReport,
}

/// Why a machine could not be calibrated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refused {
    #[error(
        "a calibration needs healthy records with line levels at {needed} speeds or more; the baseline has {speeds}"
    )]
    TooFewSpeeds { speeds: usize, needed: usize },
    #[error(
        "the calibrated model predicts a left-out speed's mesh harmonics and sidebands no better than a smooth curve of level over frequency ({model_db:.2} dB against {smooth_db:.2} dB median error): it is not used"
    )]
    NoBetterThanSmooth { model_db: f64, smooth_db: f64 },
}

/// Which structure a fit has.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Structure {
    /// The model of the module docs.
    Kinematic,
    /// A smooth curve of frequency per family, plus the load's offsets.
    Smooth,
}

/// One fitted structure: its parameters and how to read them.
#[derive(Debug, Clone, PartialEq)]
struct Fitted {
    structure: Structure,
    /// Source index of each line at each load (kinematic only).
    index: BTreeMap<(LineKey, usize), usize>,
    knots: Vec<f64>,
    loads: Vec<Option<Load>>,
    f_ref: f64,
    theta: Vec<f64>,
    lambda: f64,
}

/// One observation: a line at a record.
#[derive(Debug, Clone)]
struct Obs {
    key: LineKey,
    log_hz: f64,
    log_speed: f64,
    load: Option<Load>,
    level_db: f64,
    /// Index of its speed group and of its record.
    group: usize,
    record: usize,
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    (!v.is_empty()).then(|| crate::signal::median(&mut v))
}

fn same_load(a: &Option<Load>, b: &Option<Load>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => a.same(b),
        (None, None) => true,
        _ => false,
    }
}

/// Speed groups: each record's index of its speed (records within [`SAME_SPEED`] share one).
fn speed_groups(speeds: &[f64]) -> (Vec<usize>, Vec<f64>) {
    let mut order: Vec<usize> = (0..speeds.len()).collect();
    order.sort_by(|&a, &b| speeds[a].total_cmp(&speeds[b]));
    let mut group = vec![0; speeds.len()];
    let mut centres: Vec<f64> = Vec::new();
    for i in order {
        match centres.last() {
            Some(&c) if speeds[i] / c - 1.0 <= SAME_SPEED => {}
            _ => centres.push(speeds[i]),
        }
        group[i] = centres.len() - 1;
    }
    (group, centres)
}

impl Fitted {
    fn n_knots(&self) -> usize {
        self.knots.len()
    }

    fn n_lines(&self) -> usize {
        self.index.len()
    }

    /// Parameter blocks: kinematic `[a_i | P | γ_sideband, γ_shaft | g]`, smooth
    /// `[P_mesh | P_sideband | P_shaft | g]`.
    fn n_params(&self) -> usize {
        let g = 3 * self.loads.len().saturating_sub(1);
        match self.structure {
            Structure::Kinematic => self.n_lines() + self.n_knots() + 2,
            Structure::Smooth => 3 * self.n_knots() + g,
        }
    }

    /// The path's two knots and weights at `log10 Hz` (held flat beyond the ends).
    fn path_terms(&self, x: f64) -> [(usize, f64); 2] {
        let k = &self.knots;
        let step = 1.0 / KNOTS_PER_DECADE;
        let t = ((x - k[0]) / step).clamp(0.0, (k.len() - 1) as f64);
        let j = (t.floor() as usize).min(k.len().saturating_sub(2));
        let w = (t - j as f64).clamp(0.0, 1.0);
        [(j, 1.0 - w), ((j + 1).min(k.len() - 1), w)]
    }

    /// The design row of a line of kind `kind` at `log10 Hz` `x`, `log10` speed `s`, load
    /// index `l`; `None` when the kinematic fit does not know the line.
    fn row(&self, key: LineKey, x: f64, s: f64, l: usize) -> Option<Vec<(usize, f64)>> {
        let c = key.0.index();
        let mut r = Vec::with_capacity(6);
        let (path0, g0) = match self.structure {
            Structure::Kinematic => {
                r.push((*self.index.get(&(key, l))?, 1.0));
                let p0 = self.n_lines();
                let gam = p0 + self.n_knots();
                if c > 0 {
                    r.push((gam + c - 1, s - self.f_ref.log10()));
                }
                (p0, None)
            }
            Structure::Smooth => (c * self.n_knots(), Some(3 * self.n_knots())),
        };
        for (j, w) in self.path_terms(x) {
            r.push((path0 + j, w));
        }
        if let Some(g0) = g0.filter(|_| l > 0) {
            r.push((g0 + 3 * (l - 1) + c, 1.0));
        }
        Some(r)
    }

    fn load_index(&self, load: &Option<Load>) -> Option<usize> {
        self.loads.iter().position(|l| same_load(l, load))
    }

    fn predict(&self, key: LineKey, order: f64, speed: f64, load: &Option<Load>) -> Option<f64> {
        let l = self.load_index(load)?;
        let row = self.row(key, (order * speed).log10(), speed.log10(), l)?;
        Some(row.iter().map(|&(j, w)| w * self.theta[j]).sum())
    }

    /// Fit `structure` with smoothness `lambda` to `obs`.
    fn fit(structure: Structure, obs: &[&Obs], lambda: f64) -> Option<Fitted> {
        let lo = obs.iter().map(|o| o.log_hz).fold(f64::INFINITY, f64::min);
        let hi = obs
            .iter()
            .map(|o| o.log_hz)
            .fold(f64::NEG_INFINITY, f64::max);
        if !(lo.is_finite() && hi.is_finite()) {
            return None;
        }
        let n_knots = (((hi - lo) * KNOTS_PER_DECADE).ceil() as usize + 1).max(2);
        let knots = (0..n_knots)
            .map(|j| lo + j as f64 / KNOTS_PER_DECADE)
            .collect();
        let mut loads: Vec<Option<Load>> = Vec::new();
        for o in obs {
            if !loads.iter().any(|l| same_load(l, &o.load)) {
                loads.push(o.load.clone());
            }
        }
        let mut index = BTreeMap::new();
        if structure == Structure::Kinematic {
            for o in obs {
                let l = loads.iter().position(|l| same_load(l, &o.load))?;
                let n = index.len();
                index.entry((o.key, l)).or_insert(n);
            }
        }
        let speeds: Vec<f64> = obs.iter().map(|o| o.log_speed).collect();
        let f_ref = 10f64.powf(speeds.iter().sum::<f64>() / speeds.len() as f64);
        let mut f = Fitted {
            structure,
            index,
            knots,
            loads,
            f_ref,
            theta: Vec::new(),
            lambda,
        };
        let n = f.n_params();
        let mut a = DMatrix::<f64>::zeros(n, n);
        let mut b = DVector::<f64>::zeros(n);
        for o in obs {
            let l = f.load_index(&o.load)?;
            let row = f.row(o.key, o.log_hz, o.log_speed, l)?;
            for &(i, wi) in &row {
                b[i] += wi * o.level_db;
                for &(j, wj) in &row {
                    a[(i, j)] += wi * wj;
                }
            }
        }
        let paths: Vec<usize> = match structure {
            Structure::Kinematic => vec![f.n_lines()],
            Structure::Smooth => (0..3).map(|c| c * n_knots).collect(),
        };
        for p0 in paths {
            for j in 1..n_knots.saturating_sub(1) {
                let d = [(p0 + j - 1, 1.0), (p0 + j, -2.0), (p0 + j + 1, 1.0)];
                for &(i, wi) in &d {
                    for &(k, wk) in &d {
                        a[(i, k)] += lambda * wi * wk;
                    }
                }
            }
        }
        for i in 0..n {
            a[(i, i)] += RIDGE;
        }
        f.theta = a.cholesky()?.solve(&b).iter().copied().collect();
        Some(f)
    }
}

/// Observations of the records' lines that at least [`MIN_LINE_RECORDS`] records hold.
fn observations(records: &[Observed], group: &[usize]) -> Vec<Obs> {
    let mut count: BTreeMap<LineKey, usize> = BTreeMap::new();
    for r in records {
        for l in r.lines.iter().filter(|l| l.level_db > EMPTY_DB) {
            *count.entry(l.key()).or_default() += 1;
        }
    }
    let mut obs = Vec::new();
    for (ri, (r, &g)) in records.iter().zip(group).enumerate() {
        let f = r.state.shaft_hz;
        for l in r.lines {
            if l.level_db > EMPTY_DB
                && l.order > 0.0
                && count.get(&l.key()).is_some_and(|&n| n >= MIN_LINE_RECORDS)
            {
                obs.push(Obs {
                    key: l.key(),
                    log_hz: (l.order * f).log10(),
                    log_speed: f.log10(),
                    load: r.state.load.clone(),
                    level_db: l.level_db,
                    group: g,
                    record: ri,
                });
            }
        }
    }
    obs
}

/// Leave-one-speed-out errors of `structure` at `lambda`, each observation's `(index, error)`.
fn left_out_errors(
    structure: Structure,
    obs: &[Obs],
    groups: usize,
    lambda: f64,
) -> Vec<(usize, f64)> {
    let mut out = Vec::new();
    for g in 0..groups {
        let train: Vec<&Obs> = obs.iter().filter(|o| o.group != g).collect();
        let Some(fit) = Fitted::fit(structure, &train, lambda) else {
            continue;
        };
        for (i, o) in obs.iter().enumerate().filter(|(_, o)| o.group == g) {
            let order = 10f64.powf(o.log_hz - o.log_speed);
            if let Some(p) = fit.predict(o.key, order, 10f64.powf(o.log_speed), &o.load) {
                out.push((i, o.level_db - p));
            }
        }
    }
    out
}

/// The `λ` of [`LAMBDAS`] with the smallest median left-out error on mesh harmonics and
/// sidebands, and its errors.
fn choose_lambda(structure: Structure, obs: &[Obs], groups: usize) -> (f64, Vec<(usize, f64)>) {
    let score = |e: &[(usize, f64)]| {
        median(
            e.iter()
                .filter(|(i, _)| obs[*i].key.0 != LineKind::Shaft)
                .map(|(_, v)| v.abs())
                .collect(),
        )
        .unwrap_or(f64::INFINITY)
    };
    LAMBDAS
        .iter()
        .map(|&l| (l, left_out_errors(structure, obs, groups, l)))
        .min_by(|a, b| score(&a.1).total_cmp(&score(&b.1)))
        .expect("LAMBDAS is not empty")
}

impl MachineModel {
    /// Calibrate from healthy records with their states and line levels (see the
    /// [module docs](self)).
    ///
    /// Errors: fewer than [`MIN_SPEEDS`] speeds with lines; a model no better than the smooth
    /// curve.
    pub fn fit(records: &[Observed]) -> Result<MachineModel, Refused> {
        let records: Vec<Observed> = records
            .iter()
            .filter(|r| !r.lines.is_empty() && r.state.shaft_hz > 0.0)
            .copied()
            .collect();
        let speeds: Vec<f64> = records.iter().map(|r| r.state.shaft_hz).collect();
        let (group, centres) = speed_groups(&speeds);
        let too_few = Refused::TooFewSpeeds {
            speeds: centres.len(),
            needed: MIN_SPEEDS,
        };
        if centres.len() < MIN_SPEEDS {
            return Err(too_few);
        }
        let obs = observations(&records, &group);
        let (lambda, errors) = choose_lambda(Structure::Kinematic, &obs, centres.len());
        let (_, smooth_errors) = choose_lambda(Structure::Smooth, &obs, centres.len());
        let all: Vec<&Obs> = obs.iter().collect();
        let fit = Fitted::fit(Structure::Kinematic, &all, lambda).ok_or(too_few)?;
        let kinds = |e: &[(usize, f64)]| -> Vec<(LineKind, f64)> {
            e.iter().map(|&(i, v)| (obs[i].key.0, v)).collect()
        };
        let mut sigma = [MIN_SIGMA_DB; 3];
        for k in LineKind::ALL {
            let v: Vec<f64> = errors
                .iter()
                .filter(|(i, _)| obs[*i].key.0 == k)
                .map(|(_, e)| e * e)
                .collect();
            if !v.is_empty() {
                sigma[k.index()] = (v.iter().sum::<f64>() / v.len() as f64)
                    .sqrt()
                    .max(MIN_SIGMA_DB);
            }
        }
        let left_out = FamilyErrors::of(&kinds(&errors));
        let smooth_left_out = FamilyErrors::of(&kinds(&smooth_errors));
        let states = state_fits(&records, &obs, &fit, &errors, &smooth_errors);
        let mut lines: Vec<(LineKey, f64, String)> = Vec::new();
        for r in &records {
            for l in r.lines {
                let known = fit.index.keys().any(|(k, _)| *k == l.key());
                if known && !lines.iter().any(|x| x.0 == l.key()) {
                    lines.push((l.key(), l.order, l.feature.clone()));
                }
            }
        }
        let ranges = fit
            .loads
            .iter()
            .map(|l| {
                let s: Vec<f64> = records
                    .iter()
                    .filter(|r| same_load(&r.state.load, l))
                    .map(|r| r.state.shaft_hz)
                    .collect();
                let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                (l.clone(), lo, hi)
            })
            .collect();
        let report = report(
            &records,
            &fit,
            &centres,
            states,
            left_out,
            smooth_left_out,
            sigma,
        );
        let model = MachineModel {
            fit,
            lines,
            ranges,
            report,
        };
        match (
            left_out.mesh_and_sideband_db,
            smooth_left_out.mesh_and_sideband_db,
        ) {
            (Some(m), Some(s)) if m >= s => Err(Refused::NoBetterThanSmooth {
                model_db: m,
                smooth_db: s,
            }),
            _ => Ok(model),
        }
    }

    /// Whether `state` lies inside the calibrated range: a calibrated load (or no load on
    /// either side), a speed within that load's calibrated speeds.
    pub fn covers(&self, state: &OperatingState) -> bool {
        let f = state.shaft_hz;
        self.ranges.iter().any(|(l, lo, hi)| {
            same_load(l, &state.load)
                && f >= lo * (1.0 - RANGE_MARGIN)
                && f <= hi * (1.0 + RANGE_MARGIN)
        })
    }

    /// Every calibrated line's healthy level at `state` (empty outside the calibrated loads).
    pub fn predict(&self, state: &OperatingState) -> Vec<Predicted> {
        self.lines
            .iter()
            .filter_map(|(key, order, feature)| {
                let level = self
                    .fit
                    .predict(*key, *order, state.shaft_hz, &state.load)?;
                Some(Predicted {
                    order: *order,
                    kind: key.0,
                    feature: feature.clone(),
                    level_db: level,
                    sigma_db: self.report.sigma_db[key.0.index()],
                })
            })
            .collect()
    }

    /// How each evidence feature fed by the calibrated lines changes from `from` to `to` (ln
    /// units of amplitude, as the features are): `ln rms(to) − ln rms(from)` of its lines'
    /// predicted amplitudes, with the uncertainty of its lines' family (`σ_c`, in ln units).
    pub fn shift(&self, from: &OperatingState, to: &OperatingState) -> BTreeMap<String, Shift> {
        let energy = |s: &OperatingState| {
            let mut e: BTreeMap<String, (f64, usize, f64)> = BTreeMap::new();
            for p in self.predict(s) {
                let x = e.entry(p.feature).or_default();
                x.0 += 10f64.powf(p.level_db / 10.0);
                x.1 += 1;
                x.2 = x.2.max(p.sigma_db);
            }
            e
        };
        let (a, b) = (energy(from), energy(to));
        a.iter()
            .filter_map(|(k, (ea, na, sa))| {
                let (eb, nb, _) = b.get(k)?;
                (na == nb && *ea > 0.0 && *eb > 0.0).then(|| {
                    let s = Shift {
                        change: 0.5 * (eb / ea).ln(),
                        sigma: sa * std::f64::consts::LN_10 / 20.0,
                    };
                    (k.clone(), s)
                })
            })
            .collect()
    }

    /// Prediction uncertainty per family (dB): mesh, sideband, shaft.
    pub fn sigma_db(&self) -> [f64; 3] {
        self.report.sigma_db
    }
}

/// Each record's in-sample and left-out errors.
fn state_fits(
    records: &[Observed],
    obs: &[Obs],
    fit: &Fitted,
    errors: &[(usize, f64)],
    smooth_errors: &[(usize, f64)],
) -> Vec<StateFit> {
    records
        .iter()
        .enumerate()
        .map(|(ri, r)| {
            let mine = |i: &usize| obs[*i].record == ri;
            let in_sample: Vec<(LineKind, f64)> = obs
                .iter()
                .enumerate()
                .filter(|(i, _)| mine(i))
                .filter_map(|(_, o)| {
                    let order = 10f64.powf(o.log_hz - o.log_speed);
                    let p = fit.predict(o.key, order, r.state.shaft_hz, &o.load)?;
                    Some((o.key.0, o.level_db - p))
                })
                .collect();
            let of = |e: &[(usize, f64)]| -> Vec<(LineKind, f64)> {
                e.iter()
                    .filter(|(i, _)| mine(i))
                    .map(|&(i, v)| (obs[i].key.0, v))
                    .collect()
            };
            StateFit {
                shaft_hz: r.state.shaft_hz,
                load: r.state.load.clone(),
                fit: FamilyErrors::of(&in_sample),
                left_out: FamilyErrors::of(&of(errors)),
                smooth_left_out: FamilyErrors::of(&of(smooth_errors)),
            }
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn report(
    records: &[Observed],
    fit: &Fitted,
    centres: &[f64],
    states: Vec<StateFit>,
    left_out: FamilyErrors,
    smooth_left_out: FamilyErrors,
    sigma: [f64; 3],
) -> CalibrationReport {
    let nl = fit.n_lines();
    let nk = fit.n_knots();
    let gam = nl + nk;
    let path = (0..nk)
        .map(|j| [10f64.powf(fit.knots[j]), fit.theta[nl + j]])
        .collect();
    // A load's offset per family: the mean difference of its lines' sources from the first
    // load's.
    let load_offsets_db = (0..fit.loads.len())
        .map(|l| {
            let mut sum = [(0.0, 0usize); 3];
            for (&(key, li), &i) in &fit.index {
                if li != l {
                    continue;
                }
                if let Some(&i0) = fit.index.get(&(key, 0)) {
                    let e = &mut sum[key.0.index()];
                    e.0 += fit.theta[i] - fit.theta[i0];
                    e.1 += 1;
                }
            }
            sum.map(|(d, n)| if n > 0 { d / n as f64 } else { 0.0 })
        })
        .collect();
    CalibrationReport {
        records: records.len(),
        lines: nl,
        speeds_hz: centres.to_vec(),
        loads: fit.loads.clone(),
        states,
        left_out,
        smooth_left_out,
        lambda: fit.lambda,
        sigma_db: sigma,
        speed_growth_db_per_decade: [0.0, fit.theta[gam], fit.theta[gam + 1]],
        load_offsets_db,
        path,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::test_util::{lines, path_db, state};

    fn records(noise: f64, with_sources: bool) -> Vec<(OperatingState, Vec<LineLevel>)> {
        let mut v = Vec::new();
        for (i, f) in [30.0, 35.0, 40.0, 45.0, 50.0].into_iter().enumerate() {
            for (j, l) in ["High", "Low"].into_iter().enumerate() {
                v.push((state(f, l), lines(f, l, 2 * i + j, noise, with_sources)));
            }
        }
        v
    }

    fn observed(r: &[(OperatingState, Vec<LineLevel>)]) -> Vec<Observed<'_>> {
        r.iter()
            .map(|(s, l)| Observed { state: s, lines: l })
            .collect()
    }

    /// Sources through a resonant path: the calibration predicts a left-out speed within a
    /// fraction of a dB, far better than the smooth curve, and a speed it never saw (37 Hz,
    /// Low) line by line.
    #[test]
    fn a_resonant_path_is_learnt_across_speeds() {
        let r = records(0.2, true);
        let m = MachineModel::fit(&observed(&r)).unwrap();
        let rep = &m.report;
        let model = rep.left_out.mesh_and_sideband_db.unwrap();
        let smooth = rep.smooth_left_out.mesh_and_sideband_db.unwrap();
        assert!(model < 1.0 && model < 0.3 * smooth, "{model} vs {smooth}");
        assert!(
            (rep.load_offsets_db[1][0] + 4.0).abs() < 0.5,
            "{:?}",
            rep.load_offsets_db
        );
        let st = state(37.0, "Low");
        assert!(m.covers(&st) && !m.covers(&state(60.0, "Low")));
        assert!(!m.covers(&state(40.0, "Medium")));
        let truth = lines(37.0, "Low", 99, 0.0, true);
        let p = m.predict(&st);
        assert_eq!(p.len(), truth.len());
        for t in &truth {
            let q = p.iter().find(|q| (q.order - t.order).abs() < 1e-9).unwrap();
            assert!((q.level_db - t.level_db).abs() < 1.5, "{t:?} {q:?}");
        }
    }

    /// A feature's shift follows its lines: from 40 Hz to 30 Hz the 64-order mesh line moves
    /// from 2.56 kHz towards the 1.2 kHz mode (up), the 16-order one from 640 Hz to 480 Hz
    /// (down, away from it).
    #[test]
    fn shifts_follow_the_path() {
        let r = records(0.0, true);
        let m = MachineModel::fit(&observed(&r)).unwrap();
        let s = m.shift(&state(40.0, "High"), &state(30.0, "High"));
        let truth = |o: f64| (path_db(o * 30.0) - path_db(o * 40.0)) / 20.0 * 10f64.ln();
        for (feature, o) in [("lines.mesh.m64", 64.0), ("lines.mesh.m16", 16.0)] {
            let c = s[feature].change;
            assert!(
                (c - truth(o)).abs() < 0.05,
                "{feature}: {c} vs {}",
                truth(o)
            );
        }
        assert!(s["lines.mesh.m64"].change > 0.0 && s["lines.mesh.m16"].change < 0.0);
    }

    /// Levels that depend on frequency alone (no line's source differs) and carry run-to-run
    /// noise: the calibration adds nothing over a smooth curve and is refused, with figures.
    #[test]
    fn no_better_than_a_smooth_curve_is_refused() {
        let r = records(2.0, false);
        match MachineModel::fit(&observed(&r)) {
            Err(Refused::NoBetterThanSmooth {
                model_db,
                smooth_db,
            }) => {
                assert!(model_db >= smooth_db)
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn two_speeds_are_too_few() {
        let r: Vec<_> = records(0.0, true)
            .into_iter()
            .filter(|(s, _)| s.shaft_hz < 40.0)
            .collect();
        assert!(matches!(
            MachineModel::fit(&observed(&r)),
            Err(Refused::TooFewSpeeds {
                speeds: 2,
                needed: 3
            })
        ));
    }
}
