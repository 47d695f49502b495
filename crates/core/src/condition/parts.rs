//! The parts a finding can name: shafts, gears (stage, member, teeth), bearings — with the
//! orders at which each shows in a record resampled to the input shaft's angle.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::gearbox::{DefectOrders, Gearbox, Stage};

/// A gear: where it sits and which mesh it makes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GearPart {
    /// Stage (1-based).
    pub stage: usize,
    /// `pinion`, `gear`, `sun` or `ring`.
    pub member: &'static str,
    pub teeth: u32,
    pub shaft: String,
}

impl GearPart {
    /// "gear 24T (stage 2 pinion)".
    pub fn label(&self) -> String {
        format!(
            "gear {}T (stage {} {})",
            self.teeth, self.stage, self.member
        )
    }
}

/// A described bearing and its defect orders (per revolution of its shaft).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BearingPart {
    pub name: String,
    pub shaft: String,
    pub orders: DefectOrders,
}

/// The gearbox's parts and their orders, every rate over the input shaft's.
#[derive(Debug, Clone, PartialEq)]
pub struct Parts {
    pub input_shaft: String,
    /// Each shaft's rate over the input shaft's (magnitude).
    pub shafts: BTreeMap<String, f64>,
    /// Each stage's mesh order (mesh frequency over the input rate), in stage order.
    pub meshes: Vec<f64>,
    pub gears: Vec<GearPart>,
    pub bearings: Vec<BearingPart>,
}

impl Parts {
    /// The parts of a validated gearbox (bearings whose orders do not resolve are left out:
    /// validation refuses them before a gearbox exists).
    pub fn of(gb: &Gearbox) -> Parts {
        let train = gb.shaft_train();
        let mut gears = Vec::new();
        for (i, st) in gb.topology.stages.iter().enumerate() {
            let stage = i + 1;
            let mut add = |member, teeth, shaft: Option<&String>| {
                if let Some(shaft) = shaft {
                    gears.push(GearPart {
                        stage,
                        member,
                        teeth,
                        shaft: shaft.clone(),
                    });
                }
            };
            match st {
                Stage::Parallel {
                    pinion_shaft,
                    pinion_teeth,
                    gear_shaft,
                    gear_teeth,
                } => {
                    add("pinion", *pinion_teeth, Some(pinion_shaft));
                    add("gear", *gear_teeth, Some(gear_shaft));
                }
                Stage::Planetary {
                    sun_shaft,
                    sun_teeth,
                    ring_shaft,
                    ring_teeth,
                    ..
                } => {
                    add("sun", *sun_teeth, sun_shaft.as_ref());
                    add("ring", *ring_teeth, ring_shaft.as_ref());
                }
            }
        }
        let bearings = gb
            .description
            .bearings
            .iter()
            .filter_map(|b| {
                Some(BearingPart {
                    name: b.name.clone(),
                    shaft: b.shaft.clone(),
                    orders: b.defect_orders().ok()?,
                })
            })
            .collect();
        Parts {
            input_shaft: train.input_shaft,
            shafts: train.shafts,
            meshes: train.meshes,
            gears,
            bearings,
        }
    }

    /// The gears on a shaft.
    pub fn gears_on<'a>(&'a self, shaft: &'a str) -> impl Iterator<Item = &'a GearPart> + 'a {
        self.gears.iter().filter(move |g| g.shaft == shaft)
    }
}
