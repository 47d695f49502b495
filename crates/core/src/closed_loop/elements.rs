//! The element-effect candidates of step 5 of [`calibrate`](super::calibrate): shaft
//! modulation on each shaft of the reference mesh, planetary wear, a damaged tooth on each gear
//! of the reference mesh. Each one's amplitude is fitted at the plain model's best wear
//! ([`ElementFit::singles`]): from the gap at its fingerprint lines (one probe simulation) or by
//! its score over a grid, `ea` profiled locally, the amplitude again at the refined `ea`.

use rayon::prelude::*;

use super::effects::{ElementParams, Mesh, PLANETARY_WEAR, SHAFT_MODULATION, TOOTH_DAMAGE};
use super::fit::{Weights, fit_sensor, sensor_model};
use super::measured::Measured;
use super::residual::fingerprint_gap;
use super::simulator::{Simulator, best_point, ea_window};
use super::spectrum;
use crate::error::Result;

/// Stiffness losses a damaged-tooth candidate is scored at (then refined between neighbours).
const TOOTH_SCAN: [f64; 7] = [0.05, 0.1, 0.2, 0.35, 0.5, 0.7, 0.9];

/// Shaft-modulation sideband amplitudes (units of b) a slow shaft's modulation is scored at
/// (then refined between neighbours): the benchmark draws 0.0025–0.25.
const MODULATION_SCAN: [f64; 8] = [0.005, 0.01, 0.02, 0.04, 0.08, 0.15, 0.3, 0.6];

/// Planetary error amplitudes (units of b) a planetary-wear candidate is scored at (those
/// above the gearbox's baseline; then refined between neighbours).
const PLANETARY_SCAN: [f64; 7] = [0.2, 0.35, 0.6, 1.0, 1.7, 3.0, 5.0];

/// Puts an amplitude into a parameter set: `set(base, amplitude)`.
type SetAmplitude<'s> = &'s (dyn Fn(ElementParams, f64) -> ElementParams + Sync);

/// Fits the element effects' amplitudes to the record under the scatter's weights `w`.
pub(super) struct ElementFit<'a> {
    pub ms: &'a Measured<'a>,
    pub sim: &'a Simulator<'a>,
    pub w: &'a Weights,
}

