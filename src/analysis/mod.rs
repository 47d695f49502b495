//! Analyses of simulated responses.
pub mod motion;
pub mod simulate;
