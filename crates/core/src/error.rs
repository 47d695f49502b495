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
    /// An analysis needs more samples (or points) than it was given.
    #[error("{analysis} needs at least {needed} samples; the signal has {samples}")]
    TooFewSamples {
        analysis: &'static str,
        needed: usize,
        samples: usize,
    },
    /// A statistic that a constant signal does not have (zero variance).
    #[error("{analysis} is undefined for a constant signal ({samples} samples, zero variance)")]
    ConstantSignal {
        analysis: &'static str,
        samples: usize,
    },
    /// A value an analysis needs finite is not (record samples are [`Error::NonFiniteSample`]).
    #[error("{analysis}: {what} is not finite")]
    NonFiniteValue {
        analysis: &'static str,
        what: String,
    },
    /// An FFT could not be computed: a buffer of the wrong length, a defect of the caller and
    /// not of the signal.
    #[error("FFT of length {len} failed: {reason}")]
    Fft { len: usize, reason: String },
    /// The shaft rate could not be measured from the record's own lines.
    #[error("the shaft rate cannot be measured: {0}")]
    SpeedNotMeasured(SpeedProblem),
    /// A tachometer channel with too few pulses to time a revolution.
    #[error("the tachometer channel has {pulses} pulse(s); at least {needed} are needed")]
    TooFewPulses { pulses: usize, needed: usize },
    /// The record is shorter than the shaft revolutions an analysis needs.
    #[error(
        "the record covers {revolutions:.2} revolutions of this shaft; at least {needed} are needed"
    )]
    TooFewRevolutions { revolutions: f64, needed: f64 },
    /// Two inputs that must have the same length do not.
    #[error("{what}: {found} values where {expected} are needed")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        found: usize,
    },
    /// No mesh order lies in the synchronous average's resolvable range.
    #[error(
        "no mesh order of {orders:?} lies in 1 ..= {max_order} (half the samples per revolution)"
    )]
    NoMeshOrder {
        orders: Vec<usize>,
        max_order: usize,
    },
    /// A state-aware baseline whose records say nothing of their repeatability.
    #[error(
        "the baseline's records carry no measure of their repeatability (records too short for \
         two segments) and cannot predict one another (fewer than 3 have a neighbour of their \
         load): it needs longer healthy records"
    )]
    BaselineUnrepeatable,
    /// A transfer-path calibration that predicts a left-out speed of the healthy records no
    /// better than the plain model does (dB, RMS of the line-ratio residuals).
    #[error(
        "the transfer path calibrated on the healthy records predicts a left-out speed no better \
         than the plain model ({path_db:.2} dB against {plain_db:.2} dB RMS): it is not used; \
         check the healthy records' speeds"
    )]
    PathNoBetter { path_db: f64, plain_db: f64 },
    /// A machine's physics fit that predicts a left-out speed no better than the empirical
    /// calibration (the description's physics through a path alone).
    #[error(
        "the machine's physics fitted to its healthy records predict a left-out speed's lines to \
         {physics_db:.2} dB, no better than the description's own physics through a calibrated \
         path ({empirical_db:.2} dB): the fit is refused and the empirical calibration stands"
    )]
    PhysicsNoBetter { physics_db: f64, empirical_db: f64 },
    /// A table that would need more simulations than allowed to cover the speeds asked.
    #[error(
        "covering input-shaft rates {lo_hz:.1}–{hi_hz:.1} Hz would take {simulations} \
         simulations, over the limit of {limit}: give the machines of this gearbox a narrower \
         speed range, or describe the gearbox once per speed range"
    )]
    TableTooLarge {
        lo_hz: f64,
        hi_hz: f64,
        simulations: usize,
        limit: usize,
    },
    /// Stored data (an effect, a gearbox, a report) that cannot be read or written back.
    #[error("stored {what} cannot be read or written: {reason}")]
    Stored { what: String, reason: String },
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
         in runs of up to {longest_run} (the longest from sample {longest_at}); the sensor or its ADC saturated, which adds harmonics the \
         gearbox did not make — lower the gain or widen the input range and record again"
    )]
    ClippedRecord {
        /// `"maximum"` or `"minimum"`.
        side: &'static str,
        level: f64,
        count: usize,
        percent: f64,
        longest_run: usize,
        /// First sample of the longest run.
        longest_at: usize,
    },
    /// The record's format carries no sample rate and none was given.
    #[error("{format} carries no sample rate: {give}")]
    MissingSampleRate {
        /// What lacks it, e.g. "raw f32 (no header)".
        format: &'static str,
        /// How to give it: `"give it (--sample-rate HZ)"` from the single-channel reader the
        /// CLI uses, `"give the sample rate in Hz"` from the multichannel one (no CLI flag).
        give: &'static str,
    },
    /// A check failed on one channel of a multichannel record: the channel's name and the
    /// error (one of the record variants: [`Error::NonFiniteSample`], [`Error::FlatRecord`],
    /// …; see [`Error::split_channel`]). The message names no CLI flag.
    #[error("channel `{channel}`: {error}")]
    InChannel { channel: String, error: Box<Error> },
    /// A channel was asked for that the record does not have; `available` lists its channels
    /// in order (a channel is chosen by name or by 0-based index). The message names no CLI
    /// flag.
    #[error(
        "no channel `{requested}` in the record; its channels are {} (choose one by name or by \
         index from 0)",
        list_channels(.available)
    )]
    UnknownChannel {
        requested: String,
        available: Vec<String>,
    },
    /// The record has a defect that makes it untrustworthy (a dropout, a DC step, absurd
    /// values, more spikes than can be repaired): what, where and why
    /// ([`crate::record::quality`]).
    #[error("{}", .0.message)]
    RecordQuality(Box<crate::quality_finding::QualityFinding>),
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
    Gearbox(#[from] GearboxError),
    /// The signature table was computed for another model configuration.
    #[error(
        "stale signature table: it was computed for model hash {table_hash}, the current \
         configuration hashes to {model_hash}; regenerate it with `gearwear precompute`"
    )]
    StaleTable {
        table_hash: String,
        model_hash: String,
    },
    /// A machine baseline needs more healthy records.
    #[error(
        "a baseline needs at least {needed} healthy records of the machine; {records} given \
         (add records known to be healthy)"
    )]
    BaselineTooSmall { records: usize, needed: usize },
    /// A channel's declared unit (or the machine's ISO class) that cannot be used.
    #[error(transparent)]
    Unit(#[from] UnitError),
    /// The record is too short to resolve the lower edge of a velocity band.
    #[error(
        "the record lasts {seconds:.3} s; a velocity over {lo_hz}–{hi_hz} Hz needs at least \
         {needed_seconds:.3} s ({periods} periods of {lo_hz} Hz) to resolve the band's lower edge"
    )]
    RecordTooShortForBand {
        seconds: f64,
        needed_seconds: f64,
        periods: f64,
        lo_hz: f64,
        hi_hz: f64,
    },
    /// The sample rate does not reach the upper edge of a velocity band.
    #[error(
        "the record's sample rate {sample_rate} Hz holds frequencies up to {nyquist_hz} Hz; a \
         velocity over {lo_hz}–{hi_hz} Hz needs a sample rate above {needed} Hz"
    )]
    SampleRateBelowBand {
        sample_rate: f64,
        nyquist_hz: f64,
        needed: f64,
        lo_hz: f64,
        hi_hz: f64,
    },
}

