//! The model as the explainer: which candidate part's predicted change explains a record's
//! measured change from its state's baseline, and how much of it.
//!
//! # The measured change
//! Every line-class feature ([`super::lines`], [`super::evidence`]) is the logarithm of an
//! amplitude, `v_f = ½ ln E_f` with `E_f` the class's energy. Against the state's reference
//! `r_f` and scale `s_f` ([`super::calibration`]), the record's change is `z_f = (v_f − r_f) /
//! s_f`, and its size `χ² = Σ z_f²` over the features a candidate can explain (TSA metrics and
//! raw statistics are not energies: they support a finding, they are not fitted).
//!
//! # Candidates
//! A fault **adds energy** to the classes it excites: a candidate `c` is a few components `k`,
//! each a fixed pattern `w_ck,f ≥ 0` of added energy with a free amplitude `a_ck ≥ 0`, so that
//! its predicted energies are `E_f = E_ref,f + Σ_k a_ck w_ck,f` ([`super::candidates`] builds
//! them from the description's kinematics and the simulated response of each gear fault). A
//! change of the transfer path (a sensor remounted, a gearbox reassembled, a resonance moved)
//! instead **scales** everything in a region: `E_f = (1 + τ) E_ref,f`, `τ > −1`, rise or fall.
//!
//! # Ranking
//! First the **common changes** — a band's gain, a stage's mesh lines — each at the median of
//! its features' changes (what most of them did: the few lines a fault raised further do not
//! pull it); then the **parts**, greedy, strongest first: each candidate's amplitudes are
//! fitted alone to the part of the change not yet explained (least squares in `z`, `a ≥ 0`),
//! its **gain** is the drop of `χ²` it achieves, and the candidate of largest gain is taken,
//! its predicted energies becoming the reference of the next round. So a part is named by
//! where the vibration changed *more* than the band around it. A candidate is taken only when
//! its gain is at least [`MIN_GAIN`] — more than fitting a few amplitudes to the healthy
//! spread could give — and at least [`MIN_SHARE`] of the change, and at most [`MAX_PICKS`]
//! are taken. Each pick's **share** is its gain
//! over the change's `χ²`; what is left is unexplained.

use std::collections::BTreeMap;

use super::calibration::Departure;

/// Smallest drop of `χ²` a candidate must achieve to be taken: two features at 3 scales.
pub const MIN_GAIN: f64 = 18.0;
/// Most candidates taken.
pub const MAX_PICKS: usize = 5;
/// Smallest share of the change a candidate must explain to be taken: in a large change, a
/// gain of a few features' worth is the patterns' misfit, not a part.
pub const MIN_SHARE: f64 = 0.02;

/// What a candidate stands for.
#[derive(Debug, Clone, PartialEq)]
pub enum Cause {
    /// A gear's local tooth damage (chipped, cracked, broken): a comb of sidebands at its
    /// shaft's rate around its mesh's harmonics, impacts in the envelope.
    GearLocal { gear: usize },
    /// A gear's eccentricity: the first sidebands at its shaft's rate, its shaft's 1×.
    GearEccentric { gear: usize },
    /// A shaft's imbalance, bend or misalignment: its 1×, 2× and low harmonics.
    Shaft { shaft: String },
    /// A bearing's defect (`bpfo`, `bpfi`, `bsf`): its lines in the envelope.
    Bearing {
        bearing: String,
        defect: &'static str,
    },
    /// Vibration at no shaft's lines, no described bearing's: friction, looseness, an
    /// undescribed bearing.
    NonSynchronous,
    /// A stage's mesh lines changed together (tooth wear, load, contact).
    MeshLines { stage: usize },
    /// The transfer path changed in a band of the spectrum (`low`, `mesh`, `high`, `env`).
    Path { region: String },
}

/// A candidate: its cause and its components' patterns of added energy (feature → energy per
/// unit amplitude); a path candidate has one component, the region's features.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub cause: Cause,
    pub components: Vec<BTreeMap<String, f64>>,
}

impl Candidate {
    /// A gain on its features (rise or fall) rather than energy added.
    fn is_path(&self) -> bool {
        matches!(self.cause, Cause::Path { .. } | Cause::MeshLines { .. })
    }
}

