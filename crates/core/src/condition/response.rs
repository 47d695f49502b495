//! The model's own fault signatures: each gear's local tooth damage and eccentricity simulated
//! once in the machine's own gearbox, and the change they make — which harmonics of the gear's
//! mesh carry sidebands at its shaft's rate, and how strongly relative to each other — as the
//! explainer's gear candidates ([`super::candidates::Response`]) instead of a flat comb.
//!
//! For gear `g` (mesh frequency `f_m = r_m f1`, shaft rate `f_s = s f1`) the gearbox is
//! simulated at ea₀ three times from one initial state: healthy; with a local fault on `g`'s
//! mesh (a stiffness dip of depth [`LOCAL_DEPTH`] once per revolution of `g`'s shaft, as long as
//! one tooth's time in mesh, [`crate::model::ToothDamage`]); with an eccentricity (the mesh's
//! error modulated at `f_s`: error harmonics of [`ECCENTRICITY`] reference lengths at
//! `f_m ± f_s`). Each harmonic `k f_m` (k = 1 … [`HARMONICS`]) gets the added sideband energy
//! over its carrier's,
//!
//! ```text
//! ρ(k) = Σ_{j=1..J} [A²(k f_m ± j f_s)|fault − A²(k f_m ± j f_s)|healthy] / A²(k f_m)|fault
//! ```
//!
//! (J = 3 for the local fault, 1 for the eccentricity; amplitudes from the Hann DTFT of the
//! whole simulated record, [`PERIODS`] stage-1 mesh periods, so that `f_s` is resolved), floored
//! at a small positive value. The explainer fits each candidate's amplitude, so only the
//! pattern over `k` carries information. A gear whose shaft turns slower than
//! [`SLOWEST_SHAFT`] × f1 (its sidebands unresolved in a record of that length) keeps the flat
//! comb (ρ = 1 for every harmonic).

use rayon::prelude::*;

use super::candidates::Response;
use super::parts::Parts;
use crate::error::Result;
use crate::gearbox::Gearbox;
use crate::model::{Harmonic, ToothDamage, Wear};
use crate::signal::line_amplitude;
use crate::signature::precompute::{SimOptions, random_initial, simulate_sensor};
use crate::signature::{SensorQuantity, SplitMix64};
use crate::solver::Dopri5Options;

/// Mesh harmonics a signature covers.
pub const HARMONICS: usize = 4;
/// Stiffness lost at the centre of the local fault's pulse.
pub const LOCAL_DEPTH: f64 = 0.3;
/// The eccentricity's error amplitude (reference lengths).
pub const ECCENTRICITY: f64 = 0.05;
/// Stage-1 mesh periods of each simulated record.
pub const PERIODS: usize = 2048;
/// Slowest shaft (over f1) whose sidebands are resolved.
pub const SLOWEST_SHAFT: f64 = 8.0 / PERIODS as f64;
/// Samples per stage-1 mesh period (Nyquist above the highest harmonic's sidebands).
const SAMPLES_PER_PERIOD: usize = 16;
/// How far a harmonic's share may stand from the pattern's mean (a factor either way).
pub const PATTERN_SPAN: f64 = 4.0;
/// The smallest ratio a harmonic keeps (the explainer divides by none, but a zero would drop
/// the harmonic from the pattern altogether).
const MIN_RATIO: f64 = 1e-4;

/// One gear's fault as a change of the healthy model.
#[derive(Debug, Clone, Copy)]
enum Fault {
    Healthy,
    Local,
    Eccentric,
}

/// The simulated sensor series of `gb` at `omega1` with `fault` on element `element` (mesh
/// ratio `r_m`, the gear's shaft ratio `s`, its teeth `z`).
fn series(
    gb: &Gearbox,
    omega1: f64,
    element: usize,
    (r_m, s, z): (f64, f64, u32),
    fault: Fault,
    ea0: f64,
) -> Result<Vec<f64>> {
    let mut asm = gb.assembly(Wear::fixed_axis(ea0))?;
    let b = asm.length_ref;
    if let Some(el) = asm.elements.get_mut(element) {
        match fault {
            Fault::Healthy => {}
            Fault::Local => {
                *el = el.clone().with_tooth_damage(ToothDamage {
                    depth: LOCAL_DEPTH,
                    shaft_ratio: s,
                    width: (1.6 / z.max(2) as f64).min(0.5),
                    phase: 0.0,
                });
            }
            Fault::Eccentric => {
                let amp = ECCENTRICITY * b;
                el.error.push(Harmonic {
                    amplitude: amp,
                    freq_ratio: r_m + s,
                    phase: 0.0,
                });
                el.error.push(Harmonic {
                    amplitude: amp,
                    freq_ratio: r_m - s,
                    phase: 0.0,
                });
            }
        }
    }
    let model = asm.resolve()?;
    let mut rng = SplitMix64::new(0x51_6E_A7);
    let initial = random_initial(model.n(), 0.5, omega1, &mut rng);
    let period = std::f64::consts::TAU / omega1;
    let rec = simulate_sensor(
        &model,
        &initial,
        &SimOptions {
            omega1,
            transient_tau: 60.0 * period,
            dt_tau: period / SAMPLES_PER_PERIOD as f64,
            samples: PERIODS * SAMPLES_PER_PERIOD,
            sensor: SensorQuantity::Accel,
            poincare_every: 0,
            solver: Dopri5Options::default(),
        },
    )?;
    Ok(rec.series)
}

