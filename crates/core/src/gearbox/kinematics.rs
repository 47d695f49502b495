//! Validated topology and exact kinematics of a described gearbox.
//!
//! Rates are in Hz (revolutions per second), signed: positive in the input shaft's sense.
//!
//! - Parallel stage (pinion p, gear g, external mesh): `n_g = −n_p z_p / z_g`; mesh frequency
//!   `f_m = z_p |n_p| = z_g |n_g|`; hunting-tooth frequency `f_m gcd(z_p, z_g) / (z_p z_g)`.
//! - Planetary stage (sun s, ring r, carrier c, N planets of z_p teeth), Willis:
//!   `(n_s − n_c) z_s = −(n_r − n_c) z_r`, with the fixed member's rate 0 (ring fixed:
//!   `n_c = n_s z_s / (z_s + z_r)`; carrier fixed: `n_r = −n_s z_s / z_r`; sun fixed:
//!   `n_c = n_r z_r / (z_s + z_r)`). Mesh frequency (sun–planet and ring–planet alike)
//!   `f_m = z_s |n_s − n_c| = z_r |n_r − n_c|`; planet spin relative to the carrier `f_m / z_p`;
//!   planet-pass frequency `N |n_r − n_c|`; a damaged sun tooth meets a planet `N f_m / z_s`
//!   times a second, a planet tooth meets the sun (or the ring) `f_m / z_p`, a ring tooth
//!   `N f_m / z_r`.

use std::collections::BTreeMap;

use serde::Serialize;

use super::description::{GearSpec, GearboxDescription, MAX_STAGES, StageSpec};
use crate::error::GearboxError;

/// Most planets a planetary stage may have (each adds a coordinate and two meshes).
pub const MAX_PLANETS: u32 = 32;
/// Largest tooth count accepted (a ring gear of a large mill has a few hundred).
pub const MAX_TEETH: i64 = 100_000;

/// The member a planetary stage holds in the housing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Fixed {
    Ring,
    Carrier,
    Sun,
}

/// A stage after validation: tooth counts as integers, shafts resolved.
#[derive(Debug, Clone, PartialEq)]
pub enum Stage {
    Parallel {
        pinion_shaft: String,
        pinion_teeth: u32,
        gear_shaft: String,
        gear_teeth: u32,
    },
    Planetary {
        sun_shaft: Option<String>,
        sun_teeth: u32,
        planet_teeth: u32,
        planets: u32,
        ring_shaft: Option<String>,
        ring_teeth: u32,
        carrier_shaft: Option<String>,
        fixed: Fixed,
    },
}

impl Stage {
    /// The shafts this stage's rotating members sit on.
    pub fn shafts(&self) -> Vec<&str> {
        match self {
            Stage::Parallel {
                pinion_shaft,
                gear_shaft,
                ..
            } => vec![pinion_shaft, gear_shaft],
            Stage::Planetary {
                sun_shaft,
                ring_shaft,
                carrier_shaft,
                ..
            } => [sun_shaft, ring_shaft, carrier_shaft]
                .into_iter()
                .flatten()
                .map(|s| s.as_str())
                .collect(),
        }
    }

    /// `"parallel"` or `"planetary"`.
    pub fn kind(&self) -> &'static str {
        match self {
            Stage::Parallel { .. } => "parallel",
            Stage::Planetary { .. } => "planetary",
        }
    }
}

/// The validated structure of a gearbox: stages and shafts, no physics.
#[derive(Debug, Clone, PartialEq)]
pub struct Topology {
    pub stages: Vec<Stage>,
    /// Shafts in order of first appearance (stage order, members in order).
    pub shafts: Vec<String>,
    pub input_shaft: String,
    pub output_shaft: String,
    /// Equal-spacing warnings ((sun + ring) / planets not an integer), already phrased.
    pub warnings: Vec<String>,
}

fn teeth(stage: usize, member: &str, z: i64) -> Result<u32, GearboxError> {
    if z <= 0 || z > MAX_TEETH {
        return Err(GearboxError::Teeth {
            stage,
            member: member.into(),
            teeth: z,
        });
    }
    Ok(z as u32)
}

fn shaft_of(stage: usize, member: &str, g: &GearSpec) -> Result<String, GearboxError> {
    match &g.shaft {
        Some(s) if !s.trim().is_empty() => Ok(s.clone()),
        _ => Err(GearboxError::NoShaft {
            stage,
            member: member.into(),
        }),
    }
}