/// `` `a1`, `a2`, `a3` ``; past 16 names, the first 16 and how many there are in all (a WAV
/// header may declare 65 535 channels).
fn list_channels(names: &[String]) -> String {
    const SHOWN: usize = 16;
    let mut s = names
        .iter()
        .take(SHOWN)
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        s.push_str(&format!(", … ({} in all)", names.len()));
    }
    s
}

impl Error {
    /// `self` as the error of channel `channel` ([`Error::InChannel`]).
    pub fn in_channel(self, channel: impl Into<String>) -> Self {
        Error::InChannel {
            channel: channel.into(),
            error: Box::new(self),
        }
    }

    /// The channel an error belongs to, if any, and the error itself: `(Some("a2"), e)` for
    /// [`Error::InChannel`], `(None, self)` otherwise. For mapping errors by their kind (an
    /// HTTP problem per variant) without losing the channel.
    pub fn split_channel(&self) -> (Option<&str>, &Error) {
        match self {
            Error::InChannel { channel, error } => (Some(channel), error),
            other => (None, other),
        }
    }

    /// An FFT of length `len` that failed with `e` ([`Error::Fft`]).
    pub fn fft(len: usize, e: impl std::fmt::Display) -> Self {
        Error::Fft {
            len,
            reason: e.to_string(),
        }
    }

