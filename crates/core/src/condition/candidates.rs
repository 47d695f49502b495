//! The candidates the explainer ranks ([`super::explain`]): for every part of the described
//! gearbox, the pattern of energy its fault adds to the record's line classes, from the
//! kinematics ([`super::lines`]) and, for gears, the simulated response of the gearbox to that
//! fault ([`super::response`]).
//!
//! | cause | components (each a pattern with its own amplitude) |
//! | --- | --- |
//! | gear local damage (gear on `S`, stage `i`) | a flat comb of sidebands `h ± j r_S` around every harmonic `h = k m_i` of its mesh, the comb's energy `ρ_local(k) · C(h)` — `C(h)` the record's carrier energy there (a modulation's sidebands go with the carrier it modulates, through today's path), `ρ` the simulated sideband-to-carrier ratio — shared among the classes its lines fall in; the envelope's lines at every multiple of `r_S` |
//! | gear eccentricity | the first sidebands (`j = 1`, and `j = 2` at a quarter) around the same harmonics, scaled by `ρ_eccentric(k) · C(h)`; its shaft's 1× |
//! | shaft `S` | its 1×; its 2×; its harmonics from 3× in the low orders |
//! | bearing `b`, defect `d` | its envelope lines, and as much again in the envelope's non-synchronous class (its lines smear as the rolling elements slip) |
//! | non-synchronous | every region's `none` class in proportion to its reference; the envelope's `none` class |
//! | mesh lines of stage `i` | the carriers of its harmonics scaled together (tooth wear, load, contact) |
//! | transfer path of a band | every feature of the band scaled together: the shaft orders, the mesh regions, the orders above them, the envelope |
//!
//! Sideband energy proportional to the carrier's is amplitude modulation: the transfer path
//! multiplies a carrier and its sidebands alike, so the pattern carries the machine's own path.

use std::collections::BTreeMap;

use super::explain::{Candidate, Cause};
use super::lines::{Class, LineMap};
use super::parts::Parts;

/// Share of a bearing's line energy that also lands in the envelope's `none` class, per unit
/// of its line feature's energy (three harmonics over a Hann window's three bins).
const BEARING_SMEAR: f64 = 4.5;

/// Simulated sideband-to-carrier energy ratios of each gear's faults, `[gear][k − 1]` for the
/// harmonics `k` of its mesh ([`super::response`]); missing harmonics read 1.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Response {
    pub local: Vec<Vec<f64>>,
    pub eccentric: Vec<Vec<f64>>,
}

impl Response {
    fn ratio(table: &[Vec<f64>], gear: usize, k: usize) -> f64 {
        table
            .get(gear)
            .and_then(|v| v.get(k.wrapping_sub(1)))
            .copied()
            .filter(|r| r.is_finite() && *r > 0.0)
            .unwrap_or(1.0)
    }
}

/// Every candidate for a gearbox's `parts` (its line `map`), with the reference's energies by
/// feature (`reference`: `E_ref = exp(2 v_ref)`), the record's own (`measured`: its carriers
/// scale the gears' sidebands) and the simulated gear response when known.
pub fn candidates(
    parts: &Parts,
    map: &LineMap,
    reference: &BTreeMap<String, f64>,
    measured: &BTreeMap<String, f64>,
    response: Option<&Response>,
) -> Vec<Candidate> {
    let mut v = Vec::new();
    for (gi, g) in parts.gears.iter().enumerate() {
        let Some(rate) = parts.shafts.get(&g.shaft).copied().filter(|r| *r > 0.0) else {
            continue;
        };
        let mesh = map.meshes.get(g.stage - 1).copied().unwrap_or(0.0);
        if mesh <= 0.0 {
            continue;
        }
        let ratio = |local: bool, k: usize| {
            response.map_or(1.0, |r| {
                Response::ratio(if local { &r.local } else { &r.eccentric }, gi, k)
            })
        };
        let local = sidebands(map, measured, mesh, rate, |_| 1.0, |k| ratio(true, k));
        let ecc = sidebands(
            map,
            measured,
            mesh,
            rate,
            |j| match j {
                1 => 1.0,
                2 => 0.25,
                _ => 0.0,
            },
            |k| ratio(false, k),
        );
        let one_x = BTreeMap::from([(format!("shaft.{}.1x", g.shaft), 1.0)]);
        v.push(Candidate {
            cause: Cause::GearLocal { gear: gi },
            components: vec![local, envelope_comb(map, rate)],
        });
        v.push(Candidate {
            cause: Cause::GearEccentric { gear: gi },
            components: vec![ecc, one_x],
        });
    }
    for (s, &rate) in parts.shafts.iter().filter(|(_, r)| **r > 0.0) {
        v.push(Candidate {
            cause: Cause::Shaft { shaft: s.clone() },
            components: vec![
                BTreeMap::from([(format!("shaft.{s}.1x"), 1.0)]),
                BTreeMap::from([(format!("shaft.{s}.2x"), 1.0)]),
                low_harmonics(map, rate),
            ],
        });
    }
    for b in &parts.bearings {
        for defect in ["bpfo", "bpfi", "bsf"] {
            v.push(Candidate {
                cause: Cause::Bearing {
                    bearing: b.name.clone(),
                    defect,
                },
                components: vec![BTreeMap::from([
                    (format!("bearing.{}.{defect}", b.name), 1.0),
                    ("env.none".to_string(), BEARING_SMEAR),
                ])],
            });
        }
    }
    v.push(Candidate {
        cause: Cause::NonSynchronous,
        components: vec![
            reference
                .iter()
                .filter(|(k, _)| k.starts_with("lines.none."))
                .map(|(k, e)| (k.clone(), *e))
                .collect(),
            BTreeMap::from([("env.none".to_string(), 1.0)]),
        ],
    });
    v.extend(mesh_lines(map, reference));
    v.extend(paths(reference));
    v
}

