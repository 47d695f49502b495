//! One generic assembly of a gear train into the dimensionless relative-coordinate form.
//!
//! With generalised coordinates `q` (inertias `M = diag(m_i)`), element deflections
//! `d = G q − e(t)` and element forces `F_j = k_j(t) f_b(d_j) + c_j ḋ_j`, the equations of motion
//! `M q̈ = −Gᵀ F + T(t)` become, after multiplying by `G M⁻¹` (exact; it removes the rigid-body
//! rotation):
//!
//! ```text
//! d̈ + A F(d, ḋ, t) = G M⁻¹ T(t) − ë(t),        A = G M⁻¹ Gᵀ
//! ```
//!
//! Made dimensionless with a reference length `b_ref` (m) and the reference element `r`
//! (element 0, the stage-1 mesh): `x̄ = d / b_ref`, `τ = ω_h t`, `ω_h² = k_r A_rr`:
//!
//! ```text
//! x̄'' + Ā (k̄(τ) ∘ f(x̄) + c̄ ∘ x̄') = F̄(τ) + Σ ē Ω² sin(Ω τ + φ)
//! Ā = A / A_rr,  k̄_j = k_j / k_r,  c̄_j = c_j A_rr / ω_h,  F̄ = G M⁻¹ T / (b_ref ω_h²)
//! ```
//!
//! With damping given as a ratio, `c_j = 2 ξ sqrt(k_j / A_jj)` and so `c̄_j = 2 ξ sqrt(k̄_j / Ā_jj)`
//! (`model.md`). This is the form of the first seed's equation (1) with its typesetting repaired.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::element::{Damping, Dof, Element, Harmonic, Load, LoadSchedule};
use super::system::DimensionlessModel;
use crate::error::{Error, Result};

/// A gear train: coordinates, coupling elements and loads. Element 0 is the reference element
/// (its mean stiffness and equivalent mass set `ω_h`; its mesh frequency is `Ω1`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Assembly {
    pub name: String,
    pub dofs: Vec<Dof>,
    pub elements: Vec<Element>,
    pub loads: Vec<Load>,
    /// Reference length `b_ref` (m) that makes deflections dimensionless.
    pub length_ref: f64,
    /// Index of the element whose relative motion the simulated sensor measures (0: the
    /// reference mesh).
    #[serde(default)]
    pub sensor: usize,
}

impl Assembly {
    /// Index of a coordinate by name.
    pub fn dof_index(&self, name: &str) -> Result<usize> {
        self.dofs
            .iter()
            .position(|d| d.name == name)
            .ok_or_else(|| Error::InvalidConfig(format!("unknown coordinate `{name}`")))
    }

    /// The `n × m` matrix `G` (rows: elements, columns: coordinates).
    pub fn g_matrix(&self) -> Result<DMatrix<f64>> {
        let mut g = DMatrix::zeros(self.elements.len(), self.dofs.len());
        for (j, el) in self.elements.iter().enumerate() {
            for (name, c) in &el.terms {
                let i = self.dof_index(name)?;
                g[(j, i)] += *c;
            }
        }
        Ok(g)
    }

    /// Diagonal of `M⁻¹`.
    pub fn inverse_inertia(&self) -> DVector<f64> {
        DVector::from_iterator(self.dofs.len(), self.dofs.iter().map(|d| 1.0 / d.inertia))
    }

    /// A basis of the rigid-body modes (null space of `G`), one column per mode.
    pub fn rigid_modes(&self) -> Result<DMatrix<f64>> {
        let g = self.g_matrix()?;
        let m = g.ncols();
        // Null space from the eigen-decomposition of GᵀG (symmetric, small).
        let gtg = g.transpose() * &g;
        let eig = gtg.symmetric_eigen();
        let scale = eig
            .eigenvalues
            .iter()
            .cloned()
            .fold(0.0_f64, f64::max)
            .max(1e-300);
        let cols: Vec<DVector<f64>> = (0..m)
            .filter(|&i| eig.eigenvalues[i].abs() < 1e-10 * scale)
            .map(|i| eig.eigenvectors.column(i).into_owned())
            .collect();
        Ok(if cols.is_empty() {
            DMatrix::zeros(m, 0)
        } else {
            DMatrix::from_columns(&cols)
        })
    }

    /// The generalised force vector `T` at time `t` (s).
    pub fn load_vector(&self, t: f64) -> Result<DVector<f64>> {
        let m = self.dofs.len();
        let mut tv = DVector::zeros(m);
        let mut balancing: Option<usize> = None;
        for load in &self.loads {
            let i = self.dof_index(&load.dof)?;
            match load.schedule {
                LoadSchedule::Constant { value } => tv[i] += value,
                LoadSchedule::Step { before, after, at } => {
                    tv[i] += if t < at { before } else { after };
                }
                LoadSchedule::Balancing => {
                    if balancing.is_some() {
                        return Err(Error::InvalidConfig("more than one balancing load".into()));
                    }
                    balancing = Some(i);
                }
            }
        }
        if let Some(i) = balancing {
            // Balance against the loads at t = 0 (the steady operating point).
            let t0 = if t == 0.0 {
                tv.clone()
            } else {
                self.load_vector_unbalanced(0.0)?
            };
            let n = self.rigid_modes()?;
            if n.ncols() != 1 {
                return Err(Error::InvalidConfig(format!(
                    "a balancing load needs exactly one rigid-body mode, the assembly has {}",
                    n.ncols()
                )));
            }
            let col = n.column(0);
            if col[i].abs() < 1e-12 {
                return Err(Error::InvalidConfig(format!(
                    "the balancing load on `{}` cannot act on the rigid-body mode",
                    self.dofs[i].name
                )));
            }
            tv[i] -= col.dot(&t0) / col[i];
        }
        Ok(tv)
    }

