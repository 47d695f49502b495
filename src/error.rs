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
    #[error("cannot read or write {path}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A configuration file could not be parsed.
    #[error("{path}: {reason}")]
    Parse { path: String, reason: String },
    /// A record file could not be read as the stated format.
    #[error("record {path}: {reason}")]
    RecordFormat { path: String, reason: String },
    /// A record holds no samples at all.
    #[error("the record holds no samples; send at least one second of signal")]
    EmptyRecord,
    /// Every sample has the same value: no vibration was recorded.
    #[error(
        "all {samples} samples of the record are {value}: it carries no vibration (a \
         disconnected sensor, a dead channel or the wrong column?)"
    )]
    FlatRecord { samples: usize, value: f64 },
    /// The record sits at its extreme value for runs of samples: the sensor or ADC saturated.
    #[error(
        "the record is clipped: {count} samples ({percent:.2} %) sit exactly at its {side} {level} \
         in runs of up to {longest_run}; the sensor or its ADC saturated, which adds harmonics the \
         gearbox did not make — lower the gain or widen the input range and record again"
    )]
    ClippedRecord {
        /// `"maximum"` or `"minimum"`.
        side: &'static str,
        level: f64,
        count: usize,
        percent: f64,
        longest_run: usize,
    },
    /// The record's format carries no sample rate and none was given.
    #[error("{format} carries no sample rate: give it (--sample-rate HZ)")]
    MissingSampleRate {
        /// What lacks it, e.g. "raw f32 (no header)".
        format: &'static str,
    },
    /// A record sample is NaN or ±∞.
    #[error("sample {index} of the record is {value}; the record must contain only finite numbers")]
    NonFiniteSample { index: usize, value: f64 },
    /// A record is empty or shorter than the estimator needs.
    #[error(
        "the record is too short: {samples} samples = {periods:.1} periods of f1 = {f1_hz:.2} Hz; \
         the estimator needs at least {needed_periods} periods ({needed_samples} samples)"
    )]
    RecordTooShort {
        samples: usize,
        periods: f64,
        f1_hz: f64,
        needed_periods: usize,
        needed_samples: usize,
    },
    /// The sample rate cannot represent the highest line the estimator needs.
    #[error(
        "sample rate {sample_rate} Hz is under twice the highest needed line ({highest_line_hz:.1} Hz): \
         need more than {needed:.1} Hz"
    )]
    SampleRateTooLow {
        sample_rate: f64,
        highest_line_hz: f64,
        needed: f64,
    },
    /// No stage-1 mesh line could be located in the record.
    #[error("no stage-1 mesh line (f1) found between {lo_hz:.1} and {hi_hz:.1} Hz: {reason}")]
    NoMeshLine {
        lo_hz: f64,
        hi_hz: f64,
        reason: String,
    },
    /// The operating speed lies outside the signature table's Ω1 band.
    #[error(
        "operating point outside the signature table: f1 = {f1_hz:.2} Hz is Ω1 = {omega1:.4}, \
         the table covers Ω1 ∈ [{min:.3}, {max:.3}] (f1 ∈ [{min_hz:.1}, {max_hz:.1}] Hz)"
    )]
    SpeedOutOfBand {
        f1_hz: f64,
        omega1: f64,
        min: f64,
        max: f64,
        min_hz: f64,
        max_hz: f64,
    },
    /// A gearbox description is unusable.
    #[error(transparent)]
    Gearbox(#[from] crate::gearbox::GearboxError),
    /// The signature table was computed for another model configuration.
    #[error(
        "stale signature table: it was computed for model hash {table_hash}, the current \
         configuration hashes to {model_hash}; regenerate it with `gearwear precompute`"
    )]
    StaleTable {
        table_hash: String,
        model_hash: String,
    },
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