/// A taken candidate.
#[derive(Debug, Clone, PartialEq)]
pub struct Pick {
    pub cause: Cause,
    /// Drop of `χ²` it achieved.
    pub gain: f64,
    /// `gain` over the change's `χ²`.
    pub share: f64,
    /// Each feature it moved: `(feature, predicted change of z, the feature's z against what
    /// earlier picks left)`, largest change first.
    pub moved: Vec<(String, f64, f64)>,
    /// Fitted amplitudes (a path: `τ`).
    pub amplitudes: Vec<f64>,
}

/// The explanation of a record's change.
#[derive(Debug, Clone, PartialEq)]
pub struct Explanation {
    pub picks: Vec<Pick>,
    /// `χ²` of the change over the explainable features.
    pub total: f64,
    /// `χ²` left after the picks.
    pub left: f64,
    /// The features left most departing after the picks: `(feature, z)`, largest `|z|` first.
    pub residual: Vec<(String, f64)>,
}

/// The state of the fit: per explainable feature, the measured log energy, the current
/// reference energy and the scale in log energy (`2 s_f`).
struct Fit {
    measured: BTreeMap<String, f64>,
    current: BTreeMap<String, f64>,
    scale: BTreeMap<String, f64>,
}

impl Fit {
    fn z(&self, f: &str, energy: f64) -> f64 {
        (self.measured[f] - energy.max(1e-300).ln()) / self.scale[f]
    }

    fn chi2(&self) -> f64 {
        self.current
            .iter()
            .map(|(f, e)| self.z(f, *e).powi(2))
            .sum()
    }

    /// The predicted energies of the features `c` touches, with amplitudes `a`.
    fn predicted(&self, c: &Candidate, a: &[f64]) -> BTreeMap<String, f64> {
        let mut out: BTreeMap<String, f64> = BTreeMap::new();
        for (k, comp) in c.components.iter().enumerate() {
            for (f, w) in comp {
                let Some(&base) = self.current.get(f) else {
                    continue;
                };
                let e = out.entry(f.clone()).or_insert(base);
                if c.is_path() {
                    *e *= 1.0 + a[k];
                } else {
                    *e += a[k] * w;
                }
            }
        }
        out
    }

    /// `χ²` over the features `c` touches, with amplitudes `a`, and without (`a = 0`).
    fn local_chi2(&self, c: &Candidate, a: &[f64]) -> f64 {
        self.predicted(c, a)
            .iter()
            .map(|(f, e)| self.z(f, *e).powi(2))
            .sum()
    }

    /// The amplitudes of `c` that minimise `χ²` (coordinate descent, a golden-section search
    /// in `ln a` per component), and the gain over `a = 0`.
    fn fit(&self, c: &Candidate) -> (Vec<f64>, f64) {
        let zero = vec![0.0; c.components.len()];
        let before = self.local_chi2(c, &zero);
        let mut a = zero;
        for _round in 0..3 {
            for k in 0..c.components.len() {
                let (lo, hi) = self.range(c, k);
                if !(hi > lo) {
                    continue;
                }
                let at = |v: f64| {
                    let mut b = a.clone();
                    b[k] = v;
                    self.local_chi2(c, &b)
                };
                a[k] = golden(lo, hi, &at, c.is_path());
            }
        }
        let after = self.local_chi2(c, &a);
        (a, before - after)
    }

    /// A common change (a gain on every feature of `c`, rise or fall): the median of its
    /// features' log-energy changes — what most of them did, so that the few lines a fault
    /// raised further do not pull it — and the gain over no change.
    fn common(&self, c: &Candidate) -> (Vec<f64>, f64) {
        let mut d: Vec<f64> = c.components[0]
            .keys()
            .filter(|f| self.current.contains_key(*f))
            .map(|f| self.measured[f] - self.current[f].ln())
            .collect();
        if d.is_empty() {
            return (vec![0.0], 0.0);
        }
        let tau = crate::signal::median(&mut d).exp() - 1.0;
        let before = self.local_chi2(c, &[0.0]);
        let after = self.local_chi2(c, &[tau]);
        (vec![tau], before - after)
    }

    /// The search interval of component `k`: a path's `τ` over `(−0.99, 10³)`; an amplitude
    /// up to ten times what would lift any of its features to its measured energy alone.
    fn range(&self, c: &Candidate, k: usize) -> (f64, f64) {
        if c.is_path() {
            return (-0.99, 1e3);
        }
        let hi = c.components[k]
            .iter()
            .filter(|(f, w)| **w > 0.0 && self.current.contains_key(*f))
            .map(|(f, w)| (self.measured[f].exp() - self.current[f]).max(0.0) / w)
            .fold(0.0f64, f64::max);
        (0.0, 10.0 * hi)
    }
}

