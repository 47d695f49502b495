//! Condition monitoring of a real machine: each record judged against the machine's healthy
//! records **at its operating state**, in the order domain, with findings that name a part.
//!
//! 1. [`state`]: the input shaft's rate is measured (tachometer, else tacho-less around a
//!    hint) and the load is taken as given.
//! 2. [`evidence`]: speed-free features per mesh, shaft and bearing from the record resampled
//!    to the input shaft's angle ([`parts`] says where each part shows).
//! 3. [`baseline`]: healthy records with their states; a record is compared with what they
//!    expect at its state, the scale and threshold calibrated by leave-one-out over states.
//! 4. [`findings`]: which part the departure points at, with the evidence in words.

pub mod baseline;
pub mod evidence;
pub mod findings;
pub mod parts;
pub mod state;

pub use baseline::{Coverage, StateBaseline, StateRecord, StateScore};
pub use evidence::evidence;
pub use findings::{Finding, findings};
pub use parts::Parts;
pub use state::{Load, OperatingState, SpeedSource, Tacho, measure};
