//! The parts map: which shafts can make a line at each order of the input shaft, from the
//! description's kinematics, and the energy of a record's order spectrum in each **line class**
//! and **region**.
//!
//! # Orders of a common period
//! Every shaft's rate over the input shaft's is a fraction of tooth counts, `r_S = p_S / q_S`
//! in lowest terms. Over `P = lcm(q_S)` input revolutions — the **common period** — every shaft
//! turns a whole number of times (1 : 1/3 : 1/5 → `P = 15`). A record resampled to the input
//! shaft's angle over `n·P` revolutions has an order spectrum of resolution `1/(nP)` on which
//! every shaft's harmonics fall on bins: the line at order `j/P` belongs to every shaft `S`
//! whose harmonic it is (`(j/P)/r_S` an integer, i.e. `P p_S | j q_S`). So:
//!
//! | class | lines | what raises them |
//! | --- | --- | --- |
//! | `mesh` | harmonics of a mesh order | load, wear, the transfer path |
//! | `own.S` | lines only shaft `S` makes | a fault once per revolution of `S`: a gear on `S` (as sidebands around its meshes' harmonics), `S` itself (low orders) |
//! | `shared` | lines several shafts make (not a mesh harmonic) | any of them — the input shaft, whose harmonics every slower commensurate shaft shares, has no line of its own and is named by elimination |
//! | `none` | bins no shaft makes (between the lines, and lines of the period no shaft owns) | non-synchronous vibration: bearings, friction, looseness, noise |
//! | `shaft.S.1x`, `.2x` | the shaft's 1× and 2× lines | imbalance, bent shaft (1×), misalignment (2×) |
//!
//! A line's energy is read over its bin and one bin either side (a Hann window's main lobe)
//! when the record holds at least three common periods, else over its bin alone.
//!
//! # Regions
//! The order axis is cut at the midpoints between consecutive distinct mesh harmonics (every
//! mesh's harmonics up to 3 × the highest mesh order): `low` below half the first harmonic
//! (shaft lines), one region `m<h>` around each harmonic `h` (its sidebands: an `own.S` line is
//! `near` within two multiples of `r_S` of `h`, else `far`), and `high` above the last, up to
//! [`HIGH_BAND_MESH_ORDERS`] × the highest mesh order. Where two meshes' harmonics coincide
//! (mesh 1 at twice mesh 2, as on the PHM 2009 gearboxes) they share a region.
//!
//! # Rates that are not commensurate
//! When a rate is not a fraction of denominator ≤ [`MAX_DENOMINATOR`] or the record holds fewer
//! than two common periods, the record's own resolution `1/R` (`R` revolutions) is used: a bin
//! belongs to a shaft when one of its harmonics lies within half a bin of it
//! ([`LineMap::resolution_note`] says so).

use std::collections::BTreeMap;

use super::parts::Parts;

/// Largest denominator of a shaft's rate taken as a fraction.
pub const MAX_DENOMINATOR: u64 = 1_000_000;
/// Longest common period (input revolutions) worth a grid: longer ones use the record's own
/// resolution.
pub const MAX_PERIOD_REVS: u64 = 100_000;
/// Mesh harmonics with a region of their own: up to this many times the highest mesh order.
pub const MESH_REGION_ORDERS: f64 = 3.0;
/// The `high` region ends at this many times the highest mesh order.
pub const HIGH_BAND_MESH_ORDERS: f64 = 8.0;
/// An own line is `near` its region's mesh harmonic within this many multiples of its shaft's
/// rate (the sidebands of an eccentric gear; a local fault spreads further).
pub const NEAR_MULTIPLES: f64 = 2.0;

/// `x` as a fraction `p/q` (lowest terms, `q ≤ max_den`) within 1e-12 relative, by continued
/// fractions; `None` when no such fraction is that close.
pub fn rational(x: f64, max_den: u64) -> Option<(u64, u64)> {
    if !(x.is_finite() && x > 0.0) {
        return None;
    }
    let (mut h0, mut h1) = (0u64, 1u64);
    let (mut k0, mut k1) = (1u64, 0u64);
    let mut v = x;
    for _ in 0..64 {
        let a = v.floor();
        if a > u64::MAX as f64 / 4.0 {
            return None;
        }
        let a = a as u64;
        let h2 = a.checked_mul(h1)?.checked_add(h0)?;
        let k2 = a.checked_mul(k1)?.checked_add(k0)?;
        if k2 > max_den {
            return None;
        }
        if ((h2 as f64 / k2 as f64) / x - 1.0).abs() <= 1e-12 {
            return Some((h2, k2));
        }
        (h0, h1, k0, k1) = (h1, h2, k1, k2);
        let f = v - a as f64;
        if f <= 0.0 {
            return None;
        }
        v = 1.0 / f;
    }
    None
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// A shaft's rate over the input shaft's.
#[derive(Debug, Clone, PartialEq)]
pub struct ShaftRate {
    pub name: String,
    pub rate: f64,
    /// `rate = num / den` when commensurate.
    pub fraction: Option<(u64, u64)>,
}

/// A region of the order axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    /// `low`, `m<h>` or `high`.
    pub name: String,
    /// `[lo, hi)` in input-shaft orders.
    pub lo: f64,
    pub hi: f64,
    /// The mesh harmonic a `m<h>` region is centred on.
    pub centre: Option<f64>,
}