    /// Shorthand for [`Error::InvalidParameter`].
    pub fn param(name: impl Into<String>, value: f64, reason: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name: name.into(),
            value,
            reason: reason.into(),
        }
    }
}

/// Why the shaft rate could not be measured from the record ([`Error::SpeedNotMeasured`]).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SpeedProblem {
    /// Nothing to search around: no tachometer and no nominal rate.
    #[error("there is no tachometer channel and no nominal input-shaft rate to search around")]
    NoHint,
    /// No line of the gearbox (or no mesh line) below the usable band's top.
    #[error(
        "no {lines} of this gearbox lies under 0.45 × the sample rate ({top_hz:.0} Hz) near \
         {hint_hz:.2} Hz"
    )]
    NoLineInBand {
        /// `"mesh line"` or `"line"`.
        lines: &'static str,
        top_hz: f64,
        hint_hz: f64,
    },
    /// Shaft rates without a common period: their lines do not form one grid.
    #[error("the shafts' rates are not commensurate, so their lines do not form one grid")]
    Incommensurate,
    /// No spectrum bin near the mesh line to track.
    #[error(
        "no spectrum bin within ±{search_percent} % of {mesh_hz:.1} Hz to track a mesh line in"
    )]
    NoBinNearMesh { mesh_hz: f64, search_percent: f64 },
    /// The mesh line's demodulated magnitude is too often under a tenth of its median.
    #[error(
        "the mesh line near {mesh_hz:.1} Hz is too weak to track: its demodulated magnitude \
         falls under a tenth of its median on {weak} of {samples} decimated samples"
    )]
    MeshLineTooWeak {
        mesh_hz: f64,
        weak: usize,
        samples: usize,
    },
    /// The tracked phase of the mesh line does not grow steadily.
    #[error(
        "the tracked angle of the mesh line near {mesh_hz:.1} Hz does not increase steadily \
         (speed too irregular or line too weak to track)"
    )]
    IrregularTrack { mesh_hz: f64 },
}

// What a gearbox description can be refused for (`crate::gearbox`): one variant per mistake,
// each message saying where the mistake is and what to write instead. Defined here, with the
// library's other errors, so that `gearbox` depends on `error` and not the other way round.