/// Added energy of a comb of sidebands `h ± j r` (weight `weight(j)`) around every harmonic
/// `h = k · mesh` with a region of its own: `ratio(k) · C(h)` per harmonic (`C` the carrier's
/// energy in `carriers`), shared among its lines by weight, each line's share to the feature
/// of its class.
fn sidebands(
    map: &LineMap,
    carriers: &BTreeMap<String, f64>,
    mesh: f64,
    rate: f64,
    weight: impl Fn(usize) -> f64,
    ratio: impl Fn(usize) -> f64,
) -> BTreeMap<String, f64> {
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    for r in &map.regions {
        let Some(h) = r.centre else { continue };
        let k = (h / mesh).round();
        if k < 1.0 || (h - k * mesh).abs() > 1e-6 * h {
            continue;
        }
        let Some(&carrier) = carriers.get(&format!("lines.mesh.{}", r.name)) else {
            continue;
        };
        let mut lines: Vec<(String, f64)> = Vec::new();
        let mut j = 1;
        while h - j as f64 * rate >= r.lo || h + j as f64 * rate < r.hi {
            let w = weight(j);
            for o in [h - j as f64 * rate, h + j as f64 * rate] {
                if w > 0.0
                    && o >= r.lo
                    && o < r.hi
                    && let Some((class, name)) = map.feature_at(o, true)
                    && matches!(class, Class::Own { .. } | Class::Shared)
                {
                    lines.push((name, w));
                }
            }
            j += 1;
        }
        let total: f64 = lines.iter().map(|l| l.1).sum();
        if total <= 0.0 {
            continue;
        }
        let energy = ratio(k as usize) * carrier;
        for (name, w) in lines {
            *out.entry(name).or_default() += energy * w / total;
        }
    }
    out
}

/// The envelope's lines at every multiple of `rate` in the low orders, one unit each, to the
/// envelope's classes (`env.own.<S>`, `env.shared`).
fn envelope_comb(map: &LineMap, rate: f64) -> BTreeMap<String, f64> {
    let end = map.regions.first().map_or(0.0, |r| r.hi);
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    let mut j = 1.0;
    while j * rate < end {
        if let Some((Class::Own { .. } | Class::Shared, name)) = map.feature_at(j * rate, false)
            && let Some(class) = name
                .strip_prefix("lines.")
                .and_then(|n| n.strip_suffix(".low"))
        {
            *out.entry(format!("env.{class}")).or_default() += 1.0;
        }
        j += 1.0;
    }
    out
}

/// A shaft's harmonics from 3× in the low orders, one unit each, to their line classes.
fn low_harmonics(map: &LineMap, rate: f64) -> BTreeMap<String, f64> {
    let end = map.regions.first().map_or(0.0, |r| r.hi);
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    let mut j = 3.0;
    while j * rate < end {
        if let Some((Class::Own { .. } | Class::Shared, name)) = map.feature_at(j * rate, true) {
            *out.entry(name).or_default() += 1.0;
        }
        j += 1.0;
    }
    out
}