/// The class of a line (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    Mesh,
    /// Only shaft `i` (index into [`LineMap::shafts`]) makes it; `near` its region's mesh
    /// harmonic (mesh regions only).
    Own {
        shaft: usize,
        near: Option<bool>,
    },
    Shared,
    /// The 1× (`h = 1`) or 2× line of shaft `i`.
    ShaftLine {
        shaft: usize,
        h: u8,
    },
    None,
}

/// Which shafts make which lines, and the regions (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct LineMap {
    /// Shafts, fastest first.
    pub shafts: Vec<ShaftRate>,
    /// Each stage's mesh order.
    pub meshes: Vec<f64>,
    /// Input revolutions of the common period; `None` when the rates are not commensurate.
    pub period_revs: Option<u64>,
    pub regions: Vec<Region>,
}

/// How a record's order spectrum was laid out for the classes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layout {
    /// Input revolutions analysed (a whole number of common periods on a grid).
    pub revolutions: usize,
    /// Common periods analysed; `None`: the record's own resolution.
    pub periods: Option<usize>,
}

impl LineMap {
    /// The map of a gearbox's parts.
    pub fn of(parts: &Parts) -> LineMap {
        let mut shafts: Vec<ShaftRate> = parts
            .shafts
            .iter()
            .filter(|(_, r)| **r > 0.0)
            .map(|(n, &r)| ShaftRate {
                name: n.clone(),
                rate: r,
                fraction: rational(r, MAX_DENOMINATOR),
            })
            .collect();
        shafts.sort_by(|a, b| b.rate.total_cmp(&a.rate).then(a.name.cmp(&b.name)));
        let period_revs = shafts
            .iter()
            .try_fold(1u64, |p, s| {
                let (_, q) = s.fraction?;
                let l = p / gcd(p, q) * q;
                (l <= MAX_PERIOD_REVS).then_some(l)
            })
            .filter(|_| !shafts.is_empty());
        let meshes: Vec<f64> = parts.meshes.iter().map(|m| m.abs()).collect();
        let regions = regions(&meshes);
        LineMap {
            shafts,
            meshes,
            period_revs,
            regions,
        }
    }

    /// The highest order any region reaches.
    pub fn top_order(&self) -> f64 {
        self.regions.last().map_or(0.0, |r| r.hi)
    }

    /// How many revolutions of a record of `available` whole revolutions to analyse: the most
    /// whole common periods when at least two fit, else all of them at the record's own
    /// resolution.
    pub fn layout(&self, available: usize) -> Layout {
        match self.period_revs {
            Some(p) if available as u64 >= 2 * p => {
                let n = (available as u64 / p) as usize;
                Layout {
                    revolutions: n * p as usize,
                    periods: Some(n),
                }
            }
            _ => Layout {
                revolutions: available,
                periods: None,
            },
        }
    }

    /// Why the record's own resolution was used, when it was.
    pub fn resolution_note(&self, layout: &Layout) -> Option<String> {
        if layout.periods.is_some() {
            return None;
        }
        Some(match self.period_revs {
            None => "the shafts' rates are not commensurate: a line is assigned to the shafts \
                     with a harmonic within half a bin of it"
                .into(),
            Some(p) => format!(
                "the record holds {} input revolutions, fewer than two common periods of {p}: a \
                 line is assigned to the shafts with a harmonic within half a bin of it",
                layout.revolutions
            ),
        })
    }

    /// Index of the region holding order `o`; `None` at or beyond the last.
    pub fn region_of(&self, o: f64) -> Option<usize> {
        let i = self.regions.partition_point(|r| r.hi <= o);
        (i < self.regions.len() && o >= self.regions[i].lo).then_some(i)
    }