/// A gearbox description that cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GearboxError {
    /// Not TOML/JSON, or a field of the wrong type or an unknown field.
    #[error("gearbox description {origin}: {reason}")]
    Syntax { origin: String, reason: String },
    /// Larger than any real description.
    #[error("the gearbox description is {bytes} bytes; at most {max} are accepted")]
    TooLarge { bytes: usize, max: usize },
    /// The `format` tag is not ours.
    #[error(
        "`format` is \"{found}\"; a gearbox description starts with format = \"gearwear-gearbox\""
    )]
    Format { found: String },
    /// A version this build does not read.
    #[error("`version` is {found}; this gearwear reads gearbox descriptions of version 1")]
    Version { found: u32 },
    /// The name is empty or has characters that do not belong in an identifier.
    #[error(
        "`name` \"{name}\" must be 1–64 characters of letters, digits, '-', '_' or '.' \
         (it names the gearbox in tables and URLs)"
    )]
    Name { name: String },
    /// No stage at all, or too many.
    #[error("a gearbox needs between 1 and {max} [[stage]] tables; this one has {found}")]
    StageCount { found: usize, max: usize },
    /// `kind` is not `parallel` or `planetary`.
    #[error("stage {stage}: kind \"{kind}\" is not known; use \"parallel\" or \"planetary\"")]
    UnknownKind { stage: usize, kind: String },
    /// A member the stage's kind requires is absent.
    #[error("stage {stage} ({kind}) has no `{member}`: {hint}")]
    MissingMember {
        stage: usize,
        kind: &'static str,
        member: &'static str,
        hint: &'static str,
    },
    /// A member that belongs to the other kind of stage.
    #[error("stage {stage} ({kind}) cannot have `{member}`: it belongs to {other} stages")]
    ForeignMember {
        stage: usize,
        kind: &'static str,
        member: &'static str,
        other: &'static str,
    },
    /// Zero or negative teeth (or planets).
    #[error(
        "stage {stage}: the {member} has {teeth} teeth; tooth counts must be positive integers"
    )]
    Teeth {
        stage: usize,
        member: String,
        teeth: i64,
    },
    /// A planet count out of range.
    #[error("stage {stage}: {count} planets; a planetary stage has between 1 and {max}")]
    PlanetCount { stage: usize, count: i64, max: u32 },
    /// A gear that must turn with a shaft names none.
    #[error(
        "stage {stage}: the {member} is on no shaft; give it `shaft = \"…\"` (two gears on one \
         shaft turn together)"
    )]
    NoShaft { stage: usize, member: String },
    /// The fixed member is missing or not one of the three.
    #[error(
        "stage {stage}: `fixed` is {found}; a planetary stage holds exactly one member in the \
         housing: fixed = \"ring\", \"carrier\" or \"sun\""
    )]
    Fixed { stage: usize, found: String },
    /// The fixed member also names a shaft, or two members are held.
    #[error(
        "stage {stage}: the {member} is fixed but also sits on shaft \"{shaft}\"; a fixed member \
         turns with no shaft (remove its `shaft`, or fix another member)"
    )]
    FixedOnShaft {
        stage: usize,
        member: &'static str,
        shaft: String,
    },
    /// Ring teeth ≠ sun + 2 planet teeth.
    #[error(
        "stage {stage}: ring {ring} teeth ≠ sun {sun} + 2 × planet {planet} = {expected} \
         (coaxial condition of standard gears); fix the counts, or set `profile_shifted = true` \
         for a profile-shifted set"
    )]
    Coaxial {
        stage: usize,
        ring: i64,
        sun: i64,
        planet: i64,
        expected: i64,
    },
    /// A stage with both its members on one shaft.
    #[error(
        "stage {stage}: both gears of the pair sit on shaft \"{shaft}\"; a mesh joins two shafts"
    )]
    SameShaft { stage: usize, shaft: String },
    /// The input shaft is on no stage.
    #[error(
        "input_shaft \"{shaft}\" is on no stage; name the shaft of a gear of stage 1 (shafts: {known})"
    )]
    UnknownInput { shaft: String, known: String },
    /// A `[[bearing]]` that names an unknown shaft or gives neither geometry nor orders.
    #[error("[[bearing]] \"{name}\": {reason}")]
    Bearing { name: String, reason: String },
    /// The output shaft (or a `[shafts.X]` table) names an unknown shaft.
    #[error("{field} names shaft \"{shaft}\", which no gear sits on (shafts: {known})")]
    UnknownShaft {
        field: String,
        shaft: String,
        known: String,
    },
    /// Stages the input does not reach.
    #[error(
        "stage {stage} is not connected to input_shaft \"{input}\": no chain of shared shafts \
         leads from the input to it (check the shaft names)"
    )]
    Disconnected { stage: usize, input: String },
    /// Two stages give a shaft different rates (a closed loop of gears that cannot turn).
    #[error(
        "shaft \"{shaft}\": stage {stage} makes it turn at {found:.6} × the input rate, but it \
         already turns at {expected:.6} × (from stage {from}); the stages disagree, so the train \
         is locked — check the tooth counts and the shaft names"
    )]
    ShaftConflict {
        shaft: String,
        stage: usize,
        found: f64,
        expected: f64,
        from: usize,
    },
    /// A number out of its range (negative width, NaN, ε ≥ 1, …).
    #[error("{field} = {value}: {reason}")]
    Value {
        field: String,
        value: f64,
        reason: &'static str,
    },
    /// A stage index (sensor, wear_stages) out of range.
    #[error("{field} names stage {stage}; the gearbox has stages 1 … {stages}")]
    StageIndex {
        field: &'static str,
        stage: usize,
        stages: usize,
    },
    /// Both static-load forms given.
    #[error("give the static load as static_load or as input_torque_nm, not both")]
    TwoLoads,
    /// The resolved model is unusable (e.g. no rigid-body mode to balance the load).
    #[error("the described gearbox does not give a usable model: {0}")]
    Model(String),
}