fn require<'a, T>(
    v: &'a Option<T>,
    stage: usize,
    kind: &'static str,
    member: &'static str,
    hint: &'static str,
) -> Result<&'a T, GearboxError> {
    v.as_ref().ok_or(GearboxError::MissingMember {
        stage,
        kind,
        member,
        hint,
    })
}

fn forbid<T>(
    v: &Option<T>,
    stage: usize,
    kind: &'static str,
    member: &'static str,
    other: &'static str,
) -> Result<(), GearboxError> {
    match v {
        Some(_) => Err(GearboxError::ForeignMember {
            stage,
            kind,
            member,
            other,
        }),
        None => Ok(()),
    }
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Validate stage `i` (1-based) of a description; returns the stage and its warning, if any.
fn stage_topology(i: usize, s: &StageSpec) -> Result<(Stage, Option<String>), GearboxError> {
    match s.kind.as_str() {
        "parallel" => parallel_topology(i, s).map(|st| (st, None)),
        "planetary" => planetary_topology(i, s),
        other => Err(GearboxError::UnknownKind {
            stage: i,
            kind: other.into(),
        }),
    }
}

/// Parallel stage `i`: a pinion and a gear on two different shafts, no planetary member.
fn parallel_topology(i: usize, s: &StageSpec) -> Result<Stage, GearboxError> {
    const K: &str = "parallel";
    forbid(&s.sun, i, K, "sun", "planetary")?;
    forbid(&s.planets, i, K, "planets", "planetary")?;
    forbid(&s.ring, i, K, "ring", "planetary")?;
    forbid(&s.carrier, i, K, "carrier", "planetary")?;
    forbid(&s.fixed, i, K, "fixed", "planetary")?;
    if !s.ring_mesh.is_empty() {
        return Err(GearboxError::ForeignMember {
            stage: i,
            kind: K,
            member: "ring_mesh",
            other: "planetary",
        });
    }
    let p = require(
        &s.pinion,
        i,
        K,
        "pinion",
        "write pinion = { shaft = \"…\", teeth = … }",
    )?;
    let g = require(
        &s.gear,
        i,
        K,
        "gear",
        "write gear = { shaft = \"…\", teeth = … }",
    )?;
    let pz = teeth(i, "pinion", p.teeth)?;
    let gz = teeth(i, "gear", g.teeth)?;
    let ps = shaft_of(i, "pinion", p)?;
    let gs = shaft_of(i, "gear", g)?;
    if ps == gs {
        return Err(GearboxError::SameShaft {
            stage: i,
            shaft: ps,
        });
    }
    Ok(Stage::Parallel {
        pinion_shaft: ps,
        pinion_teeth: pz,
        gear_shaft: gs,
        gear_teeth: gz,
    })
}

/// Planetary stage `i`: sun, planets, ring and carrier, one of them fixed, coaxial unless
/// profile-shifted; with the equal-spacing warning when the planets cannot be equally spaced.
fn planetary_topology(i: usize, s: &StageSpec) -> Result<(Stage, Option<String>), GearboxError> {
    const K: &str = "planetary";
    forbid(&s.pinion, i, K, "pinion", "parallel")?;
    forbid(&s.gear, i, K, "gear", "parallel")?;
    let sun = require(
        &s.sun,
        i,
        K,
        "sun",
        "write sun = { shaft = \"…\", teeth = … }",
    )?;
    let pl = require(
        &s.planets,
        i,
        K,
        "planets",
        "write planets = { count = …, teeth = … }",
    )?;
    let ring = require(&s.ring, i, K, "ring", "write ring = { teeth = … }")?;
    let fixed = match s.fixed.as_deref() {
        Some("ring") => Fixed::Ring,
        Some("carrier") => Fixed::Carrier,
        Some("sun") => Fixed::Sun,
        Some(other) => {
            return Err(GearboxError::Fixed {
                stage: i,
                found: format!("\"{other}\""),
            });
        }
        None => {
            return Err(GearboxError::Fixed {
                stage: i,
                found: "missing".into(),
            });
        }
    };
    let zs = teeth(i, "sun", sun.teeth)?;
    let zp = teeth(i, "planet", pl.teeth)?;
    let zr = teeth(i, "ring", ring.teeth)?;
    if pl.count < 1 || pl.count > MAX_PLANETS as i64 {
        return Err(GearboxError::PlanetCount {
            stage: i,
            count: pl.count,
            max: MAX_PLANETS,
        });
    }
    let n = pl.count as u32;
    if !s.profile_shifted && ring.teeth != sun.teeth + 2 * pl.teeth {
        return Err(GearboxError::Coaxial {
            stage: i,
            ring: ring.teeth,
            sun: sun.teeth,
            planet: pl.teeth,
            expected: sun.teeth + 2 * pl.teeth,
        });
    }
    let carrier_shaft = s.carrier.as_ref().and_then(|c| c.shaft.clone());
    let member_shaft = |name: &'static str, v: Option<String>, is_fixed: bool| match (is_fixed, v) {
        (true, Some(shaft)) => Err(GearboxError::FixedOnShaft {
            stage: i,
            member: name,
            shaft,
        }),
        (true, None) => Ok(None),
        (false, Some(s)) if !s.trim().is_empty() => Ok(Some(s)),
        (false, _) => Err(GearboxError::NoShaft {
            stage: i,
            member: name.into(),
        }),
    };
    let sun_shaft = member_shaft("sun", sun.shaft.clone(), fixed == Fixed::Sun)?;
    let ring_shaft = member_shaft("ring", ring.shaft.clone(), fixed == Fixed::Ring)?;
    let carrier_shaft = member_shaft("carrier", carrier_shaft, fixed == Fixed::Carrier)?;
    let rotating: Vec<&String> = [&sun_shaft, &ring_shaft, &carrier_shaft]
        .into_iter()
        .flatten()
        .collect();
    if rotating.len() == 2 && rotating[0] == rotating[1] {
        return Err(GearboxError::SameShaft {
            stage: i,
            shaft: rotating[0].clone(),
        });
    }
    let warning = ((zs + zr) % n != 0).then(|| {
        format!(
            "stage {i}: (sun {zs} + ring {zr}) / {n} planets is not an integer, so the \
             planets cannot be equally spaced; the model spaces them equally and meshes \
             them in phase anyway"
        )
    });
    Ok((
        Stage::Planetary {
            sun_shaft,
            sun_teeth: zs,
            planet_teeth: zp,
            planets: n,
            ring_shaft,
            ring_teeth: zr,
            carrier_shaft,
            fixed,
        },
        warning,
    ))
}

