//! Analyses of simulated responses: single runs with spectra and motion states, bifurcation
//! sweeps, and the motion-state classifier.
pub mod bifurcation;
pub mod model_b;
pub mod motion;
pub mod report;
pub mod simulate;
