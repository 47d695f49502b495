//! A virtual test rig: "measured" records from the model plus effects, some of which the
//! closed loop's library knows and some it does not.
//!
//! Signal chain (physical time, sample rate `fs`):
//! 1. the augmented Model A ([`super::effects::build_model`]: wear `ea`, planetary error,
//!    eccentricity) simulated from a random initial state after a transient; sensor ẍ̄1;
//! 2. speed wander (not in the library): the record is read on a warped time axis
//!    `t' = t + (δ / (2π f_w)) sin(2π f_w t)`, i.e. the speed varies by ±δ at rate `f_w`
//!    (cubic interpolation);
//! 3. path resonance: a digital biquad (bilinear transform, pre-warped at the resonance) of
//!    `H(s) = ω_r² / (s² + 2ζ ω_r s + ω_r²)`;
//!    A peaking path mode `H(s) = 1 + g · 2ζω_r s / (s² + 2ζω_r s + ω_r²)` the same way;
//! 4. an unrelated tone (not in the library) `A sin(2π r_t f1 t)` with `A` set `level_db` re the
//!    f1 line amplitude of the signal so far, with harmonics k = 2, 3, … each 6 dB weaker;
//!    mains hum at 50 or 60 Hz with odd harmonics 3, 5, 7 (each 4 dB weaker);
//! 5. white Gaussian noise at `snr_db` (noise power = signal AC power × 10^(−SNR/10)), then
//!    noise bursts (not in the library: 10 ms of white noise at a level re the signal RMS) and
//!    the overall gain, drifting linearly by ± `gain_drift` over the record when set.
//!
//! Element effects: wear, planetary error, shaft modulation (on the input shaft or the shaft
//! of the given rate), a damaged tooth ([`crate::model::ToothDamage`] through
//! [`super::effects::build_model`]).

use std::f64::consts::{PI, TAU};

use serde::Serialize;

use super::effects::{ElementParams, build_model};
use crate::error::{Error, Result};
use crate::gearbox::Gearbox;
use crate::record::Record;
use crate::signal::line_amplitude;
use crate::signature::precompute::{SimOptions, random_initial, simulate_sensor};
use crate::signature::{SensorQuantity, SplitMix64};
use crate::solver::Dopri5Options;

/// Which effects the rig switches on (the pipeline under test never sees this).
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct RigEffects {
    /// Shaft-modulation sideband amplitude on mesh x1 (units of b).
    pub eccentricity: Option<f64>,
    /// Path resonance `(ρ = f_r / f1, ζ)`.
    pub resonance: Option<(f64, f64)>,
    /// Planetary error amplitude (units of b); `None`: the baseline 0.1.
    pub planetary: Option<f64>,
    /// Unrelated tone `(frequency over f1, level dB re the f1 line)`.
    pub tone: Option<(f64, f64)>,
    /// Speed wander `(relative depth δ, rate over f1)`.
    pub speed_wander: Option<(f64, f64)>,
    /// Rate over f1 of the shaft that modulates (`None`: the input shaft).
    pub eccentricity_shaft: Option<f64>,
    /// A peaking path mode `(ρ = f_r / f1, ζ, peak gain g)`.
    pub path_peak: Option<(f64, f64, f64)>,
    /// A damaged tooth `(its shaft's rate over f1, stiffness loss)`.
    pub tooth: Option<(f64, f64)>,
    /// Number of tones of the harmonic series of `tone` (0 or 1: the tone alone).
    pub tone_harmonics: u32,
    /// Mains hum `(50 or 60 Hz, level of the fundamental dB re the f1 line)`.
    pub mains: Option<(f64, f64)>,
    /// Noise bursts `(count, RMS level re the signal RMS, dB)`.
    pub bursts: Option<(u32, f64)>,
    /// Relative gain change from the start to the end of the record.
    pub gain_drift: Option<f64>,
}

/// A virtual measurement.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct RigSpec {
    pub ea: f64,
    pub omega1: f64,
    /// Hz.
    pub sample_rate: f64,
    /// s.
    pub duration: f64,
    /// Overall gain (the pipeline must not care).
    pub gain: f64,
    /// Signal-to-noise power ratio of the white measurement noise (dB).
    pub snr_db: f64,
    pub seed: u64,
    pub effects: RigEffects,
}

/// A tachometer channel beside a rig record of `n` samples at `fs` (Hz): `pulses_per_rev`
/// square pulses (0/5 V, half duty) per revolution of the input shaft turning at a constant
/// `shaft_hz` — what a machine's once- or several-per-revolution sensor sends. (A record with
/// speed wander has no such constant rate.)
pub fn tachometer(n: usize, fs: f64, shaft_hz: f64, pulses_per_rev: usize) -> Vec<f64> {
    let rate = shaft_hz * pulses_per_rev as f64;
    (0..n)
        .map(|i| {
            if (i as f64 / fs * rate).fract() < 0.5 {
                5.0
            } else {
                0.0
            }
        })
        .collect()
}

