//! Library errors. Variants carry the numbers that explain them; `anyhow` is used only in `main`.

use thiserror::Error;

/// Result alias for the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything the numeric library can refuse or fail at.
#[derive(Debug, Error)]
pub enum Error {
    /// A physical or numerical parameter is out of its valid range.
    #[error("invalid parameter `{name}` = {value}: {reason}")]
    InvalidParameter {
        name: String,
        value: f64,
        reason: String,
    },
    /// A configuration is structurally wrong (unknown body, empty model, …).
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// The adaptive integrator could not keep the error within tolerance.
    #[error("step size underflow at τ = {t}: h = {h:e} (tolerance too tight or solution blew up)")]
    StepSizeTooSmall { t: f64, h: f64 },
    /// The solution left the finite numbers.
    #[error("non-finite state at τ = {t}")]
    NonFinite { t: f64 },
    /// Too many steps for one integration call.
    #[error("step budget of {max_steps} exhausted at τ = {t}")]
    TooManySteps { t: f64, max_steps: usize },
    /// A signal is too short or otherwise unusable for the requested analysis.
    #[error("signal: {0}")]
    Signal(String),
    /// A plot could not be drawn or written.
    #[error("plot {path}: {reason}")]
    Plot { path: String, reason: String },
    /// File I/O.
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A configuration file could not be parsed.
    #[error("{path}: {reason}")]
    Parse { path: String, reason: String },
}

impl Error {
    /// Shorthand for [`Error::InvalidParameter`].
    pub fn param(name: impl Into<String>, value: f64, reason: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name: name.into(),
            value,
            reason: reason.into(),
        }
    }
}
