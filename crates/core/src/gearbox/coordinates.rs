//! The coordinates of a gear train and the rows of its meshes, stage by stage.
//!
//! One rotation per rigid shaft (inertia: every gear on it plus the shaft's own `inertia`);
//! a shaft with a torsional stiffness gives each gear on it its own rotation, joined in stage
//! order by shaft elements. Each planet is a rotation; the carrier's rotation carries
//! `J_c + N m_p r_c²`. The meshes' rows are given in the [`build`](super::build) module docs.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use super::assumed::{Ctx, positive};
use super::description::{GearboxDescription, MeshSpec, StageSpec};
use super::gears::{PlanetaryGears, parallel_pair, planetary_gears};
use super::kinematics::{Stage, Topology};
use super::meshes::{MeshDraft, MeshValues};
use crate::error::GearboxError;
use crate::model::element::StiffnessShape;

/// Where each member's rotation lives: shaft → coordinates of the gears on it.
#[derive(Default)]
pub(super) struct Dofs {
    pub(super) list: Vec<(String, f64)>,
    /// (stage, member) → coordinate.
    member: BTreeMap<(usize, String), String>,
    /// shaft → coordinates in order (one for a rigid shaft).
    pub(super) shaft_dofs: BTreeMap<String, Vec<String>>,
    pub(super) flexible: BTreeMap<String, f64>,
}

impl Dofs {
    fn dof_name(shaft: &str) -> String {
        format!("theta_{shaft}")
    }

    /// Put a member's inertia on its shaft; returns its coordinate.
    fn place(&mut self, stage: usize, member: &str, shaft: &str, inertia: f64) -> String {
        let name = if self.flexible.contains_key(shaft) {
            let name = format!("theta_{shaft}_{member}{stage}");
            self.list.push((name.clone(), inertia));
            self.shaft_dofs
                .entry(shaft.to_string())
                .or_default()
                .push(name.clone());
            name
        } else {
            let name = Self::dof_name(shaft);
            match self.list.iter_mut().find(|(n, _)| *n == name) {
                Some((_, j)) => *j += inertia,
                None => {
                    self.list.push((name.clone(), inertia));
                    self.shaft_dofs
                        .entry(shaft.to_string())
                        .or_default()
                        .push(name.clone());
                }
            }
            name
        };
        self.member
            .insert((stage, member.to_string()), name.clone());
        name
    }

    fn add_own(&mut self, name: String, inertia: f64) {
        self.list.push((name, inertia));
    }
}

/// The coordinates of the rotating members of a planetary stage (`None`: fixed or no shaft).
struct PlanetaryDofs {
    sun: Option<String>,
    planets: Vec<String>,
    ring: Option<String>,
    carrier: Option<String>,
}

/// The coordinates and the mesh drafts of a gear train, built stage by stage.
pub(super) struct Train<'a> {
    d: &'a GearboxDescription,
    /// Signed shaft rates (Hz) at an input rate of 1 Hz.
    pub(super) rates: BTreeMap<String, f64>,
    /// Mesh frequency over the reference mesh frequency, per stage.
    ratios: &'a [f64],
    /// Which stage set each shaft's rate: the member nearer the input comes first in a mesh.
    set_by: BTreeMap<String, usize>,
    /// Stages (1-based) whose error is the wear degree.
    wear_stages: &'a [usize],
    planetary_stages: usize,
    /// Inertia declared on shafts and not placed yet. A flexible shaft's own inertia is its
    /// first coordinate; a rigid one's joins its gears'.
    extra_inertia: BTreeMap<String, f64>,
    pub(super) dofs: Dofs,
    pub(super) drafts: Vec<MeshDraft>,
    /// The member driving the first stage: (radius × load paths (m), its rate at input 1 Hz).
    pub(super) input_member: Option<(f64, f64)>,
}

