//! `POST /v1/machines/{machine_id}/records`: decode, diagnose (off the async runtime), store in
//! one transaction, answer 201 with the diagnosis. `Idempotency-Key` makes retries safe.

use std::sync::atomic::Ordering;

use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::AppState;
use super::auth::Caller;
use super::diagnoser::{Input, MachineCalibration};
use super::error::{ApiError, ApiResult};
use super::metrics::StageClock;
use super::spectrum::{plot_from_spectrum, plot_spectrum};
use crate::keys::Scope;
use crate::store::{DiagnosisRow, IdemRow, Ingest, NewRecord, StoreError, new_id, now_ms};

/// Body formats the endpoint takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BodyFormat {
    Json,
    Csv,
    F32,
    Wav,
}

impl BodyFormat {
    pub fn from_content_type(ct: &str) -> Option<BodyFormat> {
        let mime = ct
            .split(';')
            .next()
            .unwrap_or("")
            .trim()
            .to_ascii_lowercase();
        match mime.as_str() {
            "application/json" => Some(BodyFormat::Json),
            "text/csv" => Some(BodyFormat::Csv),
            "application/octet-stream" => Some(BodyFormat::F32),
            "audio/wav" | "audio/x-wav" | "audio/wave" | "audio/vnd.wave" => Some(BodyFormat::Wav),
            _ => None,
        }
    }

    pub fn mime(self) -> &'static str {
        match self {
            BodyFormat::Json => "application/json",
            BodyFormat::Csv => "text/csv",
            BodyFormat::F32 => "application/octet-stream",
            BodyFormat::Wav => "audio/wav",
        }
    }
}

/// The JSON body: one channel, `{"sample_rate_hz": n, "samples": [..], …}`, or several,
/// `{"sample_rate_hz": n, "channels": {"a1": [..], "a2": [..]}, …}` (exactly one of
/// `samples` and `channels`; channel names non-empty and distinct, kept in the body's order).
/// [`JsonRecord::into_channels`] gives either form as channels.
#[derive(Debug, Deserialize)]
#[serde(try_from = "JsonRecordBody")]
pub struct JsonRecord {
    pub sample_rate_hz: f64,
    /// The `samples` form's samples; empty in the `channels` form.
    pub samples: Vec<f64>,
    /// The `channels` form's channels, in the body's order; `None` in the `samples` form.
    pub channels: Option<Vec<crate::record::Channel>>,
    pub shaft_hz: Option<f64>,
    pub recorded_at: Option<String>,
    pub sensor: Option<String>,
}

/// The members as written, before the one-of rule on `samples` / `channels`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonRecordBody {
    sample_rate_hz: f64,
    // Absent is `None`; present must be the form's value (`null` is refused, as before
    // `channels` existed).
    #[serde(default, deserialize_with = "present")]
    samples: Option<Vec<f64>>,
    #[serde(default, deserialize_with = "present")]
    channels: Option<JsonChannels>,
    #[serde(default)]
    shaft_hz: Option<f64>,
    #[serde(default)]
    recorded_at: Option<String>,
    #[serde(default)]
    sensor: Option<String>,
}

/// A member that, when present, must hold a `T` (not `null`).
fn present<'de, D: serde::Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

impl TryFrom<JsonRecordBody> for JsonRecord {
    type Error = String;

    fn try_from(b: JsonRecordBody) -> Result<JsonRecord, String> {
        let (samples, channels) = match (b.samples, b.channels) {
            (Some(s), None) => (s, None),
            (None, Some(c)) => (Vec::new(), Some(c.0)),
            (Some(_), Some(_)) => {
                return Err(
                    "the record has both `samples` and `channels`; give `samples` \
                     for one channel or `channels` for several, not both"
                        .into(),
                );
            }
            (None, None) => {
                return Err(
                    "missing field `samples` (an array of numbers, one channel) or \
                     `channels` (an object of channel name: array of numbers)"
                        .into(),
                );
            }
        };
        Ok(JsonRecord {
            sample_rate_hz: b.sample_rate_hz,
            samples,
            channels,
            shaft_hz: b.shaft_hz,
            recorded_at: b.recorded_at,
            sensor: b.sensor,
        })
    }
}

/// `{"a1": [..], "a2": [..]}`, in the body's order, refusing an empty object, an empty
/// name and a name given twice.
struct JsonChannels(Vec<crate::record::Channel>);

impl<'de> Deserialize<'de> for JsonChannels {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = JsonChannels;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object of channel name: array of numbers")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<JsonChannels, A::Error> {
                use crate::record::Channel;
                use serde::de::Error as _;
                let mut out: Vec<Channel> = Vec::new();
                while let Some(name) = map.next_key::<String>()? {
                    if name.is_empty() {
                        return Err(A::Error::custom("a channel name in `channels` is empty"));
                    }
                    if out.iter().any(|c| c.name == name) {
                        return Err(A::Error::custom(format!(
                            "channel `{name}` appears twice in `channels`"
                        )));
                    }
                    let samples = map.next_value::<Vec<f64>>()?;
                    out.push(Channel { name, samples });
                }
                if out.is_empty() {
                    return Err(A::Error::custom(
                        "`channels` holds no channel; give at least one",
                    ));
                }
                Ok(JsonChannels(out))
            }
        }
        d.deserialize_map(Visitor)
    }
}

impl JsonRecord {
    /// Parse a JSON body: the same answer as `serde_json::from_slice::<JsonRecord>`, faster for
    /// the usual body. [`fast_json_record`] reads the plain one-channel form (the five known
    /// members once each, numbers, strings without escapes, `null` for the optional ones) in
    /// one pass, samples included; anything else — the `channels` form, an escape, an unknown
    /// or repeated member, a sample that is not a number or overflows, any syntax error — goes
    /// through `serde_json` whole, so every error message is serde_json's.
    ///
    /// Numbers are correctly rounded (`fast_float2`, like Rust's `str::parse::<f64>`);
    /// serde_json's default number path may differ from that by one unit in the last place
    /// (the fuzzer found a long integer rate where it does).
    pub fn from_json(bytes: &[u8]) -> serde_json::Result<JsonRecord> {
        match fast_json_record(bytes) {
            Some(r) => Ok(r),
            None => serde_json::from_slice(bytes),
        }
    }