/// Generate the record of [`RigSpec`] (see the module docs for the chain).
pub fn generate(gb: &Gearbox, spec: &RigSpec) -> Result<Record> {
    if !(spec.sample_rate > 0.0 && spec.duration > 0.0 && spec.gain.is_finite()) {
        return Err(Error::param(
            "sample rate / duration",
            spec.sample_rate,
            "both must be positive",
        ));
    }
    let e = &spec.effects;
    let model = build_model(
        gb,
        &ElementParams {
            ea: spec.ea,
            planetary: e.planetary.or(gb.planetary_baseline()).unwrap_or(0.0),
            eccentricity: e.eccentricity.unwrap_or(0.0),
            ecc_shaft: e.eccentricity_shaft.unwrap_or(0.0),
            tooth_depth: e.tooth.map_or(0.0, |t| t.1),
            tooth_shaft: e.tooth.map_or(0.0, |t| t.0),
        },
    )?;
    let fs = spec.sample_rate;
    let f1 = spec.omega1 * gb.reference_frequency_hz();
    let mut rng = SplitMix64::new(spec.seed);
    let initial = random_initial(model.n(), 2.0, spec.omega1, &mut rng);
    let transient = 400.0 + rng.range(0.0, 200.0);
    let samples = (fs * spec.duration).round() as usize;
    // A margin for the time warp.
    let extra = if e.speed_wander.is_some() {
        (0.05 * samples as f64) as usize + 8
    } else {
        0
    };
    let rec = simulate_sensor(
        &model,
        &initial,
        &SimOptions {
            omega1: spec.omega1,
            transient_tau: transient,
            dt_tau: model.omega_h / fs,
            samples: samples + 2 * extra,
            sensor: SensorQuantity::Accel,
            poincare_every: 0,
            solver: Dopri5Options::default(),
        },
    )?;
    let mut x: Vec<f64> = match e.speed_wander {
        None => rec.series,
        Some((depth, rate)) => {
            let fw = rate * f1;
            (0..samples)
                .map(|n| {
                    let t = n as f64 / fs;
                    let tw = t + depth / (TAU * fw) * (TAU * fw * t).sin();
                    cubic(&rec.series, extra as f64 + tw * fs)
                })
                .collect()
        }
    };
    if let Some((rho, zeta)) = e.resonance {
        biquad_resonance(&mut x, fs, rho * f1, zeta);
    }
    if let Some((rho, zeta, g)) = e.path_peak {
        biquad_peak(&mut x, fs, rho * f1, zeta, g);
    }
    let a1 = if e.tone.is_some() || e.mains.is_some() {
        line_amplitude(&x, fs, f1)?
    } else {
        0.0
    };
    let add_tone = |x: &mut [f64], hz: f64, level_db: f64, ph: f64| {
        if hz >= 0.45 * fs {
            return;
        }
        let a = a1 * 10f64.powf(level_db / 20.0);
        for (n, v) in x.iter_mut().enumerate() {
            *v += a * (TAU * hz * n as f64 / fs + ph).sin();
        }
    };
    if let Some((ratio, level_db)) = e.tone {
        for k in 1..=e.tone_harmonics.max(1) {
            let ph = rng.range(0.0, TAU);
            add_tone(
                &mut x,
                k as f64 * ratio * f1,
                level_db - 6.0 * (k - 1) as f64,
                ph,
            );
        }
    }
    if let Some((hz, level_db)) = e.mains {
        for (i, k) in [1.0, 3.0, 5.0, 7.0].iter().enumerate() {
            let ph = rng.range(0.0, TAU);
            add_tone(&mut x, k * hz, level_db - 4.0 * i as f64, ph);
        }
    }
    let n = x.len().max(1) as f64;
    let mean = x.iter().sum::<f64>() / n;
    let power = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let sigma = (power / 10f64.powf(spec.snr_db / 10.0)).sqrt();
    for v in x.iter_mut() {
        *v += sigma * rng.normal();
    }
    if let Some((count, level_db)) = e.bursts {
        let len = ((0.01 * fs) as usize).max(1).min(x.len());
        let a = power.sqrt() * 10f64.powf(level_db / 20.0);
        for _ in 0..count {
            let start = rng.range(0.0, (x.len() - len) as f64) as usize;
            for v in &mut x[start..start + len] {
                *v += a * rng.normal();
            }
        }
    }
    let drift = e.gain_drift.unwrap_or(0.0);
    for (i, v) in x.iter_mut().enumerate() {
        *v *= spec.gain * (1.0 + drift * (i as f64 / n - 0.5));
    }
    Ok(Record {
        samples: x,
        sample_rate: fs,
    })
}

