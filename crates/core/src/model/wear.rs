//! The wear state a model is built for.

use serde::{Deserialize, Serialize};

/// Operating condition of a run that changes the assembly (not Ω1): the wear degree of the
/// wear stages and, optionally, the planetary stages' composite error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Wear {
    /// Fixed-axis composite-error amplitude `ea1 = ea2` (units of `b_ref`) of the wear stages.
    pub ea: f64,
    /// Planetary composite-error amplitude (units of `b_ref`); `None`: the configured baseline.
    pub planetary: Option<f64>,
}

impl Wear {
    /// Fixed-axis wear `ea` with the baseline planetary error.
    pub fn fixed_axis(ea: f64) -> Self {
        Wear {
            ea,
            planetary: None,
        }
    }
}