impl<'a> Train<'a> {
    /// Place every stage's members and draft its meshes, then the inertia declared on rigid
    /// shafts.
    pub(super) fn build(
        cx: &mut Ctx,
        d: &'a GearboxDescription,
        topo: &Topology,
        ratios: &'a [f64],
        wear_stages: &'a [usize],
    ) -> Result<Self, GearboxError> {
        let mut dofs = Dofs::default();
        for (name, s) in &d.shafts {
            if let Some(k) = s.torsional_stiffness_nm_per_rad {
                dofs.flexible.insert(name.clone(), k);
            }
        }
        let mut train = Train {
            d,
            rates: topo.signed_rates(1.0),
            ratios,
            set_by: topo.set_by(),
            wear_stages,
            planetary_stages: topo
                .stages
                .iter()
                .filter(|s| matches!(s, Stage::Planetary { .. }))
                .count(),
            extra_inertia: d
                .shafts
                .iter()
                .filter_map(|(n, s)| s.inertia.map(|j| (n.clone(), j)))
                .collect(),
            dofs,
            drafts: Vec::new(),
            input_member: None,
        };
        for (k0, (st, spec)) in topo.stages.iter().zip(&d.stages).enumerate() {
            match st {
                Stage::Parallel { .. } => train.parallel(cx, k0 + 1, st, spec)?,
                Stage::Planetary { .. } => train.planetary(cx, k0 + 1, st, spec)?,
            }
        }
        train.place_shaft_inertia();
        Ok(train)
    }

    /// True when `shaft` turns before `stage` is reached (it is the stage's input side).
    fn reached_before(&self, shaft: &str, stage: usize) -> bool {
        self.set_by[shaft] != stage
    }

    /// Put a member of `stage` on its shaft (a flexible shaft's own inertia first); returns
    /// its coordinate.
    fn place(&mut self, stage: usize, member: &str, shaft: &str, j: f64) -> String {
        let dofs = &mut self.dofs;
        if dofs.flexible.contains_key(shaft)
            && !dofs.shaft_dofs.contains_key(shaft)
            && let Some(own) = self.extra_inertia.remove(shaft)
        {
            let name = Dofs::dof_name(shaft);
            dofs.add_own(name.clone(), own);
            dofs.shaft_dofs.insert(shaft.to_string(), vec![name]);
        }
        dofs.place(stage, member, shaft, j)
    }

    /// Draft one mesh of stage `k` (values settled later).
    fn draft(
        &mut self,
        k: usize,
        (name, terms): (String, Vec<(String, f64)>),
        planetary: bool,
        spec: MeshSpec,
        width_m: f64,
        label: String,
    ) {
        self.drafts.push(MeshDraft {
            values: MeshValues {
                name,
                stage: k,
                freq_ratio: self.ratios[k - 1],
                stiffness_n_per_m: 0.0,
                shape: StiffnessShape::Constant,
                damping_ratio: 0.0,
                half_clearance_m: 0.0,
                baseline_error_m: 0.0,
                error_scale: 1.0,
                phase_rad: 0.0,
                wears: self.wear_stages.contains(&k),
                planetary,
                terms,
            },
            spec,
            width_m,
            label,
        });
    }

    /// Parallel stage `k`: each gear on its shaft, one mesh with the member nearer the input
    /// first (`x_k = r_a θ_a − r_b θ_b − e(t)`).
    fn parallel(
        &mut self,
        cx: &mut Ctx,
        k: usize,
        st: &Stage,
        spec: &StageSpec,
    ) -> Result<(), GearboxError> {
        let Stage::Parallel {
            pinion_shaft,
            pinion_teeth,
            gear_shaft,
            gear_teeth,
        } = st
        else {
            unreachable!("called for a parallel stage")
        };
        let (p, g) = parallel_pair(cx, k, spec, *pinion_teeth, *gear_teeth)?;
        let pd = self.place(k, "pinion", pinion_shaft, p.inertia);
        let gd = self.place(k, "gear", gear_shaft, g.inertia);
        // The member nearer the input first.
        let pinion_first = self.reached_before(pinion_shaft, k);
        let (a, b, ga, gb, shaft_a) = if pinion_first {
            (pd, gd, p, g, pinion_shaft)
        } else {
            (gd, pd, g, p, gear_shaft)
        };
        if self.input_member.is_none() {
            self.input_member = Some((ga.base_radius_m, self.rates[shaft_a].abs()));
        }
        self.draft(
            k,
            (
                format!("x{k}"),
                vec![(a, ga.base_radius_m), (b, -gb.base_radius_m)],
            ),
            false,
            spec.mesh.or(&self.d.mesh),
            ga.face_width_m.min(gb.face_width_m),
            format!("stage {k} mesh"),
        );
        Ok(())
    }

