//! Whether a record's effect changes its spectrum by more than the noise (module docs): the
//! one-draw measure, the K-draw measure, and a pair's members one at a time.

use std::f64::consts::SQRT_2;

use gearwear::closed_loop::spectrum::log_spectrum;
use gearwear::closed_loop::virtual_rig::{
    RigEffects, RigSpec, effect_visibility, generate, spread_of_difference,
};
use gearwear::gearbox::Gearbox;
use gearwear::signature::mix_seed;
use rayon::prelude::*;

use super::draw::Draw;
use super::row::{Members, Row};

/// Records of the same gearbox as a drawn one, their log spectra on the closed loop's grid.
struct Rig<'a> {
    gb: &'a Gearbox,
    spec: RigSpec,
    /// The true f1 (Hz).
    f1: f64,
    k_draws: usize,
}

/// The row of `d` with its visibility (`samples`: the record; `f1` the true f1, Hz).
pub fn seen(
    gb: &Gearbox,
    d: &Draw,
    samples: &[f64],
    f1: f64,
    k_draws: usize,
) -> Result<Row, String> {
    let rig = Rig {
        gb,
        spec: d.spec,
        f1,
        k_draws,
    };
    let m = rig.ls(samples)?;
    let clean = d.kind == "clean";
    let (v_effect, v_noise) = if clean { (0.0, 0.0) } else { rig.one_draw(&m)? };
    // The K-draw measure (module docs): K records with the effect (this one and K − 1 other
    // seeds) against K without it (K other seeds).
    let (with_k, vis_d, vis_s) = if clean {
        (Vec::new(), 0.0, 0.0)
    } else {
        // Draw 0 is the record itself.
        let mut with_k = vec![m.clone()];
        with_k.extend(rig.draws(d.e, 0xD1, 1)?);
        let without_k = rig.draws(RigEffects::default(), 0xD0, 0)?;
        let (d, s) = effect_visibility(&with_k, &without_k);
        (with_k, d, s)
    };
    let (member_visible, member_visible_k): (Members, Members) = if d.kind == "pair" {
        rig.members(d, &m, &with_k, v_noise)?
    } else {
        (Vec::new(), Vec::new())
    };
    // The row's draw and visibility, shared by both answers.
    Ok(Row {
        visible: !clean && v_effect > v_noise,
        v_effect,
        v_noise,
        visible_k: !clean && vis_d > SQRT_2 * vis_s,
        vis_d,
        vis_s,
        member_visible,
        member_visible_k,
        ..d.blank(None)
    })
}

impl Rig<'_> {
    /// The log spectrum of a record on the grid at the true f1.
    fn ls(&self, x: &[f64]) -> Result<Vec<f64>, String> {
        log_spectrum(x, self.spec.sample_rate, self.f1).map_err(|e| e.to_string())
    }

    /// The record generated from `spec`, its log spectrum.
    fn spectrum_of(&self, spec: &RigSpec) -> Result<Vec<f64>, String> {
        let r = generate(self.gb, spec).map_err(|e| e.to_string())?;
        self.ls(&r.samples)
    }

    /// The one-draw measure's two figures: the record `m` against the same record without the
    /// effect, and against the same record with another seed.
    fn one_draw(&self, m: &[f64]) -> Result<(f64, f64), String> {
        let spec = self.spec;
        let without = self.spectrum_of(&RigSpec {
            effects: RigEffects::default(),
            ..spec
        })?;
        let other = self.spectrum_of(&RigSpec {
            seed: spec.seed ^ 0x5EED_0000_7777,
            ..spec
        })?;
        Ok((
            spread_of_difference(m, &without),
            spread_of_difference(m, &other),
        ))
    }

    /// Draws `from..K` with `effects` (seeds mixed from the record's, `salt` and the draw
    /// index), in parallel.
    fn draws(&self, effects: RigEffects, salt: u64, from: usize) -> Result<Vec<Vec<f64>>, String> {
        let spec = self.spec;
        (from..self.k_draws)
            .into_par_iter()
            .map(|j| {
                let seed = mix_seed(&[spec.seed, salt, j as u64]);
                self.spectrum_of(&RigSpec {
                    effects,
                    seed,
                    ..spec
                })
            })
            .collect()
    }

    /// A pair's members one at a time: the record `m` against the same record without that
    /// member (the other kept), by both measures (`with_k`: the K draws with both members).
    fn members(
        &self,
        d: &Draw,
        m: &[f64],
        with_k: &[Vec<f64>],
        v_noise: f64,
    ) -> Result<(Members, Members), String> {
        let mut one = Vec::new();
        let mut many = Vec::new();
        for (idx, name) in d.truth.iter().enumerate() {
            let mut less = d.e;
            if name == "path-resonance" {
                less.path_peak = None;
            } else {
                less.eccentricity = None;
                less.eccentricity_shaft = None;
                less.tooth = None;
            }
            let w = self.spectrum_of(&RigSpec {
                effects: less,
                ..self.spec
            })?;
            one.push((name.clone(), spread_of_difference(m, &w) > v_noise));
            let (dk, s) = effect_visibility(with_k, &self.draws(less, 0xD2 + idx as u64, 0)?);
            many.push((name.clone(), dk > SQRT_2 * s));
        }
        Ok((one, many))
    }
}