/// Catmull–Rom interpolation of `s` at fractional index `pos` (clamped to the ends).
fn cubic(s: &[f64], pos: f64) -> f64 {
    let last = s.len() as isize - 1;
    let i = pos.floor() as isize;
    let u = pos - i as f64;
    let at = |k: isize| s[k.clamp(0, last) as usize];
    let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
    0.5 * (2.0 * p1
        + (-p0 + p2) * u
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u * u
        + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * u * u * u)
}

/// Filter `x` in place with the bilinear transform (pre-warped at `fr`) of the peaking mode
/// `1 + g · 2ζω_r s / (s² + 2ζω_r s + ω_r²)` (unit gain away from `fr`, `1 + g` at it).
fn biquad_peak(x: &mut [f64], fs: f64, fr: f64, zeta: f64, g: f64) {
    let w = TAU * fr;
    let k = w / (PI * fr / fs).tan();
    let (w2, k2) = (w * w, k * k);
    let c = 2.0 * zeta * w * (1.0 + g);
    let d = 2.0 * zeta * w;
    // Numerator s² + c s + w², denominator s² + d s + w², s = k (z − 1)/(z + 1).
    let a0 = k2 + d * k + w2;
    let b = [
        (k2 + c * k + w2) / a0,
        (2.0 * w2 - 2.0 * k2) / a0,
        (k2 - c * k + w2) / a0,
    ];
    let a1 = (2.0 * w2 - 2.0 * k2) / a0;
    let a2 = (k2 - d * k + w2) / a0;
    let (mut x1, mut x2, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0);
    for v in x.iter_mut() {
        let x0 = *v;
        let y0 = b[0] * x0 + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2;
        x2 = x1;
        x1 = x0;
        y2 = y1;
        y1 = y0;
        *v = y0;
    }
}

/// Filter `x` in place with the bilinear transform (pre-warped at `fr`) of the unit-DC-gain
/// resonance `ω_r² / (s² + 2ζω_r s + ω_r²)`.
fn biquad_resonance(x: &mut [f64], fs: f64, fr: f64, zeta: f64) {
    let w = TAU * fr;
    let k = w / (PI * fr / fs).tan(); // pre-warp: s = k (z − 1)/(z + 1)
    let (w2, k2) = (w * w, k * k);
    let a0 = k2 + 2.0 * zeta * w * k + w2;
    let b = [w2 / a0, 2.0 * w2 / a0, w2 / a0];
    let a1 = (2.0 * w2 - 2.0 * k2) / a0;
    let a2 = (k2 - 2.0 * zeta * w * k + w2) / a0;
    let (mut x1, mut x2, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0);
    for v in x.iter_mut() {
        let x0 = *v;
        let y0 = b[0] * x0 + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2;
        x2 = x1;
        x1 = x0;
        y2 = y1;
        y1 = y0;
        *v = y0;
    }
}

/// Whether an effect is visible in a record, from K records with it and K without it (other
/// seeds: other initial states and noise), each a log spectrum on one grid (dB).
///
/// Returns `(d, s)`: `s²` is the per-point variance between the draws, pooled over both sets
/// and averaged over the grid (one record's scatter), and
/// `d = sqrt(max(0, D² − (1/K_with + 1/K_without) s²))` with
/// `D = std_j(mean_with_j − mean_without_j)` (the RMS about the mean difference, so that a level
/// change alone does not count): the effect's change of the expected spectrum, less the part the
/// draws' scatter explains. The benchmark calls an effect visible when `d > √2 s`, i.e. it
/// changes the spectrum by more than two records of the same gearbox differ. Unlike a
/// comparison of one record with and without the effect, this does not depend on the draw: in a
/// chaotic model any change, however small, sends the trajectory elsewhere.
///
/// Both sets need at least two spectra of one length.
pub fn effect_visibility(with: &[Vec<f64>], without: &[Vec<f64>]) -> (f64, f64) {
    let mean = |set: &[Vec<f64>]| -> Vec<f64> {
        let k = set.len() as f64;
        (0..set[0].len())
            .map(|j| set.iter().map(|v| v[j]).sum::<f64>() / k)
            .collect()
    };
    let var = |set: &[Vec<f64>], mu: &[f64]| -> f64 {
        let k = set.len() as f64;
        mu.iter()
            .enumerate()
            .map(|(j, m)| set.iter().map(|v| (v[j] - m).powi(2)).sum::<f64>() / (k - 1.0))
            .sum::<f64>()
            / mu.len() as f64
    };
    let (mw, mo) = (mean(with), mean(without));
    let s2 = 0.5 * (var(with, &mw) + var(without, &mo));
    let d2 = spread_of_difference(&mw, &mo).powi(2)
        - s2 * (1.0 / with.len() as f64 + 1.0 / without.len() as f64);
    (d2.max(0.0).sqrt(), s2.sqrt())
}