/// The bands a path change spans: the shaft orders (`low`), the mesh harmonics' regions
/// together (`mesh`), the orders above them (`high`), the envelope (`env`). Broad on purpose: a
/// sensor remounted or a gearbox reassembled changes how a whole band reaches the sensor,
/// while a fault adds lines in the regions its mesh and shafts make.
fn band_of(feature: &str) -> Option<&'static str> {
    if feature.starts_with("env.") || feature.starts_with("bearing.") {
        return Some("env");
    }
    if feature.starts_with("shaft.") || feature.ends_with(".low") {
        return Some("low");
    }
    if !feature.starts_with("lines.") {
        return None;
    }
    Some(if feature.ends_with(".high") {
        "high"
    } else {
        "mesh"
    })
}

/// One path candidate per band ([`band_of`]): every feature of the band scaled together.
fn paths(reference: &BTreeMap<String, f64>) -> Vec<Candidate> {
    ["low", "mesh", "high", "env"]
        .into_iter()
        .map(|band| Candidate {
            cause: Cause::Path {
                region: band.to_string(),
            },
            components: vec![
                reference
                    .iter()
                    .filter(|(k, _)| band_of(k) == Some(band))
                    .map(|(k, e)| (k.clone(), *e))
                    .collect(),
            ],
        })
        .filter(|c| !c.components[0].is_empty())
        .collect()
}

/// One candidate per stage: its mesh lines (the carriers of its harmonics' regions) scaled
/// together — tooth wear, or a change of load or contact.
fn mesh_lines(map: &LineMap, reference: &BTreeMap<String, f64>) -> Vec<Candidate> {
    map.meshes
        .iter()
        .enumerate()
        .map(|(i, &m)| Candidate {
            cause: Cause::MeshLines { stage: i + 1 },
            components: vec![
                map.regions
                    .iter()
                    .filter(|r| {
                        r.centre.is_some_and(|h| {
                            let k = (h / m).round();
                            k >= 1.0 && (h - k * m).abs() <= 1e-6 * h
                        })
                    })
                    .filter_map(|r| {
                        let k = format!("lines.mesh.{}", r.name);
                        reference.get(&k).map(|e| (k, *e))
                    })
                    .collect(),
            ],
        })
        .filter(|c| !c.components[0].is_empty())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::test_util::spur;

    /// The 48T idler pinion (stage 2, mesh order 16) with local damage: its comb around 16
    /// falls two thirds in the idler's own lines and one third in the shared ones (every third
    /// multiple of 1/3 is an input harmonic), scaled by the carrier; the 96T (stage 1, mesh
    /// 32) has nothing around 16 and 48; the output's 80T puts its lines in the output's.
    #[test]
    fn a_gears_comb_lands_in_its_shafts_lines() {
        let parts = spur();
        let map = LineMap::of(&parts);
        let reference: BTreeMap<String, f64> = map
            .regions
            .iter()
            .filter(|r| r.centre.is_some())
            .map(|r| (format!("lines.mesh.{}", r.name), 2.0))
            .collect();
        let c = candidates(&parts, &map, &reference, &reference, None);
        let gear = |teeth: u32| parts.gears.iter().position(|g| g.teeth == teeth).unwrap();
        let local = |g: usize| {
            c.iter()
                .find(|x| x.cause == Cause::GearLocal { gear: g })
                .unwrap()
        };
        let p48 = &local(gear(48)).components[0];
        let own: f64 = p48
            .iter()
            .filter(|(k, _)| k.starts_with("lines.own.idler") && k.ends_with(".m16"))
            .map(|x| x.1)
            .sum();
        let shared = p48["lines.shared.m16"];
        assert!((own + shared - 2.0).abs() < 1e-9, "{p48:?}");
        // 32 own lines (j not a multiple of 3) against 15 shared ones.
        assert!((own / shared - 32.0 / 15.0).abs() < 1e-9, "{own} {shared}");
        let p96 = &local(gear(96)).components[0];
        assert!(
            p96.keys()
                .all(|k| !k.ends_with(".m16") && !k.ends_with(".m48"))
        );
        assert!(p96.keys().any(|k| k.ends_with(".m32")));
        let p80 = &local(gear(80)).components[0];
        assert!(p80.keys().any(|k| k.starts_with("lines.own.out")));
        assert!(p80.keys().all(|k| !k.starts_with("lines.own.idler")));
        // The envelope comb of the idler: its own lines and every third one shared.
        let env = &local(gear(48)).components[1];
        assert!(env["env.own.idler"] > env["env.shared"]);
    }
}