    /// The record's channels: the `channels` form's, in the body's order, or the `samples`
    /// form's one channel, named `"0"` (as a one-column CSV's or a raw f32 body's).
    pub fn into_channels(self) -> Vec<crate::record::Channel> {
        match self.channels {
            Some(c) => c,
            None => vec![crate::record::Channel {
                name: "0".into(),
                samples: self.samples,
            }],
        }
    }
}

/// One-pass reader of the plain JSON record (see [`JsonRecord::from_json`]); `None` for
/// anything it does not take, valid or not.
pub fn fast_json_record(b: &[u8]) -> Option<JsonRecord> {
    let mut p = JsonCursor { b, i: 0 };
    let (mut rate, mut samples, mut shaft, mut recorded_at, mut sensor) =
        (None, None, None, None, None);
    p.ws();
    p.eat(b'{')?;
    loop {
        p.ws();
        let key = p.plain_string()?;
        p.ws();
        p.eat(b':')?;
        p.ws();
        match key {
            "sample_rate_hz" if rate.is_none() => rate = Some(p.number()?),
            "samples" if samples.is_none() => samples = Some(p.numbers()?),
            "shaft_hz" if shaft.is_none() => {
                shaft = Some(if p.null() { None } else { Some(p.number()?) })
            }
            "recorded_at" if recorded_at.is_none() => {
                recorded_at = Some(if p.null() {
                    None
                } else {
                    Some(p.plain_string()?.to_owned())
                })
            }
            "sensor" if sensor.is_none() => {
                sensor = Some(if p.null() {
                    None
                } else {
                    Some(p.plain_string()?.to_owned())
                })
            }
            _ => return None,
        }
        p.ws();
        match p.next()? {
            b',' => continue,
            b'}' => break,
            _ => return None,
        }
    }
    p.ws();
    if p.i != b.len() {
        return None;
    }
    Some(JsonRecord {
        sample_rate_hz: rate?,
        samples: samples?,
        channels: None,
        shaft_hz: shaft.flatten(),
        recorded_at: recorded_at.flatten(),
        sensor: sensor.flatten(),
    })
}

/// `t`, a number `fast_float2` read whole, is also one in JSON's grammar. `fast_float2` takes
/// `[+-]? digits* (. digits*)? ([eE][+-]?digits+)?` with at least one mantissa digit, and
/// `inf`/`nan`; JSON differs in wanting a digit first (after an optional `-`; the caller has
/// excluded `+`), no leading zero before another digit, and a digit after the point.
fn is_json_number(t: &[u8]) -> bool {
    let t = t.strip_prefix(b"-").unwrap_or(t);
    match t {
        [b'0', b'0'..=b'9', ..] => false,
        [b'0'..=b'9', ..] => match t.iter().position(|&c| c == b'.') {
            Some(p) => t.get(p + 1).is_some_and(u8::is_ascii_digit),
            None => true,
        },
        _ => false,
    }
}

struct JsonCursor<'a> {
    b: &'a [u8],
    i: usize,
}

impl<'a> JsonCursor<'a> {
    fn ws(&mut self) {
        while let Some(b' ' | b'\t' | b'\n' | b'\r') = self.b.get(self.i) {
            self.i += 1;
        }
    }
    fn next(&mut self) -> Option<u8> {
        let c = *self.b.get(self.i)?;
        self.i += 1;
        Some(c)
    }
    fn eat(&mut self, c: u8) -> Option<()> {
        (self.next()? == c).then_some(())
    }
    fn null(&mut self) -> bool {
        let hit = self.b[self.i..].starts_with(b"null");
        if hit {
            self.i += 4;
        }
        hit
    }
    /// A string without escapes or control characters, valid UTF-8.
    fn plain_string(&mut self) -> Option<&'a str> {
        self.eat(b'"')?;
        let start = self.i;
        loop {
            match self.next()? {
                b'"' => break,
                b'\\' | 0..=0x1f => return None,
                _ => {}
            }
        }
        std::str::from_utf8(&self.b[start..self.i - 1]).ok()
    }
    /// A number in JSON's grammar, `-?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?`, finite
    /// as an `f64`. `fast_float2` reads a superset of that grammar (`1.`, `.5`, `01`, `inf`);
    /// the text it took is then checked against JSON's.
    fn number(&mut self) -> Option<f64> {
        let rest = &self.b[self.i..];
        if !matches!(rest.first(), Some(b'-' | b'0'..=b'9')) {
            return None;
        }
        let (v, used): (f64, usize) = fast_float2::parse_partial(rest).ok()?;
        if !(v.is_finite() && is_json_number(&rest[..used])) {
            return None;
        }
        self.i += used;
        Some(v)
    }
    /// `[number, …]`.
    fn numbers(&mut self) -> Option<Vec<f64>> {
        self.eat(b'[')?;
        let mut out = Vec::new();
        self.ws();
        if self.b.get(self.i) == Some(&b']') {
            self.i += 1;
            return Some(out);
        }
        loop {
            out.push(self.number()?);
            self.ws();
            match self.next()? {
                b',' => self.ws(),
                b']' => return Some(out),
                _ => return None,
            }
        }
    }
}

/// Query parameters (for the non-JSON bodies; `shaft_hz`, `recorded_at`, `sensor` also with
/// JSON, where the body wins).
#[derive(Debug, Default, Deserialize)]
pub struct RecordQuery {
    sample_rate_hz: Option<String>,
    shaft_hz: Option<String>,
    recorded_at: Option<String>,
    sensor: Option<String>,
    /// Diagnose only this channel of a multichannel record (a name or a 0-based index).
    pub channel: Option<String>,
    /// `true`: the record is healthy, part of the machine's baseline.
    baseline: Option<String>,
}

impl RecordQuery {
    /// The `baseline` flag.
    pub fn baseline(&self) -> ApiResult<bool> {
        match self.baseline.as_deref() {
            None | Some("false") | Some("0") => Ok(false),
            Some("true") | Some("1") => Ok(true),
            Some(other) => Err(ApiError::bad_request(
                "invalid-query",
                "Invalid query parameter",
                format!("`baseline` is `true` or `false`, got `{other}`"),
            )
            .with("parameter", "baseline")),
        }
    }
}

/// Whether `id` is 1–64 characters of `A–Z a–z 0–9 . _ -` (machine and gearbox ids).
pub fn is_valid_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 64
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'.' || b == b'_' || b == b'-')
}

