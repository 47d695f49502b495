//! The machine's own physics: the described gearbox's unknown physical values fitted to the
//! machine's healthy records **by simulating it**, and the wear read against that machine.
//!
//! # Model
//! A healthy record's feature `ℓ` (the table's gain-free `y_ℓ = ln(A_ℓ / A_f1)`, channel `c`,
//! stage-1 mesh frequency `f1`) is the simulated healthy machine seen through the channel's
//! transfer path:
//!
//! ```text
//! y_ℓ = μ_ℓ(ea₀, f1 / f_ref(θ); θ) + P_c(r_ℓ f1) − P_c(f1) + ε,   ε ~ N(0, v_ℓ + s₀²)
//! ```
//!
//! with `μ` the features of the described gearbox simulated at its physics factors `θ`
//! ([`crate::gearbox::factors`]: per stage the mesh stiffness, damping, stiffness fluctuation
//! and transmission-error amplitude, and the gearbox's load and clearance; `ln` of each
//! factor is fitted within physical bounds), `ea₀` the table's lowest wear (a healthy machine
//! is read as unworn), `v_ℓ` the simulations' own scatter, `s₀` the diagnosis's measurement
//! floor, and `P_c` the channel's path: piecewise linear in `log10 Hz` (24 knots a decade),
//! its second differences penalised by `λ`. A line's level comes from the simulated dynamics
//! through the path — never from a level of its own. Lines the record does not show (at the
//! clipping floor) only penalise a prediction above the floor.
//!
//! # Fit ([`MachinePhysics::fit`])
//! For each `λ` of the options, bounded Levenberg–Marquardt in `θ` (forward differences with
//! common random initial states) with the path profiled out (refitted by weighted least
//! squares at every `θ`) and a Gaussian prior `θ ~ N(0, σ_p²)` around the description's values;
//! the `λ` whose fit predicts a left-out speed best is kept. The parameters' covariance is the
//! Gauss–Newton one, scaled by the fit's χ² per residual when above 1; a factor whose data
//! barely move it keeps the prior's width and is reported as not identified.
//!
//! Leave one speed out (the report's `left_out`): each speed group's records predicted by a
//! fit of the others — `θ` refitted from the full fit (a few iterations) and the path
//! refitted — per line family. The yardstick is the machine's empirical calibration, the
//! description's own physics through a path calibrated alone
//! ([`super::machine_path::PathCalibration`]): a physics fit that predicts a left-out speed no
//! better is refused with both figures ([`Error::PhysicsNoBetter`]).
//!
//! # Reading wear
//! The machine's own gearbox is the description with the fitted factors
//! ([`MachinePhysics::gearbox`]); its table is computed over the machine's speeds like any
//! table. A record is read against that table with each feature's path colouring removed and
//! its uncertainty added ([`MachinePhysics::shift_at`]): the path's left-out scatter and the
//! factors' uncertainty carried to the feature (`J C Jᵀ`, `J` the fit's sensitivity of the
//! feature's residual to `θ` at the nearest calibrated speeds) — so the interval widens where
//! the physics is uncertain.

mod fit;
mod read;
mod simulate;
mod solve;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::DiagnoseOptions;
use super::machine_path::{KNOTS_PER_DECADE, LineRatios, Path};
use crate::error::{Error, Result};
use crate::gearbox::factors::STAGE_FACTOR_NAMES;
use crate::gearbox::{Gearbox, PhysicsFactors};
use crate::model::StiffnessShape;
use crate::signature::SignatureTable;
use solve::{Data, Knob, Obs, Param};

pub use fit::knots;

/// Records within this relative f1 of each other are one speed.
const SAME_SPEED: f64 = 0.03;
/// Fewest healthy records, and fewest speeds, a fit needs.
pub const MIN_RECORDS: usize = 4;
/// Fewest distinct speeds a fit needs (the path and the physics separate across speeds).
pub const MIN_SPEEDS: usize = 3;

/// How the fit runs.
#[derive(Debug, Clone, Serialize)]
pub struct PhysicsFitOptions {
    /// Simulations (random initial states) per healthy record's speed.
    pub seeds: usize,
    /// Retained stage-1 mesh periods of each simulation.
    pub periods: usize,
    /// Levenberg–Marquardt iterations of the full fit.
    pub iterations: usize,
    /// Iterations of each left-out speed's refit (from the full fit).
    pub left_out_iterations: usize,
    /// Prior standard deviation of every `ln` factor.
    pub prior_sigma: f64,
    /// Finite-difference step (ln units).
    pub step: f64,
    /// Path smoothness weights tried.
    pub lambdas: Vec<f64>,
}

