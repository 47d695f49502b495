//! RIFF/WAVE records: reading PCM and float channels, and encoding them.

use super::channels::{channel_key, find_channel, index_names};
use super::{Channel, Column, MultiRecord, ReadOptions, Record, Voice, fmt_err};
use crate::error::Result;

fn u16_at(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(i..i + 2)?.try_into().ok()?))
}
fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?))
}

/// A RIFF/WAVE file's layout: interleaved frames of `channels` samples of `bytes_per` bytes.
struct Wav<'a> {
    channels: usize,
    /// The header's sample rate (Hz; 0 if it says 0).
    rate: u32,
    bytes_per: usize,
    decode: fn(&[u8]) -> f64,
    data: &'a [u8],
}

impl Wav<'_> {
    /// Refuse a data chunk that is not a whole number of frames.
    fn check_frames(&self, origin: &str) -> Result<()> {
        let frame = self.bytes_per * self.channels;
        if !self.data.len().is_multiple_of(frame) {
            return Err(fmt_err(
                origin,
                format!(
                    "truncated: {} data bytes is not a whole number of {frame}-byte frames",
                    self.data.len()
                ),
            ));
        }
        Ok(())
    }

    /// The samples of channel `ch` (< `channels`; frames checked).
    fn channel(&self, ch: usize) -> Vec<f64> {
        let b = self.bytes_per;
        self.data
            .chunks_exact(b * self.channels)
            .map(|f| (self.decode)(&f[ch * b..(ch + 1) * b]))
            .collect()
    }

    fn sample_rate(&self, given: Option<f64>, origin: &str, voice: Voice) -> Result<f64> {
        match given {
            Some(fs) => Ok(fs),
            None if self.rate > 0 => Ok(self.rate as f64),
            None => Err(fmt_err(
                origin,
                format!("the header's sample rate is 0; {}", voice.give_rate()),
            )),
        }
    }
}

/// Read a RIFF/WAVE header (`fmt ` and `data` chunks, any order, other chunks skipped).
fn wav_layout<'a>(bytes: &'a [u8], origin: &str) -> Result<Wav<'a>> {
    let e = |r: String| fmt_err(origin, r);
    if bytes.len() < 12 || &bytes[0..4] != b"RIFF" || &bytes[8..12] != b"WAVE" {
        return Err(e("not a RIFF/WAVE file".into()));
    }
    let mut pos = 12usize;
    let mut fmt: Option<(u16, u16, u32, u16)> = None; // tag, channels, rate, bits
    let mut data: Option<&[u8]> = None;
    while pos + 8 <= bytes.len() {
        let id = &bytes[pos..pos + 4];
        let size = u32_at(bytes, pos + 4).unwrap_or(0) as usize;
        let body_start = pos + 8;
        let body_end = body_start.saturating_add(size);
        if id == b"data" {
            if body_end > bytes.len() {
                return Err(e(format!(
                    "truncated: the data chunk declares {size} bytes, {} are present",
                    bytes.len() - body_start
                )));
            }
            data = Some(&bytes[body_start..body_end]);
        } else if id == b"fmt " {
            if size < 16 || body_end > bytes.len() {
                return Err(e("truncated or malformed fmt chunk".into()));
            }
            let mut tag = u16_at(bytes, body_start).unwrap_or(0);
            let channels = u16_at(bytes, body_start + 2).unwrap_or(0);
            let rate = u32_at(bytes, body_start + 4).unwrap_or(0);
            let bits = u16_at(bytes, body_start + 14).unwrap_or(0);
            if tag == 0xFFFE {
                // WAVE_FORMAT_EXTENSIBLE: the sub-format GUID starts with the real tag.
                tag = u16_at(bytes, body_start + 24)
                    .ok_or_else(|| e("truncated WAVE_FORMAT_EXTENSIBLE fmt chunk".into()))?;
            }
            fmt = Some((tag, channels, rate, bits));
        }
        if body_end >= bytes.len() {
            break;
        }
        pos = body_end + (size & 1); // chunks are padded to even sizes
    }
    let (tag, channels, rate, bits) = fmt.ok_or_else(|| e("no fmt chunk (truncated?)".into()))?;
    let data = data.ok_or_else(|| e("no data chunk (truncated?)".into()))?;
    if channels == 0 {
        return Err(e("fmt chunk declares 0 channels".into()));
    }
    let decode: fn(&[u8]) -> f64 = match (tag, bits) {
        (1, 8) => |c| (c[0] as f64 - 128.0) / 128.0,
        (1, 16) => |c| i16::from_le_bytes([c[0], c[1]]) as f64 / 32768.0,
        (1, 24) => |c| {
            let v = i32::from_le_bytes([0, c[0], c[1], c[2]]) >> 8;
            v as f64 / 8_388_608.0
        },
        (1, 32) => |c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64 / 2_147_483_648.0,
        (3, 32) => |c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
        (3, 64) => |c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
        _ => {
            return Err(e(format!(
                "unsupported WAV encoding: format tag {tag}, {bits} bits (supported: PCM \
                 8/16/24/32-bit integer, IEEE float 32/64-bit)"
            )));
        }
    };
    Ok(Wav {
        channels: channels as usize,
        rate,
        bytes_per: (bits as usize).div_ceil(8),
        decode,
        data,
    })
}