/// The minimum of `f` over `[lo, hi]`: a path's `τ` searched in `ln(1 + τ)`, an amplitude in
/// `ln a` from `hi · 1e-8` (and `a = 0` kept when better).
fn golden(lo: f64, hi: f64, f: &dyn Fn(f64) -> f64, path: bool) -> f64 {
    type Map = fn(f64) -> f64;
    let (to, from): (Map, Map) = if path {
        (|u| u.exp() - 1.0, |t| (1.0 + t).ln())
    } else {
        (f64::exp, f64::ln)
    };
    let (mut a, mut b) = if path {
        (from(lo), from(hi))
    } else {
        (from(hi * 1e-8), from(hi))
    };
    const R: f64 = 0.618_033_988_749_895;
    let mut c = b - R * (b - a);
    let mut d = a + R * (b - a);
    let (mut fc, mut fd) = (f(to(c)), f(to(d)));
    for _ in 0..60 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - R * (b - a);
            fc = f(to(c));
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + R * (b - a);
            fd = f(to(d));
        }
    }
    let best = to(0.5 * (a + b));
    if !path && f(0.0) <= f(best) {
        0.0
    } else {
        best
    }
}

/// Explain `departures` (a record against its state's reference) by `candidates` (see the
/// [module docs](self)); only features some candidate touches are fitted.
pub fn explain(departures: &[Departure], candidates: &[Candidate]) -> Explanation {
    let touched = |f: &str| {
        candidates
            .iter()
            .any(|c| c.components.iter().any(|m| m.contains_key(f)))
    };
    let mut fit = Fit {
        measured: BTreeMap::new(),
        current: BTreeMap::new(),
        scale: BTreeMap::new(),
    };
    for d in departures
        .iter()
        .filter(|d| touched(&d.feature) && d.scale > 0.0)
    {
        fit.measured
            .insert(d.feature.clone(), 2.0 * (d.reference + d.change));
        fit.current
            .insert(d.feature.clone(), (2.0 * d.reference).exp());
        fit.scale.insert(d.feature.clone(), 2.0 * d.scale);
    }
    let total = fit.chi2();
    let mut picks: Vec<Pick> = Vec::new();
    let (common, parts): (Vec<&Candidate>, Vec<&Candidate>) =
        candidates.iter().partition(|c| c.is_path());
    take(&mut fit, &common, &mut picks, total, |f, c| f.common(c));
    take(&mut fit, &parts, &mut picks, total, |f, c| f.fit(c));
    let left = fit.chi2();
    let mut residual: Vec<(String, f64)> = fit
        .current
        .iter()
        .map(|(f, e)| (f.clone(), fit.z(f, *e)))
        .collect();
    residual.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
    Explanation {
        picks,
        total,
        left,
        residual,
    }
}

