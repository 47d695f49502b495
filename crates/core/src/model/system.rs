//! The resolved dimensionless model and its right-hand side.

use std::f64::consts::TAU;

use nalgebra::DMatrix;

use super::element::{Harmonic, StiffnessShape, ToothDamage};
use crate::error::{Error, Result};
use crate::solver::OdeSystem;

/// A gear train in the dimensionless relative form (see [`crate::model::assembly`]):
///
/// ```text
/// x̄'' + Ā (k̄(τ) ∘ f(x̄) + c̄ ∘ x̄') = F̄(τ) + Σ_h ē_h Ω_h² sin(Ω_h τ + φ_h)
/// k̄_j(τ) = k_ratio_j · s_j(Ω_j τ + phase_j),      Ω_j = omega_ratio_j · Ω1
/// ```
///
/// with `s_j` the element's stiffness shape of mean 1 (`1 + ε cos(·)` for the first harmonic)
/// and `f` the dead zone of half-width `backlash_j`. Element order is the assembly's. An element
/// with `damping_in_contact_only` has `k̄_j f(x̄_j) + c̄_j x̄'_j` replaced by 0 while
/// `|x̄_j| ≤ b̄_j` (free flight in the clearance).
#[derive(Debug, Clone)]
pub struct DimensionlessModel {
    pub name: String,
    /// Element names, e.g. `x1, x2, xsp1..4, xrp1..4` for Model A.
    pub names: Vec<String>,
    /// Element kinds (`mesh`, `shaft`, `bearing`).
    pub kinds: Vec<String>,
    /// `Ā = A / A_00` (n × n, symmetric).
    pub a: DMatrix<f64>,
    /// Mean stiffness over the reference element's.
    pub k_ratio: Vec<f64>,
    pub shape: Vec<StiffnessShape>,
    /// Dimensionless damping `c̄`.
    pub c: Vec<f64>,
    /// Static load `F̄` at τ = 0.
    pub f: Vec<f64>,
    /// Jumps of `F̄`: (τ, ΔF̄).
    pub load_steps: Vec<(f64, Vec<f64>)>,
    /// Mesh frequency over the reference mesh frequency.
    pub omega_ratio: Vec<f64>,
    /// Phase of the stiffness variation (rad).
    pub phase: Vec<f64>,
    /// Half-clearance in units of `length_ref`.
    pub backlash: Vec<f64>,
    /// Per element: damping only while in contact (`|x̄| > b̄`), zero force inside the
    /// clearance ([`crate::model::Element::damping_in_contact_only`]).
    pub damping_in_contact_only: Vec<bool>,
    /// Error harmonics per element, amplitudes in units of `length_ref`.
    pub error: Vec<Vec<Harmonic>>,
    /// Per element: a damaged tooth (stiffness dip once per revolution of its gear's shaft).
    pub tooth_damage: Vec<Option<ToothDamage>>,
    /// Reference frequency `ω_h` (rad/s): `τ = ω_h t`.
    pub omega_h: f64,
    /// Reference length `b_ref` (m).
    pub length_ref: f64,
    /// `A_00` (1/kg) and `k_00` (N/m) of the reference element.
    pub a_ref: f64,
    pub k_ref: f64,
    /// Physical `G` (n × m) and `diag(M⁻¹)`, for reconstructing coordinates.
    pub g: DMatrix<f64>,
    pub inverse_inertia: Vec<f64>,
    /// Basis of the rigid-body modes (m × r).
    pub rigid_modes: DMatrix<f64>,
    pub dof_names: Vec<String>,
    /// Element the simulated sensor measures (0: the reference mesh).
    pub sensor: usize,
}

impl DimensionlessModel {
    /// Number of deflection coordinates.
    pub fn n(&self) -> usize {
        self.names.len()
    }

    /// Distinct mesh and error frequencies other than the reference one, over it (Model A:
    /// 0.36 and 0.0875). They modulate a response sampled once per reference period.
    pub fn other_frequency_ratios(&self) -> Vec<f64> {
        let mut v: Vec<f64> = Vec::new();
        let all = self
            .omega_ratio
            .iter()
            .cloned()
            .chain(self.error.iter().flatten().map(|h| h.freq_ratio));
        for r in all {
            if r > 0.0 && (r - 1.0).abs() > 1e-12 && !v.iter().any(|x| (x - r).abs() < 1e-12) {
                v.push(r);
            }
        }
        v
    }

