//! Lumped-parameter gear-train models.
//!
//! - [`element`]: coordinates, coupling elements (mesh, shaft, bearing) and loads.
//! - [`assembly`]: one generic assembly into the relative form `ẍ + A F(x, ẋ, t) = F̄ − ë` and
//!   its dimensionless version.
//! - [`system`]: the resolved [`DimensionlessModel`] and its right-hand side [`GearOde`].
//! - [`wear`]: the wear state a model is built for.
//! - Any gearbox, the first seed's rig included, is described and built in [`crate::gearbox`]
//!   (the original hand-written Model A configuration is a test oracle in
//!   `crates/core/tests/support/`).
//! - [`rig_b`]: the second seed's 10-DOF space drive (Model B) as a configuration.
//! - [`reconstruct`]: physical angles, speeds and accelerations from the relative form.

pub mod assembly;
pub mod element;
pub mod reconstruct;
pub mod rig_b;
pub mod system;
pub mod wear;

pub use assembly::Assembly;
pub use element::{
    Damping, Dof, DofKind, Element, Harmonic, Load, LoadSchedule, StiffnessShape, ToothDamage,
};
pub use reconstruct::{Reconstructor, static_state};
pub use rig_b::{LoadCase, ModelBConfig, ModelBOptions, StiffnessForm};
pub use system::{DimensionlessModel, GearOde, dead_zone};
pub use wear::Wear;