    /// Is order `o` (exactly, within `tol` orders) a harmonic of a mesh?
    fn on_mesh(&self, o: f64, tol: f64) -> bool {
        self.meshes.iter().any(|&m| {
            let k = (o / m).round();
            k >= 1.0 && (o - k * m).abs() <= tol
        })
    }

    /// The class of a line at order `o` that the shafts of `owners` (indices, fastest first)
    /// make; `tol`: how close (orders) counts as the same line.
    fn class(&self, o: f64, owners: &[usize], tol: f64, shaft_lines: bool) -> Class {
        if self.on_mesh(o, tol) {
            return Class::Mesh;
        }
        for &i in owners.iter().filter(|_| shaft_lines) {
            let r = self.shafts[i].rate;
            for h in [1u8, 2] {
                if (o - h as f64 * r).abs() <= tol {
                    return Class::ShaftLine { shaft: i, h };
                }
            }
        }
        match owners {
            [] => Class::None,
            [i] => {
                let near = self
                    .region_of(o)
                    .and_then(|k| self.regions[k].centre)
                    .map(|c| (o - c).abs() <= NEAR_MULTIPLES * self.shafts[*i].rate + tol);
                Class::Own { shaft: *i, near }
            }
            _ => Class::Shared,
        }
    }

    /// Every line up to the top region's end, with its class: `(bin, class)` for an order
    /// spectrum of `layout`'s resolution; `shaft_lines`: the 1× and 2× lines of each shaft as a
    /// class of their own (else in the shaft's own or the shared class).
    pub fn lines(&self, layout: &Layout, shaft_lines: bool) -> Vec<(usize, Class)> {
        let top = self.top_order();
        let bins_per_order = layout.revolutions as f64;
        match (layout.periods, self.period_revs) {
            (Some(n), Some(p)) => {
                let jmax = (top * p as f64).floor() as u64;
                (1..=jmax)
                    .filter_map(|j| {
                        let owners: Vec<usize> = (0..self.shafts.len())
                            .filter(|&i| {
                                let (num, den) = self.shafts[i].fraction.expect("commensurate");
                                (j as u128 * den as u128).is_multiple_of(p as u128 * num as u128)
                            })
                            .collect();
                        let o = j as f64 / p as f64;
                        let class = self.class(o, &owners, 0.25 / p as f64, shaft_lines);
                        (class != Class::None).then_some((j as usize * n, class))
                    })
                    .collect()
            }
            _ => {
                let mut owners: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
                for (i, s) in self.shafts.iter().enumerate() {
                    let mut h = 1.0;
                    while h * s.rate < top {
                        let bin = (h * s.rate * bins_per_order).round() as usize;
                        if bin > 0 {
                            let v = owners.entry(bin).or_default();
                            if !v.contains(&i) {
                                v.push(i);
                            }
                        }
                        h += 1.0;
                    }
                }
                owners
                    .into_iter()
                    .map(|(bin, v)| {
                        let o = bin as f64 / bins_per_order;
                        (bin, self.class(o, &v, 0.5 / bins_per_order, shaft_lines))
                    })
                    .collect()
            }
        }
    }

    /// The energy (sum of squared amplitudes) of an order spectrum `amplitude` (one value per
    /// bin, `layout.revolutions` bins per order) in each class and region: the evidence
    /// features' names (`lines.mesh.<region>`, `lines.own.<S>[.near|.far].<region>`,
    /// `lines.shared.<region>`, `lines.none.<region>`, `shaft.<S>.1x|2x`) → energy. Regions
    /// above `max_order` (the record's usable orders) are left out; `shaft_lines` as in
    /// [`LineMap::lines`].
    pub fn energies(
        &self,
        amplitude: &[f64],
        layout: &Layout,
        max_order: f64,
        shaft_lines: bool,
    ) -> BTreeMap<String, f64> {
        let bpo = layout.revolutions as f64;
        let half = match layout.periods {
            Some(n) if n >= 3 => 1,
            _ => 0,
        };
        let usable_bins = ((max_order.min(self.top_order())) * bpo).floor() as usize;
        let last = usable_bins.min(amplitude.len().saturating_sub(1));
        let mut used = vec![false; last + 1];
        let mut out: BTreeMap<String, f64> = BTreeMap::new();
        for (bin, class) in self.lines(layout, shaft_lines) {
            if bin + half > last || bin < half.max(1) {
                continue;
            }
            let o = bin as f64 / bpo;
            let Some(r) = self.region_of(o) else { continue };
            let e: f64 = (bin - half..=bin + half)
                .map(|k| amplitude[k] * amplitude[k])
                .sum();
            (bin - half..=bin + half).for_each(|k| used[k] = true);
            *out.entry(self.name(class, r)).or_default() += e;
        }
        for (k, &u) in used.iter().enumerate().skip(1) {
            if !u && let Some(r) = self.region_of(k as f64 / bpo) {
                *out.entry(self.name(Class::None, r)).or_default() += amplitude[k] * amplitude[k];
            }
        }
        // A region cut by the usable orders would read less than a whole one.
        let cut = self.region_of(last as f64 / bpo);
        if let Some(c) = cut.filter(|&c| self.regions[c].hi > (last + 1) as f64 / bpo) {
            let suffix = format!(".{}", self.regions[c].name);
            out.retain(|k, _| !k.ends_with(&suffix));
        }
        out
    }

