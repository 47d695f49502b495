//! The residual after the fit: runs beyond a threshold ([`residual_features`]) and, for what
//! the library does not hold, a plain-words guess a person can act on ([`annotate`]).
//!
//! The guesses, in order (the first that applies):
//! 1. **Mains pickup**: two or more `extra` lines within tolerance of odd multiples of 50 Hz
//!    (or of 60 Hz), one of them at × 1, 3, 5 or 7, or one such line at 50/60/150/180 Hz:
//!    "electrical pickup".
//! 2. **Sidebands off every shaft's rate**: when the record's sidebands were measured off a
//!    shaft's rate ([`super::sidebands`], spacing `δ`), an extra line within 0.75 grid step of
//!    `a f1 ± n δ` (a = 1, 2; n = 1…3), unless `δ` lies within 0.75 record bin of 1–3 times a
//!    shaft's rate: "the speed or the load fluctuates at δ f1 Hz".
//! 3. **Harmonic of another extra line**: its frequency an integer multiple (2–6) of a
//!    stronger extra line's.
//! 4. **Broadband**: a run wider than 0.05 f1: "a raised band: broadband noise, impacts,
//!    bursts".
//! 5. **Synchronous**: at `a f1 + n f_s` (a = 0, 1, 2; |n| ≤ 3; f_s the rate of a shaft of
//!    the gearbox; or a multiple of another mesh frequency) within half a grid step: "an
//!    unmodelled component synchronous with shaft …".
//! 6. Otherwise **non-synchronous**: "a bearing or another machine?".
//!
//! `missing` runs: a line the model makes and the record lacks (wrong description, sensor
//! position, or an over-predicted line). Tolerance: 1.5 grid steps (`1.5 f1 / 128`).

use super::ResidualFeature;
use super::effects::shaft_rates;
use super::sidebands::SidebandCheck;
use super::spectrum::{GRID_PERIODS, grid_index};
use crate::gearbox::Gearbox;

/// Lines of one residual beyond ±`thr` dB (runs, reported at their extreme point).
pub(crate) fn residual_features(
    resid: &[f64],
    measured_rel: &[f64],
    r: &[f64],
    f1: f64,
    thr: f64,
) -> Vec<ResidualFeature> {
    let mut out = Vec::new();
    let mut j = 0;
    while j < resid.len() {
        let sign = if resid[j] > thr {
            1.0
        } else if resid[j] < -thr {
            -1.0
        } else {
            j += 1;
            continue;
        };
        let start = j;
        let mut best = j;
        while j < resid.len() && sign * resid[j] > thr {
            if sign * resid[j] > sign * resid[best] {
                best = j;
            }
            j += 1;
        }
        out.push(ResidualFeature {
            kind: if sign > 0.0 { "extra" } else { "missing" },
            frequency_ratio: r[best],
            frequency_hz: r[best] * f1,
            size_db: resid[best],
            level_db: measured_rel[best],
            width_ratio: (j - start) as f64 / GRID_PERIODS,
            guess: String::new(),
        });
    }
    out
}

