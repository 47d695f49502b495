//! One error type for the API, rendered as `application/problem+json` (RFC 9457).
//!
//! Every problem has a stable `type` (`urn:gearwear:problem:<slug>`), a `title` per type, a
//! `detail` a person can act on, and — where a number explains it — extension members
//! (`limit`, `index`, `value`, …).

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::{Map, Value, json};

use crate::store::StoreError;

/// An API error: status, problem slug, human detail, extension members.
#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub slug: &'static str,
    pub title: &'static str,
    pub detail: String,
    pub extra: Map<String, Value>,
    /// Seconds for a `Retry-After` header (429, 503).
    pub retry_after: Option<u64>,
    /// Add `WWW-Authenticate: Bearer` (401).
    pub authenticate: bool,
}

pub type ApiResult<T> = Result<T, ApiError>;

impl ApiError {
    pub fn new(
        status: StatusCode,
        slug: &'static str,
        title: &'static str,
        detail: impl Into<String>,
    ) -> Self {
        ApiError {
            status,
            slug,
            title,
            detail: detail.into(),
            extra: Map::new(),
            retry_after: None,
            authenticate: false,
        }
    }

    /// Add an extension member.
    pub fn with(mut self, key: &str, value: impl Into<Value>) -> Self {
        self.extra.insert(key.to_string(), value.into());
        self
    }

    pub fn retry_after(mut self, seconds: u64) -> Self {
        self.retry_after = Some(seconds.max(1));
        self
    }

    pub fn unauthorized(detail: impl Into<String>) -> Self {
        let mut e = Self::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "Missing or invalid API key",
            detail,
        );
        e.authenticate = true;
        e
    }

    pub fn forbidden(needed: &str) -> Self {
        Self::new(
            StatusCode::FORBIDDEN,
            "forbidden",
            "The API key lacks a scope",
            format!(
                "this request needs a key with the `{needed}` scope; create one with \
                 `gearwear keys create --scope {needed}`"
            ),
        )
        .with("required_scope", needed)
    }

    pub fn not_found(slug: &'static str, detail: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, slug, "Not found", detail)
    }

    pub fn bad_request(slug: &'static str, title: &'static str, detail: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, slug, title, detail)
    }

    pub fn unprocessable(
        slug: &'static str,
        title: &'static str,
        detail: impl Into<String>,
    ) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, slug, title, detail)
    }

    pub fn internal(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            "Internal error",
            detail,
        )
    }

    /// The problem document.
    pub fn body(&self) -> Value {
        let mut v = json!({
            "type": format!("urn:gearwear:problem:{}", self.slug),
            "title": self.title,
            "status": self.status.as_u16(),
            "detail": self.detail,
        });
        if let Value::Object(m) = &mut v {
            for (k, x) in &self.extra {
                m.insert(k.clone(), x.clone());
            }
        }
        v
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        if let StoreError::UnregisteredMachine(id) = &e {
            return unregistered_machine(id);
        }
        if e.is_unavailable() {
            tracing::warn!(error = %e, "store unavailable");
            ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "store-unavailable",
                "The database is unavailable",
                "the service cannot reach its database right now; retry the same request \
                 later — a record re-sent with the same Idempotency-Key is stored at most once",
            )
            .retry_after(5)
        } else {
            tracing::error!(error = %e, "store error");
            ApiError::internal("a database error occurred; it has been logged")
        }
    }
}

/// 404 `unknown-machine`: no machine of that id (the reads, its trend, its configuration).
pub fn unknown_machine(id: &str) -> ApiError {
    ApiError::not_found(
        "unknown-machine",
        format!(
            "no machine `{id}`: it has no accepted record and no configuration yet (machines \
             appear with their first POSTed record or PUT /v1/machines/{id})"
        ),
    )
    .with("machine_id", id)
}

/// 404 `unknown-machine` for a record refused by `--require-registered-machines`: the
/// machine was not registered with `PUT /v1/machines/{id}` (nothing was stored).
pub fn unregistered_machine(id: &str) -> ApiError {
    ApiError::not_found(
        "unknown-machine",
        format!(
            "machine `{id}` is not registered, and this service takes records only for \
             registered machines (--require-registered-machines): register it with \
             PUT /v1/machines/{id} (or `gearwear machine set {id}`), then send the record \
             again — nothing was stored; check the id for a typo"
        ),
    )
    .with("machine_id", id)
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut r = (self.status, self.body().to_string()).into_response();
        let h = r.headers_mut();
        h.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        if let Some(s) = self.retry_after {
            h.insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if self.authenticate {
            h.insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"gearwear\""),
            );
        }
        r
    }
}