    /// Planetary stage `k`: sun, ring and carrier on their shafts (the fixed one has no
    /// coordinate), a coordinate per planet, a sun–planet and a ring–planet mesh per planet.
    fn planetary(
        &mut self,
        cx: &mut Ctx,
        k: usize,
        st: &Stage,
        spec: &StageSpec,
    ) -> Result<(), GearboxError> {
        let Stage::Planetary {
            sun_shaft,
            sun_teeth,
            planet_teeth,
            planets,
            ring_shaft,
            ring_teeth,
            carrier_shaft,
            fixed,
        } = st
        else {
            unreachable!("called for a planetary stage")
        };
        let gears = planetary_gears(
            cx,
            k,
            spec,
            (*sun_teeth, *planet_teeth, *ring_teeth),
            *fixed,
        )?;
        let np = *planets as usize;
        let shafts = [sun_shaft, ring_shaft, carrier_shaft];
        let dofs = self.planetary_dofs(cx, k, spec, shafts, np, &gears)?;
        if self.input_member.is_none() {
            self.input_member = Some(self.planetary_input(k, shafts, np, &gears));
        }
        self.planetary_meshes(k, spec, &dofs, &gears);
        Ok(())
    }

    /// Place the members of planetary stage `k` on their shafts `[sun, ring, carrier]`, and a
    /// coordinate per planet; the carrier carries `J_c + N m_p r_c²`.
    fn planetary_dofs(
        &mut self,
        cx: &mut Ctx,
        k: usize,
        spec: &StageSpec,
        [sun_shaft, ring_shaft, carrier_shaft]: [&Option<String>; 3],
        np: usize,
        gears: &PlanetaryGears,
    ) -> Result<PlanetaryDofs, GearboxError> {
        let PlanetaryGears {
            sun,
            planet,
            ring,
            carrier_radius_m: rc,
        } = *gears;
        let sd = sun_shaft
            .as_ref()
            .map(|s| self.place(k, "sun", s, sun.inertia));
        let mut pds = Vec::new();
        for n in 1..=np {
            let name = if self.planetary_stages > 1 {
                format!("theta_s{k}p{n}")
            } else {
                format!("theta_p{n}")
            };
            self.dofs.add_own(name.clone(), planet.inertia);
            pds.push(name);
        }
        let rd = ring_shaft
            .as_ref()
            .map(|s| self.place(k, "ring", s, ring.inertia));
        let carrier = spec.carrier.clone().unwrap_or_default();
        let cd = match carrier_shaft {
            Some(s) => {
                let jc = match positive(format!("stage {k} carrier inertia"), carrier.inertia)? {
                    Some(j) => j,
                    None => {
                        let r = (sun.module_m * sun.teeth as f64
                            + planet.module_m * planet.teeth as f64)
                            / 2.0;
                        cx.assume_dynamic(
                            format!("stage {k} carrier inertia"),
                            0.5 * cx.density() * PI * r.powi(4) * planet.face_width_m,
                            "kg·m²",
                            "steel disc of the planet-centre radius, planet face width thick",
                        )
                    }
                };
                Some(self.place(k, "carrier", s, jc + np as f64 * planet.mass_kg * rc * rc))
            }
            None => None,
        };
        Ok(PlanetaryDofs {
            sun: sd,
            planets: pds,
            ring: rd,
            carrier: cd,
        })
    }