/// The RMS of `a − b` about its mean (dB for log spectra): how differently two spectra are
/// shaped, a level change alone reading 0.
pub fn spread_of_difference(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let mean = d.iter().sum::<f64>() / n;
    (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `k` draws of `base + pattern + N(0, sigma²)` per point (Box–Muller on SplitMix64).
    fn draws(k: usize, pattern: &[f64], sigma: f64, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = SplitMix64::new(seed);
        (0..k)
            .map(|_| {
                pattern
                    .iter()
                    .map(|p| {
                        let (u1, u2) = (rng.uniform().max(1e-300), rng.uniform());
                        p + sigma * (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_same_spectrum_with_scatter_is_not_an_effect() {
        let flat = vec![-40.0; 314];
        // Pure scatter: the corrected d is small against s, however large the scatter.
        for (seed, sigma) in [(1, 1.0), (2, 3.0), (3, 8.0)] {
            let (d, s) = effect_visibility(
                &draws(4, &flat, sigma, seed),
                &draws(4, &flat, sigma, seed + 100),
            );
            assert!((s / sigma - 1.0).abs() < 0.1, "s {s} for sigma {sigma}");
            assert!(d < 0.35 * s, "d {d} s {s}: scatter taken for an effect");
        }
    }

    #[test]
    fn a_shape_change_is_measured_and_a_level_change_is_not() {
        let flat = vec![-40.0; 314];
        // A raised band of 6 dB over a fifth of the grid: RMS about its mean = 6·sqrt(0.2·0.8).
        let band: Vec<f64> = (0..314)
            .map(|j| {
                if (100..163).contains(&j) {
                    -34.0
                } else {
                    -40.0
                }
            })
            .collect();
        let (d, s) = effect_visibility(&draws(6, &band, 1.0, 7), &draws(6, &flat, 1.0, 8));
        let truth = 6.0 * (0.2f64 * 0.8).sqrt();
        assert!((d - truth).abs() < 0.15 * truth, "d {d} for {truth}");
        assert!(d > std::f64::consts::SQRT_2 * s);
        // The whole spectrum 10 dB higher: a level change only.
        let up: Vec<f64> = flat.iter().map(|v| v + 10.0).collect();
        let (d, s) = effect_visibility(&draws(4, &up, 1.0, 9), &draws(4, &flat, 1.0, 10));
        assert!(d < 0.35 * s, "a level change counted: d {d} s {s}");
    }
}

/// One mesh's physics over its description's (the unknown machine of a check: every mesh
/// its own, unlike a description's per-stage [`crate::gearbox::PhysicsFactors`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeshPhysics {
    pub stiffness: f64,
    pub damping: f64,
    pub fluctuation: f64,
    pub error: f64,
}

/// `gb` with each mesh's stiffness, damping ratio, first-harmonic fluctuation and error scale
/// multiplied by its entry of `meshes` (in the physics' mesh order; missing: unchanged) and
/// `ω_h` moved with the reference mesh's stiffness (`√factor`). The description and its hash
/// stay the base's: this machine is not a description, it is what a description misses. A
/// record of it at input rate `n` is at `Ω1 = f1(n) / f_ref` of the returned gearbox.
pub fn with_mesh_physics(gb: &Gearbox, meshes: &[MeshPhysics]) -> Result<Gearbox> {
    use crate::model::StiffnessShape;
    let mut g = gb.clone();
    for (m, f) in g.physics.meshes.iter_mut().zip(meshes) {
        m.stiffness_n_per_m *= f.stiffness;
        m.damping_ratio *= f.damping;
        m.error_scale *= f.error;
        if let StiffnessShape::FirstHarmonic { eps } = m.shape {
            m.shape = StiffnessShape::FirstHarmonic {
                eps: (eps * f.fluctuation).min(0.95),
            };
        }
    }
    if let Some(f) = meshes.first() {
        g.physics.reference_frequency_hz *= f.stiffness.sqrt();
    }
    // It must still resolve.
    g.assembly(crate::model::Wear::fixed_axis(0.5))?.resolve()?;
    Ok(g)
}
