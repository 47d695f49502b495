//! Physical coordinates from the relative (deflection) form, and the static operating point.
//!
//! The relative form integrates the element deflections `d = G q − e(t)` only. The generalised
//! coordinates split M-orthogonally into the rigid-body modes `N` (columns spanning the null
//! space of `G`) and an elastic part in the range of `M⁻¹Gᵀ`:
//!
//! ```text
//! q = N u + M⁻¹ Gᵀ A⁻¹ (d + e),          A = G M⁻¹ Gᵀ
//! ```
//!
//! (apply `G`: `G q = A A⁻¹ (d + e)`; and `Nᵀ M (M⁻¹ Gᵀ z) = (G N)ᵀ z = 0`). Projecting
//! `M q̈ = −Gᵀ F + T` on `N` kills the element forces, so the rigid-body coordinates obey
//!
//! ```text
//! (Nᵀ M N) ü = Nᵀ T(t)
//! ```
//!
//! exactly; with piecewise-constant loads `u(t)` is integrated in closed form. The same
//! decomposition gives `q̇ = N u̇ + M⁻¹Gᵀ A⁻¹ (ḋ + ė)` and `q̈ = N ü + M⁻¹Gᵀ A⁻¹ (d̈ + ë)`, with
//! `d = b_ref x̄`, `ḋ = b_ref ω_h x̄'`, `d̈ = b_ref ω_h² x̄''` (`τ = ω_h t`). `A` must be invertible:
//! the element rows must be independent (true for Model A and Model B).

use nalgebra::{DMatrix, DVector};

use super::assembly::Assembly;
use super::element::LoadSchedule;
use super::system::{DimensionlessModel, GearOde};
use crate::error::{Error, Result};

/// A piece of constant load: start time (s), rigid acceleration `ü`, and `u̇`, `u` at the start.
type LoadPiece = (f64, DVector<f64>, DVector<f64>, DVector<f64>);

/// Maps a relative-form state `[x̄, x̄']` at `τ` to physical coordinates, speeds and accelerations.
#[derive(Debug, Clone)]
pub struct Reconstructor {
    /// `P = M⁻¹ Gᵀ A⁻¹` (m × n), physical units.
    p: DMatrix<f64>,
    /// Rigid-body modes (m × r).
    modes: DMatrix<f64>,
    /// Load pieces: (start time s, rigid acceleration ü (r), u̇ and u at the start).
    pieces: Vec<LoadPiece>,
    b_ref: f64,
    omega_h: f64,
    omega1: f64,
    /// Error harmonics per element (amplitude in units of b_ref, freq ratio, phase).
    error: Vec<Vec<(f64, f64, f64)>>,
    pub dof_names: Vec<String>,
}

impl Reconstructor {
    /// Build from the assembly (for the loads) and its resolved model, at the operating point
    /// `Ω1`, with the rigid-body part of the initial velocity `q̇0` (physical units; only its
    /// projection on the rigid modes is used).
    pub fn new(
        asm: &Assembly,
        model: &DimensionlessModel,
        omega1: f64,
        q_dot0: &[f64],
    ) -> Result<Self> {
        let m = model.dof_names.len();
        if q_dot0.len() != m {
            return Err(Error::InvalidConfig(format!(
                "initial velocity has {} components, the assembly {m} coordinates",
                q_dot0.len()
            )));
        }
        let minv = DMatrix::from_diagonal(&DVector::from_vec(model.inverse_inertia.clone()));
        let mass = DMatrix::from_diagonal(&DVector::from_iterator(
            m,
            model.inverse_inertia.iter().map(|v| 1.0 / v),
        ));
        let g = &model.g;
        let a = g * &minv * g.transpose();
        let a_inv = a.clone().try_inverse().ok_or_else(|| {
            Error::InvalidConfig("A = G M⁻¹ Gᵀ is singular: dependent element rows".into())
        })?;
        let p = &minv * g.transpose() * a_inv;
        let modes = model.rigid_modes.clone();
        let r = modes.ncols();
        let ntmn = modes.transpose() * &mass * &modes;
        let ntmn_inv = if r == 0 {
            DMatrix::zeros(0, 0)
        } else {
            ntmn.try_inverse().ok_or_else(|| {
                Error::InvalidConfig("rigid-body modes with no inertia (NᵀMN singular)".into())
            })?
        };
        let proj = &ntmn_inv * modes.transpose();
        let u_dot0 = &proj * &mass * DVector::from_column_slice(q_dot0);
        // Load pieces.
        let mut starts = vec![0.0];
        for l in &asm.loads {
            if let LoadSchedule::Step { at, .. } = l.schedule
                && at > 0.0
            {
                starts.push(at);
            }
        }
        starts.sort_by(f64::total_cmp);
        starts.dedup();
        let mut pieces = Vec::with_capacity(starts.len());
        let (mut ud, mut u) = (u_dot0, DVector::zeros(r));
        for (k, &t0) in starts.iter().enumerate() {
            let acc = &proj * asm.load_vector(t0)?;
            pieces.push((t0, acc.clone(), ud.clone(), u.clone()));
            if let Some(&t1) = starts.get(k + 1) {
                let dt = t1 - t0;
                u += &ud * dt + &acc * (0.5 * dt * dt);
                ud += &acc * dt;
            }
        }
        Ok(Reconstructor {
            p,
            modes,
            pieces,
            b_ref: model.length_ref,
            omega_h: model.omega_h,
            omega1,
            error: model
                .error
                .iter()
                .map(|hs| {
                    hs.iter()
                        .map(|h| (h.amplitude, h.freq_ratio, h.phase))
                        .collect()
                })
                .collect(),
            dof_names: model.dof_names.clone(),
        })
    }

