//! Kinematic frequencies of the multistage drive from tooth counts.
//!
//! Stage 1: `f1 = z1 n1`; stage 2: `f2 = z3 nB` with `nB = n1 z1/z2`; planetary stage with the
//! ring fixed and the sun driven at `nC = nB z3/z4`: carrier `nc = nC zs/(zs + zr)`, mesh
//! `f3 = zs (nC − nc)` (the paper's Table 2: f2/f1 = 0.3599 ≈ 0.36, f3/f1 = 0.0877 ≈ 0.0875).
//!
//! The original hand-written three-mesh kinematics of the first paper's rig, kept as the test
//! oracle the gearbox descriptions are checked against (included by `tests/paper_rig.rs` with
//! `#[path]`).

use gearwear_core::error::{Error, Result};
use serde::Serialize;

/// Most planets a configuration may have. Real planetary stages carry 3 to 8; each planet
/// adds a coordinate and two meshes to the model, so an unchecked count (a config file may say
/// 4 294 967 295) would make building the model allocate without bound.
pub const MAX_PLANETS: u32 = 32;

/// Tooth counts of the two fixed-axis stages and the planetary stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ToothCounts {
    pub z1: u32,
    pub z2: u32,
    pub z3: u32,
    pub z4: u32,
    pub zs: u32,
    pub zp: u32,
    pub zr: u32,
    pub planets: u32,
}

/// Characteristic frequencies, all as ratios to the stage-1 mesh frequency `f1`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Frequencies {
    pub f1: f64,
    pub f2: f64,
    pub two_f2: f64,
    pub f3: f64,
    pub half_f1: f64,
    pub f1_minus_f2: f64,
    /// Input (motor) shaft rate.
    pub shaft_in: f64,
    /// Intermediate shaft (gears 2, 3).
    pub shaft_b: f64,
    /// Sun shaft (gear 4, sun).
    pub shaft_c: f64,
    /// Carrier (output).
    pub carrier: f64,
    /// Planet spin relative to the carrier.
    pub planet_spin: f64,
}

impl ToothCounts {
    /// Validate: no zero teeth, at least one and at most [`MAX_PLANETS`] planets, ring larger
    /// than sun.
    pub fn validate(&self) -> Result<()> {
        for (name, z) in [
            ("z1", self.z1),
            ("z2", self.z2),
            ("z3", self.z3),
            ("z4", self.z4),
            ("zs", self.zs),
            ("zp", self.zp),
            ("zr", self.zr),
            ("planets", self.planets),
        ] {
            if z == 0 {
                return Err(Error::param(
                    name,
                    0.0,
                    "tooth counts and the planet count must be positive",
                ));
            }
        }
        if self.planets > MAX_PLANETS {
            return Err(Error::param(
                "planets",
                self.planets as f64,
                format!("at most {MAX_PLANETS} planets"),
            ));
        }
        if self.zr <= self.zs {
            return Err(Error::param(
                "zr",
                self.zr as f64,
                "the ring must have more teeth than the sun",
            ));
        }
        Ok(())
    }

    /// Frequencies over `f1`.
    pub fn frequencies(&self) -> Frequencies {
        let n1 = 1.0 / self.z1 as f64; // input shaft rate for f1 = 1
        let nb = n1 * self.z1 as f64 / self.z2 as f64;
        let nc_sun = nb * self.z3 as f64 / self.z4 as f64;
        // In f64: `zs + zr` overflows u32 for tooth counts near u32::MAX.
        let carrier = nc_sun * self.zs as f64 / (self.zs as f64 + self.zr as f64);
        let f2 = self.z3 as f64 * nb;
        let f3 = self.zs as f64 * (nc_sun - carrier);
        Frequencies {
            f1: 1.0,
            f2,
            two_f2: 2.0 * f2,
            f3,
            half_f1: 0.5,
            f1_minus_f2: 1.0 - f2,
            shaft_in: n1,
            shaft_b: nb,
            shaft_c: nc_sun,
            carrier,
            planet_spin: f3 / self.zp as f64,
        }
    }

    /// Overall reduction ratio input speed / carrier speed.
    pub fn reduction(&self) -> f64 {
        let f = self.frequencies();
        f.shaft_in / f.carrier
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig() -> ToothCounts {
        ToothCounts {
            z1: 29,
            z2: 100,
            z3: 36,
            z4: 90,
            zs: 28,
            zp: 36,
            zr: 100,
            planets: 4,
        }
    }

    #[test]
    fn table_2_ratios() {
        let f = rig().frequencies();
        // Paper's Table 2: 1, 0.3599, 0.0877 (within its rounding).
        assert!((f.f2 - 0.36).abs() < 1e-12 && (f.f2 - 0.3599).abs() < 5e-4);
        assert!((f.f3 - 0.0875).abs() < 1e-12 && (f.f3 - 0.0877).abs() < 5e-4);
        assert!((f.f1_minus_f2 - 0.64).abs() < 1e-12);
        assert!((f.two_f2 - 0.72).abs() < 1e-12);
    }

    #[test]
    fn shaft_rates_and_reduction() {
        let f = rig().frequencies();
        // f1 = 29 × motor rate.
        assert!((f.shaft_in * 29.0 - 1.0).abs() < 1e-12);
        // 100/29 × 90/36 × 128/28 = 39.4
        assert!((rig().reduction() - (100.0 / 29.0) * (90.0 / 36.0) * (128.0 / 28.0)).abs() < 1e-9);
        // A wrong ratio (swapping a stage's teeth) must not pass.
        let mut wrong = rig();
        std::mem::swap(&mut wrong.z3, &mut wrong.z4);
        assert!((wrong.frequencies().f2 - 0.36).abs() > 0.1);
    }

    #[test]
    fn rejects_zero_teeth() {
        let mut z = rig();
        z.zp = 0;
        assert!(z.validate().is_err());
    }

    #[test]
    fn rejects_more_planets_than_the_cap() {
        // fuzz/regressions/model_config/planets-4e9.toml: building Model A with 4e9 planets
        // allocated a coordinate and two meshes per planet.
        let mut tc = rig();
        tc.planets = MAX_PLANETS;
        assert!(tc.validate().is_ok());
        tc.planets = MAX_PLANETS + 1;
        assert!(tc.validate().is_err());
        tc.planets = 4_000_000_000;
        assert!(tc.validate().is_err());
    }

    #[test]
    fn huge_tooth_counts_do_not_overflow() {
        // fuzz/regressions/model_config/sun-ring-teeth-overflow.toml: `zs + zr` in u32
        // overflowed (a panic with overflow checks, a wrapped carrier rate without).
        let tc = ToothCounts {
            zs: u32::MAX - 1,
            zr: u32::MAX,
            ..rig()
        };
        assert!(tc.validate().is_ok());
        let f = tc.frequencies();
        assert!((f.carrier / f.shaft_c - 0.5).abs() < 1e-9, "{f:?}");
        assert!(f.f3.is_finite() && f.f3 > 0.0);
    }
}