    /// Index of an element by name.
    pub fn index(&self, name: &str) -> Result<usize> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| Error::InvalidConfig(format!("unknown element `{name}`")))
    }

    /// The right-hand side at the operating point `Ω1` (stage-1 mesh frequency over `ω_h`).
    pub fn system(&self, omega1: f64) -> Result<GearOde> {
        GearOde::new(self, omega1)
    }

    /// Project a state `[x̄, x̄']` onto the kinematically consistent set: `x̄ + ē` and
    /// `x̄' + ē'` must lie in the range of `G` (they are `G q / b_ref`). The relative form keeps
    /// that property, so a consistent start stays consistent; an inconsistent one (zero velocity
    /// against a nonzero `ē'(0)` on meshes whose errors differ between planets) would drift along
    /// the constraint directions forever. With the paper's equal planetary errors the zero state
    /// is already consistent and this changes nothing.
    pub fn project_consistent(&self, omega1: f64, tau: f64, y: &mut [f64]) {
        let n = self.n();
        let svd = self.g.clone().svd(true, false);
        let Some(u) = svd.u else { return };
        let smax = svd.singular_values.iter().cloned().fold(0.0_f64, f64::max);
        let cols: Vec<usize> = (0..svd.singular_values.len())
            .filter(|&i| svd.singular_values[i] > 1e-10 * smax)
            .collect();
        let mut e = vec![0.0; n];
        let mut ed = vec![0.0; n];
        for (j, hs) in self.error.iter().enumerate() {
            for h in hs {
                let w = h.freq_ratio * omega1;
                e[j] += h.amplitude * (w * tau + h.phase).sin();
                ed[j] += h.amplitude * w * (w * tau + h.phase).cos();
            }
        }
        for (off, err) in [(0usize, &e), (n, &ed)] {
            let z: Vec<f64> = (0..n).map(|j| y[off + j] + err[j]).collect();
            let mut p = vec![0.0; n];
            for &c in &cols {
                let col = u.column(c);
                let dot: f64 = (0..n).map(|j| col[j] * z[j]).sum();
                for j in 0..n {
                    p[j] += dot * col[j];
                }
            }
            let scale = z.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
            let off_range = (0..n).fold(0.0_f64, |m, j| m.max((p[j] - z[j]).abs()));
            // Already consistent (to rounding): leave the state bit-for-bit as given.
            if off_range <= 1e-12 * scale {
                continue;
            }
            for j in 0..n {
                y[off + j] = p[j] - err[j];
            }
        }
    }

    /// Largest undamped natural frequency of the linearised model (all meshes in contact, mean
    /// stiffness), in units of `ω_h`: `sqrt(max eig(Ā diag(k̄)))`.
    pub fn natural_frequencies(&self) -> Vec<f64> {
        let n = self.n();
        // Ā diag(k̄) is similar to the symmetric diag(√k̄) Ā diag(√k̄).
        let s = DMatrix::from_fn(n, n, |i, j| {
            self.k_ratio[i].sqrt() * self.a[(i, j)] * self.k_ratio[j].sqrt()
        });
        let mut w: Vec<f64> = s
            .symmetric_eigen()
            .eigenvalues
            .iter()
            .filter(|&&l| l > 1e-9)
            .map(|l| l.sqrt())
            .collect();
        w.sort_by(f64::total_cmp);
        w
    }
}

/// Dead-zone function: `x − b` above `b`, `0` inside, `x + b` below `−b`.
#[inline]
pub fn dead_zone(x: f64, b: f64) -> f64 {
    if x > b {
        x - b
    } else if x < -b {
        x + b
    } else {
        0.0
    }
}

/// Per-element data laid out for a fast right-hand side.
#[derive(Debug, Clone)]
struct ElementRt {
    k: f64,
    c: f64,
    b: f64,
    /// Damping only in contact (`|x| > b`).
    contact_only: bool,
    shape: ShapeRt,
    /// Index into the table of distinct frequencies, and cos/sin of the phase.
    freq: usize,
    cos_phi: f64,
    sin_phi: f64,
    /// A damaged tooth: (shaft angular frequency, phase fraction, damage).
    damage: Option<(f64, f64, ToothDamage)>,
}

#[derive(Debug, Clone, Copy)]
enum ShapeRt {
    Constant,
    FirstHarmonic(f64),
    /// (double-contact fraction, double/single ratio, smoothing, normalisation)
    Square(f64, f64, f64, f64),
}

/// One forcing term `amp_w2 · sin(ω τ + φ)` on element `j` (`amp_w2 = ē Ω²`).
#[derive(Debug, Clone)]
struct ForcingRt {
    j: usize,
    amp_w2: f64,
    freq: usize,
    cos_phi: f64,
    sin_phi: f64,
}