impl Topology {
    /// Validate the structure of a description.
    pub fn new(d: &GearboxDescription) -> Result<Self, GearboxError> {
        if d.stages.is_empty() || d.stages.len() > MAX_STAGES {
            return Err(GearboxError::StageCount {
                found: d.stages.len(),
                max: MAX_STAGES,
            });
        }
        let mut stages = Vec::new();
        let mut warnings = Vec::new();
        for (k, s) in d.stages.iter().enumerate() {
            let (st, w) = stage_topology(k + 1, s)?;
            stages.push(st);
            warnings.extend(w);
        }
        let mut shafts: Vec<String> = Vec::new();
        for st in &stages {
            for s in st.shafts() {
                if !shafts.iter().any(|x| x == s) {
                    shafts.push(s.to_string());
                }
            }
        }
        let known = || shafts.join(", ");
        if !shafts.contains(&d.input_shaft) {
            return Err(GearboxError::UnknownInput {
                shaft: d.input_shaft.clone(),
                known: known(),
            });
        }
        for name in d.shafts.keys() {
            if !shafts.contains(name) {
                return Err(GearboxError::UnknownShaft {
                    field: format!("[shafts.{name}]"),
                    shaft: name.clone(),
                    known: known(),
                });
            }
        }
        let mut topo = Topology {
            stages,
            shafts: shafts.clone(),
            input_shaft: d.input_shaft.clone(),
            output_shaft: String::new(),
            warnings,
        };
        // Connectivity and consistency: propagate the rates once.
        let (_, order) = topo.propagate(1.0)?;
        topo.output_shaft = match &d.output_shaft {
            Some(o) if shafts.contains(o) => o.clone(),
            Some(o) => {
                return Err(GearboxError::UnknownShaft {
                    field: "output_shaft".into(),
                    shaft: o.clone(),
                    known: known(),
                });
            }
            // The shaft reached last: the far end of the chain from the input.
            None => order
                .last()
                .cloned()
                .unwrap_or_else(|| d.input_shaft.clone()),
        };
        if topo.output_shaft == topo.input_shaft && topo.shafts.len() > 1 {
            return Err(GearboxError::UnknownShaft {
                field: "output_shaft".into(),
                shaft: topo.output_shaft.clone(),
                known: "the output must differ from the input".into(),
            });
        }
        Ok(topo)
    }