    /// The member through which power enters planetary stage `k`, as
    /// (radius × load paths (m), its rate at input 1 Hz).
    fn planetary_input(
        &self,
        k: usize,
        [sun_shaft, ring_shaft, carrier_shaft]: [&Option<String>; 3],
        np: usize,
        gears: &PlanetaryGears,
    ) -> (f64, f64) {
        // Torque on the member through which power enters the stage.
        let first = |sh: &Option<String>| sh.as_ref().is_some_and(|s| self.reached_before(s, k));
        let (r, shaft) = if first(sun_shaft) {
            (gears.sun.base_radius_m, sun_shaft)
        } else if first(ring_shaft) {
            (gears.ring.base_radius_m, ring_shaft)
        } else {
            (2.0 * gears.carrier_radius_m, carrier_shaft)
        };
        let n = shaft.as_ref().map_or(0.0, |s| self.rates[s].abs());
        (r * np as f64, n)
    }

    /// The sun–planet meshes `x_spn = r_s θ_s − r_p θ_pn − r_c θ_c − e(t)`, then the
    /// ring–planet meshes `x_rpn = r_p θ_pn + r_r θ_r − r_c θ_c − e(t)` of planetary stage `k`.
    fn planetary_meshes(
        &mut self,
        k: usize,
        spec: &StageSpec,
        dofs: &PlanetaryDofs,
        gears: &PlanetaryGears,
    ) {
        let PlanetaryGears {
            sun,
            planet,
            ring,
            carrier_radius_m: rc,
        } = *gears;
        let PlanetaryDofs {
            sun: sd,
            planets: pds,
            ring: rd,
            carrier: cd,
        } = dofs;
        let name = |m: &str, n: usize| {
            if self.planetary_stages > 1 {
                format!("x{k}{m}{n}")
            } else {
                format!("x{m}{n}")
            }
        };
        let d = self.d;
        let stage_mesh = spec.mesh.or(&d.mesh);
        let ring_mesh = spec.ring_mesh.or(&spec.mesh).or(&d.mesh);
        let width = sun.face_width_m.min(planet.face_width_m);
        let ring_width = ring.face_width_m.min(planet.face_width_m);
        let mut sp = Vec::new();
        let mut rp = Vec::new();
        for (n, pd) in pds.iter().enumerate() {
            let mut terms = Vec::new();
            if let Some(s) = sd {
                terms.push((s.clone(), sun.base_radius_m));
            }
            terms.push((pd.clone(), -planet.base_radius_m));
            if let Some(c) = cd {
                terms.push((c.clone(), -rc));
            }
            sp.push((name("sp", n + 1), terms));
            let mut terms = vec![(pd.clone(), planet.base_radius_m)];
            if let Some(c) = cd {
                terms.push((c.clone(), -rc));
            }
            if let Some(r) = rd {
                terms.push((r.clone(), ring.base_radius_m));
            }
            rp.push((name("rp", n + 1), terms));
        }
        for (row, (spec, w, what)) in sp
            .into_iter()
            .map(|t| (t, (stage_mesh.clone(), width, "sun–planet")))
            .chain(
                rp.into_iter()
                    .map(|t| (t, (ring_mesh.clone(), ring_width, "ring–planet"))),
            )
        {
            self.draft(k, row, true, spec, w, format!("stage {k} {what} mesh"));
        }
    }

    /// Shafts whose only inertia was declared on the shaft (rigid): add it to their
    /// coordinate.
    fn place_shaft_inertia(&mut self) {
        let dofs = &mut self.dofs;
        for (shaft, j) in std::mem::take(&mut self.extra_inertia) {
            if let Some(dofs_of) = dofs.shaft_dofs.get(&shaft) {
                let first = dofs_of[0].clone();
                if let Some((_, jj)) = dofs.list.iter_mut().find(|(n, _)| *n == first) {
                    *jj += j;
                }
            }
        }
    }
}