    /// Index of a coordinate by name.
    pub fn dof(&self, name: &str) -> Result<usize> {
        self.dof_names
            .iter()
            .position(|d| d == name)
            .ok_or_else(|| Error::InvalidConfig(format!("unknown coordinate `{name}`")))
    }

    /// Rigid-body (u, u̇, ü) at physical time `t` (s).
    fn rigid(&self, t: f64) -> (DVector<f64>, DVector<f64>, DVector<f64>) {
        let k = self.pieces.iter().rposition(|p| p.0 <= t).unwrap_or(0);
        let (t0, acc, ud, u) = &self.pieces[k];
        let dt = t - t0;
        (
            u + ud * dt + acc * (0.5 * dt * dt),
            ud + acc * dt,
            acc.clone(),
        )
    }

    /// Prescribed error `ē` and its τ-derivatives (units of b_ref) for element `j`.
    fn error_terms(&self, j: usize, tau: f64) -> (f64, f64, f64) {
        let (mut e, mut ed, mut edd) = (0.0, 0.0, 0.0);
        for &(a, fr, ph) in &self.error[j] {
            let w = fr * self.omega1;
            let (s, c) = (w * tau + ph).sin_cos();
            e += a * s;
            ed += a * w * c;
            edd -= a * w * w * s;
        }
        (e, ed, edd)
    }

    /// Physical coordinates `q` (m, rad) at `τ` for the state `y = [x̄, x̄']`.
    pub fn positions(&self, tau: f64, y: &[f64]) -> DVector<f64> {
        let n = self.p.ncols();
        let d = DVector::from_fn(n, |j, _| (y[j] + self.error_terms(j, tau).0) * self.b_ref);
        let (u, _, _) = self.rigid(tau / self.omega_h);
        &self.modes * u + &self.p * d
    }

    /// Physical speeds `q̇` (m/s, rad/s).
    pub fn velocities(&self, tau: f64, y: &[f64]) -> DVector<f64> {
        let n = self.p.ncols();
        let s = self.b_ref * self.omega_h;
        let dd = DVector::from_fn(n, |j, _| (y[n + j] + self.error_terms(j, tau).1) * s);
        let (_, ud, _) = self.rigid(tau / self.omega_h);
        &self.modes * ud + &self.p * dd
    }

    /// Physical accelerations `q̈` (m/s², rad/s²) given the state and its τ-derivative
    /// `dy = [x̄', x̄'']` (the right-hand side).
    pub fn accelerations(&self, tau: f64, dy: &[f64]) -> DVector<f64> {
        let n = self.p.ncols();
        let s = self.b_ref * self.omega_h * self.omega_h;
        let ddd = DVector::from_fn(n, |j, _| (dy[n + j] + self.error_terms(j, tau).2) * s);
        let (_, _, udd) = self.rigid(tau / self.omega_h);
        &self.modes * udd + &self.p * ddd
    }

    /// The row `c P` that maps `d + e` (m) to the elastic part of `c · q`: for a combination
    /// of coordinates that does not move with the rigid modes (`c · N = 0`, e.g. a transmission
    /// error) this is the whole value.
    pub fn elastic_row(&self, c: &[f64]) -> Result<Vec<f64>> {
        let cv = DVector::from_column_slice(c);
        let cn = cv.transpose() * &self.modes;
        let scale = c.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        if cn.iter().any(|v| v.abs() > 1e-9 * scale.max(1e-300)) {
            return Err(Error::InvalidConfig(
                "the combination moves with a rigid-body mode".into(),
            ));
        }
        Ok((cv.transpose() * &self.p).iter().cloned().collect())
    }

    /// Reference length and frequency used to scale states.
    pub fn scales(&self) -> (f64, f64) {
        (self.b_ref, self.omega_h)
    }
}

/// The static deflection under the loads at `τ` with the stiffness at `τ`, as a state
/// `[x̄, 0]`: `k̄_j(τ) f_b(x̄_j) = (Ā⁻¹ F̄(τ))_j`, so `x̄_j = F_j/k̄_j + sign(F_j) b̄_j`. With this
/// start a run has no load-application transient.
pub fn static_state(model: &DimensionlessModel, sys: &GearOde, tau: f64) -> Result<Vec<f64>> {
    use crate::solver::OdeSystem;
    let n = model.n();
    let a_inv =
        model.a.clone().try_inverse().ok_or_else(|| {
            Error::InvalidConfig("Ā is singular: no unique static deflection".into())
        })?;
    // F̄(τ): the right-hand side at zero deflection and speed has no element forces.
    let zero = vec![0.0; 2 * n];
    let mut dy = vec![0.0; 2 * n];
    sys.rhs(tau, &zero, &mut dy);
    let f = DVector::from_fn(n, |j, _| dy[n + j]);
    let forces = a_inv * f;
    // k̄_j(τ): the element force at a unit deflection beyond the clearance.
    let mut probe = vec![0.0; 2 * n];
    for (p, b) in probe.iter_mut().zip(&model.backlash) {
        *p = b + 1.0;
    }
    let mut k = vec![0.0; n];
    sys.element_forces(tau, &probe, &mut k);
    let mut y = vec![0.0; 2 * n];
    for j in 0..n {
        let fj = forces[j];
        y[j] = if fj == 0.0 {
            0.0
        } else {
            fj / k[j] + fj.signum() * model.backlash[j]
        };
    }
    Ok(y)
}