    /// The class and feature name of a line at order `o` (any order: its owners are the shafts
    /// with a harmonic within 1e-6 of it); `None` outside the regions.
    pub fn feature_at(&self, o: f64, shaft_lines: bool) -> Option<(Class, String)> {
        let tol = 1e-6 * o.max(1.0);
        let owners: Vec<usize> = (0..self.shafts.len())
            .filter(|&i| {
                let r = self.shafts[i].rate;
                let m = (o / r).round();
                m >= 1.0 && (o - m * r).abs() <= tol
            })
            .collect();
        let class = self.class(o, &owners, tol, shaft_lines);
        let r = self.region_of(o)?;
        Some((class, self.name(class, r)))
    }

    /// The feature name of a class in region `r`.
    fn name(&self, class: Class, r: usize) -> String {
        let region = &self.regions[r].name;
        match class {
            Class::Mesh => format!("lines.mesh.{region}"),
            Class::Own { shaft, near } => {
                let s = &self.shafts[shaft].name;
                match near {
                    Some(true) => format!("lines.own.{s}.near.{region}"),
                    Some(false) => format!("lines.own.{s}.far.{region}"),
                    None => format!("lines.own.{s}.{region}"),
                }
            }
            Class::Shared => format!("lines.shared.{region}"),
            Class::ShaftLine { shaft, h } => format!("shaft.{}.{h}x", self.shafts[shaft].name),
            Class::None => format!("lines.none.{region}"),
        }
    }
}

