//! Gzip-compressed records: decompression with a size limit against "gzip bombs".

use std::io::Read;

use super::fmt_err;
use crate::error::Result;

/// Largest decompressed size [`read_record`] accepts from a `.gz` file: 256 MiB, about three
/// times an 80 s `time,value` CSV at 25.6 kHz (the service's record limit). A stream that
/// expands further (a "gzip bomb") is refused instead of filling memory.
pub const MAX_DECOMPRESSED_BYTES: usize = 256 << 20;

/// Decompress a gzip stream (several concatenated members allowed), refusing more than `limit`
/// output bytes with [`Error::RecordFormat`] ("expands beyond …"): decoding stops one byte
/// past `limit`, so memory stays below about twice `limit` whatever size the stream claims.
/// `origin` names the input in errors.
pub fn gunzip(bytes: &[u8], origin: &str, limit: usize) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    // Read one byte past the limit: reaching it means the stream is longer than allowed.
    flate2::read::MultiGzDecoder::new(bytes)
        .take(limit as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| fmt_err(origin, format!("gzip decompression failed: {e}")))?;
    if out.len() > limit {
        return Err(fmt_err(
            origin,
            format!(
                "the gzip stream expands beyond {limit} bytes (the limit for a compressed \
                 record); decompress it and pass the file itself"
            ),
        ));
    }
    Ok(out)
}
