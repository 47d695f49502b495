//! HTTP plumbing shared by the handlers: reading (and refusing) bodies, undoing a
//! `Content-Encoding`, naming the body format, JSON answers (with an ETag for reads) and the id
//! rules of the paths.

use axum::body::Body;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::error::{ApiError, ApiResult, problem_from_error};
use super::wire::BodyFormat;

pub use crate::machine::is_valid_id;

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

/// A gearbox id: like a machine id.
pub fn check_gearbox_id(id: &str) -> ApiResult<()> {
    if is_valid_id(id) {
        Ok(())
    } else {
        Err(ApiError::bad_request(
            "invalid-gearbox-id",
            "Invalid gearbox id",
            "a gearbox id is 1 to 64 characters of letters, digits, `.`, `_` and `-`",
        )
        .with("gearbox_id", id))
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

/// JSON with a strong ETag over the body; 304 when `If-None-Match` matches.
pub fn json_with_etag(headers: &HeaderMap, body: &Value) -> Response {
    let text = body.to_string();
    let tag = format!(
        "\"{}\"",
        &hex::encode(Sha256::digest(text.as_bytes()))[..32]
    );
    let matches = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == tag || t.trim() == "*"));
    let mut r = if matches {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        let mut r = (StatusCode::OK, text).into_response();
        r.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        );
        r
    };
    if let Ok(v) = HeaderValue::from_str(&tag) {
        r.headers_mut().insert(header::ETAG, v);
    }
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r
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

/// Content sniffing, the safety net under `Content-Type` and `Content-Encoding`: a body whose
/// bytes are gzip (`1f 8b`) is inflated even without `Content-Encoding: gzip`, and a body that
/// starts `RIFF….WAVE` is read as WAV whatever the `Content-Type` says, so neither is decoded
/// as the wrong format. Returns the format to decode, the bytes, and a sentence per assumption
/// for the answer's warnings.
pub fn sniffed(
    format: BodyFormat,
    bytes: bytes_::Bytes,
    limit: usize,
) -> ApiResult<(BodyFormat, bytes_::Bytes, Vec<String>)> {
    let mut notes = Vec::new();
    let mut bytes = bytes;
    if bytes.starts_with(&[0x1f, 0x8b]) {
        let max = limit.saturating_mul(8);
        bytes = crate::record::gunzip(&bytes, "body", max)
            .map(bytes_::Bytes::from)
            .map_err(|e| {
                if e.to_string().contains("expands beyond") {
                    body_too_large(max)
                } else {
                    let mut p = problem_from_error(&e);
                    p.detail = format!(
                        "the body starts with the gzip magic bytes (1f 8b) but could not be \
                         inflated: {}; send the whole gzip file (with `Content-Encoding: gzip`) \
                         or the uncompressed record",
                        p.detail
                    );
                    p
                }
            })?;
        notes.push(
            "the body is gzip-compressed but came without `Content-Encoding: gzip`: it was \
             inflated before decoding (send the header to say so)"
                .to_string(),
        );
    }
    let riff = bytes.len() >= 12 && &bytes[..4] == b"RIFF" && &bytes[8..12] == b"WAVE";
    if riff && format != BodyFormat::Wav {
        notes.push(format!(
            "the body is a WAV file (it starts with RIFF….WAVE) sent as `{}`: it was read as \
             audio/wav (send `Content-Type: audio/wav`)",
            format.mime()
        ));
        return Ok((BodyFormat::Wav, bytes, notes));
    }
    Ok((format, bytes, notes))
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