/// The right-hand side of a [`DimensionlessModel`] at one operating point: the state is
/// `y = [x̄ (n), x̄' (n)]`. Switching functions: `x̄_j − b̄_j` and `x̄_j + b̄_j` for every element
/// with backlash.
#[derive(Debug, Clone)]
pub struct GearOde {
    n: usize,
    omega1: f64,
    /// Row-major Ā.
    a: Vec<f64>,
    el: Vec<ElementRt>,
    forcing: Vec<ForcingRt>,
    /// Distinct angular frequencies (dimensionless).
    freqs: Vec<f64>,
    f0: Vec<f64>,
    load_steps: Vec<(f64, Vec<f64>)>,
    backlash_idx: Vec<usize>,
    /// Some element damps only in contact: the right-hand side takes the (slower) branch that
    /// checks the clearance; otherwise the first seed's form runs unchanged.
    any_contact_only: bool,
}

/// Smoothed contact-ratio square wave of mean `1` at phase fraction `u ∈ [0, 1)`.
fn square_wave(u: f64, d: f64, r: f64, w: f64, norm: f64) -> f64 {
    // Indicator of the double-contact interval [0, d) with tanh edges, made periodic by
    // summing the neighbouring periods.
    let mut s = 0.0;
    for shift in [-1.0, 0.0, 1.0] {
        let v = u + shift;
        s += 0.5 * (((v) / w).tanh() - ((v - d) / w).tanh());
    }
    (1.0 + (r - 1.0) * s) / norm
}

impl GearOde {
    /// Prepare the right-hand side for `Ω1 > 0`.
    pub fn new(m: &DimensionlessModel, omega1: f64) -> Result<Self> {
        if !(omega1.is_finite() && omega1 > 0.0) {
            return Err(Error::param(
                "Ω1",
                omega1,
                "the operating frequency must be positive",
            ));
        }
        let n = m.n();
        let mut freqs: Vec<f64> = Vec::new();
        let mut freq_index = |w: f64| -> usize {
            if let Some(i) = freqs
                .iter()
                .position(|&f| (f - w).abs() <= 1e-12 * w.abs().max(1.0))
            {
                i
            } else {
                freqs.push(w);
                freqs.len() - 1
            }
        };
        let mut el = Vec::with_capacity(n);
        for j in 0..n {
            let w = m.omega_ratio[j] * omega1;
            let shape = match m.shape[j] {
                StiffnessShape::Constant => ShapeRt::Constant,
                StiffnessShape::FirstHarmonic { eps } => ShapeRt::FirstHarmonic(eps),
                StiffnessShape::SquareWave {
                    contact_ratio,
                    double_to_single,
                    smoothing,
                } => {
                    let d = contact_ratio - 1.0;
                    // Normalise to mean 1 numerically (the tanh edges shift the mean slightly).
                    let np = 4096;
                    let mean = (0..np)
                        .map(|i| {
                            square_wave(i as f64 / np as f64, d, double_to_single, smoothing, 1.0)
                        })
                        .sum::<f64>()
                        / np as f64;
                    ShapeRt::Square(d, double_to_single, smoothing, mean)
                }
            };
            el.push(ElementRt {
                k: m.k_ratio[j],
                c: m.c[j],
                b: m.backlash[j],
                contact_only: m.damping_in_contact_only.get(j).copied().unwrap_or(false)
                    && m.backlash[j] > 0.0,
                shape,
                freq: freq_index(w),
                cos_phi: m.phase[j].cos(),
                sin_phi: m.phase[j].sin(),
                damage: m
                    .tooth_damage
                    .get(j)
                    .copied()
                    .flatten()
                    .map(|d| (d.shaft_ratio * omega1, d.phase / TAU, d)),
            });
        }
        let mut forcing = Vec::new();
        for (j, hs) in m.error.iter().enumerate() {
            for h in hs {
                if h.amplitude == 0.0 || h.freq_ratio == 0.0 {
                    continue;
                }
                let w = h.freq_ratio * omega1;
                forcing.push(ForcingRt {
                    j,
                    amp_w2: h.amplitude * w * w,
                    freq: freq_index(w),
                    cos_phi: h.phase.cos(),
                    sin_phi: h.phase.sin(),
                });
            }
        }
        let mut a = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                a.push(m.a[(i, j)]);
            }
        }
        Ok(GearOde {
            n,
            omega1,
            a,
            forcing,
            freqs,
            f0: m.f.clone(),
            load_steps: m.load_steps.clone(),
            backlash_idx: (0..n).filter(|&j| m.backlash[j] > 0.0).collect(),
            any_contact_only: el.iter().any(|e| e.contact_only),
            el,
        })
    }

    /// The operating frequency Ω1.
    pub fn omega1(&self) -> f64 {
        self.omega1
    }

    /// Number of deflection coordinates (the state has twice as many components).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Stiffness factor `k̄_j(τ)` for all elements given sin/cos of the distinct frequencies.
    #[inline]
    fn stiffness(&self, j: usize, t: f64, sc: &[(f64, f64)]) -> f64 {
        let e = &self.el[j];
        let k = self.healthy_stiffness(e, t, sc);
        match e.damage {
            None => k,
            Some((w, ph, d)) => k * d.factor((w * t / TAU + ph).rem_euclid(1.0)),
        }
    }

    #[inline]
    fn healthy_stiffness(&self, e: &ElementRt, t: f64, sc: &[(f64, f64)]) -> f64 {
        match e.shape {
            ShapeRt::Constant => e.k,
            ShapeRt::FirstHarmonic(eps) => {
                let (s, c) = sc[e.freq];
                // cos(ωτ + φ) = cos ωτ cos φ − sin ωτ sin φ
                e.k * (1.0 + eps * (c * e.cos_phi - s * e.sin_phi))
            }
            ShapeRt::Square(d, r, w, norm) => {
                let phase = self.freqs[e.freq] * t + e.sin_phi.atan2(e.cos_phi);
                let u = (phase / TAU).rem_euclid(1.0);
                e.k * square_wave(u, d, r, w, norm)
            }
        }
    }

    /// The mesh forces `k̄ f(x̄) + c̄ x̄'` (dimensionless) at a state, e.g. as a sensor quantity
    /// (0 inside the clearance for an element with contact-only damping).
    pub fn element_forces(&self, t: f64, y: &[f64], out: &mut [f64]) {
        let sc: Vec<(f64, f64)> = self.freqs.iter().map(|w| (w * t).sin_cos()).collect();
        for j in 0..self.n {
            let e = &self.el[j];
            out[j] = if e.contact_only && y[j].abs() <= e.b {
                0.0
            } else {
                self.stiffness(j, t, &sc) * dead_zone(y[j], e.b) + e.c * y[self.n + j]
            };
        }
    }

    /// Static load at τ (including load steps).
    fn static_load(&self, t: f64, i: usize) -> f64 {
        let mut f = self.f0[i];
        // Left-continuous at a jump: a step that ends on τ sees the old load in all its stages;
        // the solvers evaluate the new one at `τ.next_up()` when they start from τ.
        for (tau, d) in &self.load_steps {
            if t > *tau {
                f += d[i];
            }
        }
        f
    }
}

