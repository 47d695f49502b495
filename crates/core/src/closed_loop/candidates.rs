//! Step 5 of [`calibrate`](super::calibrate): the candidate models. No effect (the plain
//! model, [`super::scatter::Null`]), a path resonance searched over the whole band
//! ([`search_resonance`]), each element effect ([`super::elements`]), and the pairs: an element
//! effect with a resonance searched again over the band on top of the element's spectrum, or
//! with the single resonance's, whichever fits better; two element effects together.

use super::SensorFit;
use super::effects::{
    Effect, ElementParams, Mesh, PATH_RESONANCE, Resonance, SHAFT_MODULATION, effect_resonance,
    element_effects,
};
use super::elements::ElementFit;
use super::fit::{Weights, fit_sensor, search_resonance};
use super::measured::Measured;
use super::scatter::Null;
use super::sidebands::{SidebandCheck, SidebandScan, refuses};
use super::simulator::{Simulator, best_point};
use super::spectrum;
use crate::error::Result;

/// A candidate model fitted to the record.
pub(super) struct Fitted {
    /// Effects, joined by `+` (`none` for the plain model).
    pub name: String,
    pub effects: Vec<Effect>,
    pub params: ElementParams,
    pub sensor: SensorFit,
    /// The weighted robust score `Σ ρ(u_j)` (rescored over seeds by
    /// [`super::scoring::rescore_over_seeds`] when asked).
    pub rss: f64,
    /// Fitted parameters k (gain, noise, ea, plus the effects').
    pub k: usize,
}

/// Every candidate of the selection and what they were fitted against.
pub(super) struct Candidates {
    /// "none" first, the path resonance, the element effects, then the pairs.
    pub list: Vec<Fitted>,
    /// `list[..n_single]`: "none" and the single effects.
    pub n_single: usize,
    pub mesh: Mesh,
    /// Where the record's sidebands lie against each shaft of `mesh` ([`super::sidebands`]).
    pub sideband_checks: Vec<SidebandCheck>,
}

impl Candidates {
    /// Fit every candidate: "none" is the null's point; `p0` the plain model at the table's
    /// estimate (where the profiles start).
    pub(super) fn fit(
        ms: &Measured,
        sim: &Simulator,
        p0: ElementParams,
        null: &Null,
    ) -> Result<Candidates> {
        let (pn, sn, rn) = null.point;
        let fit = CandidateFit {
            ms,
            sim,
            w: &null.weights,
            mesh: Mesh::new(ms.gb),
        };
        let mut list = vec![Fitted {
            name: "none".into(),
            effects: vec![],
            params: pn,
            sensor: sn,
            rss: rn,
            k: 3,
        }];
        let (resonance, res_best) = fit.path_resonance(p0, pn)?;
        list.push(resonance);
        // Where the record's sidebands lie, at its own resolution ([`super::sidebands`]): shaft
        // modulation is eligible only where the strongest are at its shaft's rate, tooth damage
        // not where they are off it ([`refuses`]).
        let scan = SidebandScan::new(&ms.record.samples, ms.fs, ms.f1, spectrum::BAND_HI);
        let sideband_checks: Vec<SidebandCheck> = fit
            .mesh
            .shafts
            .iter()
            .filter_map(|g| scan.as_ref()?.check(&g.shaft, g.shaft_ratio))
            .collect();
        let elements = ElementFit {
            ms,
            sim,
            w: &null.weights,
        };
        let singles = elements.singles(pn, &fit.mesh)?;
        for (name, p) in &singles {
            list.push(fit.make(name.clone(), *p, None)?);
        }
        // Pairs: the best variant of each element effect with the resonance, and with each other.
        let n_single = list.len();
        let best = best_variants(
            &singles,
            &list[n_single - singles.len()..],
            &sideband_checks,
        );
        fit.with_resonance(&best, res_best, &mut list)?;
        fit.element_pairs(&best, &mut list)?;
        Ok(Candidates {
            list,
            n_single,
            mesh: fit.mesh,
            sideband_checks,
        })
    }
}

/// The fitting context of the candidates.
struct CandidateFit<'a> {
    ms: &'a Measured<'a>,
    sim: &'a Simulator<'a>,
    w: &'a Weights,
    mesh: Mesh,
}