    fn load_vector_unbalanced(&self, t: f64) -> Result<DVector<f64>> {
        let mut tv = DVector::zeros(self.dofs.len());
        for load in &self.loads {
            let i = self.dof_index(&load.dof)?;
            match load.schedule {
                LoadSchedule::Constant { value } => tv[i] += value,
                LoadSchedule::Step { before, after, at } => {
                    tv[i] += if t < at { before } else { after };
                }
                LoadSchedule::Balancing => {}
            }
        }
        Ok(tv)
    }

    /// Check the assembly (names, parameters, a usable reference element).
    pub fn validate(&self) -> Result<()> {
        if self.elements.is_empty() || self.dofs.is_empty() {
            return Err(Error::InvalidConfig(
                "an assembly needs coordinates and elements".into(),
            ));
        }
        let mut seen = HashMap::new();
        for d in &self.dofs {
            if seen.insert(d.name.as_str(), ()).is_some() {
                return Err(Error::InvalidConfig(format!(
                    "coordinate `{}` defined twice",
                    d.name
                )));
            }
            Dof::rotation(d.name.clone(), d.inertia)?;
        }
        for el in &self.elements {
            el.validate()?;
            for (name, _) in &el.terms {
                self.dof_index(name)?;
            }
        }
        if !(self.length_ref.is_finite() && self.length_ref > 0.0) {
            return Err(Error::param(
                "length_ref",
                self.length_ref,
                "must be positive",
            ));
        }
        if self.sensor >= self.elements.len() {
            return Err(Error::InvalidConfig(format!(
                "sensor element {} out of range ({} elements)",
                self.sensor,
                self.elements.len()
            )));
        }
        if self.elements[0].freq_ratio != 1.0 {
            return Err(Error::param(
                "reference element frequency ratio",
                self.elements[0].freq_ratio,
                "element 0 is the reference mesh: its frequency ratio must be 1",
            ));
        }
        Ok(())
    }

    /// Times (s) at which a load jumps.
    fn load_breaks(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self
            .loads
            .iter()
            .filter_map(|l| match l.schedule {
                LoadSchedule::Step { at, .. } => Some(at),
                _ => None,
            })
            .collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    }

    /// Assemble into the dimensionless relative-coordinate form.
    pub fn resolve(&self) -> Result<DimensionlessModel> {
        self.validate()?;
        let g = self.g_matrix()?;
        let minv = self.inverse_inertia();
        let gm = &g * DMatrix::from_diagonal(&minv);
        let a = &gm * g.transpose();
        let n = self.elements.len();
        let a_ref = a[(0, 0)];
        let k_ref = self.elements[0].stiffness;
        if a_ref <= 0.0 {
            return Err(Error::InvalidConfig(
                "the reference element has no equivalent mass (A_00 = 0)".into(),
            ));
        }
        let omega_h = (k_ref * a_ref).sqrt();
        let b = self.length_ref;
        let a_bar = &a / a_ref;
        let mut k_ratio = Vec::with_capacity(n);
        let mut c_bar = Vec::with_capacity(n);
        for (j, el) in self.elements.iter().enumerate() {
            let kr = el.stiffness / k_ref;
            k_ratio.push(kr);
            let ajj = a_bar[(j, j)];
            if ajj <= 0.0 {
                return Err(Error::InvalidConfig(format!(
                    "element {} couples no inertia (A_jj = 0)",
                    el.name
                )));
            }
            c_bar.push(match el.damping {
                Damping::Ratio(xi) => 2.0 * xi * (kr / ajj).sqrt(),
                Damping::Coefficient(c) => c * a_ref / omega_h,
            });
        }
        let scale_f = 1.0 / (b * omega_h * omega_h);
        let force = |t: f64| -> Result<Vec<f64>> {
            let tv = self.load_vector(t)?;
            Ok((&gm * tv).iter().map(|v| v * scale_f).collect())
        };
        let f0 = force(0.0)?;
        let mut load_steps = Vec::new();
        let mut prev = f0.clone();
        for at in self.load_breaks() {
            let f = force(at)?;
            let delta: Vec<f64> = f.iter().zip(&prev).map(|(a, b)| a - b).collect();
            load_steps.push((at * omega_h, delta));
            prev = f;
        }
        let error = self
            .elements
            .iter()
            .map(|el| {
                el.error
                    .iter()
                    .map(|h| Harmonic {
                        amplitude: h.amplitude / b,
                        ..*h
                    })
                    .collect()
            })
            .collect();
        let rigid = self.rigid_modes()?;
        Ok(DimensionlessModel {
            name: self.name.clone(),
            names: self.elements.iter().map(|e| e.name.clone()).collect(),
            kinds: self.elements.iter().map(|e| e.kind.clone()).collect(),
            a: a_bar,
            k_ratio,
            shape: self.elements.iter().map(|e| e.shape).collect(),
            c: c_bar,
            f: f0,
            load_steps,
            omega_ratio: self.elements.iter().map(|e| e.freq_ratio).collect(),
            phase: self.elements.iter().map(|e| e.phase).collect(),
            backlash: self.elements.iter().map(|e| e.backlash / b).collect(),
            damping_in_contact_only: self
                .elements
                .iter()
                .map(|e| e.damping_in_contact_only)
                .collect(),
            error,
            tooth_damage: self.elements.iter().map(|e| e.tooth_damage).collect(),
            omega_h,
            length_ref: b,
            a_ref,
            k_ref,
            g,
            inverse_inertia: minv.iter().cloned().collect(),
            rigid_modes: rigid,
            dof_names: self.dofs.iter().map(|d| d.name.clone()).collect(),
            sensor: self.sensor,
        })
    }
}