    /// Signed shaft rates for an input rate `n_in` (Hz), and the shafts in the order they
    /// were reached from the input.
    fn propagate(&self, n_in: f64) -> Result<(Rates, Vec<String>), GearboxError> {
        // shaft -> (rate, stage that set it; 0 for the input)
        let mut rate: BTreeMap<String, (f64, usize)> = BTreeMap::new();
        rate.insert(self.input_shaft.clone(), (n_in, 0));
        let mut order = vec![self.input_shaft.clone()];
        let mut done = vec![false; self.stages.len()];
        loop {
            let mut progress = false;
            for (k, st) in self.stages.iter().enumerate() {
                if done[k] {
                    continue;
                }
                let get = |s: &Option<String>| s.as_ref().and_then(|s| rate.get(s).map(|r| r.0));
                let set: Vec<(String, f64)> = match st {
                    Stage::Parallel {
                        pinion_shaft,
                        pinion_teeth,
                        gear_shaft,
                        gear_teeth,
                    } => {
                        let (zp, zg) = (*pinion_teeth as f64, *gear_teeth as f64);
                        if let Some(np) = get(&Some(pinion_shaft.clone())) {
                            vec![(gear_shaft.clone(), -(np * zp / zg))]
                        } else if let Some(ng) = get(&Some(gear_shaft.clone())) {
                            vec![(pinion_shaft.clone(), -(ng * zg / zp))]
                        } else {
                            continue;
                        }
                    }
                    Stage::Planetary {
                        sun_shaft,
                        sun_teeth,
                        ring_shaft,
                        ring_teeth,
                        carrier_shaft,
                        fixed,
                        ..
                    } => {
                        let (zs, zr) = (*sun_teeth as f64, *ring_teeth as f64);
                        let (ns, nr, nc) = (get(sun_shaft), get(ring_shaft), get(carrier_shaft));
                        match fixed {
                            Fixed::Ring => match (ns, nc) {
                                (Some(ns), _) => opt(carrier_shaft, ns * zs / (zs + zr)),
                                (None, Some(nc)) => opt(sun_shaft, nc * (zs + zr) / zs),
                                _ => continue,
                            },
                            Fixed::Carrier => match (ns, nr) {
                                (Some(ns), _) => opt(ring_shaft, -(ns * zs / zr)),
                                (None, Some(nr)) => opt(sun_shaft, -(nr * zr / zs)),
                                _ => continue,
                            },
                            Fixed::Sun => match (nr, nc) {
                                (Some(nr), _) => opt(carrier_shaft, nr * zr / (zs + zr)),
                                (None, Some(nc)) => opt(ring_shaft, nc * (zs + zr) / zr),
                                _ => continue,
                            },
                        }
                    }
                };
                for (shaft, r) in set {
                    match rate.get(&shaft) {
                        Some(&(old, from)) => {
                            let tol = 1e-9 * old.abs().max(r.abs());
                            if (old - r).abs() > tol {
                                return Err(GearboxError::ShaftConflict {
                                    shaft,
                                    stage: k + 1,
                                    found: r / n_in,
                                    expected: old / n_in,
                                    from,
                                });
                            }
                        }
                        None => {
                            rate.insert(shaft.clone(), (r, k + 1));
                            order.push(shaft);
                        }
                    }
                }
                done[k] = true;
                progress = true;
            }
            if !progress {
                break;
            }
        }
        if let Some(k) = done.iter().position(|d| !d) {
            return Err(GearboxError::Disconnected {
                stage: k + 1,
                input: self.input_shaft.clone(),
            });
        }
        Ok((rate, order))
    }

