//! The record wire format: the body formats the record endpoints take, the query parameters
//! that go with them, and [`decode`] — body bytes to a validated [`Decoded`] record, or the
//! problem a client is answered with.

pub mod json;

use axum::http::StatusCode;
use serde::Deserialize;

pub use json::{JsonRecord, fast_json_record};

use super::error::{ApiError, ApiResult, problem_from_error};
use crate::condition::Load;
use crate::condition::state::MAX_PULSES_PER_REV;

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

/// Query parameters (for the non-JSON bodies; `shaft_hz`, `recorded_at`, `sensor`, `load`
/// also with JSON, where the body wins).
#[derive(Debug, Default, Deserialize)]
pub struct RecordQuery {
    sample_rate_hz: Option<String>,
    shaft_hz: Option<String>,
    recorded_at: Option<String>,
    sensor: Option<String>,
    /// The load the record was taken at: a number or a label ([`Load::parse`]).
    load: Option<String>,
    /// Diagnose only this channel of a multichannel record (a name or a 0-based index).
    pub channel: Option<String>,
    /// `true`: the record is healthy, part of the machine's baseline.
    baseline: Option<String>,
    /// The tachometer's pulses per input-shaft revolution, for this record (overrides the
    /// machine's `tacho_ppr`).
    tacho_ppr: Option<String>,
}

/// Longest load label.
pub const MAX_LOAD_LABEL: usize = 100;

impl RecordQuery {
    /// The `tacho_ppr` parameter: a whole number from 1 to [`MAX_PULSES_PER_REV`].
    pub fn tacho_ppr(&self) -> ApiResult<Option<usize>> {
        let Some(s) = &self.tacho_ppr else {
            return Ok(None);
        };
        match s.trim().parse::<i64>() {
            Ok(n) if (1..=MAX_PULSES_PER_REV as i64).contains(&n) => Ok(Some(n as usize)),
            _ => Err(ApiError::bad_request(
                "invalid-query",
                "Invalid query parameter",
                format!(
                    "`tacho_ppr` is the tachometer's pulses per input-shaft revolution, a whole \
                     number from 1 to {MAX_PULSES_PER_REV}, got `{s}`"
                ),
            )
            .with("parameter", "tacho_ppr")),
        }
    }

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

/// Decode a non-JSON body into samples with the record module's parsers (the same as
/// `gearwear diagnose` uses for files).
fn decode_binary(
    format: BodyFormat,
    bytes: &[u8],
    sample_rate: Option<f64>,
    pulses: Option<&str>,
) -> ApiResult<(Channels, f64)> {
    use crate::record::{Format, ReadOptions, parse_record_channels_with_pulses};
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
    let r = parse_record_channels_with_pulses(bytes, f, &opts, "body", pulses).map_err(|e| {
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
    /// The load the record was taken at (body, else query).
    pub load: Option<Load>,
    /// A JSON body's `record_id` (MQTT ingest de-duplicates by it).
    pub record_id: Option<String>,
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
    /// else those the machine lists, else all — never the tachometer's (index `tacho`), which
    /// gives the speed.
    pub fn select(
        &self,
        wanted: Option<&str>,
        machine: Option<&[String]>,
        tacho: Option<usize>,
    ) -> ApiResult<Vec<usize>> {
        let picked = self.select_any(wanted, machine, tacho)?;
        if picked.is_empty() || tacho.is_some_and(|t| picked.contains(&t)) {
            let t = &self.channels[tacho.unwrap_or(0)].0;
            return Err(ApiError::unprocessable(
                "no-vibration-channel",
                "No channel to diagnose",
                format!(
                    "channel `{t}` is the tachometer: it gives the record's speed and is not \
                     diagnosed, and the record has no other channel {}; send the vibration \
                     channels with it",
                    if wanted.is_some() {
                        "chosen (the `channel` query parameter names the tachometer)"
                    } else {
                        "to diagnose"
                    }
                ),
            )
            .with("tacho_channel", t.as_str()));
        }
        Ok(picked)
    }

    fn select_any(
        &self,
        wanted: Option<&str>,
        machine: Option<&[String]>,
        tacho: Option<usize>,
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
        let vibration = (0..self.channels.len()).filter(|i| Some(*i) != tacho);
        if let Some(list) = machine {
            let picked: Vec<usize> = vibration
                .clone()
                .filter(|i| list.contains(&self.channels[*i].0))
                .collect();
            if picked.is_empty() && self.channels.len() > 1 + usize::from(tacho.is_some()) {
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
        Ok(vibration.collect())
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
        let i = self.select(wanted, None, None)?[0];
        Ok(&self.channels[i].1)
    }
}

/// Decode and validate a record body of `format` (JSON body fields win over the query),
/// the same for every endpoint that takes a record. The channel named `pulses` (the
/// machine's tachometer, when the record has it) is checked as a pulse train
/// ([`crate::record::check_pulses`]): pulses at a supply rail are not a clipped record.
pub fn decode(
    format: BodyFormat,
    q: &RecordQuery,
    bytes: &[u8],
    limits: &crate::configuration::Limits,
    pulses: Option<&str>,
) -> ApiResult<Decoded> {
    let mut shaft = parse_number("shaft_hz", &q.shaft_hz)?;
    let mut recorded_at = q.recorded_at.clone();
    let mut sensor = q.sensor.clone();
    let mut load = q.load.as_deref().and_then(Load::parse);
    let mut record_id = None;
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
            if r.load.is_some() {
                load = r.load.take();
            }
            record_id = r.record_id.take();
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
        f => decode_binary(
            f,
            bytes,
            parse_number("sample_rate_hz", &q.sample_rate_hz)?,
            pulses,
        )?,
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
    if let Some(Load::Label(l)) = &load
        && l.chars().count() > MAX_LOAD_LABEL
    {
        return Err(ApiError::bad_request(
            "invalid-load",
            "Invalid load",
            format!(
                "`load` is a number or a label of at most {MAX_LOAD_LABEL} characters (such as \
                 `high` or `75 %`), got a label of {} characters",
                l.chars().count()
            ),
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
            let r = if pulses == Some(name.as_str()) {
                crate::record::check_pulses(x)
            } else {
                crate::record::check_signal(x)
            };
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
        load,
        record_id,
    })
}

/// The record's channels from its stored f32 samples (one after another in the order of its
/// channel names; a single channel is `"0"`).
pub fn stored_channels(rec: &crate::store::NewRecord, bytes: &[u8]) -> Vec<(String, Vec<f64>)> {
    let names = rec.channels.clone().unwrap_or_else(|| vec!["0".into()]);
    let n = rec.sample_count.max(0) as usize;
    let all: Vec<f64> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64)
        .collect();
    names
        .into_iter()
        .enumerate()
        .map(|(i, name)| {
            let lo = (i * n).min(all.len());
            let hi = ((i + 1) * n).min(all.len());
            (name, all[lo..hi].to_vec())
        })
        .collect()
}
