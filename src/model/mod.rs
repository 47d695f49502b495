//! Lumped-parameter gear-train models.
//!
//! - [`element`]: coordinates, coupling elements (mesh, shaft, bearing) and loads.
//! - [`assembly`]: one generic assembly into the relative form `ẍ + A F(x, ẋ, t) = F̄ − ë` and
//!   its dimensionless version.
//! - [`system`]: the resolved [`DimensionlessModel`] and its right-hand side [`GearOde`].
//! - [`kinematics`]: mesh and shaft frequencies from tooth counts.
//! - [`rig_a`]: the first seed's rig (Model A) as a configuration.
//! - [`rig_b`]: the second seed's 10-DOF space drive (Model B) as a configuration.
//! - [`reconstruct`]: physical angles, speeds and accelerations from the relative form.

pub mod assembly;
pub mod element;
pub mod export;
pub mod kinematics;
pub mod reconstruct;
pub mod rig_a;
pub mod rig_b;
pub mod system;
pub mod wear;

pub use assembly::Assembly;
pub use element::{Damping, Dof, DofKind, Element, Harmonic, Load, LoadSchedule, StiffnessShape};
pub use kinematics::{Frequencies, ToothCounts};
pub use reconstruct::{Reconstructor, static_state};
pub use rig_a::ModelAConfig;
pub use rig_b::{LoadCase, ModelBConfig, ModelBOptions, StiffnessForm};
pub use system::{DimensionlessModel, GearOde, dead_zone};
pub use wear::Wear;
