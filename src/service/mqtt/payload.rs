//! An MQTT payload: the record formats of the HTTP endpoint, told apart by their first bytes,
//! and an optional header that carries what HTTP puts in the query string.
//!
//! * JSON (first non-blank byte `{`): the HTTP body (`JsonRecord`), plus an optional
//!   `"record_id"` member;
//! * WAV (`RIFF….WAVE`): as over HTTP; the sample rate is in the file;
//! * the header, then f32 or WAV: bytes 0–3 `GWR1`, bytes 4–5 the header's length `n`
//!   (unsigned 16-bit, little-endian), then `n` bytes of UTF-8 text in the form of the HTTP
//!   query string (`sample_rate_hz=25600&record_id=r-42&shaft_hz=30`; every query parameter
//!   of `POST /v1/machines/{id}/records` plus `record_id`), then the record: little-endian f32
//!   samples (one channel; `sample_rate_hz` is then required) or a WAV file.

use sha2::{Digest, Sha256};

use super::super::error::ApiError;
use super::super::wire::BodyFormat;

/// The header's magic bytes.
pub const HEADER_MAGIC: &[u8; 4] = b"GWR1";

/// Longest record id.
pub const MAX_RECORD_ID: usize = 255;

/// A payload split into its format, its header (query-string text) and its record bytes.
#[derive(Debug)]
pub struct Payload<'a> {
    pub format: BodyFormat,
    /// The header's text, when there is one.
    pub query: Option<&'a str>,
    /// The record: the whole payload, or what follows the header.
    pub body: &'a [u8],
    /// The header's `record_id`.
    pub record_id: Option<String>,
}

fn bad_payload(detail: impl Into<String>) -> ApiError {
    ApiError::bad_request("invalid-mqtt-payload", "Unreadable MQTT payload", detail)
}

fn is_wav(b: &[u8]) -> bool {
    b.len() >= 12 && &b[..4] == b"RIFF" && &b[8..12] == b"WAVE"
}

/// Tell the payload's format and split off its header.
pub fn split(payload: &[u8]) -> Result<Payload<'_>, ApiError> {
    if let Some(rest) = payload.strip_prefix(HEADER_MAGIC) {
        if rest.len() < 2 {
            return Err(bad_payload(
                "the GWR1 header is cut short: no length after the magic",
            ));
        }
        let n = u16::from_le_bytes([rest[0], rest[1]]) as usize;
        let Some(text) = rest.get(2..2 + n) else {
            return Err(bad_payload(format!(
                "the GWR1 header says it is {n} bytes long but the payload ends before"
            )));
        };
        let text = std::str::from_utf8(text)
            .map_err(|_| bad_payload("the GWR1 header is not UTF-8 text"))?;
        let body = &rest[2 + n..];
        let pairs: Vec<(String, String)> = serde_urlencoded::from_str(text)
            .map_err(|e| bad_payload(format!("the GWR1 header is not a query string: {e}")))?;
        let record_id = pairs
            .into_iter()
            .find(|(k, _)| k == "record_id")
            .map(|p| p.1);
        let format = if is_wav(body) {
            BodyFormat::Wav
        } else {
            BodyFormat::F32
        };
        return Ok(Payload {
            format,
            query: Some(text),
            body,
            record_id,
        });
    }
    let format = if is_wav(payload) {
        BodyFormat::Wav
    } else if payload.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{') {
        BodyFormat::Json
    } else {
        return Err(bad_payload(
            "the payload is neither a JSON record, nor a WAV file, nor a record after a GWR1 \
             header; raw f32 samples need the header, which carries `sample_rate_hz` (see \
             docs/service.md, MQTT ingest)",
        ));
    };
    Ok(Payload {
        format,
        query: None,
        body: payload,
        record_id: None,
    })
}

/// The id a record is de-duplicated by: the one it carries (header or JSON member), else
/// `sha256:` and the payload's SHA-256 (a redelivery is the same bytes).
pub fn record_id(carried: Option<String>, payload: &[u8]) -> Result<String, ApiError> {
    match carried {
        Some(id) if (1..=MAX_RECORD_ID).contains(&id.len()) => Ok(id),
        Some(_) => Err(bad_payload(format!(
            "`record_id` is 1 to {MAX_RECORD_ID} bytes"
        ))),
        None => Ok(format!("sha256:{}", hex::encode(Sha256::digest(payload)))),
    }
}

/// A payload of little-endian f32 `samples` after a GWR1 header of `query` (what a
/// publisher sends; the tests use it).
pub fn with_header(query: &str, samples: &[f32]) -> Vec<u8> {
    let mut v = Vec::with_capacity(6 + query.len() + 4 * samples.len());
    v.extend_from_slice(HEADER_MAGIC);
    v.extend_from_slice(&(query.len() as u16).to_le_bytes());
    v.extend_from_slice(query.as_bytes());
    for s in samples {
        v.extend_from_slice(&s.to_le_bytes());
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_are_told_apart() {
        let p = with_header("sample_rate_hz=100&record_id=r1", &[1.0, 2.0]);
        let s = split(&p).unwrap();
        assert_eq!(s.format, BodyFormat::F32);
        assert_eq!(s.record_id.as_deref(), Some("r1"));
        assert_eq!(s.query, Some("sample_rate_hz=100&record_id=r1"));
        assert_eq!(s.body.len(), 8);
        assert_eq!(split(b"  {\"a\":1}").unwrap().format, BodyFormat::Json);
        assert_eq!(
            split(b"RIFF\0\0\0\0WAVEfmt ").unwrap().format,
            BodyFormat::Wav
        );
        for bad in [&b"\x00\x01\x02\x03"[..], b"GWR1", b"GWR1\x09\x00abc"] {
            let e = split(bad).unwrap_err();
            assert_eq!(e.slug, "invalid-mqtt-payload", "{}", e.detail);
        }
    }

    #[test]
    fn a_record_without_an_id_is_named_by_its_bytes() {
        let a = record_id(None, b"x").unwrap();
        assert_eq!(a, record_id(None, b"x").unwrap());
        assert_ne!(a, record_id(None, b"y").unwrap());
        assert_eq!(record_id(Some("k".into()), b"x").unwrap(), "k");
        assert!(record_id(Some(String::new()), b"x").is_err());
    }
}