impl CandidateFit<'_> {
    /// Path resonance (sensor stage): searched over the band at the plain model's best ea
    /// (`pn`), ea profiled over the whole grid with the resonance re-fitted (the plain model's
    /// simulations, cached), searched again at the new ea, profiled again. The candidate and
    /// its resonance.
    fn path_resonance(&self, p0: ElementParams, pn: ElementParams) -> Result<(Fitted, Resonance)> {
        let (m, r, w, sim) = (&self.ms.m, &self.ms.r, self.w, self.sim);
        let mut res_start = search_resonance(m, &sim.spectrum(&pn)?, r, w)
            .0
            .resonance
            .expect("fitted resonance");
        let mut prof_res = sim.profile_adaptive(m, r, p0, Some(res_start), None, w)?;
        let (pr1, _, _) = best_point(&prof_res);
        if (pr1.ea - pn.ea).abs() > 1e-9 {
            let (again, _) = search_resonance(m, &sim.spectrum(&pr1)?, r, w);
            res_start = again.resonance.expect("fitted resonance");
            let prof2 = sim.profile_adaptive(m, r, p0, Some(res_start), None, w)?;
            if best_point(&prof2).2 < best_point(&prof_res).2 {
                prof_res = prof2;
            }
        }
        let (pr, sr_, rr) = best_point(&prof_res);
        let res_best = sr_.resonance.expect("fitted");
        let fitted = Fitted {
            name: PATH_RESONANCE.into(),
            effects: vec![effect_resonance(&res_best, self.ms.f1)],
            params: pr,
            sensor: sr_,
            rss: rr,
            k: if res_best.peak_gain.is_some() { 6 } else { 5 },
        };
        Ok((fitted, res_best))
    }

    /// The model at `p` with its sensor fitted (a path resonance re-fitted from `res` when
    /// given), named `name`.
    fn make(&self, name: String, p: ElementParams, res: Option<Resonance>) -> Result<Fitted> {
        let ms = self.ms;
        let s = self.sim.spectrum(&p)?;
        let (sens, rss) = fit_sensor(&ms.m, &s, &ms.r, res, self.w);
        let mut effects = element_effects(
            &p,
            ms.baseline_planetary,
            &self.mesh.gears,
            &self.mesh.input,
        );
        if let Some(res) = sens.resonance {
            effects.push(effect_resonance(&res, ms.f1));
        }
        // gain, noise, ea + one amplitude per element effect + ρ, ζ (and g) of a resonance.
        let k = 3 + effects
            .iter()
            .map(|e| match e.name.as_str() {
                PATH_RESONANCE => 2 + e.parameters.contains_key("peak_gain") as usize,
                _ => 1,
            })
            .sum::<usize>();
        Ok(Fitted {
            name,
            effects,
            params: p,
            sensor: sens,
            rss,
            k,
        })
    }

    /// Each element effect's best variant with a path resonance. The resonance of a pair is
    /// searched again over the whole band on top of the element effect's spectrum: the one
    /// found on the plain model (`res_best`) may be a stand-in for the element's own lines. The
    /// better of that and the single resonance's is kept.
    fn with_resonance(
        &self,
        best: &[(String, ElementParams)],
        res_best: Resonance,
        list: &mut Vec<Fitted>,
    ) -> Result<()> {
        for (name, p) in best {
            let pair = format!("{name}+{PATH_RESONANCE}");
            let from_single = self.make(pair.clone(), *p, Some(res_best))?;
            let searched = search_resonance(&self.ms.m, &self.sim.spectrum(p)?, &self.ms.r, self.w)
                .0
                .resonance;
            let from_search = self.make(pair, *p, searched)?;
            list.push(if from_search.rss < from_single.rss {
                from_search
            } else {
                from_single
            });
        }
        Ok(())
    }

    /// Every two element effects' best variants together.
    fn element_pairs(
        &self,
        best: &[(String, ElementParams)],
        list: &mut Vec<Fitted>,
    ) -> Result<()> {
        for (i, (na, pa)) in best.iter().enumerate() {
            for (nb, pb) in best.iter().skip(i + 1) {
                list.push(self.make(format!("{na}+{nb}"), combine(pa, pb), None)?);
            }
        }
        Ok(())
    }
}

/// Two element parameter sets in one (each effect from the set that holds it; `pa`'s ea).
fn combine(pa: &ElementParams, pb: &ElementParams) -> ElementParams {
    ElementParams {
        eccentricity: pa.eccentricity.max(pb.eccentricity),
        ecc_shaft: if pa.eccentricity > 0.0 {
            pa.ecc_shaft
        } else {
            pb.ecc_shaft
        },
        planetary: pa.planetary.max(pb.planetary),
        tooth_depth: pa.tooth_depth.max(pb.tooth_depth),
        tooth_shaft: if pa.tooth_depth > 0.0 {
            pa.tooth_shaft
        } else {
            pb.tooth_shaft
        },
        ea: pa.ea,
    }
}

/// The lowest-score variant of each element effect among `singles` (fitted as `fits`, in the
/// same order). A variant the record's sidebands refuse cannot be claimed: the pairs take the
/// best of the others.
fn best_variants(
    singles: &[(String, ElementParams)],
    fits: &[Fitted],
    sideband_checks: &[SidebandCheck],
) -> Vec<(String, ElementParams)> {
    let mut best_variant: Vec<(String, ElementParams)> = Vec::new();
    for (k, (name, p)) in singles.iter().enumerate() {
        let shaft = match name.as_str() {
            SHAFT_MODULATION => p.ecc_shaft,
            _ => p.tooth_shaft,
        };
        if refuses(sideband_checks, name, shaft) {
            continue;
        }
        let rss = fits[k].rss;
        match best_variant.iter().position(|(n, _)| n == name) {
            Some(i) => {
                let j = singles
                    .iter()
                    .position(|(n, q)| n == name && *q == best_variant[i].1);
                let old = j.map_or(f64::INFINITY, |j| fits[j].rss);
                if rss < old {
                    best_variant[i].1 = *p;
                }
            }
            None => best_variant.push((name.clone(), *p)),
        }
    }
    best_variant
}