/// What a channel's declared unit, or a machine's ISO 20816-3 class, can be refused for
/// ([`crate::units`]). The messages name the values, not the caller's parameter: the service
/// adds the member (`channel_units.a1`), the CLI the flag (`--unit`).
#[derive(Debug, Error, Clone, PartialEq)]
pub enum UnitError {
    /// Not a unit gearwear converts.
    #[error(
        "`{unit}` is not a unit gearwear converts: use g or m/s² (an accelerometer), mm/s (a \
         velocity sensor), or V with the sensor's sensitivity"
    )]
    Unknown { unit: String },
    /// A displacement (proximity-probe) unit.
    #[error(
        "`{unit}` is a displacement: a proximity probe measures the shaft's motion relative to \
         its bearing, not the housing vibration that a velocity RMS and the ISO 20816-3 zones \
         describe; declare an accelerometer (g, m/s²) or a velocity sensor (mm/s), or V with \
         the sensitivity of one"
    )]
    Displacement { unit: String },
    /// Volts without the sensor's sensitivity.
    #[error(
        "a channel in V needs its sensor's sensitivity to be converted: in mV/g or mV/(m/s²) \
         for an accelerometer, in mV/(mm/s) for a velocity sensor (it is on the sensor's \
         calibration sheet)"
    )]
    NoSensitivity,
    /// A sensitivity given for a channel that is not in volts.
    #[error(
        "a sensitivity ({value} mV/{per}) converts volts; this channel is in `{unit}`, which is \
         already a physical unit: remove the sensitivity, or declare the unit V"
    )]
    SensitivityWithoutVolts {
        unit: String,
        value: f64,
        per: &'static str,
    },
    /// More than one sensitivity.
    #[error("give one sensitivity, not both mV/{first} and mV/{second}")]
    TwoSensitivities {
        first: &'static str,
        second: &'static str,
    },
    /// A sensitivity out of range.
    #[error(
        "a sensitivity of {value} mV/{per} is not usable: it is a number above 0 and at most \
         {max} (sensor sheets give 0.1 to 10 000 mV/g)"
    )]
    BadSensitivity {
        value: f64,
        per: &'static str,
        max: f64,
    },
    /// A sensitivity written in a form that is not understood.
    #[error(
        "`{text}` is not a sensitivity: write a number and its unit, e.g. 100mV/g, \
         10.2mV/(m/s²) or 20mV/(mm/s)"
    )]
    SensitivitySyntax { text: String },
    /// An ISO 20816-3 machine group other than 1 or 2.
    #[error(
        "ISO 20816-3 machine group {group} does not exist: group 1 is large machines (300 kW to \
         50 MW, or electrical machines with shaft height 315 mm and more), group 2 medium ones \
         (15 kW to 300 kW, or shaft height 160 mm to 315 mm)"
    )]
    IsoGroup { group: i64 },
    /// An ISO 20816-3 support other than rigid or flexible.
    #[error(
        "ISO 20816-3 support `{support}` is not known: \"rigid\" (the machine and its support's \
         lowest natural frequency is at least 25 % above the main excitation frequency) or \
         \"flexible\" (every other support)"
    )]
    IsoSupport { support: String },
}
