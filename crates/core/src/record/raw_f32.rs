//! Raw little-endian `f32` records (no header: the sample rate must be given).

use super::channels::{channel_key, find_channel};
use super::{Channel, MultiRecord, ReadOptions, Record, Voice, fmt_err};
use crate::error::Result;

/// Raw little-endian `f32` as `f64`, refusing a length that is not a multiple of 4.
fn f32_samples(bytes: &[u8], origin: &str) -> Result<Vec<f64>> {
    if !bytes.len().is_multiple_of(4) {
        return Err(fmt_err(
            origin,
            format!(
                "{} bytes is not a whole number of 4-byte f32 samples (truncated file?)",
                bytes.len()
            ),
        ));
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
        .collect())
}

pub(super) fn parse_f32(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
    let fs = opts
        .sample_rate
        .ok_or_else(|| Voice::Cli.missing_rate("raw f32 (no header)"))?;
    Ok(Record {
        samples: f32_samples(bytes, origin)?,
        sample_rate: fs,
    })
}

pub(super) fn f32_channels(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<MultiRecord> {
    let sample_rate = opts
        .sample_rate
        .ok_or_else(|| Voice::Neutral.missing_rate("raw f32 (no header)"))?;
    if let Some(c) = &opts.column {
        find_channel(&["0"][..], &channel_key(c))?;
    }
    Ok(MultiRecord {
        sample_rate,
        channels: vec![Channel {
            name: "0".into(),
            samples: f32_samples(bytes, origin)?,
        }],
    })
}
