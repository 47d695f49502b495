//! Scoring the candidates of [`calibrate`](super::calibrate): optionally over the model seeds
//! ([`rescore_over_seeds`]), then by a BIC on the deviance of the weighted robust score,
//! `J ln(score/J) + k ln J`, against "no effect" from the best of its initial states
//! ([`Scores`]).

use super::candidates::{Candidates, Fitted};
use super::fit::{Weights, fit_sensor};
use super::measured::Measured;
use super::scatter::Null;
use super::simulator::{Simulator, pointwise_mean};
use crate::error::Result;

/// A chaotic model's score from one initial state scatters by `null_spread`; "no effect"
/// takes the best of `1 + model_seeds`, so a candidate from one state is handicapped by
/// that scatter. Optionally every candidate is scored from the same initial states: on its
/// mean spectrum over them, "no effect" included ([`super::CalibrateOptions::mean_seeds`]), or
/// by the best of them like "no effect" ([`super::CalibrateOptions::candidate_seeds`]).
pub(super) fn rescore_over_seeds(
    ms: &Measured,
    sim: &Simulator,
    w: &Weights,
    cands: &mut [Fitted],
) -> Result<()> {
    let (m, r, opts) = (&ms.m, &ms.r, ms.opts);
    let seeds = sim.seeds(opts.model_seeds as u64 + 1);
    if opts.mean_seeds {
        for c in cands.iter_mut() {
            let mean = pointwise_mean(&sim.spectra_seeded(&c.params, &seeds)?);
            c.rss = fit_sensor(m, &mean, r, c.sensor.resonance, w).1;
        }
    } else if opts.candidate_seeds {
        for c in cands.iter_mut().skip(1) {
            c.rss = sim
                .spectra_seeded(&c.params, &seeds[1..])?
                .iter()
                .map(|s| fit_sensor(m, s, r, c.sensor.resonance, w).1)
                .fold(c.rss, f64::min);
        }
    }
    Ok(())
}

/// The candidates' scores: a BIC on the deviance of the weighted robust score,
/// `J ln(score/J) + k ln J`; an effect must beat "none" by `bic_margin + null_z · null_spread` (the model's
/// own seed-to-seed scatter) and lower the plain RMS error of the table's estimate.
pub(super) struct Scores {
    /// Each candidate's unweighted residual sum of squares (dB²).
    pub rss_unw: Vec<f64>,
    /// Each candidate's BIC.
    pub bic: Vec<f64>,
    /// The BIC of "no effect" the candidates are measured against.
    pub bic0: f64,
    /// The ΔBIC an effect must beat: `bic_margin + null_z · null_spread`.
    pub claim_margin: f64,
}

impl Scores {
    /// `fitted`: each candidate's fitted spectrum.
    pub(super) fn new(ms: &Measured, null: &Null, cands: &[Fitted], fitted: &[Vec<f64>]) -> Scores {
        let unit = Weights::unit(ms.r.len());
        let rss_unw: Vec<f64> = fitted.iter().map(|fc| unit.score(&ms.m, fc)).collect();
        let bic: Vec<f64> = cands.iter().map(|c| ms.bic(c.rss, c.k)).collect();
        // "No effect" from the best of its initial states (its profile's best point, each seed).
        let none_ref = null.deviances.iter().copied().fold(f64::INFINITY, f64::min);
        let bic0 = if ms.opts.mean_seeds {
            // "No effect" is scored on its mean spectrum like every candidate.
            bic[0]
        } else {
            bic[0].min(none_ref + 3.0 * ms.j_n.ln())
        };
        let claim_margin = ms.opts.bic_margin + ms.opts.null_z * null.spread;
        Scores {
            rss_unw,
            bic,
            bic0,
            claim_margin,
        }
    }

    /// The best-scoring single candidate of an effect (of its variants).
    pub(super) fn best_single(&self, cands: &Candidates, name: &str) -> Option<usize> {
        (1..cands.n_single)
            .filter(|&k| cands.list[k].effects.len() == 1 && cands.list[k].effects[0].name == name)
            .min_by(|&a, &b| self.bic[a].total_cmp(&self.bic[b]))
    }
}