impl Default for PhysicsFitOptions {
    fn default() -> Self {
        PhysicsFitOptions {
            seeds: 1,
            periods: 128,
            iterations: 6,
            left_out_iterations: 2,
            prior_sigma: 0.5,
            step: 0.08,
            lambdas: vec![3.0, 30.0, 300.0],
        }
    }
}

/// One fitted factor with its 90 % interval.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedFactor {
    /// `stage 1 stiffness`, `load`, `clearance`, …
    pub name: String,
    /// The factor over the description's value.
    pub value: f64,
    pub lower: f64,
    pub upper: f64,
    /// The physical bounds searched.
    pub bounds: [f64; 2],
    /// False when the healthy records barely constrain it (its interval is the prior's).
    pub identified: bool,
}

/// A line family's fit at one speed (or over all): RMS errors in dB.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FamilyFit {
    /// `f1` (harmonics of the reference mesh), `f2`, `f1×f2` (their combinations), …
    pub family: String,
    /// Line levels compared (measured above the floor).
    pub lines: usize,
    pub in_sample_db: f64,
    pub left_out_db: f64,
}

/// The fit of one speed group.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateFit {
    /// The group's stage-1 mesh frequency (Hz).
    pub f1_hz: f64,
    pub records: usize,
    pub families: Vec<FamilyFit>,
}

/// A channel's transfer path as the fit left it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelPath {
    /// `log10 Hz` of the first knot; knots every 1/24 decade.
    pub lo_log10_hz: f64,
    /// The path at the knots (dB).
    pub path_db: Vec<f64>,
    /// Each feature's left-out scatter (ln; the table's order without the power fraction).
    pub sigma: Vec<f64>,
}

/// The sensitivity of the features' residuals to the `ln` factors at one speed group (rows:
/// features, columns: parameters), from the fit's last Jacobian.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sensitivity {
    pub channel: String,
    pub f1_hz: f64,
    pub rows: Vec<Vec<f64>>,
}

/// The machine's physics fitted to its healthy records (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MachinePhysics {
    /// Hash of the description the factors apply to.
    pub gearbox_hash: String,
    pub factors: PhysicsFactors,
    pub parameters: Vec<FittedFactor>,
    /// The healthy machine's wear degree (the table's lowest).
    pub healthy_ea: f64,
    pub records: usize,
    /// Speed groups fitted (stage-1 mesh frequency, Hz).
    pub f1_hz: Vec<f64>,
    /// The path smoothness chosen.
    pub lambda: f64,
    pub channels: BTreeMap<String, ChannelPath>,
    pub states: Vec<StateFit>,
    /// Over every speed and family, mesh lines and their combinations: RMS dB.
    pub in_sample_db: f64,
    pub left_out_db: f64,
    /// The median |error| of the left-out lines (dB).
    pub left_out_median_db: f64,
    /// Most left-out error (RMS dB) at which the model reads wear: three times the
    /// diagnosis's measurement floor per feature. Above it the model misses a healthy speed's
    /// lines by far more than the records' own scatter: every reading against it is withheld
    /// (`poor-fit`).
    pub predictive_limit_db: f64,
    /// The same records' left-out error under the empirical calibration (the description's
    /// physics, a path alone): the yardstick (dB). `None` when it could not be fitted.
    pub yardstick_db: Option<f64>,
    /// The description's physics with no path at all (dB).
    pub plain_db: f64,
    /// Covariance of the `ln` factors (parameter order).
    pub covariance: Vec<Vec<f64>>,
    pub sensitivity: Vec<Sensitivity>,
    pub simulations: usize,
    pub seconds: f64,
}