/// Take candidates greedily, largest gain first, while a gain reaches [`MIN_GAIN`] (at most
/// [`MAX_PICKS`] in all): each taken candidate's predicted energies become the reference.
fn take(
    fit: &mut Fit,
    candidates: &[&Candidate],
    picks: &mut Vec<Pick>,
    total: f64,
    fitter: impl Fn(&Fit, &Candidate) -> (Vec<f64>, f64),
) {
    while picks.len() < MAX_PICKS {
        let best = candidates
            .iter()
            .filter(|c| !picks.iter().any(|p| p.cause == c.cause))
            .map(|c| {
                let (a, gain) = fitter(fit, c);
                (*c, a, gain)
            })
            .max_by(|x, y| x.2.total_cmp(&y.2));
        let Some((c, a, gain)) = best.filter(|b| b.2 >= MIN_GAIN && b.2 >= MIN_SHARE * total)
        else {
            return;
        };
        let new = fit.predicted(c, &a);
        let mut moved: Vec<(String, f64, f64)> = new
            .iter()
            .map(|(f, e)| {
                let before = fit.current[f];
                (
                    f.clone(),
                    (e.ln() - before.ln()) / fit.scale[f],
                    fit.z(f, before),
                )
            })
            .filter(|(_, dz, _)| dz.abs() > 1e-6)
            .collect();
        moved.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
        for (f, e) in new {
            fit.current.insert(f, e);
        }
        picks.push(Pick {
            cause: c.cause.clone(),
            gain,
            share: if total > 0.0 { gain / total } else { 0.0 },
            moved,
            amplitudes: a,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dep(f: &str, reference: f64, change: f64, scale: f64) -> Departure {
        Departure {
            feature: f.into(),
            change,
            z: change / scale,
            reference,
            scale,
        }
    }

    fn comp(v: &[(&str, f64)]) -> BTreeMap<String, f64> {
        v.iter().map(|(k, w)| (k.to_string(), *w)).collect()
    }

    /// Energy added in the pattern of candidate A (two features, 3:1) is explained by A, not by
    /// B (a pattern on another feature) nor by a path change (most of whose features did not
    /// move); its share is nearly all.
    #[test]
    fn the_candidate_whose_pattern_was_added_explains_it() {
        // Reference energies 1 (ln amplitude 0); A adds 8 and 8/3 → ln amplitudes ½ ln 9, ½ ln 11/3.
        let d = vec![
            dep("x", 0.0, 0.5 * 9f64.ln(), 0.1),
            dep("y", 0.0, 0.5 * (1.0 + 8.0 / 3.0f64).ln(), 0.1),
            dep("z", 0.0, 0.0, 0.1),
            dep("u", 0.0, 0.0, 0.1),
            dep("v", 0.0, 0.0, 0.1),
        ];
        let cands = vec![
            Candidate {
                cause: Cause::Shaft { shaft: "b".into() },
                components: vec![comp(&[("z", 1.0), ("y", 0.2)])],
            },
            Candidate {
                cause: Cause::Shaft { shaft: "a".into() },
                components: vec![comp(&[("x", 3.0), ("y", 1.0)])],
            },
            Candidate {
                cause: Cause::Path {
                    region: "all".into(),
                },
                components: vec![comp(&[
                    ("x", 1.0),
                    ("y", 1.0),
                    ("z", 1.0),
                    ("u", 1.0),
                    ("v", 1.0),
                ])],
            },
        ];
        let e = explain(&d, &cands);
        assert_eq!(e.picks.len(), 1, "{e:?}");
        assert_eq!(e.picks[0].cause, Cause::Shaft { shaft: "a".into() });
        assert!((e.picks[0].amplitudes[0] - 8.0 / 3.0).abs() < 1e-3, "{e:?}");
        assert!(e.picks[0].share > 0.999, "{e:?}");
        assert!(e.left < 1e-3, "{e:?}");
    }

    /// Everything in a region falling by the same ratio is a path change (τ < 0); no additive
    /// candidate can lower energy.
    #[test]
    fn a_common_fall_is_the_path() {
        let d: Vec<Departure> = ["x", "y", "z"]
            .iter()
            .map(|f| dep(f, 1.0, -0.6, 0.1))
            .collect();
        let cands = vec![
            Candidate {
                cause: Cause::Shaft { shaft: "a".into() },
                components: vec![comp(&[("x", 1.0)])],
            },
            Candidate {
                cause: Cause::Path {
                    region: "m8".into(),
                },
                components: vec![comp(&[("x", 1.0), ("y", 1.0), ("z", 1.0)])],
            },
        ];
        let e = explain(&d, &cands);
        assert_eq!(e.picks.len(), 1, "{e:?}");
        assert_eq!(
            e.picks[0].cause,
            Cause::Path {
                region: "m8".into()
            }
        );
        assert!(
            ((1.0 + e.picks[0].amplitudes[0]).ln() + 1.2).abs() < 1e-3,
            "{e:?}"
        );
    }

    /// A change within the healthy spread takes no candidate.
    #[test]
    fn noise_is_not_explained() {
        let d = vec![dep("x", 0.0, 0.15, 0.1), dep("y", 0.0, -0.1, 0.1)];
        let cands = vec![Candidate {
            cause: Cause::Shaft { shaft: "a".into() },
            components: vec![comp(&[("x", 1.0)])],
        }];
        let e = explain(&d, &cands);
        assert!(e.picks.is_empty(), "{e:?}");
        // `y` is no candidate's: only `x` counts.
        assert!((e.total - 1.5f64.powi(2)).abs() < 1e-9);
    }
}