    /// Exact kinematics at an input rate `input_hz` (Hz).
    pub fn kinematics(&self, input_hz: f64) -> Kinematics {
        let (rate, _) = self
            .propagate(input_hz)
            .expect("a validated topology propagates");
        let n = |s: &Option<String>| s.as_ref().map_or(0.0, |s| rate[s].0);
        let mut meshes = Vec::new();
        let mut planetary = Vec::new();
        for (k, st) in self.stages.iter().enumerate() {
            match st {
                Stage::Parallel {
                    pinion_shaft,
                    pinion_teeth,
                    gear_teeth,
                    ..
                } => {
                    let np = rate[pinion_shaft].0;
                    let hz = *pinion_teeth as f64 * np.abs();
                    let g = gcd(*pinion_teeth as u64, *gear_teeth as u64) as f64;
                    meshes.push(MeshKinematics {
                        stage: k + 1,
                        kind: "parallel",
                        hz,
                        hunting_tooth_hz: Some(
                            hz * g / (*pinion_teeth as f64 * *gear_teeth as f64),
                        ),
                    });
                }
                Stage::Planetary {
                    sun_shaft,
                    sun_teeth,
                    planet_teeth,
                    planets,
                    ring_shaft,
                    ring_teeth,
                    carrier_shaft,
                    ..
                } => {
                    let (ns, nr, nc) = (n(sun_shaft), n(ring_shaft), n(carrier_shaft));
                    let hz = *sun_teeth as f64 * (ns - nc).abs();
                    let np = *planets as f64;
                    meshes.push(MeshKinematics {
                        stage: k + 1,
                        kind: "planetary",
                        hz,
                        hunting_tooth_hz: None,
                    });
                    planetary.push(PlanetaryKinematics {
                        stage: k + 1,
                        sun_hz: ns.abs(),
                        ring_hz: nr.abs(),
                        carrier_hz: nc.abs(),
                        planet_spin_hz: hz / *planet_teeth as f64,
                        planet_pass_hz: np * (nr - nc).abs(),
                        sun_tooth_defect_hz: np * hz / *sun_teeth as f64,
                        planet_tooth_defect_hz: hz / *planet_teeth as f64,
                        ring_tooth_defect_hz: np * hz / *ring_teeth as f64,
                    });
                }
            }
        }
        let shafts = rate.iter().map(|(s, r)| (s.clone(), r.0.abs())).collect();
        let directions = rate
            .iter()
            .map(|(s, r)| (s.clone(), if r.0 < 0.0 { -1 } else { 1 }))
            .collect();
        let out = rate[&self.output_shaft].0.abs();
        Kinematics {
            input_shaft: self.input_shaft.clone(),
            input_hz,
            output_shaft: self.output_shaft.clone(),
            reduction: if out > 0.0 {
                input_hz.abs() / out
            } else {
                f64::INFINITY
            },
            shafts,
            shaft_directions: directions,
            meshes,
            planetary,
        }
    }

    /// For each shaft, the stage whose mesh set its rate (0: the input shaft). A stage's
    /// members on shafts set by an earlier stage are its input side.
    pub fn set_by(&self) -> BTreeMap<String, usize> {
        self.propagate(1.0)
            .expect("a validated topology propagates")
            .0
            .into_iter()
            .map(|(s, (_, k))| (s, k))
            .collect()
    }

    /// Signed shaft rates (Hz) at input rate `input_hz`.
    pub fn signed_rates(&self, input_hz: f64) -> BTreeMap<String, f64> {
        self.propagate(input_hz)
            .expect("a validated topology propagates")
            .0
            .into_iter()
            .map(|(s, (r, _))| (s, r))
            .collect()
    }
}

/// Shaft → (signed rate in Hz, stage that set it; 0 for the input).
type Rates = BTreeMap<String, (f64, usize)>;

fn opt(shaft: &Option<String>, r: f64) -> Vec<(String, f64)> {
    shaft.iter().map(|s| (s.clone(), r)).collect()
}

/// One mesh's frequency.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshKinematics {
    /// 1-based stage index.
    pub stage: usize,
    pub kind: &'static str,
    /// Mesh frequency (Hz).
    pub hz: f64,
    /// Parallel stages: how often the same pair of teeth meets again (Hz).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hunting_tooth_hz: Option<f64>,
}

/// The rates of a planetary stage.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlanetaryKinematics {
    pub stage: usize,
    pub sun_hz: f64,
    pub ring_hz: f64,
    pub carrier_hz: f64,
    /// Planet spin relative to the carrier (Hz).
    pub planet_spin_hz: f64,
    /// A planet passing a point of the ring (Hz).
    pub planet_pass_hz: f64,
    pub sun_tooth_defect_hz: f64,
    pub planet_tooth_defect_hz: f64,
    pub ring_tooth_defect_hz: f64,
}

/// Every shaft rate and mesh frequency at one input rate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Kinematics {
    pub input_shaft: String,
    pub input_hz: f64,
    pub output_shaft: String,
    /// Input rate over output rate (magnitudes).
    pub reduction: f64,
    /// Shaft rates (Hz, magnitudes).
    pub shafts: BTreeMap<String, f64>,
    /// +1: turns with the input, −1: against it.
    pub shaft_directions: BTreeMap<String, i8>,
    /// Mesh frequencies in stage order.
    pub meshes: Vec<MeshKinematics>,
    /// Planetary stages' carrier, planet-spin, planet-pass and defect rates.
    pub planetary: Vec<PlanetaryKinematics>,
}