/// `A²` at frequency `ratio × f1` of a series sampled [`SAMPLES_PER_PERIOD`] times per f1
/// period (f1 = 1 in these units).
fn power(x: &[f64], ratio: f64) -> f64 {
    let fs = SAMPLES_PER_PERIOD as f64;
    if !(ratio > 0.0 && ratio < 0.5 * fs) {
        return 0.0;
    }
    line_amplitude(x, fs, ratio).map_or(0.0, |a| a * a)
}

/// `ρ(k)` for `k = 1 …` [`HARMONICS`] from the healthy and the faulted series.
fn ratios(healthy: &[f64], faulted: &[f64], r_m: f64, s: f64, sidebands: usize) -> Vec<f64> {
    (1..=HARMONICS)
        .map(|k| {
            let h = k as f64 * r_m;
            let carrier = power(faulted, h);
            let mut added = 0.0;
            for j in 1..=sidebands {
                for f in [h - j as f64 * s, h + j as f64 * s] {
                    added += power(faulted, f) - power(healthy, f);
                }
            }
            if carrier > 0.0 {
                (added / carrier).max(MIN_RATIO)
            } else {
                MIN_RATIO
            }
        })
        .collect()
}

/// The model's fault signatures of every gear of `parts` in `gb` (the machine's own gearbox)
/// at input-shaft rate `input_hz` (see the [module docs](self)), each gear's pattern over its
/// harmonics [`tempered`].
pub fn simulate(gb: &Gearbox, parts: &Parts, input_hz: f64) -> Result<Response> {
    let raw = signatures(gb, parts, input_hz)?;
    Ok(Response {
        local: raw.local.into_iter().map(tempered).collect(),
        eccentric: raw.eccentric.into_iter().map(tempered).collect(),
    })
}

/// The raw `ρ(k)` of every gear (see the [module docs](self)).
fn signatures(gb: &Gearbox, parts: &Parts, input_hz: f64) -> Result<Response> {
    let f1_order = parts.meshes.first().copied().unwrap_or(1.0);
    let omega1 = gb.f1_hz(input_hz) / gb.reference_frequency_hz();
    let ea0 = 0.1;
    let per_gear: Vec<(Vec<f64>, Vec<f64>)> = parts
        .gears
        .par_iter()
        .map(|g| -> Result<(Vec<f64>, Vec<f64>)> {
            let flat = vec![1.0; HARMONICS];
            let s = parts.shafts.get(&g.shaft).copied().unwrap_or(0.0).abs() / f1_order;
            let r_m = parts.meshes.get(g.stage - 1).copied().unwrap_or(0.0) / f1_order;
            let element = gb.physics.meshes.iter().position(|m| m.stage == g.stage);
            let (Some(element), true) = (element, s >= SLOWEST_SHAFT && r_m > 0.0) else {
                return Ok((flat.clone(), flat));
            };
            let key = (r_m, s, g.teeth);
            let healthy = series(gb, omega1, element, key, Fault::Healthy, ea0)?;
            let local = series(gb, omega1, element, key, Fault::Local, ea0)?;
            let ecc = series(gb, omega1, element, key, Fault::Eccentric, ea0)?;
            Ok((
                ratios(&healthy, &local, r_m, s, 3),
                ratios(&healthy, &ecc, r_m, s, 1),
            ))
        })
        .collect::<Result<_>>()?;
    let (local, eccentric) = per_gear.into_iter().unzip();
    Ok(Response { local, eccentric })
}

/// A pattern over the harmonics relative to its geometric mean, held within
/// [`1 / PATTERN_SPAN`, `PATTERN_SPAN`]: which harmonics carry more of the fault than the others,
/// without letting one harmonic take the whole candidate.
fn tempered(v: Vec<f64>) -> Vec<f64> {
    let n = v.len().max(1) as f64;
    let g = (v.iter().map(|x| x.max(MIN_RATIO).ln()).sum::<f64>() / n).exp();
    v.into_iter()
        .map(|x| (x.max(MIN_RATIO) / g).clamp(1.0 / PATTERN_SPAN, PATTERN_SPAN))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a single spur pair (25T pinion, 67T gear) each fault's pattern is finite and positive,
    /// one entry per harmonic and gear; a damaged pinion tooth, in mesh for a larger share of
    /// its revolution, makes more sideband energy at every harmonic than a damaged gear tooth.
    #[test]
    fn a_local_fault_and_an_eccentricity_make_sidebands_of_their_own_pattern() {
        let gb = Gearbox::from_file(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../configs/gearboxes/spur-pair.toml"),
        )
        .unwrap();
        let parts = Parts::of(&gb);
        assert_eq!(parts.gears.len(), 2);
        let r = signatures(&gb, &parts, 25.0).unwrap();
        assert_eq!(r.local.len(), parts.gears.len());
        for v in r.local.iter().chain(&r.eccentric) {
            assert_eq!(v.len(), HARMONICS);
            assert!(v.iter().all(|x| x.is_finite() && *x > 0.0), "{v:?}");
        }
        for k in 0..HARMONICS {
            assert!(r.local[0][k] > r.local[1][k], "{:?}", r.local);
        }
        // A harmonic the fault reaches stands above the floor.
        assert!(
            r.local[0].iter().any(|&x| x > 100.0 * MIN_RATIO),
            "{:?}",
            r.local
        );
        assert!(
            r.eccentric[0].iter().all(|&x| x > 100.0 * MIN_RATIO),
            "{:?}",
            r.eccentric
        );
        // Tempered: each pattern relative to its own mean, within the span.
        let t = simulate(&gb, &parts, 25.0).unwrap();
        for v in t.local.iter().chain(&t.eccentric) {
            assert!(
                v.iter()
                    .all(|x| (1.0 / PATTERN_SPAN..=PATTERN_SPAN).contains(x)),
                "{v:?}"
            );
        }
    }
}