pub(super) fn parse_wav(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
    let w = wav_layout(bytes, origin)?;
    let ch = match &opts.column {
        None => 0,
        Some(Column::Index(i)) => *i,
        Some(Column::Name(n)) => {
            return Err(fmt_err(
                origin,
                format!("WAV channels have no names (`{n}`); give a channel index"),
            ));
        }
    };
    if ch >= w.channels {
        return Err(fmt_err(
            origin,
            format!(
                "channel {ch} requested, the file has {} (0-based)",
                w.channels
            ),
        ));
    }
    w.check_frames(origin)?;
    Ok(Record {
        samples: w.channel(ch),
        sample_rate: w.sample_rate(opts.sample_rate, origin, Voice::Cli)?,
    })
}

pub(super) fn wav_channels(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<MultiRecord> {
    let w = wav_layout(bytes, origin)?;
    let names = index_names(w.channels);
    let chosen: Vec<usize> = match &opts.column {
        None => (0..w.channels).collect(),
        Some(c) => vec![find_channel(&names[..], &channel_key(c))?],
    };
    w.check_frames(origin)?;
    let sample_rate = w.sample_rate(opts.sample_rate, origin, Voice::Neutral)?;
    Ok(MultiRecord {
        sample_rate,
        channels: chosen
            .into_iter()
            .map(|ch| Channel {
                name: names[ch].clone(),
                samples: w.channel(ch),
            })
            .collect(),
    })
}

/// Encode samples as a mono WAV file (PCM 16-bit when `float` is false, else 32-bit float);
/// samples are clipped to `[−1, 1]` for PCM. For tests and for exporting simulated records.
pub fn encode_wav(samples: &[f64], sample_rate: u32, float: bool) -> Vec<u8> {
    encode_wav_channels(&[samples], sample_rate, float)
}

/// Encode channels as one WAV file, frames interleaved (channel *i* is what
/// [`parse_record_channels`] names `"i"`); otherwise as [`encode_wav`].
///
/// # Panics
/// If `channels` is empty or the channels differ in length.
pub fn encode_wav_channels(channels: &[&[f64]], sample_rate: u32, float: bool) -> Vec<u8> {
    assert!(
        !channels.is_empty(),
        "a WAV file needs at least one channel"
    );
    let frames = channels[0].len();
    assert!(
        channels.iter().all(|c| c.len() == frames),
        "every channel of a WAV file has the same length"
    );
    let (tag, bits): (u16, u16) = if float { (3, 32) } else { (1, 16) };
    let n_ch = channels.len() as u32;
    let bytes_per = bits as u32 / 8;
    let data_len = frames as u32 * n_ch * bytes_per;
    let mut b = Vec::with_capacity(44 + data_len as usize);
    b.extend_from_slice(b"RIFF");
    b.extend_from_slice(&(36 + data_len).to_le_bytes());
    b.extend_from_slice(b"WAVEfmt ");
    b.extend_from_slice(&16u32.to_le_bytes());
    b.extend_from_slice(&tag.to_le_bytes());
    b.extend_from_slice(&(n_ch as u16).to_le_bytes());
    b.extend_from_slice(&sample_rate.to_le_bytes());
    b.extend_from_slice(&(sample_rate * n_ch * bytes_per).to_le_bytes());
    b.extend_from_slice(&((n_ch * bytes_per) as u16).to_le_bytes());
    b.extend_from_slice(&bits.to_le_bytes());
    b.extend_from_slice(b"data");
    b.extend_from_slice(&data_len.to_le_bytes());
    for k in 0..frames {
        for c in channels {
            let s = c[k];
            if float {
                b.extend_from_slice(&(s as f32).to_le_bytes());
            } else {
                let v = (s.clamp(-1.0, 1.0) * 32767.0).round() as i16;
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    b
}
