//! The machine's own model as the assessment holds it: its physics fitted to its healthy
//! records ([`MachinePhysics`]), the table of its own gearbox, ready to diagnose, and its own
//! gears' fault signatures ([`crate::condition::response`]) for the explainer.

use super::diagnoser::TableDiagnoser;
use crate::condition::Parts;
use crate::condition::candidates::Response;
use crate::condition::response;
use crate::diagnosis::machine_physics::MachinePhysics;

/// A machine's physics, its own table and its gears' simulated fault signatures (see
/// [`crate::diagnosis::machine_physics`]).
pub struct OwnModel {
    pub physics: MachinePhysics,
    /// The table of the machine's own gearbox (the description with the fitted factors).
    pub diagnoser: TableDiagnoser,
    /// Each gear's local-damage and eccentricity signature simulated in the machine's own
    /// gearbox at the middle of its fitted speeds; `None` when it could not be simulated (the
    /// explainer then uses flat combs).
    pub response: Option<Response>,
}

impl OwnModel {
    /// The own model of `physics` read with `diagnoser` (its own table), its gears' fault
    /// signatures simulated in the table's gearbox.
    pub fn new(physics: MachinePhysics, diagnoser: TableDiagnoser) -> OwnModel {
        let gb = diagnoser.table().gearbox();
        let mid = physics.f1_hz[physics.f1_hz.len() / 2] / gb.f1_per_input_hz;
        let response = response::simulate(gb, &Parts::of(gb), mid).ok();
        OwnModel {
            physics,
            diagnoser,
            response,
        }
    }
}
