//! Condition monitoring of a real machine: each record judged against the machine's healthy
//! records **at its operating state**, in the order domain, with findings that name a part.
//!
//! 1. [`state`]: the input shaft's rate is measured (tachometer, else tacho-less around a
//!    hint) and the load is taken as given.
//! 2. [`lines`]: the parts map — which shafts can make a line at each order of a common period
//!    of the shafts — and the line classes it sorts a record's order spectrum into.
//! 3. [`evidence`]: speed-free features per line class, region, shaft and bearing from the
//!    record resampled to the input shaft's angle, and their spread over its segments.
//! 4. [`baseline`] and [`calibration`]: healthy records with their states; a record is compared
//!    with what they expect at its state, scaled by the repeatability of a state.
//! 5. [`explain`], [`candidates`] and [`findings`]: which part's predicted change explains the
//!    record's change, and how much of it.
//! 6. [`plot`]: the order and envelope spectra with the lines the findings rest on, for people.

pub mod baseline;
pub mod calibration;
pub mod candidates;
pub mod evidence;
pub mod explain;
pub mod findings;
pub mod lines;
pub mod machine_model;
pub(crate) mod marked;
pub mod measured_loop;
pub mod parts;
pub mod plot;
pub mod response;
pub mod setup;
pub mod state;
pub mod synchronous;
#[cfg(test)]
mod test_util;

pub use baseline::{Coverage, StateBaseline, StateRecord, StateScore};
pub use evidence::{EVIDENCE_VERSION, Evidence, evidence};
pub use findings::{Finding, FindingKind, findings};
pub use parts::Parts;
pub use plot::{EvidencePlot, evidence_plot};
pub use state::{Load, OperatingState, SpeedSource, Tacho, measure};
