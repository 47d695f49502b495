//! The evaluation zones of ISO 20816-3:2022 (*Mechanical vibration — Measurement and
//! evaluation of machine vibration — Part 3: Industrial machines with a power rating above
//! 15 kW and operating speeds between 120 r/min and 30 000 r/min*) for the broad-band r.m.s.
//! vibration velocity measured on a bearing housing or pedestal.
//!
//! # Boundaries (r.m.s. velocity, mm/s)
//!
//! | group | support | A/B | B/C | C/D |
//! | --- | --- | --- | --- | --- |
//! | 1 | rigid | 2.3 | 4.5 | 7.1 |
//! | 1 | flexible | 3.5 | 7.1 | 11.0 |
//! | 2 | rigid | 1.4 | 2.8 | 4.5 |
//! | 2 | flexible | 2.3 | 4.5 | 7.1 |
//!
//! Source: ISO 20816-3:2022, Annex A, Table A.1 (group 1) and Table A.2 (group 2) — the same
//! values as ISO 10816-3:2009's Tables A.1 and A.2, which it replaced. They hold for the velocity
//! over 10–1000 Hz of machines running above 600 r/min (for 120–600 r/min the standard
//! measures over 2–1000 Hz, which gearwear does not).
//!
//! * **Group 1**: large machines, rated power above 300 kW and at most 50 MW; electrical
//!   machines with a shaft height of 315 mm or more.
//! * **Group 2**: medium machines, above 15 kW and at most 300 kW; electrical machines with a
//!   shaft height from 160 mm to 315 mm.
//! * **Rigid** support: the lowest natural frequency of the machine on its support, in the
//!   direction measured, is at least 25 % above the main excitation frequency (usually the
//!   running speed); every other support is **flexible**.
//!
//! A velocity on a boundary belongs to the higher zone (`v < A/B` is A, `A/B ≤ v < B/C` is B, …).
//! The zones' meanings are ISO 20816-1's (see [`Zone::meaning`]).

use serde::{Deserialize, Serialize};

use crate::error::UnitError;

/// How the machine is supported, in the direction measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Support {
    Rigid,
    Flexible,
}

impl Support {
    /// `rigid` or `flexible`, as written in a configuration.
    pub fn as_str(self) -> &'static str {
        match self {
            Support::Rigid => "rigid",
            Support::Flexible => "flexible",
        }
    }
}

/// A machine's ISO 20816-3 class: `{"group": 2, "support": "rigid"}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct IsoClass {
    /// 1 (large) or 2 (medium).
    pub group: u8,
    pub support: Support,
}

impl IsoClass {
    /// Check a class as given: `group` 1 or 2, `support` `rigid` or `flexible`.
    pub fn new(group: i64, support: &str) -> Result<IsoClass, UnitError> {
        let group = match group {
            1 | 2 => group as u8,
            g => return Err(UnitError::IsoGroup { group: g }),
        };
        let support = match support {
            "rigid" => Support::Rigid,
            "flexible" => Support::Flexible,
            s => {
                return Err(UnitError::IsoSupport {
                    support: s.to_string(),
                });
            }
        };
        Ok(IsoClass { group, support })
    }

    /// The class's zone boundaries, mm/s (the [module's](self) table).
    pub fn boundaries(&self) -> Boundaries {
        let (a_b, b_c, c_d) = match (self.group, self.support) {
            (1, Support::Rigid) => (2.3, 4.5, 7.1),
            (1, Support::Flexible) => (3.5, 7.1, 11.0),
            (_, Support::Rigid) => (1.4, 2.8, 4.5),
            (_, Support::Flexible) => (2.3, 4.5, 7.1),
        };
        Boundaries { a_b, b_c, c_d }
    }

    /// The zone of an r.m.s. velocity `v_mm_s` (mm/s over 10–1000 Hz).
    pub fn zone(&self, v_mm_s: f64) -> IsoZone {
        let b = self.boundaries();
        let zone = if v_mm_s < b.a_b {
            Zone::A
        } else if v_mm_s < b.b_c {
            Zone::B
        } else if v_mm_s < b.c_d {
            Zone::C
        } else {
            Zone::D
        };
        IsoZone {
            zone,
            meaning: zone.meaning(),
            group: self.group,
            support: self.support,
            boundaries_mm_s: b,
        }
    }
}

/// The velocities (mm/s r.m.s.) between zones A and B, B and C, C and D.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Boundaries {
    pub a_b: f64,
    pub b_c: f64,
    pub c_d: f64,
}

/// An evaluation zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum Zone {
    A,
    B,
    C,
    D,
}

impl Zone {
    /// What the zone means (the general zone descriptions of ISO 20816-1:2016, which Part 3
    /// uses).
    pub fn meaning(self) -> &'static str {
        match self {
            Zone::A => "the vibration of newly commissioned machines",
            Zone::B => "acceptable for unrestricted long-term operation",
            Zone::C => {
                "unsatisfactory for long-term continuous operation: the machine may run for a \
                 limited period until a suitable opportunity for remedial action"
            }
            Zone::D => "severe enough to cause damage to the machine",
        }
    }
}

/// A velocity's zone, with the class and the boundaries it was judged by.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IsoZone {
    pub zone: Zone,
    pub meaning: &'static str,
    pub group: u8,
    pub support: Support,
    pub boundaries_mm_s: Boundaries,
}