/// Mean of `m − f` over the grid points nearest `ratios` where the measurement stands `min_db`
/// above the fitted noise floor (`None`: no such point).
pub(crate) fn fingerprint_gap(
    m: &[f64],
    f: &[f64],
    noise_db: f64,
    ratios: &[f64],
    min_db: f64,
) -> Option<f64> {
    let v: Vec<f64> = ratios
        .iter()
        .filter_map(|&x| grid_index(x))
        .filter(|&j| m[j] > noise_db + min_db)
        .map(|j| m[j] - f[j])
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The highest odd mains harmonic that can anchor a mains series (see [`annotate`]).
pub const MAINS_LOW_HARMONIC: u32 = 7;

/// Fill `guess` of every feature (see the module docs). `f1` in Hz.
pub(crate) fn annotate(
    features: &mut [ResidualFeature],
    gb: &Gearbox,
    f1: f64,
    sidebands: &[SidebandCheck],
) {
    let extra: Vec<usize> = (0..features.len())
        .filter(|&i| features[i].kind == "extra")
        .collect();
    let shafts = shaft_rates(gb);
    guess_mains(features, &extra, f1);
    guess_fluctuation(features, &extra, &shafts, f1, sidebands);
    guess_harmonics(features, &extra, f1);
    // 4–6.
    for f in features.iter_mut() {
        if f.guess.is_empty() {
            f.guess = guess_rest(f, gb, &shafts);
        }
    }
}

/// Guess 1, mains: odd harmonics of 50 or 60 Hz among the `extra` features.
fn guess_mains(features: &mut [ResidualFeature], extra: &[usize], f1: f64) {
    let step_hz = f1 / GRID_PERIODS;
    let tol_hz = 1.5 * step_hz;
    for mains in [50.0, 60.0] {
        let near = |f: f64| -> Option<u32> {
            let k = (f / mains).round();
            (k >= 1.0 && (k as u32) % 2 == 1 && (f - k * mains).abs() <= tol_hz).then_some(k as u32)
        };
        let hits: Vec<(usize, u32)> = extra
            .iter()
            .filter_map(|&i| near(features[i].frequency_hz).map(|k| (i, k)))
            .filter(|(i, _)| features[*i].guess.is_empty())
            .collect();
        // Pickup is strongest at the low odd harmonics: a series needs one at × 1–7 (with a
        // grid tolerance of ±1.5 f1/128 ≈ ±10 Hz, odd multiples of 50 Hz lie 100 Hz apart,
        // and two of several unrelated lines high up the series fall on them by chance).
        let low = hits.iter().any(|(_, k)| *k <= MAINS_LOW_HARMONIC);
        let strong_single = hits.len() == 1 && hits[0].1 <= 3;
        if (hits.len() >= 2 && low) || strong_single {
            let ks: Vec<String> = hits.iter().map(|(_, k)| k.to_string()).collect();
            for (i, k) in &hits {
                features[*i].guess = format!(
                    "{mains:.0} Hz mains and odd harmonics (this is × {k}; found × {}): \
                     electrical pickup — check the sensor cable's shield and grounding",
                    ks.join(", ")
                );
            }
        }
    }
}

/// Guess 2, sidebands off every shaft's rate: a speed or load fluctuation. (Not when the
/// spacing is a low harmonic of some shaft's rate: that shaft's own sidebands, guessed as
/// synchronous.)
fn guess_fluctuation(
    features: &mut [ResidualFeature],
    extra: &[usize],
    shafts: &[(String, f64)],
    f1: f64,
    sidebands: &[SidebandCheck],
) {
    let synchronous = |c: &SidebandCheck| {
        shafts.iter().any(|(_, v)| {
            (1..=3).any(|m| (c.spacing_ratio - m as f64 * v).abs() <= 0.75 * c.resolution_ratio)
        })
    };
    let Some(off) = sidebands.iter().find(|c| c.off_rate && !synchronous(c)) else {
        return;
    };
    let d = off.spacing_ratio;
    for &i in extra {
        if !features[i].guess.is_empty() {
            continue;
        }
        let r = features[i].frequency_ratio;
        let hit = [1.0f64, 2.0].iter().find_map(|&a| {
            (-3i32..=3)
                .filter(|n| *n != 0)
                .find(|&n| (a + n as f64 * d - r).abs() <= 0.75 / GRID_PERIODS)
                .map(|n| (a, n))
        });
        if let Some((a, n)) = hit {
            // The shaft whose rate lies nearest the spacing, for the reader (when it is
            // not the checked shaft itself).
            let near = shafts
                .iter()
                .min_by(|x, y| (x.1 - d).abs().total_cmp(&(y.1 - d).abs()))
                .filter(|(name, _)| *name != off.shaft)
                .map_or(String::new(), |(name, v)| {
                    format!(" (the nearest shaft rate: `{name}`, {:.1} Hz)", v * f1)
                });
            features[i].guess = format!(
                "a sideband ({a:.0} f1 {n:+} × {:.1} Hz) of the mesh line: the record's \
                 sidebands lie {:.1} Hz apart, off the rate of shaft `{}` ({:.1} Hz){near} \
                 — the speed or the load fluctuates at {:.1} Hz; check the drive's speed \
                 control and the driven load",
                off.spacing_hz,
                off.spacing_hz,
                off.shaft,
                off.shaft_ratio * f1,
                off.spacing_hz
            );
        }
    }
}

/// Guess 3, harmonics of a stronger extra line.
fn guess_harmonics(features: &mut [ResidualFeature], extra: &[usize], f1: f64) {
    let step_hz = f1 / GRID_PERIODS;
    let tol_hz = 1.5 * step_hz;
    for &i in extra {
        if !features[i].guess.is_empty() {
            continue;
        }
        let fi = features[i].frequency_hz;
        let base = extra.iter().copied().find(|&j| {
            let fj = features[j].frequency_hz;
            let k = (fi / fj).round();
            j != i
                && features[j].size_db >= features[i].size_db - 3.0
                && (2.0..=6.0).contains(&k)
                && (fi - k * fj).abs() <= tol_hz
        });
        if let Some(j) = base {
            features[i].guess = format!(
                "harmonic {:.0} of the extra line at {:.1} Hz: one source with harmonics",
                (fi / features[j].frequency_hz).round(),
                features[j].frequency_hz
            );
        }
    }
}

/// Guesses 4–6 of a feature no earlier guess explained: a missing line, a broadband run, a
/// line synchronous with the gearbox, or a non-synchronous one.
fn guess_rest(f: &ResidualFeature, gb: &Gearbox, shafts: &[(String, f64)]) -> String {
    let r = f.frequency_ratio;
    if f.kind == "missing" {
        return format!(
            "the model has a line at {:.1} Hz ({r:.3} f1) that the record lacks \
             ({:.1} dB): the description, the sensor position or an over-predicted line",
            f.frequency_hz, f.size_db
        );
    }
    if f.width_ratio > 0.05 {
        return format!(
            "a raised band around {:.0} Hz ({:.2} f1 wide, {:+.1} dB): broadband noise, \
             impacts or noise bursts — not a line",
            f.frequency_hz, f.width_ratio, f.size_db
        );
    }
    match synchronous_with(r, &gb.mesh_ratios, shafts) {
        Some(w) => format!(
            "a line at {:.1} Hz synchronous with the gearbox ({w}) that the model does not \
             make: misalignment, a coupling, or a fault the library does not hold",
            f.frequency_hz
        ),
        None => format!(
            "a non-synchronous line at {:.1} Hz ({:+.1} dB): a bearing or another machine?",
            f.frequency_hz, f.size_db
        ),
    }
}

/// What a line at `r` (over f1) is synchronous with, within half a grid step: `a f1 + n f_s`
/// (a = 0, 1, 2; |n| ≤ 3; f_s a shaft's rate), or a multiple (1–4) of another stage's mesh
/// frequency (`meshes`, over f1; the first is stage 1's).
fn synchronous_with(r: f64, meshes: &[f64], shafts: &[(String, f64)]) -> Option<String> {
    let tol_r = 0.5 / GRID_PERIODS;
    for (name, s) in shafts {
        for a in 0..=2 {
            for n in -3i32..=3 {
                if a == 0 && n <= 0 {
                    continue;
                }
                if (a as f64 + n as f64 * s - r).abs() <= tol_r {
                    return Some(if a == 0 {
                        format!("order {n} of shaft `{name}`")
                    } else {
                        format!("{a} f1 {:+} × shaft `{name}`", n)
                    });
                }
            }
        }
    }
    for (k, fk) in meshes.iter().enumerate().skip(1) {
        let h = (r / fk).round();
        if (1.0..=4.0).contains(&h) && (r - h * fk).abs() <= tol_r {
            return Some(format!("{h:.0} × the stage-{} mesh frequency", k + 1));
        }
    }
    None
}