/// Machine ids: 1–64 characters of `A–Z a–z 0–9 . _ -`.
pub fn check_machine_id(id: &str) -> ApiResult<()> {
    if is_valid_id(id) {
        Ok(())
    } else {
        Err(ApiError::bad_request(
            "invalid-machine-id",
            "Invalid machine id",
            "a machine id is 1 to 64 characters of letters, digits, `.`, `_` and `-`",
        )
        .with("machine_id", id))
    }
}

/// A JSON answer with `status`.
pub fn json_response(status: StatusCode, v: &Value) -> Response {
    let mut r = (status, v.to_string()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}

fn parse_number(name: &'static str, v: &Option<String>) -> ApiResult<Option<f64>> {
    match v {
        None => Ok(None),
        Some(s) => match s.trim().parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(Some(x)),
            _ => Err(ApiError::bad_request(
                "invalid-query",
                "Invalid query parameter",
                format!("query parameter `{name}` must be a finite number, got `{s}`"),
            )
            .with("parameter", name)),
        },
    }
}

fn body_too_large(limit: usize) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "body-too-large",
        "Request body too large",
        format!(
            "the body exceeds the limit of {limit} bytes; send a shorter record or a binary \
             format (application/octet-stream f32 is 4 bytes a sample)"
        ),
    )
    .with("limit_bytes", limit as u64)
}

/// Read the body, refusing more than `limit` bytes. A refused upload is still read and
/// discarded (up to 256 MiB or 5 s, nothing kept) before the 413 goes out: a client that is
/// mid-upload then reads the problem instead of a reset connection ("lingering close").
pub async fn read_body(headers: &HeaderMap, body: Body, limit: usize) -> ApiResult<bytes_::Bytes> {
    use http_body_util::BodyExt;
    const DRAIN_CAP: usize = 256 << 20;
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|s| s.parse::<u64>().ok());
    let mut too_big = declared.is_some_and(|n| n > limit as u64);
    let mut buf = Vec::with_capacity(if too_big {
        0
    } else {
        declared.unwrap_or(0).min(limit as u64) as usize
    });
    let mut body = body;
    let mut drained = 0usize;
    let drain_for = std::time::Duration::from_secs(5);
    // Only the discarding of a refused upload is time-boxed here; a normal upload is bounded
    // by the request timeout.
    let mut deadline = too_big.then(|| tokio::time::Instant::now() + drain_for);
    loop {
        let next = match deadline {
            Some(d) => tokio::time::timeout_at(d, body.frame()).await,
            None => Ok(body.frame().await),
        };
        let frame = match next {
            Ok(Some(Ok(f))) => f,
            Ok(None) => break,
            Ok(Some(Err(e))) => {
                if too_big {
                    break;
                }
                return Err(ApiError::bad_request(
                    "body-unreadable",
                    "Request body could not be read",
                    format!("the upload broke off: {e}"),
                ));
            }
            Err(_) => break,
        };
        let Ok(data) = frame.into_data() else {
            continue;
        };
        if too_big {
            drained += data.len();
            if drained > DRAIN_CAP {
                break;
            }
        } else if buf.len() + data.len() > limit {
            too_big = true;
            buf = Vec::new();
            deadline = Some(tokio::time::Instant::now() + drain_for);
        } else {
            buf.extend_from_slice(&data);
        }
    }
    if too_big {
        return Err(body_too_large(limit));
    }
    Ok(bytes_::Bytes::from(buf))
}

mod bytes_ {
    pub use axum::body::Bytes;
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
        E::Signal(m) => un("unusable-record", "Unusable record", m.clone()),
        other => {
            tracing::error!(error = %other, "diagnosis failed");
            ApiError::internal(format!("the diagnosis failed: {other}"))
        }
    }
}

/// Decode a non-JSON body into samples with the record module's parsers (the same as
/// `gearwear diagnose` uses for files).
fn decode_binary(
    format: BodyFormat,
    bytes: &[u8],
    sample_rate: Option<f64>,
) -> ApiResult<(Channels, f64)> {
    use crate::record::{Format, ReadOptions, parse_record_channels};
    let f = match format {
        BodyFormat::Csv => Format::Csv,
        BodyFormat::F32 => Format::F32,
        BodyFormat::Wav => Format::Wav,
        BodyFormat::Json => unreachable!("JSON is decoded by serde"),
    };
    let opts = ReadOptions {
        format: Some(f),
        sample_rate,
        column: None,
    };
    let r = parse_record_channels(bytes, f, &opts, "body").map_err(|e| {
        let mut p = problem_from_error(&e);
        // The parsers speak CLI; a web client sets a query parameter.
        p.detail = p
            .detail
            .replace("--sample-rate HZ", "`?sample_rate_hz=…`")
            .replace("--sample-rate", "`?sample_rate_hz=…`")
            .replace(
                "give the sample rate in Hz",
                "give it (`?sample_rate_hz=…`)",
            )
            .replace("give the sample rate", "give `?sample_rate_hz=…`");
        p
    })?;
    Ok((
        r.channels
            .into_iter()
            .map(|c| (c.name, c.samples))
            .collect(),
        r.sample_rate,
    ))
}

/// The body with its `Content-Encoding` undone: `gzip` is inflated (at most 8 × the body
/// limit, so a 16 MiB limit takes a 4-channel CSV of a few million rows), `identity` or none
/// is the body; anything else is a 415.
pub fn content_decoded(
    headers: &HeaderMap,
    bytes: bytes_::Bytes,
    limit: usize,
) -> ApiResult<bytes_::Bytes> {
    let enc = headers
        .get(header::CONTENT_ENCODING)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("identity")
        .trim()
        .to_ascii_lowercase();
    match enc.as_str() {
        "identity" | "" => Ok(bytes),
        "gzip" | "x-gzip" => {
            let max = limit.saturating_mul(8);
            crate::record::gunzip(&bytes, "body", max)
                .map(bytes_::Bytes::from)
                .map_err(|e| {
                    if e.to_string().contains("expands beyond") {
                        body_too_large(max)
                    } else {
                        problem_from_error(&e)
                    }
                })
        }
        other => Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported-encoding",
            "Unsupported content encoding",
            format!("Content-Encoding `{other}` is not supported; send the body as is or gzip it"),
        )),
    }
}