/// An order as a region name: `m16`, `m21.33`.
fn order_name(o: f64) -> String {
    let s = format!("{o:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    format!("m{s}")
}

/// The regions of a train with mesh orders `meshes` (see the [module docs](self)).
fn regions(meshes: &[f64]) -> Vec<Region> {
    let top = meshes.iter().fold(0.0f64, |a, &b| a.max(b));
    if top <= 0.0 {
        return Vec::new();
    }
    let mut h: Vec<f64> = meshes
        .iter()
        .filter(|m| **m > 0.0)
        .flat_map(|&m| {
            (1..)
                .map(move |k| k as f64 * m)
                .take_while(move |&o| o <= MESH_REGION_ORDERS * top * (1.0 + 1e-9))
        })
        .collect();
    h.sort_by(f64::total_cmp);
    h.dedup_by(|a, b| (*a - *b).abs() <= 1e-6 * b.abs());
    let mut v = vec![Region {
        name: "low".into(),
        lo: 0.0,
        hi: 0.5 * h[0],
        centre: None,
    }];
    for (i, &c) in h.iter().enumerate() {
        let lo = v[v.len() - 1].hi;
        let hi = match h.get(i + 1) {
            Some(&next) => 0.5 * (c + next),
            None => c + 0.5 * (c - if i > 0 { h[i - 1] } else { 0.0 }),
        };
        v.push(Region {
            name: order_name(c),
            lo,
            hi,
            centre: Some(c),
        });
    }
    let lo = v[v.len() - 1].hi;
    let hi = (HIGH_BAND_MESH_ORDERS * top).max(lo * 1.5);
    v.push(Region {
        name: "high".into(),
        lo,
        hi,
        centre: None,
    });
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::test_util::spur;

    #[test]
    fn fractions_of_tooth_counts() {
        assert_eq!(rational(1.0 / 3.0, MAX_DENOMINATOR), Some((1, 3)));
        assert_eq!(
            rational(32.0 / 96.0 * 48.0 / 80.0, MAX_DENOMINATOR),
            Some((1, 5))
        );
        assert_eq!(
            rational(17.0 / 113.0 * 29.0 / 71.0, MAX_DENOMINATOR),
            Some((493, 8023))
        );
        assert_eq!(rational(std::f64::consts::PI, 1000), None);
    }

    /// 1 : 1/3 : 1/5 → a period of 15 input revolutions; the idler alone makes 1/3 and 2/3,
    /// every shaft makes order 1 (the input's 1×), nobody makes 1/15; mesh 2 (16) and mesh 1
    /// (32) share the region m32.
    #[test]
    fn the_spur_trains_map() {
        let m = LineMap::of(&spur());
        assert_eq!(m.period_revs, Some(15));
        assert_eq!(m.shafts[0].name, "in");
        let names: Vec<&str> = m.regions.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            ["low", "m16", "m32", "m48", "m64", "m80", "m96", "high"]
        );
        assert_eq!(m.regions[1].lo, 8.0);
        assert_eq!(m.regions[1].hi, 24.0);
        let layout = m.layout(120);
        assert_eq!(layout.periods, Some(8));
        let lines = m.lines(&layout, true);
        let at = |o: f64| {
            lines
                .iter()
                .find(|(b, _)| *b == (o * 120.0).round() as usize)
                .map(|x| x.1)
        };
        let idler = m.shafts.iter().position(|s| s.name == "idler").unwrap();
        let out = m.shafts.iter().position(|s| s.name == "out").unwrap();
        assert_eq!(at(1.0 / 3.0), Some(Class::ShaftLine { shaft: idler, h: 1 }));
        assert_eq!(
            at(4.0 / 3.0),
            Some(Class::Own {
                shaft: idler,
                near: None
            })
        );
        assert_eq!(at(1.0), Some(Class::ShaftLine { shaft: 0, h: 1 }));
        assert_eq!(at(3.0), Some(Class::Shared));
        assert_eq!(at(1.0 / 15.0), None);
        assert_eq!(at(16.0), Some(Class::Mesh));
        assert_eq!(
            at(32.0 + 0.2),
            Some(Class::Own {
                shaft: out,
                near: Some(true)
            })
        );
        assert_eq!(
            at(32.0 + 0.6),
            Some(Class::Own {
                shaft: out,
                near: Some(false)
            })
        );
        assert_eq!(
            at(32.0 - 2.0 / 3.0),
            Some(Class::Own {
                shaft: idler,
                near: Some(true)
            })
        );
        assert_eq!(at(33.0), Some(Class::Shared));
    }

    /// A spectrum with a unit line at the idler's 4/3 and noise-free elsewhere puts its whole
    /// energy (over its three bins) in `lines.own.idler.low`; a line between the grid's lines
    /// lands in `lines.none`.
    #[test]
    fn energies_land_in_their_class() {
        let m = LineMap::of(&spur());
        let layout = m.layout(120);
        let mut a = vec![0.0; 120 * 300];
        let b = (4.0 / 3.0 * 120.0f64).round() as usize;
        a[b] = 1.0;
        a[b - 1] = 0.5;
        a[b + 1] = 0.5;
        a[(5.5 * 120.0) as usize + 3] = 2.0;
        let e = m.energies(&a, &layout, 290.0, true);
        assert!((e["lines.own.idler.low"] - 1.5).abs() < 1e-12, "{e:?}");
        assert!((e["lines.none.low"] - 4.0).abs() < 1e-12, "{e:?}");
        assert_eq!(e["lines.shared.m16"], 0.0);
        // The high region ends at 8 × 32 = 256 < 290: every region is whole.
        assert!(e.contains_key("lines.none.high"));
        // Up to order 100 only: the m96 region ends at 104, so it and `high` are left out.
        let e = m.energies(&a, &layout, 100.0, true);
        assert!(
            !e.keys()
                .any(|k| k.ends_with(".m96") || k.ends_with(".high"))
        );
    }

    /// Rates that are no fraction of small denominator, or a record under two periods: the
    /// record's own resolution, and a note that says so.
    #[test]
    fn incommensurate_rates_use_the_records_resolution() {
        let mut p = spur();
        p.shafts
            .insert("odd".into(), std::f64::consts::FRAC_1_SQRT_2);
        let m = LineMap::of(&p);
        assert_eq!(m.period_revs, None);
        let layout = m.layout(100);
        assert_eq!(layout.periods, None);
        assert!(
            m.resolution_note(&layout)
                .unwrap()
                .contains("not commensurate")
        );
        let m = LineMap::of(&spur());
        let layout = m.layout(20);
        assert!(
            m.resolution_note(&layout)
                .unwrap()
                .contains("fewer than two")
        );
        let lines = m.lines(&layout, true);
        assert!(
            lines
                .iter()
                .any(|(b, c)| *b == 20 && *c == Class::ShaftLine { shaft: 0, h: 1 })
        );
    }
}
