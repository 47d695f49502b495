//! A single mesh with backlash: an exact piecewise closed-form reference, shared by
//! `tests/physics.rs` and `benches/solvers/main.rs` (included in both with `#[path]`), and the
//! same mesh built through the generic assembly.
//!
//! `x'' + c x' + k f_b(x) = F + a Ω² sin(Ω τ + φ)`, with `f_b` the backlash dead zone of half
//! width `b`: linear in each region, so each region has a closed form and only the switches
//! between regions are searched (bisection to 1e-14).

use gearwear_core::model::{Assembly, Damping, Dof, Element, Load, LoadSchedule, StiffnessShape};

/// x'' + c x' + k f_b(x) = F + a Ω² sin(Ω τ + φ), solved region by region in closed form.
#[derive(Clone, Copy)]
pub struct OneMesh {
    pub c: f64,
    pub k: f64,
    pub b: f64,
    pub f: f64,
    pub a: f64,
    pub w: f64,
    pub phi: f64,
}

impl OneMesh {
    /// Closed-form (x, v) at τ0 + u from (x0, v0) at τ0 in region s ∈ {-1, 0, 1}.
    pub fn solve(&self, s: i32, tau0: f64, x0: f64, v0: f64, u: f64) -> (f64, f64) {
        let (c, w, amp) = (self.c, self.w, self.a * self.w * self.w);
        let th0 = w * tau0 + self.phi;
        let th = th0 + w * u;
        if s == 0 {
            // x'' + c x' = F + amp sin θ
            let d0 = w.powi(4) + c * c * w * w;
            let p = -amp * w * w / d0;
            let q = -amp * c * w / d0;
            let c2 = -(v0 - self.f / c - w * (p * th0.cos() - q * th0.sin())) / c;
            let c1 = x0 - c2 - (p * th0.sin() + q * th0.cos());
            let e = (-c * u).exp();
            let x = c1 + c2 * e + self.f / c * u + p * th.sin() + q * th.cos();
            let v = -c * c2 * e + self.f / c + w * (p * th.cos() - q * th.sin());
            (x, v)
        } else {
            let k = self.k;
            let xs = (k * s as f64 * self.b + self.f) / k;
            let d = (k - w * w).powi(2) + (c * w).powi(2);
            let p = amp * (k - w * w) / d;
            let q = -amp * c * w / d;
            let xp0 = xs + p * th0.sin() + q * th0.cos();
            let vp0 = w * (p * th0.cos() - q * th0.sin());
            let wd = (k - c * c / 4.0).sqrt();
            let c1 = x0 - xp0;
            let c2 = (v0 - vp0 + c / 2.0 * c1) / wd;
            let e = (-c / 2.0 * u).exp();
            let (sn, cs) = (wd * u).sin_cos();
            let xh = e * (c1 * cs + c2 * sn);
            let vh = e * (-c / 2.0 * (c1 * cs + c2 * sn) + wd * (-c1 * sn + c2 * cs));
            (
                xs + p * th.sin() + q * th.cos() + xh,
                w * (p * th.cos() - q * th.sin()) + vh,
            )
        }
    }

    pub fn region(&self, x: f64) -> i32 {
        if x > self.b {
            1
        } else if x < -self.b {
            -1
        } else {
            0
        }
    }

    /// Reference solution on a grid: march region by region, locating each switch by
    /// bisection to 1e-14 on the closed form.
    pub fn reference(&self, x0: f64, v0: f64, grid: &[f64]) -> Vec<f64> {
        let (mut tau0, mut x, mut v) = (0.0, x0, v0);
        let mut s = self.region(x0);
        let mut out = Vec::with_capacity(grid.len());
        let mut gi = 0;
        let du = 1e-3;
        loop {
            // Find the next switch time from (tau0, x, v) in region s.
            let boundary_hit = |u: f64| -> bool {
                let (xu, _) = self.solve(s, tau0, x, v, u);
                self.region(xu) != s
            };
            let t_last = *grid.last().unwrap();
            let mut u = 0.0;
            let mut switch: Option<f64> = None;
            while tau0 + u < t_last + du {
                if boundary_hit(u + du) {
                    let (mut lo, mut hi) = (u, u + du);
                    while hi - lo > 1e-14 {
                        let mid = 0.5 * (lo + hi);
                        if boundary_hit(mid) {
                            hi = mid
                        } else {
                            lo = mid
                        }
                    }
                    switch = Some(hi);
                    break;
                }
                u += du;
            }
            let end = switch.map(|u| tau0 + u).unwrap_or(f64::INFINITY);
            while gi < grid.len() && grid[gi] <= end {
                out.push(self.solve(s, tau0, x, v, grid[gi] - tau0).0);
                gi += 1;
            }
            if gi == grid.len() {
                return out;
            }
            let u = switch.unwrap();
            let (xn, vn) = self.solve(s, tau0, x, v, u);
            tau0 += u;
            x = xn;
            v = vn;
            s = self.region(x);
            if s == self.region(x - 1e-12 * v.signum()) {
                // Exactly on the boundary: the region is the one we move into.
                s = self.region(x + 1e-9 * v.signum());
            }
        }
    }
}

/// The same single mesh built through the generic assembly: one rotation driven through a
/// base radius r = 1 m against the ground, so `A = 1/J`.
pub fn one_mesh_assembly(p: &OneMesh) -> Assembly {
    // With b_ref = 1, k = ω_h² J: choose J = 1, k = 1 → ω_h = 1 and all values are the
    // dimensionless ones.
    let mut el = Element::mesh(
        "x",
        ("q", 1.0),
        ("q", 0.0),
        1.0,
        StiffnessShape::Constant,
        1.0,
        Damping::Coefficient(p.c),
        p.b,
    );
    el = el.with_error(p.a, 1.0, p.phi);
    Assembly {
        name: "one-mesh".into(),
        dofs: vec![Dof::rotation("q", 1.0).unwrap()],
        elements: vec![el],
        loads: vec![Load {
            dof: "q".into(),
            schedule: LoadSchedule::Constant { value: p.f },
        }],
        length_ref: 1.0,
        sensor: 0,
    }
}