/// Turn a library error from decoding or diagnosing into a problem.
pub fn problem_from_error(e: &crate::Error) -> ApiError {
    use crate::Error as E;
    if let (Some(ch), inner) = e.split_channel() {
        let mut p = problem_from_error(inner);
        p.detail = format!("channel `{ch}`: {}", p.detail);
        return p.with("channel", ch);
    }
    let un = ApiError::unprocessable;
    match e {
        E::UnknownChannel { available, .. } => {
            un("unknown-channel", "Unknown channel", e.to_string())
                .with("available", json!(available))
        }
        E::RecordFormat { reason, .. } => ApiError::bad_request(
            "malformed-record",
            "Malformed record",
            format!("the body could not be read as the stated format: {reason}"),
        ),
        E::EmptyRecord => un("empty-record", "Empty record", e.to_string()),
        E::MissingSampleRate { .. } => {
            un("missing-sample-rate", "Sample rate missing", e.to_string())
        }
        E::FlatRecord { samples, .. } => {
            un("flat-record", "Flat record", e.to_string()).with("samples", *samples as u64)
        }
        E::ClippedRecord {
            count, longest_run, ..
        } => un("clipped-record", "Clipped record", e.to_string())
            .with("clipped_samples", *count as u64)
            .with("longest_run", *longest_run as u64),
        E::RecordQuality(f) => un(
            "record-quality",
            "Record quality too poor to diagnose",
            format!("{}; nothing was stored", f.message),
        )
        .with("defect", f.defect)
        .with("first_sample", f.first_sample as u64)
        .with("last_sample", f.last_sample as u64)
        .with("start_s", f.start_s)
        .with("end_s", f.end_s),
        E::NonFiniteSample { index, value } => un(
            "non-finite-sample",
            "Non-finite sample",
            format!(
                "sample {index} is {value}; every sample must be a finite number (check the \
                 sensor for dropouts or saturation)"
            ),
        )
        .with("index", *index as u64),
        E::RecordTooShort {
            samples,
            needed_samples,
            ..
        } => un("record-too-short", "Record too short", e.to_string())
            .with("samples", *samples as u64)
            .with("needed_samples", *needed_samples as u64),
        E::SampleRateTooLow { needed, .. } => {
            un("sample-rate-too-low", "Sample rate too low", e.to_string())
                .with("needed_hz", *needed)
        }
        E::NoMeshLine { .. } => un(
            "no-mesh-line",
            "No gear-mesh line found",
            format!("{e}; give `shaft_hz` if the input-shaft speed is known"),
        ),
        E::SpeedOutOfBand { .. } => un(
            "speed-out-of-band",
            "Operating speed outside the signature table",
            e.to_string(),
        ),
        E::InvalidParameter { name, .. } => {
            un("invalid-parameter", "Invalid parameter", e.to_string())
                .with("parameter", name.as_str())
        }
        E::SpeedNotMeasured(_) => un(
            "unusable-record",
            "Shaft rate not measurable",
            format!(
                "{e}; give the machine a tachometer channel (`tacho_channel` and `tacho_ppr` of \
                 PUT /v1/machines/{{id}}) or the record's `shaft_hz`"
            ),
        ),
        E::TooFewSamples {
            samples, needed, ..
        } => un(
            "unusable-record",
            "Unusable record",
            format!("{e}: send a longer record"),
        )
        .with("samples", *samples as u64)
        .with("needed_samples", *needed as u64),
        E::TooFewRevolutions { .. } => un(
            "unusable-record",
            "Unusable record",
            format!("{e}: send a longer record"),
        ),
        E::ConstantSignal { .. } | E::TooFewPulses { .. } | E::NoMeshOrder { .. } => {
            un("unusable-record", "Unusable record", e.to_string())
        }
        E::Unit(u) => un("invalid-unit", "Unit cannot be used", u.to_string()),
        other => {
            tracing::error!(error = %other, "diagnosis failed");
            ApiError::internal(format!("the diagnosis failed: {other}"))
        }
    }
}
