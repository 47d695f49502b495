//! What a gearbox description can be refused for: one variant per mistake, each message saying
//! where the mistake is and what to write instead.

use thiserror::Error;

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