impl ElementFit<'_> {
    /// Every element effect's best parameter set, fitted from the plain model's best point
    /// `pn`: a shaft modulation per shaft of `mesh`, planetary wear (with a planetary stage),
    /// a damaged tooth per gear of the reference mesh; named.
    pub(super) fn singles(
        &self,
        pn: ElementParams,
        mesh: &Mesh,
    ) -> Result<Vec<(String, ElementParams)>> {
        let mut singles: Vec<(String, ElementParams)> = Vec::new();
        for sh in &mesh.shafts {
            let p = self.shaft_modulation(pn, sh.shaft_ratio)?;
            singles.push((SHAFT_MODULATION.into(), p));
        }
        if let Some(f3) = self.ms.gb.planetary_ratio() {
            singles.push((PLANETARY_WEAR.into(), self.planetary_wear(pn, f3)?));
        }
        for g in &mesh.gears {
            let s = g.shaft_ratio;
            let set = move |b: ElementParams, dep: f64| ElementParams {
                tooth_depth: dep,
                tooth_shaft: s,
                ..b
            };
            let p = self.by_scan(pn, &set, &TOOTH_SCAN)?;
            singles.push((TOOTH_DAMAGE.into(), p));
        }
        Ok(singles)
    }

    /// A shaft modulation on the shaft of rate `s` (over f1).
    fn shaft_modulation(&self, pn: ElementParams, s: f64) -> Result<ElementParams> {
        let sb: Vec<f64> = [1.0, 2.0].iter().flat_map(|c| [c - s, c + s]).collect();
        let set = move |b: ElementParams, e: f64| ElementParams {
            eccentricity: e,
            ecc_shaft: s,
            ..b
        };
        // Sidebands within 3 grid steps of their carrier sit in its main lobe on the grid
        // (a gear of many teeth: the stage-1 gear shaft at f1/100 is 1.3 steps out), where the
        // gap at the sideband lines measures the carrier: the amplitude by score instead.
        Ok(if s * spectrum::GRID_PERIODS < 3.0 {
            self.by_scan(pn, &set, &MODULATION_SCAN)?
        } else {
            // The gap at the sideband lines, and the scan by score as a guard: on a chaotic
            // record the gap can read the trajectory's own lines as sidebands and put in an
            // amplitude far worse than none (seed 25 of the benchmark, record 27: ΔBIC +433).
            // The better-scoring of the two is kept.
            let by_gap = self.by_gap(pn, &set, 0.05, &sb, 1e-3, 2.0)?;
            let by_scan = self.by_scan(pn, &set, &MODULATION_SCAN)?;
            if self.score(&by_scan)? < self.score(&by_gap)? {
                by_scan
            } else {
                by_gap
            }
        })
    }

    /// Planetary wear (`f3`: the planetary family's rate over f1).
    fn planetary_wear(&self, pn: ElementParams, f3: f64) -> Result<ElementParams> {
        let baseline_planetary = self.ms.baseline_planetary;
        let fam: Vec<f64> = vec![f3, 2.0 * f3, 1.0 - f3, 1.0 + f3];
        let set = |b: ElementParams, p: f64| ElementParams { planetary: p, ..b };
        let grid: Vec<f64> = PLANETARY_SCAN
            .iter()
            .copied()
            .filter(|p| *p > baseline_planetary)
            .collect();
        if grid.is_empty() {
            self.by_gap(pn, &set, 1.0, &fam, baseline_planetary, 5.0)
        } else {
            self.by_scan(pn, &set, &grid)
        }
    }

    /// The sensor-fitted score of the model at `q`.
    fn score(&self, q: &ElementParams) -> Result<f64> {
        let (m, r) = (&self.ms.m, &self.ms.r);
        Ok(fit_sensor(m, &self.sim.spectrum(q)?, r, None, self.w).1)
    }

    /// An amplitude from the gap at the fingerprint lines `ratios`: the model at `probe`
    /// (`make(probe)`) fitted, its amplitude scaled by the mean gap (dB) there, within
    /// `[lo, hi]` (`lo` when no fingerprint line stands above the noise floor).
    fn amplitude_by_gap(
        &self,
        make: &dyn Fn(f64) -> ElementParams,
        probe: f64,
        ratios: &[f64],
        lo: f64,
        hi: f64,
    ) -> Result<f64> {
        let (m, r) = (&self.ms.m, &self.ms.r);
        let sp = self.sim.spectrum(&make(probe))?;
        let (sens, _) = fit_sensor(m, &sp, r, None, self.w);
        let fp = sensor_model(&sp, r, &sens);
        Ok(match fingerprint_gap(m, &fp, sens.noise_db, ratios, 6.0) {
            Some(gap) => (probe * 10f64.powf(gap.clamp(-40.0, 40.0) / 20.0)).clamp(lo, hi),
            None => lo,
        })
    }

    /// An element effect by the gap at its lines: the amplitude, `ea` profiled within ±0.05,
    /// the amplitude again at the refined `ea`.
    fn by_gap(
        &self,
        base: ElementParams,
        set: SetAmplitude,
        probe: f64,
        ratios: &[f64],
        lo: f64,
        hi: f64,
    ) -> Result<ElementParams> {
        let (m, r) = (&self.ms.m, &self.ms.r);
        let a1 = self.amplitude_by_gap(&|a| set(base, a), probe, ratios, lo, hi)?;
        let first = set(base, a1);
        let prof = self
            .sim
            .profile(m, r, first, &ea_window(first.ea), None, None, self.w)?;
        let (refined, _, _) = best_point(&prof);
        let a2 = self.amplitude_by_gap(&|a| set(refined, a), a1, ratios, lo, hi)?;
        Ok(set(refined, a2))
    }

    /// An element effect whose lines the grid cannot measure one by one (a damaged tooth on a
    /// gear of many teeth puts its sidebands 1.3 grid steps apart, inside the mesh line's own
    /// main lobe; the planetary family sits far below f1): the amplitude by its score, not by
    /// a gap at lines. Every amplitude of `grid` simulated at `base` (rayon, cached), the best
    /// kept; ea profiled within ±0.05; then the best amplitude's neighbours on a grid twice as
    /// fine, at the refined ea.
    fn by_scan(
        &self,
        base: ElementParams,
        set: SetAmplitude,
        grid: &[f64],
    ) -> Result<ElementParams> {
        let (m, r) = (&self.ms.m, &self.ms.r);
        let i = self.best_amplitude(base, set, grid)?;
        let a1 = grid[i];
        let first = set(base, a1);
        let prof = self
            .sim
            .profile(m, r, first, &ea_window(first.ea), None, None, self.w)?;
        let (refined, _, _) = best_point(&prof);
        let mut local = vec![a1];
        if i > 0 {
            local.push(0.5 * (grid[i - 1] + a1));
        }
        if i + 1 < grid.len() {
            local.push(0.5 * (grid[i + 1] + a1));
        }
        Ok(set(
            refined,
            local[self.best_amplitude(refined, set, &local)?],
        ))
    }

    /// The index of the best-scoring amplitude of `amps` at `b`.
    fn best_amplitude(&self, b: ElementParams, set: SetAmplitude, amps: &[f64]) -> Result<usize> {
        let (m, r) = (&self.ms.m, &self.ms.r);
        let scores: Vec<f64> = amps
            .par_iter()
            .map(|&a| Ok(fit_sensor(m, &self.sim.spectrum(&set(b, a))?, r, None, self.w).1))
            .collect::<Result<_>>()?;
        Ok((0..scores.len())
            .min_by(|&x, &y| scores[x].total_cmp(&scores[y]))
            .expect("a non-empty amplitude grid"))
    }
}