/// Largest number of elements handled with stack buffers in the right-hand side.
const MAX_STACK: usize = 32;

impl OdeSystem for GearOde {
    fn dim(&self) -> usize {
        2 * self.n
    }

    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        let n = self.n;
        let mut sc_buf = [(0.0, 0.0); MAX_STACK];
        let mut sc_vec;
        let sc: &mut [(f64, f64)] = if self.freqs.len() <= MAX_STACK {
            &mut sc_buf[..self.freqs.len()]
        } else {
            sc_vec = vec![(0.0, 0.0); self.freqs.len()];
            &mut sc_vec
        };
        for (k, w) in self.freqs.iter().enumerate() {
            sc[k] = (w * t).sin_cos();
        }
        let mut fk_buf = [0.0; MAX_STACK];
        let mut fk_vec;
        let fk: &mut [f64] = if n <= MAX_STACK {
            &mut fk_buf[..n]
        } else {
            fk_vec = vec![0.0; n];
            &mut fk_vec
        };
        if self.any_contact_only {
            for j in 0..n {
                let e = &self.el[j];
                fk[j] = if e.contact_only && y[j].abs() <= e.b {
                    // Free flight inside the clearance: neither spring nor damper.
                    0.0
                } else {
                    self.stiffness(j, t, sc) * dead_zone(y[j], e.b) + e.c * y[n + j]
                };
            }
        } else {
            for j in 0..n {
                let e = &self.el[j];
                fk[j] = self.stiffness(j, t, sc) * dead_zone(y[j], e.b) + e.c * y[n + j];
            }
        }
        let loads_static = self.load_steps.is_empty();
        for i in 0..n {
            let row = &self.a[i * n..(i + 1) * n];
            let mut acc = 0.0;
            for j in 0..n {
                acc += row[j] * fk[j];
            }
            let f = if loads_static {
                self.f0[i]
            } else {
                self.static_load(t, i)
            };
            dy[i] = y[n + i];
            dy[n + i] = f - acc;
        }
        for fo in &self.forcing {
            let (s, c) = sc[fo.freq];
            // sin(ωτ + φ) = sin ωτ cos φ + cos ωτ sin φ
            dy[n + fo.j] += fo.amp_w2 * (s * fo.cos_phi + c * fo.sin_phi);
        }
    }

    fn n_switches(&self) -> usize {
        2 * self.backlash_idx.len()
    }

    fn switches(&self, _t: f64, y: &[f64], g: &mut [f64]) {
        for (k, &j) in self.backlash_idx.iter().enumerate() {
            let b = self.el[j].b;
            g[2 * k] = y[j] - b;
            g[2 * k + 1] = y[j] + b;
        }
    }

    fn breakpoints(&self) -> Vec<f64> {
        self.load_steps.iter().map(|(t, _)| *t).collect()
    }
}