/// The parameters fitted for `gb`: per stage stiffness, damping, fluctuation (when its
/// stiffness varies) and error, then load and clearance — each within physical bounds.
fn parameters(gb: &Gearbox) -> Vec<Param> {
    let stages = gb.topology.stages.len();
    let mut v = Vec::new();
    for s in 1..=stages {
        let eps_max = gb
            .physics
            .meshes
            .iter()
            .filter(|m| m.stage == s)
            .map(|m| match m.shape {
                StiffnessShape::FirstHarmonic { eps } => eps,
                _ => 0.0,
            })
            .fold(0.0, f64::max);
        let bounds: [(f64, f64); 4] = [
            (0.4, 2.5),
            (0.3, 3.5),
            (
                0.4,
                if eps_max > 0.0 {
                    (0.9 / eps_max).min(2.5)
                } else {
                    2.5
                },
            ),
            (0.3, 3.5),
        ];
        for (i, (lo, hi)) in bounds.iter().enumerate() {
            v.push(Param {
                knob: Knob::Stage(s, i),
                lo: lo.ln(),
                hi: hi.ln(),
            });
        }
    }
    v.push(Param {
        knob: Knob::Load,
        lo: 0.5f64.ln(),
        hi: 2.0f64.ln(),
    });
    v.push(Param {
        knob: Knob::Clearance,
        lo: 0.5f64.ln(),
        hi: 2.0f64.ln(),
    });
    v
}

fn param_name(p: &Param) -> String {
    match p.knob {
        Knob::Stage(s, i) => format!("stage {s} {}", STAGE_FACTOR_NAMES[i]),
        Knob::Load => "load".into(),
        Knob::Clearance => "clearance".into(),
    }
}

/// The line family of a feature's name: the meshes (`f1`, `f2`, …) it is made of.
fn family(name: &str) -> String {
    let mut meshes: Vec<String> = Vec::new();
    let b = name.as_bytes();
    for i in 0..b.len() {
        if b[i] == b'f' {
            let digits: String = name[i + 1..]
                .chars()
                .take_while(|c| c.is_ascii_digit())
                .collect();
            if !digits.is_empty() && !meshes.contains(&format!("f{digits}")) {
                meshes.push(format!("f{digits}"));
            }
        }
    }
    meshes.sort();
    meshes.join("×")
}

fn median_abs_db(e: &[f64]) -> f64 {
    let mut v: Vec<f64> = e
        .iter()
        .map(|x| x.abs() * 20.0 / std::f64::consts::LN_10)
        .collect();
    if v.is_empty() {
        return f64::NAN;
    }
    crate::signal::median(&mut v)
}

fn rms_db(e: &[f64]) -> f64 {
    let db = 20.0 / std::f64::consts::LN_10;
    (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt() * db
}

/// The healthy records as the fit reads them; errors name what is missing.
fn gather(
    table: &SignatureTable,
    opts: &DiagnoseOptions,
    healthy: &BTreeMap<String, Vec<LineRatios>>,
) -> Result<Data> {
    let nf = table.features.names.len() - 1;
    let ratios: Vec<f64> = table
        .features
        .lines
        .iter()
        .filter(|l| l.name != "f1")
        .map(|l| l.ratio)
        .collect();
    let mut f1: Vec<f64> = Vec::new();
    let mut obs = Vec::new();
    let mut channels = Vec::new();
    for (c, (name, list)) in healthy.iter().enumerate() {
        channels.push(name.clone());
        for r in list {
            if r.lines.len() != nf {
                return Err(Error::LengthMismatch {
                    what: "a healthy record's lines",
                    expected: nf,
                    found: r.lines.len(),
                });
            }
            let speed = match f1.iter().position(|&f| f == r.f1_hz) {
                Some(i) => i,
                None => {
                    f1.push(r.f1_hz);
                    f1.len() - 1
                }
            };
            obs.push(Obs {
                channel: c,
                speed,
                group: 0,
                y: r.lines
                    .iter()
                    .map(|[_, db]| db * std::f64::consts::LN_10 / 20.0)
                    .collect(),
            });
        }
    }
    let mut sorted = f1.clone();
    sorted.sort_by(f64::total_cmp);
    let mut groups: Vec<f64> = Vec::new();
    for &f in &sorted {
        if groups.last().is_none_or(|&c| f / c - 1.0 > SAME_SPEED) {
            groups.push(f);
        }
    }
    let group = |f: f64| {
        groups
            .iter()
            .rposition(|&c| f >= c * (1.0 - 1e-9))
            .unwrap_or(0)
    };
    for o in obs.iter_mut() {
        o.group = group(f1[o.speed]);
    }
    let records = healthy.values().map(Vec::len).max().unwrap_or(0);
    if records < MIN_RECORDS || groups.len() < MIN_SPEEDS {
        return Err(Error::BaselineTooSmall {
            records: records.min(groups.len()),
            needed: MIN_RECORDS.max(MIN_SPEEDS),
        });
    }
    Ok(Data {
        channels,
        f1,
        groups,
        obs,
        ratios,
        floor: opts.floor_db * std::f64::consts::LN_10 / 20.0,
        s0: opts.feature_sigma,
    })
}