/// The body format named by `Content-Type` (415 problem otherwise).
pub fn body_format(headers: &HeaderMap) -> ApiResult<BodyFormat> {
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    BodyFormat::from_content_type(ct).ok_or_else(|| {
        ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported-media-type",
            "Unsupported content type",
            format!(
                "content type `{ct}` is not a record format; send application/json, text/csv, \
                 application/octet-stream (little-endian f32) or audio/wav"
            ),
        )
        .with(
            "accepted",
            json!([
                "application/json",
                "text/csv",
                "application/octet-stream",
                "audio/wav"
            ]),
        )
    })
}

/// The record query parameters (`sample_rate_hz`, `shaft_hz`, `recorded_at`, `sensor`).
pub fn parse_query(query: Option<&str>) -> ApiResult<RecordQuery> {
    serde_urlencoded::from_str(query.unwrap_or("")).map_err(|e| {
        ApiError::bad_request("invalid-query", "Invalid query parameter", e.to_string())
    })
}

/// `(name, samples)` of each channel of a record.
pub type Channels = Vec<(String, Vec<f64>)>;

/// A decoded, validated record and what the request said about it.
#[derive(Debug, Clone)]
pub struct Decoded {
    /// `(name, samples)` of each channel; a single-channel record's one is named `"0"`.
    pub channels: Channels,
    pub sample_rate_hz: f64,
    pub shaft_hz: Option<f64>,
    pub recorded_at: Option<String>,
    pub sensor: Option<String>,
}

fn too_many_samples(samples: usize, limit: usize) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "too-many-samples",
        "Record too long",
        format!(
            "the record has {samples} samples; the limit is {limit} — split it into shorter records"
        ),
    )
    .with("limit_samples", limit as u64)
    .with("samples", samples as u64)
}

