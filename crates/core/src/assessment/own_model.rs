//! The machine's own model as the assessment holds it: its physics fitted to its healthy
//! records ([`MachinePhysics`]) and the table of its own gearbox, ready to diagnose.

use super::diagnoser::TableDiagnoser;
use crate::diagnosis::machine_physics::MachinePhysics;

/// A machine's physics and its own table (see [`crate::diagnosis::machine_physics`]).
pub struct OwnModel {
    pub physics: MachinePhysics,
    /// The table of the machine's own gearbox (the description with the fitted factors).
    pub diagnoser: TableDiagnoser,
}
