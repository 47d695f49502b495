//! The described gearbox simulated at a set of physics factors: the table's features of the
//! healthy machine at each healthy record's speed.

use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use crate::error::Result;
use crate::gearbox::{Gearbox, PhysicsFactors};
use crate::model::Wear;
use crate::signature::precompute::simulate_seed;
use crate::signature::{LineDef, SensorQuantity, SignatureTable, SimulationSettings, mix_seed};

/// How the healthy machine is simulated: the table's sensor, lines and settings (with fewer
/// retained periods), at the table's lowest wear.
#[derive(Debug, Clone)]
pub(super) struct Simulator {
    pub(super) settings: SimulationSettings,
    pub(super) sensor: SensorQuantity,
    pub(super) lines: Vec<LineDef>,
    /// The healthy machine's wear degree.
    pub(super) ea0: f64,
    /// Simulations (random initial states) per speed.
    pub(super) seeds: usize,
    /// Simulations run so far (every evaluation adds its own).
    pub(super) runs: std::sync::Arc<AtomicUsize>,
}

/// The simulated features at one speed: the mean over the seeds and their variance (ln
/// units, the table's feature order without the power fraction).
#[derive(Debug, Clone)]
pub(super) struct Simulated {
    pub(super) mean: Vec<f64>,
    pub(super) var: Vec<f64>,
}

impl Simulator {
    pub(super) fn new(table: &SignatureTable, periods: usize, seeds: usize) -> Simulator {
        Simulator {
            settings: SimulationSettings {
                periods,
                ..table.simulation.clone()
            },
            sensor: table.sensor,
            lines: table.features.lines.clone(),
            ea0: table.grid.ea[0],
            seeds: seeds.max(1),
            runs: Default::default(),
        }
    }

    /// The healthy features of `gb` with `factors` at each input-shaft-independent stage-1
    /// mesh frequency of `f1_hz` (Hz). The initial states depend on the speed's index and
    /// the seed only, so two evaluations at nearby factors differ by the factors, not by
    /// their draws (common random numbers: finite differences stay smooth).
    pub(super) fn run(
        &self,
        gb: &Gearbox,
        factors: &PhysicsFactors,
        f1_hz: &[f64],
    ) -> Result<Vec<Simulated>> {
        let g = gb.with_factors(factors)?;
        let model = g.assembly(Wear::fixed_axis(self.ea0))?.resolve()?;
        let f_ref = g.reference_frequency_hz();
        let jobs: Vec<(usize, usize)> = (0..f1_hz.len())
            .flat_map(|i| (0..self.seeds).map(move |s| (i, s)))
            .collect();
        let out: Vec<Vec<f64>> = jobs
            .par_iter()
            .map(|&(i, s)| {
                let seed = mix_seed(&[self.settings.base_seed, 0x9E11, i as u64, s as u64]);
                let omega1 = f1_hz[i] / f_ref;
                let (f, _) = simulate_seed(
                    &model,
                    omega1,
                    &self.settings,
                    self.sensor,
                    &self.lines,
                    seed,
                )?;
                self.runs.fetch_add(1, Ordering::Relaxed);
                Ok(f)
            })
            .collect::<Result<_>>()?;
        let nf = self.lines.len().saturating_sub(1);
        Ok((0..f1_hz.len())
            .map(|i| {
                let runs = &out[i * self.seeds..(i + 1) * self.seeds];
                let n = runs.len() as f64;
                let mean: Vec<f64> = (0..nf)
                    .map(|k| runs.iter().map(|r| r[k]).sum::<f64>() / n)
                    .collect();
                let var = (0..nf)
                    .map(|k| {
                        runs.iter().map(|r| (r[k] - mean[k]).powi(2)).sum::<f64>()
                            / (n - 1.0).max(1.0)
                    })
                    .collect();
                Simulated { mean, var }
            })
            .collect())
    }
}
