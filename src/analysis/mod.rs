//! Analyses of simulated responses.
pub mod motion;