impl Decoded {
    /// The channels to diagnose: the `channel` query parameter's (by name or 0-based index),
    /// else those the machine lists, else all.
    pub fn select(
        &self,
        wanted: Option<&str>,
        machine: Option<&[String]>,
    ) -> ApiResult<Vec<usize>> {
        let names = || {
            self.channels
                .iter()
                .map(|(n, _)| format!("`{n}`"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if let Some(w) = wanted {
            let by_name = self.channels.iter().position(|(n, _)| n == w);
            let by_index = w.parse::<usize>().ok().filter(|i| *i < self.channels.len());
            return match by_name.or(by_index) {
                Some(i) => Ok(vec![i]),
                None => Err(ApiError::unprocessable(
                    "unknown-channel",
                    "Unknown channel",
                    format!(
                        "the record has no channel `{w}`; its channels are {} (name or 0-based index \
                         in the `channel` query parameter)",
                        names()
                    ),
                )
                .with("channel", w)),
            };
        }
        if let Some(list) = machine {
            let picked: Vec<usize> = (0..self.channels.len())
                .filter(|i| list.contains(&self.channels[*i].0))
                .collect();
            if picked.is_empty() && self.channels.len() > 1 {
                return Err(ApiError::unprocessable(
                    "unknown-channel",
                    "Unknown channel",
                    format!(
                        "none of the record's channels ({}) is one the machine records ({}); \
                         name one with the `channel` query parameter or update the machine's \
                         `channels`",
                        names(),
                        list.join(", ")
                    ),
                ));
            }
            if !picked.is_empty() {
                return Ok(picked);
            }
        }
        Ok((0..self.channels.len()).collect())
    }

    /// The one channel of a record an endpoint needs one of: the `channel` query parameter's,
    /// or the only one.
    pub fn single(&self, wanted: Option<&str>) -> ApiResult<&[f64]> {
        if wanted.is_none() && self.channels.len() > 1 {
            return Err(ApiError::unprocessable(
                "several-channels",
                "Several channels",
                format!(
                    "the record has {} channels ({}); choose one with the `channel` query parameter",
                    self.channels.len(),
                    self.channels
                        .iter()
                        .map(|(n, _)| n.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        let i = self.select(wanted, None)?[0];
        Ok(&self.channels[i].1)
    }
}

/// Decode and validate a record body of `format` (JSON body fields win over the query),
/// the same for every endpoint that takes a record.
pub fn decode(
    format: BodyFormat,
    q: &RecordQuery,
    bytes: &[u8],
    limits: &crate::configuration::Limits,
) -> ApiResult<Decoded> {
    let mut shaft = parse_number("shaft_hz", &q.shaft_hz)?;
    let mut recorded_at = q.recorded_at.clone();
    let mut sensor = q.sensor.clone();
    let (channels, fs) = match format {
        BodyFormat::Json => {
            let mut r = JsonRecord::from_json(bytes).map_err(|e| {
                let hint = if bytes.windows(3).any(|w| w == b"NaN") || bytes.windows(8).any(|w| w == b"Infinity") {
                    " (JSON has no NaN or Infinity: every sample must be a finite number)"
                } else {
                    ""
                };
                ApiError::bad_request(
                    "invalid-json",
                    "Malformed JSON record",
                    format!(
                        "the body is not a valid record: {e}{hint}; expected \
                         {{\"sample_rate_hz\": number, \"samples\": [numbers] or \"channels\": {{name: [numbers]}}, \"shaft_hz\"?: number, \
                         \"recorded_at\"?: RFC 3339 string, \"sensor\"?: string}}"
                    ),
                )
            })?;
            if r.shaft_hz.is_some() {
                shaft = r.shaft_hz;
            }
            if r.recorded_at.is_some() {
                recorded_at = r.recorded_at.take();
            }
            if r.sensor.is_some() {
                sensor = r.sensor.take();
            }
            let fs = r.sample_rate_hz;
            let chans = r.into_channels();
            (
                chans
                    .into_iter()
                    .map(|c| (c.name, c.samples))
                    .collect::<Vec<_>>(),
                fs,
            )
        }
        BodyFormat::F32 if bytes.len() / 4 > limits.max_samples => {
            // Refused before decoding: no vector of more samples than allowed is built.
            return Err(too_many_samples(bytes.len() / 4, limits.max_samples));
        }
        f => decode_binary(f, bytes, parse_number("sample_rate_hz", &q.sample_rate_hz)?)?,
    };
    if let Some(t) = &recorded_at
        && crate::time::parse_rfc3339(t).is_none()
    {
        return Err(ApiError::bad_request(
            "invalid-recorded-at",
            "Invalid recorded_at",
            format!(
                "`recorded_at` must be an RFC 3339 timestamp such as 2026-11-22T08:30:00Z, got `{t}`"
            ),
        ));
    }
    if let Some(s) = &sensor
        && s.len() > 200
    {
        return Err(ApiError::bad_request(
            "invalid-sensor",
            "Invalid sensor",
            "`sensor` is at most 200 characters",
        ));
    }
    let total: usize = channels.iter().map(|c| c.1.len()).sum();
    if total > limits.max_samples {
        return Err(too_many_samples(total, limits.max_samples));
    }
    // Empty, NaN/±∞, flat or clipped samples and an impossible rate: the library's checks
    // (the binary formats already passed them in `parse_record_channels`; a JSON body has
    // not). A multichannel record's error names its channel.
    if format == BodyFormat::Json {
        for (name, x) in &channels {
            let r = crate::record::check_signal(x);
            let r = if channels.len() > 1 {
                r.map_err(|e| e.in_channel(name.clone()))
            } else {
                r
            };
            r.map_err(|e| problem_from_error(&e))?;
        }
        crate::record::check_sample_rate(fs).map_err(|e| problem_from_error(&e))?;
    }

    Ok(Decoded {
        channels,
        sample_rate_hz: fs,
        shaft_hz: shaft,
        recorded_at,
        sensor,
    })
}

fn f32_bytes(x: &[f64]) -> Vec<u8> {
    let mut v = Vec::with_capacity(x.len() * 4);
    for s in x {
        v.extend_from_slice(&(*s as f32).to_le_bytes());
    }
    v
}

/// The handler.
pub async fn post_record(
    State(app): State<AppState>,
    caller: Caller,
    Path(machine_id): Path<String>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
    body: Body,
) -> Response {
    match ingest(&app, &caller, &machine_id, query, &headers, body).await {
        Ok(r) => r,
        Err(e) => {
            app.metrics.rejected(e.slug);
            e.into_response()
        }
    }
}

async fn ingest(
    app: &AppState,
    caller: &Caller,
    machine_id: &str,
    query: Option<String>,
    headers: &HeaderMap,
    body: Body,
) -> ApiResult<Response> {
    let limits = &app.settings.limits;
    if let Err(e) = caller.require(app, Scope::Ingest) {
        // Read (and drop) the upload so the client sees the 401/403/429, not a reset.
        let _ = read_body(headers, body, limits.max_body_bytes).await;
        return Err(e);
    }
    check_machine_id(machine_id)?;
    let format = body_format(headers)?;
    let q = parse_query(query.as_deref())?;
    let bytes = read_body(headers, body, limits.max_body_bytes).await?;
    // CPU time by stage (`/metrics`), booked only for synchronous sections: a task may move to
    // another thread at an await.
    let mut clock = StageClock::new();
    let bytes = content_decoded(headers, bytes, limits.max_body_bytes)?;
    clock.lap("decode");

    // Idempotency: replay the stored answer of an earlier identical request.
    let idem_key = match headers.get("idempotency-key") {
        None => None,
        Some(v) => {
            let s = v.to_str().ok().filter(|s| !s.is_empty() && s.len() <= 255);
            Some(
                s.ok_or_else(|| {
                    ApiError::bad_request(
                        "invalid-idempotency-key",
                        "Invalid Idempotency-Key",
                        "an Idempotency-Key is 1 to 255 visible ASCII characters (a UUID is a good choice)",
                    )
                })?
                .to_string(),
            )
        }
    };
    let key_id = caller.key_id.clone().unwrap_or_default();
    // The body is hashed once (it is stored as the record's `sha256`); the request hash
    // covers machine, content type, query and that body hash.
    let body_sha256 = hex::encode(Sha256::digest(&bytes));
    let request_hash = {
        let mut h = Sha256::new();
        for part in [
            machine_id.as_bytes(),
            format.mime().as_bytes(),
            query.as_deref().unwrap_or("").as_bytes(),
            body_sha256.as_bytes(),
        ] {
            h.update(part);
            h.update([0u8]);
        }
        hex::encode(h.finalize())
    };
    clock.lap("hash");
    if let Some(k) = &idem_key
        && let Some(prev) = app.store.get_idempotent(&key_id, k).await?
    {
        return replay(app, &prev, &request_hash);
    }

    clock.skip();
    let dec = decode(format, &q, &bytes, limits)?;
    let baseline = q.baseline()?;
    clock.lap("decode");

    // The machine's gearbox (and its table, when ready), baseline and calibration.
    let ctx = super::machines::context(app, machine_id).await?;
    let chosen = dec.select(
        q.channel.as_deref(),
        ctx.machine.as_ref().and_then(|m| m.channels.as_deref()),
    )?;
    let (baselines, baseline_counts) =
        super::machines::baselines(app, machine_id, &ctx.gearbox_row.hash).await?;
    let calibration = app
        .store
        .get_calibration(machine_id)
        .await?
        .map(|c| MachineCalibration::from_row(&c));
    let table_note = ctx.table_note();
    let job = ChannelJob {
        dec,
        chosen,
        shaft: None,
        calibration,
        diagnoser: ctx.diagnoser.clone(),
        gearbox: ctx.gearbox.clone(),
        input_shaft_hz: ctx.input_shaft_hz(),
        baselines,
        thresholds: app.settings.thresholds,
        table_note: table_note.clone(),
        declared_healthy: baseline,
        described: ctx.machine.as_ref().is_some_and(|m| m.gearbox_id.is_some()),
    };
    let (dec, results, spectrum, job_clock) = tokio::task::spawn_blocking(move || job.run())
        .await
        .map_err(|e| ApiError::internal(format!("the diagnosis task failed: {e}")))?
        .map_err(|e| problem_from_error(&e))?;
    clock.absorb(job_clock);
    clock.skip();
    let Decoded {
        channels,
        sample_rate_hz: fs,
        shaft_hz: shaft,
        recorded_at,
        sensor,
    } = dec;
    let di = super::assess::deciding(&results);
    let decide = &results[di];

    // Build everything, then store it in one transaction.
    let now = now_ms();
    let record_id = new_id();
    let diagnosis_id = new_id();
    let level = decide.alert.level;
    let mut body = match &decide.output {
        Some(o) => o.diagnosis.clone(),
        None => json!({
            "wear_degree": null,
            "motion_state": "unknown",
            "sensor": sensor.clone().unwrap_or_default(),
            "warnings": [],
        }),
    };
    if let Value::Object(m) = &mut body {
        m.insert("channel".into(), decide.name.clone().into());
        if results.len() > 1 {
            m.insert(
                "channels".into(),
                results
                    .iter()
                    .map(|r| r.summary())
                    .collect::<Vec<_>>()
                    .into(),
            );
        }
        m.insert("gearbox".into(), ctx.json());
        m.insert(
            "novelty".into(),
            serde_json::to_value(&decide.novelty).unwrap_or(Value::Null),
        );
        m.insert(
            "baseline".into(),
            json!({
                "records": baseline_counts.get(&decide.name).copied().unwrap_or(0),
                "min_records": crate::novelty::MIN_BASELINE_RECORDS,
                "this_record": baseline,
            }),
        );
        m.insert("indicators".into(), decide.features.indicators.clone());
        m.insert(
            "alert".into(),
            serde_json::to_value(&decide.alert).unwrap_or(Value::Null),
        );
        if let (Some(note), Some(Value::Array(w))) = (&table_note, m.get_mut("warnings")) {
            w.push(note.clone().into());
        }
    }
    let mut response = body.clone();
    if let Value::Object(m) = &mut response {
        m.insert("id".into(), diagnosis_id.clone().into());
        m.insert("machine_id".into(), machine_id.into());
        m.insert("record_id".into(), record_id.clone().into());
        m.insert("created_at".into(), crate::time::rfc3339(now).into());
        m.insert("alert_level".into(), level.into());
    }
    let response_text = response.to_string();
    let keep_raw = !app.settings.raw_retention.is_zero();
    let mut features = match &decide.output {
        Some(o) => o.features.clone(),
        None => json!({}),
    };
    features["gearbox_id"] = ctx.gearbox_row.id.clone().into();
    features["gearbox_hash"] = ctx.gearbox_row.hash.clone().into();
    features["channels"] = results
        .iter()
        .map(|r| {
            (
                r.name.clone(),
                json!({"novelty_features": r.features, "alert_level": r.alert.level}),
            )
        })
        .collect::<serde_json::Map<_, _>>()
        .into();
    let sample_count = channels.first().map(|c| c.1.len()).unwrap_or(0);
    let multi = channels.len() > 1;
    let (ea, lower, upper, motion) = match &decide.output {
        Some(o) => (
            o.ea_estimate,
            o.ea_lower,
            o.ea_upper,
            o.motion_state.clone(),
        ),
        None => (0.0, 0.0, 0.0, "unknown".to_string()),
    };
    let ing = Ingest {
        record: NewRecord {
            id: record_id.clone(),
            machine_id: machine_id.to_string(),
            received_at: now,
            recorded_at,
            sensor,
            content_type: format.mime().into(),
            sample_rate_hz: fs,
            shaft_hz: shaft,
            sample_count: sample_count as i64,
            sha256: body_sha256,
            features: features.to_string(),
            samples: keep_raw.then(|| {
                let mut v = Vec::with_capacity(4 * sample_count * channels.len());
                for (_, x) in &channels {
                    v.extend_from_slice(&f32_bytes(x));
                }
                v
            }),
            baseline,
            channels: multi.then(|| channels.iter().map(|c| c.0.clone()).collect()),
        },
        diagnosis: DiagnosisRow {
            seq: 0,
            id: diagnosis_id.clone(),
            record_id,
            machine_id: machine_id.to_string(),
            created_at: now,
            ea_estimate: ea,
            ea_lower: lower,
            ea_upper: upper,
            alert_level: level.into(),
            motion_state: motion,
            body: body.to_string(),
            spectrum: serde_json::to_string(&spectrum).unwrap_or_else(|_| "null".into()),
            has_wear: decide.output.is_some(),
            novelty_score: decide.novelty.as_ref().map(|n| n.score),
            novelty_threshold: decide.novelty.as_ref().map(|n| n.threshold),
            channel: Some(decide.name.clone()),
        },
        idempotency: idem_key.as_ref().map(|k| IdemRow {
            key_id: key_id.clone(),
            idem_key: k.clone(),
            request_hash: request_hash.clone(),
            status: 201,
            response: response_text.clone(),
        }),
    };
    clock.lap("assemble");
    match app.ingest_queue.ingest(ing).await {
        Ok(()) => {}
        Err(StoreError::Conflict(_)) if idem_key.is_some() => {
            // A concurrent request with the same key committed first: answer as it did.
            let k = idem_key.as_deref().unwrap_or_default();
            if let Some(prev) = app.store.get_idempotent(&key_id, k).await? {
                return replay(app, &prev, &request_hash);
            }
            return Err(ApiError::internal(
                "idempotency conflict without a stored answer",
            ));
        }
        Err(e) => return Err(e.into()),
    }
    app.metrics.records_accepted.fetch_add(1, Ordering::Relaxed);
    app.metrics.stages(&clock);
    app.webhook_wake.notify_one();
    tracing::info!(machine = machine_id, diagnosis = %diagnosis_id, ea, alert_level = level, "record accepted");
    let mut r = (StatusCode::CREATED, response_text).into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/diagnoses/{diagnosis_id}")) {
        h.insert(header::LOCATION, v);
    }
    Ok(r)
}

/// Everything the blocking part of an ingest needs: each chosen channel diagnosed (when the
/// table is ready), its features, its novelty, its alert; the spectrum plot of the deciding
/// channel.
struct ChannelJob {
    dec: Decoded,
    chosen: Vec<usize>,
    shaft: Option<f64>,
    calibration: Option<MachineCalibration>,
    diagnoser: Option<std::sync::Arc<dyn super::diagnoser::Diagnoser>>,
    gearbox: std::sync::Arc<crate::gearbox::Gearbox>,
    input_shaft_hz: Option<f64>,
    baselines: std::collections::BTreeMap<String, crate::novelty::MachineBaseline>,
    thresholds: crate::configuration::Thresholds,
    table_note: Option<String>,
    /// Posted with `?baseline=true`.
    declared_healthy: bool,
    /// The machine names its gearbox (not the built-in default).
    described: bool,
}

type JobResult = (
    Decoded,
    Vec<super::assess::ChannelResult>,
    Option<super::spectrum::PlotSpectrum>,
    StageClock,
);

impl ChannelJob {
    fn run(mut self) -> crate::Result<JobResult> {
        use super::assess::{ChannelResult, alert, deciding};
        let fs = self.dec.sample_rate_hz;
        let shaft = self.shaft.or(self.dec.shaft_hz);
        let mut clock = StageClock::new();
        let mut results = Vec::with_capacity(self.chosen.len());
        for &i in &self.chosen {
            // The channel's samples move into the diagnosis input and back (no copy).
            let name = self.dec.channels[i].0.clone();
            let input = Input {
                record: crate::record::Record {
                    samples: std::mem::take(&mut self.dec.channels[i].1),
                    sample_rate: fs,
                },
                shaft_hz: shaft,
                sensor: self.dec.sensor.clone(),
                calibration: self.calibration.clone(),
            };
            let rec = &input.record;
            let output = match &self.diagnoser {
                Some(d) => Some(d.diagnose(&input)?),
                None => None,
            };
            clock.lap("diagnosis");
            let hint = shaft.or(self.input_shaft_hz).or(output
                .as_ref()
                .map(|o| o.f1_hz / self.gearbox.f1_per_input_hz));
            // Order features only for a gearbox the machine was given: the built-in rig a
            // machine defaults to would track 29 teeth in another gearbox's records (noise
            // features that make a baseline unstable); without one the features are
            // description-free.
            let gb = self.described.then_some(self.gearbox.as_ref());
            // A described machine's diagnosis ran on its own gearbox's table and tracked the
            // record already: its order analysis is reused, not computed twice — when the f1
            // it tracked from agrees (±1 %, its tracker's search) with the speed the features
            // would start from (a given or configured shaft rate may disagree with a tacho-less
            // diagnosis; then the record is tracked again from that rate).
            let order = output
                .as_ref()
                .filter(|o| {
                    hint.is_none_or(|h| (o.f1_hz / self.gearbox.f1_hz(h) - 1.0).abs() < 0.01)
                })
                .and_then(|o| o.order.as_ref());
            let features = crate::novelty::record_features_with(rec, gb, hint, order)?;
            self.dec.channels[i].1 = input.record.samples;
            let novelty = self.baselines.get(&name).map(|b| b.score(&features));
            let alert = alert(
                output.as_ref().map(ChannelResult::wear),
                novelty.as_ref(),
                &self.thresholds,
                self.table_note.as_deref(),
                self.declared_healthy,
            );
            results.push(ChannelResult {
                name,
                output,
                features,
                novelty,
                alert,
            });
            clock.lap("features");
        }
        let di = deciding(&results);
        let samples = &self.dec.channels[self.chosen[di]].1;
        let spectrum = match results[di].output.as_mut() {
            Some(o) => match o.spectrum.take() {
                Some(s) => plot_from_spectrum(&s, o.f1_hz, &o.marks),
                None => plot_spectrum(samples, fs, o.f1_hz, &o.marks),
            },
            None => {
                let f1 = self
                    .input_shaft_hz
                    .map(|h| self.gearbox.f1_hz(h))
                    .unwrap_or(f64::NAN);
                plot_spectrum(samples, fs, f1, &[])
            }
        };
        clock.lap("plot");
        Ok((self.dec, results, spectrum, clock))
    }
}

fn replay(app: &AppState, prev: &IdemRow, request_hash: &str) -> ApiResult<Response> {
    if prev.request_hash != request_hash {
        return Err(ApiError::unprocessable(
            "idempotency-key-reused",
            "Idempotency-Key reused with a different request",
            "this Idempotency-Key was already used for a different record; use a new key for a new record",
        ));
    }
    app.metrics.records_replayed.fetch_add(1, Ordering::Relaxed);
    let status = StatusCode::from_u16(prev.status as u16).unwrap_or(StatusCode::CREATED);
    let mut r = (status, prev.response.clone()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r.headers_mut()
        .insert("idempotent-replayed", HeaderValue::from_static("true"));
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serde_record(body: &str) -> serde_json::Result<JsonRecord> {
        serde_json::from_slice(body.as_bytes())
    }

    /// Same samples as serde_json (to its one-ulp rounding) and exactly Rust's correctly
    /// rounded parse, for numbers written in every form JSON allows.
    #[test]
    fn fast_samples_match_serde_json() {
        let mut rng = crate::signature::SplitMix64::new(7);
        let mut texts: Vec<String> = vec![
            "0".into(),
            "-0".into(),
            "-0.0".into(),
            "1E+2".into(),
            "1e-2".into(),
            "123456789012345678901234567890".into(),
            "0.1000000000000000055511151231257827021181583404541015625".into(),
            "2.2250738585072014e-308".into(),
            "4.9e-324".into(),
            "1.7976931348623157e308".into(),
        ];
        for _ in 0..3000 {
            let u = rng.uniform();
            let v = (u - 0.5) * 10f64.powi((rng.uniform() * 40.0) as i32 - 20);
            texts.push(format!("{v}"));
            texts.push(format!("{v:e}"));
            texts.push(format!("{v:.3}"));
            texts.push(format!("{}", (v * 1e4).round() as i64));
        }
        for sep in [",", ", ", " ,\n\t", "\r\n,  "] {
            let body = format!(
                "{{ \"samples\" : [ {} ] , \"sample_rate_hz\": 25600, \"sensor\": \"é b\", \"shaft_hz\":null}}",
                texts.join(sep)
            );
            let fast = fast_json_record(body.as_bytes()).expect("the fast path takes this body");
            let slow = serde_record(&body).unwrap();
            assert_eq!(fast.samples.len(), texts.len());
            assert_eq!((fast.sensor.as_deref(), fast.shaft_hz), (Some("é b"), None));
            for ((a, b), t) in fast.samples.iter().zip(&slow.samples).zip(&texts) {
                assert_eq!(*a, t.parse::<f64>().unwrap(), "{t}");
                assert_eq!(a.is_sign_negative(), b.is_sign_negative(), "{t}");
                let ulps = (a.to_bits() as i64 - b.to_bits() as i64).abs();
                assert!(ulps <= 1, "{t}: {a} vs serde_json {b}");
            }
        }
        let empty = fast_json_record(br#"{"sample_rate_hz": 1, "samples": [ ]}"#).unwrap();
        assert!(empty.samples.is_empty());
        let full = fast_json_record(
            br#" {"recorded_at":"2026-11-22T08:30:00Z","shaft_hz":30.5,"sample_rate_hz":2.56e4,"samples":[-1,0.5],"sensor":null} "#,
        )
        .unwrap();
        assert_eq!(
            (
                full.sample_rate_hz,
                full.shaft_hz,
                full.recorded_at.as_deref(),
                full.sensor
            ),
            (25600.0, Some(30.5), Some("2026-11-22T08:30:00Z"), None)
        );
        assert_eq!(full.samples, [-1.0, 0.5]);
    }

    /// Whatever the fast path does not take gets serde_json's own answer, message included.
    #[test]
    fn everything_else_is_serde_json_s_answer() {
        for body in [
            r#"{"sample_rate_hz": 25600, "samples": [1, "2", 3]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, null]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, [2]]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, {"a": 2}]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [true]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, 1e999, 2]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [-1e400]}"#,
            r#"{"sample_rate_hz": 25600, "samples": null}"#,
            r#"{"sample_rate_hz": 25600, "samples": 3}"#,
            r#"{"sample_rate_hz": 25600, "samples": "1,2"}"#,
            r#"{"sample_rate_hz": 25600}"#,
            r#"{"samples": [1, 2]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "extra": 1}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "samples": [2]}"#,
            r#"{"sample_rate_hz": "x", "samples": ["a"]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, 2,]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [NaN]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [01]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1 2]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1]} x"#,
            r#"[1, 2]"#,
            "",
            "{}",
            r#"{"sample_rate_hz": 25600, "samples": [1.]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [.5]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [+1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1e]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1e+]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [-]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1.e5]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [-01.5]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [0x10]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1,]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [,1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1]"#,
            r#"{"sample_rate_hz": 25600, "samples": [1],}"#,
            r#"{"sample_rate_hz": 25600 "samples": [1]}"#,
            r#"{"sample_rate_hz": null, "samples": [1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": null, "sensor": null}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": nul}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": "30"}"#,
            r#"{"\u0073amples": [1, 2], "sample_rate_hz": 25600}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "sensor": "a\"b"}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "sensor": "\u00e9"}"#,
            "{\"sample_rate_hz\": 25600, \"samples\": [1], \"sensor\": \"a\tb\"}",
            r#"{"sample_rate_hz": 25600, "samples": [1], "recorded_at": 5}"#,
            r#"{"sample_rate_hz": 1e999, "samples": [1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": 30, "shaft_hz": 31}"#,
            "\u{feff}{\"sample_rate_hz\": 25600, \"samples\": [1]}",
            "{\"sample_rate_hz\": 25600,\u{a0}\"samples\": [1]}",
            r#"{"sample_rate_hz": 25600, "channels": {"a1": [1, 2], "a2": [3, 4]}}"#,
            r#"{"channels": {"a1": [1]}, "sample_rate_hz": 25600, "sensor": "s"}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "channels": {"a1": [1]}}"#,
            r#"{"sample_rate_hz": 25600, "channels": {"a1": [1]}, "samples": [1]}"#,
            r#"{"sample_rate_hz": 25600, "channels": {}}"#,
            r#"{"sample_rate_hz": 25600, "channels": null}"#,
            r#"{"sample_rate_hz": 25600, "channels": [[1]]}"#,
        ] {
            let fast = JsonRecord::from_json(body.as_bytes()).map_err(|e| e.to_string());
            let slow = serde_record(body).map_err(|e| e.to_string());
            match (&fast, &slow) {
                (Err(a), Err(b)) => assert_eq!(a, b, "{body}"),
                (Ok(a), Ok(b)) => assert_eq!(
                    (
                        &a.samples,
                        &a.channels,
                        a.sample_rate_hz,
                        a.shaft_hz,
                        &a.recorded_at,
                        &a.sensor
                    ),
                    (
                        &b.samples,
                        &b.channels,
                        b.sample_rate_hz,
                        b.shaft_hz,
                        &b.recorded_at,
                        &b.sensor
                    ),
                    "{body}"
                ),
                _ => panic!("{body}: fast {fast:?}, serde_json {slow:?}"),
            }
        }
    }

    /// The several-channel form: channels in the body's order, the other members as in the
    /// one-channel form, and `into_channels` for both forms.
    #[test]
    fn channels_form_and_into_channels() {
        use crate::record::Channel;
        let body = br#"{"sample_rate_hz": 12800, "channels": {"a2": [1, 2.5], "a1": [-1, 0]},
            "shaft_hz": 30, "sensor": "s1"}"#;
        let r = JsonRecord::from_json(body).unwrap();
        assert_eq!(
            (r.sample_rate_hz, r.shaft_hz, r.sensor.as_deref()),
            (12800.0, Some(30.0), Some("s1"))
        );
        assert!(r.samples.is_empty());
        assert_eq!(
            r.into_channels(),
            [
                Channel {
                    name: "a2".into(),
                    samples: vec![1.0, 2.5]
                },
                Channel {
                    name: "a1".into(),
                    samples: vec![-1.0, 0.0]
                }
            ]
        );
        let r = JsonRecord::from_json(br#"{"sample_rate_hz": 1, "samples": [1, 2]}"#).unwrap();
        assert_eq!(r.channels, None);
        assert_eq!(
            r.into_channels(),
            [Channel {
                name: "0".into(),
                samples: vec![1.0, 2.0]
            }]
        );
    }

    /// Each mistake in the choice of form gets its own serde_json error, the same through
    /// `from_json` as through serde_json.
    #[test]
    fn channels_form_errors() {
        for (body, want) in [
            (
                r#"{"sample_rate_hz": 1, "samples": [1], "channels": {"a": [1]}}"#,
                "the record has both `samples` and `channels`",
            ),
            (
                r#"{"sample_rate_hz": 1}"#,
                "missing field `samples` (an array of numbers, one channel) or `channels`",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {}}"#,
                "`channels` holds no channel; give at least one at line 1 column",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {"a1": [1], "a1": [2]}}"#,
                "channel `a1` appears twice in `channels` at line 1 column",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {"": [1]}}"#,
                "a channel name in `channels` is empty",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": [[1, 2]]}"#,
                "invalid type: sequence, expected an object of channel name: array of numbers",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {"a": [1, "x"]}}"#,
                "invalid type: string \"x\", expected f64",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": null}"#,
                "invalid type: null, expected an object of channel name",
            ),
            (
                r#"{"sample_rate_hz": 1, "samples": null}"#,
                "invalid type: null, expected a sequence",
            ),
            (
                r#"{"sample_rate_hz": 1, "channel": {"a": [1]}}"#,
                "unknown field `channel`, expected one of `sample_rate_hz`, `samples`, \
                 `channels`",
            ),
        ] {
            let e = JsonRecord::from_json(body.as_bytes())
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{body}: {e}");
            assert_eq!(e, serde_record(body).unwrap_err().to_string(), "{body}");
        }
    }
}
