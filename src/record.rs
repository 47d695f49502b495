//! Measured records and the file formats they come in.
//!
//! | format | layout | sample rate |
//! | --- | --- | --- |
//! | `csv` | one value per line, or `time,value`, or several columns (pick one with `column`); header optional; `,` `;` tab or spaces; `#` comments; gzip when the name ends in `.gz` | `sample_rate`, else from a time column |
//! | `f32` | raw little-endian IEEE-754 `f32`, no header | `sample_rate` (required) |
//! | `wav` | RIFF/WAVE, PCM 8/16/24/32-bit integer or 32/64-bit float (also `WAVE_FORMAT_EXTENSIBLE`), any channel count (pick one with `column`, default 0) | the header (overridden by `sample_rate` if given) |
//!
//! Integer WAV samples are scaled to `[−1, 1)`; the unit does not matter to the diagnosis
//! (every matching feature is gain-invariant). Nothing here panics on malformed input: every
//! problem comes back as [`Error::RecordFormat`] (or [`Error::NonFiniteSample`]) naming the
//! file and what is wrong.

use std::io::Read;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// A sampled record: samples in arbitrary (consistent) units, sample rate in Hz.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub samples: Vec<f64>,
    /// Samples per second.
    pub sample_rate: f64,
}

/// File formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Csv,
    F32,
    Wav,
}

impl Format {
    /// Guess from the file name: `.wav` → WAV, `.f32`/`.raw`/`.bin` → f32, otherwise CSV
    /// (`.gz` is stripped first).
    pub fn from_path(path: &Path) -> Format {
        let name = path
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let name = name.strip_suffix(".gz").unwrap_or(&name);
        if name.ends_with(".wav") {
            Format::Wav
        } else if name.ends_with(".f32") || name.ends_with(".raw") || name.ends_with(".bin") {
            Format::F32
        } else {
            Format::Csv
        }
    }
}

/// Which column (CSV) or channel (WAV) to read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Column {
    /// 0-based index.
    Index(usize),
    /// Header name (CSV only).
    Name(String),
}

impl Column {
    /// `"2"` → index 2, anything else → a name.
    pub fn parse(s: &str) -> Column {
        match s.trim().parse::<usize>() {
            Ok(i) => Column::Index(i),
            Err(_) => Column::Name(s.trim().to_string()),
        }
    }
}

/// How to read a record.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Format; `None`: from the file name ([`Format::from_path`]).
    pub format: Option<Format>,
    /// Sample rate in Hz; overrides a WAV header or a CSV time column.
    pub sample_rate: Option<f64>,
    /// Column / channel; `None`: the only column, the value of `time,value`, channel 0.
    pub column: Option<Column>,
}

fn fmt_err(path: &str, reason: impl Into<String>) -> Error {
    Error::RecordFormat {
        path: path.to_string(),
        reason: reason.into(),
    }
}

/// Read a record file (gzip-compressed when the name ends in `.gz`).
pub fn read_record(path: &Path, opts: &ReadOptions) -> Result<Record> {
    let name = path.display().to_string();
    let mut bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: name.clone(),
        source,
    })?;
    if name.to_ascii_lowercase().ends_with(".gz") {
        bytes = gunzip(&bytes, &name, MAX_DECOMPRESSED_BYTES)?;
    }
    let format = opts.format.unwrap_or_else(|| Format::from_path(path));
    parse_record(&bytes, format, opts, &name)
}

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

/// Highest sample rate a record may claim: 10 MHz, far above any vibration ADC. A larger value
/// is a unit mistake (ns for s, a sample count for a rate), not a measurement.
pub const MAX_SAMPLE_RATE_HZ: f64 = 10e6;

/// Refuse a sample rate that is not a positive finite number of Hz up to
/// [`MAX_SAMPLE_RATE_HZ`], with [`Error::InvalidParameter`] (`"sample rate"`).
pub fn check_sample_rate(fs: f64) -> Result<()> {
    if !(fs.is_finite() && fs > 0.0) {
        return Err(Error::param(
            "sample rate",
            fs,
            "must be a positive number of samples per second",
        ));
    }
    if fs > MAX_SAMPLE_RATE_HZ {
        return Err(Error::param(
            "sample rate",
            fs,
            format!(
                "is above {MAX_SAMPLE_RATE_HZ:e} Hz, beyond any vibration ADC; give the rate in \
                 samples per second"
            ),
        ));
    }
    Ok(())
}

/// Smallest number of samples at one extreme that can count as clipping, as a fraction of the
/// record (0.1 %; at least [`CLIP_MIN_COUNT`]).
pub const CLIP_MIN_FRACTION: f64 = 1e-3;
/// Smallest number of samples at one extreme that can count as clipping.
pub const CLIP_MIN_COUNT: usize = 8;
/// Shortest run of consecutive samples at the extreme that counts as a saturated plateau.
pub const CLIP_MIN_RUN: usize = 3;
/// How many times more samples the extreme value must hold than the nearest value inside it.
pub const CLIP_PILE_UP: usize = 4;

/// Refuse a record whose samples cannot be a vibration measurement: empty
/// ([`Error::EmptyRecord`]), NaN or ±∞ ([`Error::NonFiniteSample`]), all one value
/// ([`Error::FlatRecord`]) or clipped ([`Error::ClippedRecord`]).
///
/// Clipping: a saturated sensor or ADC writes its limit value for as long as the signal stays
/// beyond it, so the record's maximum (or minimum) value is *exactly* repeated, in plateaus,
/// far more often than any value just inside it. The rule, per extreme: at least
/// max([`CLIP_MIN_COUNT`], [`CLIP_MIN_FRACTION`]·n) samples equal to it, a run of at least
/// [`CLIP_MIN_RUN`] consecutive ones, and at least [`CLIP_PILE_UP`] times as many as the
/// nearest value inside. An unclipped continuous record holds its extreme once; a quantised
/// unclipped sine holds its top ADC code at most ≈ 2.4 times as often as the next code (the
/// arcsine density near a peak), so neither trips the rule. Checked on the SpectraQuest
/// records (`shared/data`): every channel holds its extremes once.
pub fn check_signal(x: &[f64]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::EmptyRecord);
    }
    // Branch-free passes (they vectorise): extremes with NaN/∞ folded in, then counts at the
    // extremes; the detailed look only when a count is large enough to matter.
    let (mut hi, mut lo, mut finite) = (f64::NEG_INFINITY, f64::INFINITY, true);
    for &v in x {
        hi = hi.max(v);
        lo = lo.min(v);
        finite &= v.is_finite();
    }
    if !finite {
        let (index, &value) = x
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
            .expect("a non-finite sample exists");
        return Err(Error::NonFiniteSample { index, value });
    }
    if x.len() < 2 {
        return Ok(());
    }
    if hi == lo {
        return Err(Error::FlatRecord {
            samples: x.len(),
            value: hi,
        });
    }
    let (n_hi, n_lo) = x.iter().fold((0usize, 0usize), |(h, l), &v| {
        (h + usize::from(v == hi), l + usize::from(v == lo))
    });
    let need = CLIP_MIN_COUNT.max((CLIP_MIN_FRACTION * x.len() as f64).ceil() as usize);
    for (side, level, count) in [("maximum", hi, n_hi), ("minimum", lo, n_lo)] {
        if count < need {
            continue;
        }
        let (mut run, mut longest) = (0usize, 0usize);
        // The nearest value inside the extreme and how often it occurs.
        let mut next = f64::NAN;
        let mut next_count = 0usize;
        for &v in x {
            if v == level {
                run += 1;
                longest = longest.max(run);
            } else {
                run = 0;
                let closer = next.is_nan() || if level == hi { v > next } else { v < next };
                if closer {
                    next = v;
                    next_count = 1;
                } else if v == next {
                    next_count += 1;
                }
            }
        }
        if longest >= CLIP_MIN_RUN && count >= CLIP_PILE_UP * next_count {
            return Err(Error::ClippedRecord {
                side,
                level,
                count,
                percent: 100.0 * count as f64 / x.len() as f64,
                longest_run: longest,
            });
        }
    }
    Ok(())
}

/// Parse a record from bytes (already decompressed); `origin` names it in errors.
pub fn parse_record(
    bytes: &[u8],
    format: Format,
    opts: &ReadOptions,
    origin: &str,
) -> Result<Record> {
    if let Some(fs) = opts.sample_rate {
        check_sample_rate(fs)?;
    }
    let rec = match format {
        Format::Csv => parse_csv(bytes, opts, origin)?,
        Format::F32 => parse_f32(bytes, opts, origin)?,
        Format::Wav => parse_wav(bytes, opts, origin)?,
    };
    // A CSV time column or a WAV header states its own rate: the same bounds apply.
    check_sample_rate(rec.sample_rate)?;
    check_signal(&rec.samples)?;
    Ok(rec)
}

fn split_fields(line: &str) -> Vec<&str> {
    let sep: &[char] = if line.contains(',') {
        &[',']
    } else if line.contains(';') {
        &[';']
    } else if line.contains('\t') {
        &['\t']
    } else {
        &[' ']
    };
    line.split(sep)
        .map(|f| f.trim().trim_matches('"'))
        .filter(|f| !(sep == [' '] && f.is_empty()))
        .collect()
}

fn parse_number(s: &str) -> Option<f64> {
    // Accept "nan"/"inf" as numbers so that they are reported as non-finite samples, not as a
    // header.
    s.parse::<f64>().ok()
}

fn parse_csv(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| fmt_err(origin, format!("not UTF-8 text ({e}); wrong --format?")))?;
    let mut header: Option<Vec<String>> = None;
    // All numbers row after row, `width` per row: 8 bytes a number in one allocation, not a
    // `Vec` per row (a heap block plus a 24-byte header for every line, many times the 2 bytes
    // of a one-column line; see docs/reliability/fuzzing.md).
    let mut cells: Vec<f64> = Vec::new();
    let mut n_rows = 0usize;
    let mut width = 0usize;
    for (lineno, raw) in text.lines().enumerate() {
        let line = raw.trim().trim_start_matches('\u{feff}');
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields = split_fields(line);
        if fields.is_empty() {
            // Nothing but quotes and spaces (`"`): no field, like a blank line. Taken as a row
            // of width 0 it let the next line set the width, and indexing it panicked.
            continue;
        }
        let nums: Vec<Option<f64>> = fields.iter().map(|f| parse_number(f)).collect();
        if n_rows == 0 && header.is_none() && nums.iter().any(|v| v.is_none()) {
            header = Some(fields.iter().map(|s| s.to_string()).collect());
            width = fields.len();
            continue;
        }
        if width == 0 {
            width = fields.len();
        }
        if fields.len() != width {
            return Err(fmt_err(
                origin,
                format!(
                    "line {}: {} fields, expected {width} (as on the first line)",
                    lineno + 1,
                    fields.len()
                ),
            ));
        }
        for (f, v) in fields.iter().zip(nums) {
            match v {
                Some(v) => cells.push(v),
                None => {
                    return Err(fmt_err(
                        origin,
                        format!("line {}: `{f}` is not a number", lineno + 1),
                    ));
                }
            }
        }
        n_rows += 1;
    }
    if n_rows == 0 {
        // Empty, or only a header and comments: a record without samples, not a format error.
        return Err(Error::EmptyRecord);
    }
    let names = header.clone().unwrap_or_default();
    let is_time = |s: &str| {
        let s = s.to_ascii_lowercase();
        s == "t" || s.starts_with("time") || s == "t_s" || s == "seconds"
    };
    let time_col = if width == 2 {
        Some(0)
    } else {
        names.iter().position(|n| is_time(n))
    };
    let value_col = match &opts.column {
        Some(Column::Index(i)) => {
            if *i >= width {
                return Err(fmt_err(
                    origin,
                    format!("column {i} requested, the file has {width} (0-based indices)"),
                ));
            }
            *i
        }
        Some(Column::Name(n)) => names.iter().position(|h| h == n).ok_or_else(|| {
            fmt_err(
                origin,
                if names.is_empty() {
                    format!("column `{n}` requested but the file has no header; use an index")
                } else {
                    format!("no column `{n}`; the header has: {}", names.join(", "))
                },
            )
        })?,
        None => match width {
            1 => 0,
            2 => 1,
            _ => {
                return Err(fmt_err(
                    origin,
                    format!(
                        "{width} columns{}: choose one with --column (index from 0 or a name)",
                        if names.is_empty() {
                            String::new()
                        } else {
                            format!(" ({})", names.join(", "))
                        }
                    ),
                ));
            }
        },
    };
    let at = |k: usize, c: usize| cells[k * width + c];
    let samples: Vec<f64> = (0..n_rows).map(|k| at(k, value_col)).collect();
    let sample_rate = match opts.sample_rate {
        Some(fs) => fs,
        None => match time_col.filter(|&t| t != value_col) {
            Some(t) if n_rows >= 2 => {
                let t0 = at(0, t);
                let t1 = at(n_rows - 1, t);
                let dt = (t1 - t0) / (n_rows - 1) as f64;
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "the time column does not increase ({t0} … {t1}); give --sample-rate"
                        ),
                    ));
                }
                // Uniform sampling check: every step within 1 % of the mean step.
                if let Some(k) =
                    (1..n_rows).find(|&k| ((at(k, t) - at(k - 1, t)) - dt).abs() > 0.01 * dt)
                {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "non-uniform time column at row {k}: step {} vs mean {dt}; \
                             resample or give --sample-rate",
                            at(k, t) - at(k - 1, t)
                        ),
                    ));
                }
                // A step below 1/f64::MAX (e.g. 5e-324 s) is positive but has no finite rate.
                let rate = 1.0 / dt;
                if !rate.is_finite() {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "the time column's step {dt} s gives no finite sample rate; \
                             give --sample-rate"
                        ),
                    ));
                }
                rate
            }
            _ => {
                return Err(Error::MissingSampleRate {
                    format: "a CSV without a time column",
                });
            }
        },
    };
    Ok(Record {
        samples,
        sample_rate,
    })
}

fn parse_f32(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
    let fs = opts.sample_rate.ok_or(Error::MissingSampleRate {
        format: "raw f32 (no header)",
    })?;
    if !bytes.len().is_multiple_of(4) {
        return Err(fmt_err(
            origin,
            format!(
                "{} bytes is not a whole number of 4-byte f32 samples (truncated file?)",
                bytes.len()
            ),
        ));
    }
    Ok(Record {
        samples: bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .collect(),
        sample_rate: fs,
    })
}

fn u16_at(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(i..i + 2)?.try_into().ok()?))
}
fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?))
}

fn parse_wav(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
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
    let bytes_per = (bits as usize).div_ceil(8);
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
    let ch = match &opts.column {
        None => 0,
        Some(Column::Index(i)) => *i,
        Some(Column::Name(n)) => {
            return Err(e(format!(
                "WAV channels have no names (`{n}`); give a channel index"
            )));
        }
    };
    if ch >= channels as usize {
        return Err(e(format!(
            "channel {ch} requested, the file has {channels} (0-based)"
        )));
    }
    let frame = bytes_per * channels as usize;
    if data.len() % frame != 0 {
        return Err(e(format!(
            "truncated: {} data bytes is not a whole number of {frame}-byte frames",
            data.len()
        )));
    }
    let samples = data
        .chunks_exact(frame)
        .map(|f| decode(&f[ch * bytes_per..(ch + 1) * bytes_per]))
        .collect();
    let sample_rate = match opts.sample_rate {
        Some(fs) => fs,
        None if rate > 0 => rate as f64,
        None => return Err(e("the header's sample rate is 0; give --sample-rate".into())),
    };
    Ok(Record {
        samples,
        sample_rate,
    })
}

/// Encode samples as a mono WAV file (PCM 16-bit when `float` is false, else 32-bit float);
/// samples are clipped to `[−1, 1]` for PCM. For tests and for exporting simulated records.
pub fn encode_wav(samples: &[f64], sample_rate: u32, float: bool) -> Vec<u8> {
    let (tag, bits): (u16, u16) = if float { (3, 32) } else { (1, 16) };
    let bytes_per = bits as u32 / 8;
    let data_len = samples.len() as u32 * bytes_per;
    let mut b = Vec::with_capacity(44 + data_len as usize);
    b.extend_from_slice(b"RIFF");
    b.extend_from_slice(&(36 + data_len).to_le_bytes());
    b.extend_from_slice(b"WAVEfmt ");
    b.extend_from_slice(&16u32.to_le_bytes());
    b.extend_from_slice(&tag.to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&sample_rate.to_le_bytes());
    b.extend_from_slice(&(sample_rate * bytes_per).to_le_bytes());
    b.extend_from_slice(&(bytes_per as u16).to_le_bytes());
    b.extend_from_slice(&bits.to_le_bytes());
    b.extend_from_slice(b"data");
    b.extend_from_slice(&data_len.to_le_bytes());
    for &s in samples {
        if float {
            b.extend_from_slice(&(s as f32).to_le_bytes());
        } else {
            let v = (s.clamp(-1.0, 1.0) * 32767.0).round() as i16;
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine(n: usize, per_period: f64, amp: f64) -> Vec<f64> {
        (0..n)
            .map(|i| amp * (std::f64::consts::TAU * i as f64 / per_period + 0.3).sin())
            .collect()
    }

    #[test]
    fn check_signal_refuses_empty_nan_flat_and_clipped() {
        assert!(matches!(check_signal(&[]), Err(Error::EmptyRecord)));
        assert!(matches!(
            check_signal(&[1.0, f64::NAN, 2.0]),
            Err(Error::NonFiniteSample { index: 1, .. })
        ));
        assert!(matches!(
            check_signal(&[0.0, 1.0, f64::NEG_INFINITY]),
            Err(Error::NonFiniteSample { index: 2, .. })
        ));
        assert!(matches!(
            check_signal(&[0.0; 1000]),
            Err(Error::FlatRecord { samples: 1000, .. })
        ));
        // One sample is not flat: the estimator says it is too short.
        assert!(check_signal(&[0.5]).is_ok());
        // A sine of amplitude 1.6 through an ADC whose range ends at ±1.
        let clipped: Vec<f64> = sine(25_600, 29.4, 1.6)
            .iter()
            .map(|v| v.clamp(-1.0, 1.0))
            .collect();
        match check_signal(&clipped) {
            Err(Error::ClippedRecord {
                side,
                level,
                longest_run,
                ..
            }) => {
                assert_eq!((side, level), ("maximum", 1.0));
                assert!(longest_run >= 5, "{longest_run}");
            }
            other => panic!("clipped sine passed: {other:?}"),
        }
        // Only the bottom saturates.
        let bottom: Vec<f64> = sine(25_600, 29.4, 1.0)
            .iter()
            .map(|v| v.max(-0.8))
            .collect();
        assert!(matches!(
            check_signal(&bottom),
            Err(Error::ClippedRecord {
                side: "minimum",
                ..
            })
        ));
    }

    #[test]
    fn check_signal_accepts_unclipped_records_even_coarsely_quantised() {
        // Continuous values: every extreme occurs once.
        assert!(check_signal(&sine(25_600, 29.4, 1.6)).is_ok());
        // A slow sine on an 8-bit ADC using its whole range: the top code is held for several
        // samples at each peak, but no more often than the codes just below (no pile-up).
        for per_period in [29.4, 200.0, 1000.0] {
            let q: Vec<f64> = sine(25_600, per_period, 127.0)
                .iter()
                .map(|v| v.round())
                .collect();
            assert!(
                check_signal(&q).is_ok(),
                "8-bit sine, {per_period} samples/period"
            );
        }
        // Plus noise, 16-bit.
        let mut state = 7u64;
        let noisy: Vec<f64> = sine(25_600, 29.4, 20_000.0)
            .iter()
            .map(|v| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (v + ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2000.0).round()
            })
            .collect();
        assert!(check_signal(&noisy).is_ok());
    }

    #[test]
    fn sample_rates_beyond_any_adc_are_refused() {
        assert!(check_sample_rate(25_600.0).is_ok());
        assert!(check_sample_rate(MAX_SAMPLE_RATE_HZ).is_ok());
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e12] {
            assert!(
                matches!(check_sample_rate(bad), Err(Error::InvalidParameter { .. })),
                "{bad}"
            );
        }
    }

    fn opts(fs: Option<f64>, col: Option<&str>) -> ReadOptions {
        ReadOptions {
            format: None,
            sample_rate: fs,
            column: col.map(Column::parse),
        }
    }

    #[test]
    fn csv_variants() {
        let r = parse_record(b"1\n2\n3\n", Format::Csv, &opts(Some(10.0), None), "t").unwrap();
        assert_eq!(r.samples, vec![1.0, 2.0, 3.0]);
        let r = parse_record(
            b"time,acc\n0,1\n0.5,2\n1.0,3\n",
            Format::Csv,
            &opts(None, None),
            "t",
        )
        .unwrap();
        assert_eq!(r.samples, vec![1.0, 2.0, 3.0]);
        assert!((r.sample_rate - 2.0).abs() < 1e-12);
        let r = parse_record(
            b"a1,a2,a3\n1,2,3\n4,5,6\n",
            Format::Csv,
            &opts(Some(1.0), Some("a2")),
            "t",
        )
        .unwrap();
        assert_eq!(r.samples, vec![2.0, 5.0]);
        let r = parse_record(
            b"1;2;3\n4;5;6\n",
            Format::Csv,
            &opts(Some(1.0), Some("2")),
            "t",
        )
        .unwrap();
        assert_eq!(r.samples, vec![3.0, 6.0]);
        assert!(parse_record(b"1,2,3\n", Format::Csv, &opts(Some(1.0), None), "t").is_err());
        assert!(parse_record(b"1\n2\n", Format::Csv, &opts(None, None), "t").is_err());
        assert!(parse_record(b"", Format::Csv, &opts(Some(1.0), None), "t").is_err());
        assert!(matches!(
            parse_record(b"1\nnan\n", Format::Csv, &opts(Some(1.0), None), "t"),
            Err(Error::NonFiniteSample { index: 1, .. })
        ));
    }

    #[test]
    fn f32_and_wav() {
        let x: Vec<f64> = (0..100).map(|i| (i as f64 * 0.1).sin() * 0.5).collect();
        let raw: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
        let r = parse_record(&raw, Format::F32, &opts(Some(100.0), None), "t").unwrap();
        assert!((r.samples[7] - x[7]).abs() < 1e-6);
        assert!(
            parse_record(
                &raw[..raw.len() - 1],
                Format::F32,
                &opts(Some(1.0), None),
                "t"
            )
            .is_err()
        );
        assert!(parse_record(&raw, Format::F32, &opts(None, None), "t").is_err());
        for float in [false, true] {
            let w = encode_wav(&x, 8000, float);
            let r = parse_record(&w, Format::Wav, &opts(None, None), "t").unwrap();
            assert_eq!(r.sample_rate, 8000.0);
            assert_eq!(r.samples.len(), x.len());
            assert!((r.samples[7] - x[7]).abs() < 1e-4);
            assert!(parse_record(&w[..w.len() - 3], Format::Wav, &opts(None, None), "t").is_err());
            assert!(parse_record(&w[..30], Format::Wav, &opts(None, None), "t").is_err());
        }
    }

    /// A gzip member of `n` zero bytes (compresses about 1000:1).
    fn gz_zeros(n: usize) -> Vec<u8> {
        use flate2::{Compression, write::GzEncoder};
        use std::io::Write;
        let mut enc = GzEncoder::new(Vec::new(), Compression::best());
        enc.write_all(&vec![0u8; n]).unwrap();
        enc.finish().unwrap()
    }

    #[test]
    fn gunzip_refuses_a_stream_beyond_its_limit() {
        let gz = gz_zeros(10_000);
        assert_eq!(gunzip(&gz, "t.gz", 10_000).unwrap().len(), 10_000);
        let e = gunzip(&gz, "t.gz", 9_999).unwrap_err().to_string();
        assert!(e.contains("expands beyond 9999 bytes"), "{e}");
        // Concatenated members count together.
        let two = [gz.clone(), gz].concat();
        assert_eq!(gunzip(&two, "t.gz", 20_000).unwrap().len(), 20_000);
        assert!(gunzip(&two, "t.gz", 19_999).is_err());
        assert!(gunzip(b"not gzip", "t.gz", 100).is_err());
    }

    /// A gzip bomb: 257 concatenated 1 MiB members of zeros (about 260 KB on disk) expand to
    /// 257 MiB, past `MAX_DECOMPRESSED_BYTES`; `read_record` refuses it instead of
    /// decompressing without bound (before the cap it read the whole stream into memory).
    #[test]
    fn read_record_refuses_a_gzip_bomb() {
        let member = gz_zeros(1 << 20);
        let n = MAX_DECOMPRESSED_BYTES / (1 << 20) + 1;
        let bomb: Vec<u8> = member
            .iter()
            .copied()
            .cycle()
            .take(member.len() * n)
            .collect();
        assert!(bomb.len() < 1 << 20, "the bomb is small on disk");
        let dir = std::env::temp_dir().join(format!("gearwear-bomb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bomb.csv.gz");
        std::fs::write(&path, &bomb).unwrap();
        let r = read_record(&path, &opts(Some(1.0), None));
        std::fs::remove_dir_all(&dir).ok();
        match r {
            Err(Error::RecordFormat { reason, .. }) => {
                assert!(
                    reason.contains("expands beyond 268435456 bytes"),
                    "{reason}"
                )
            }
            other => panic!("a gzip bomb was not refused: {other:?}"),
        }
    }

    #[test]
    fn csv_time_step_without_a_finite_rate_is_refused() {
        // Found by review for the fuzz harness's rate invariant: 1/5e-324 = inf.
        let e = parse_record(b"t,v\n0,1\n5e-324,2\n", Format::Csv, &opts(None, None), "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no finite sample rate"), "{e}");
    }

    #[test]
    fn csv_line_of_only_quotes_is_skipped() {
        // fuzz/regressions/csv/quote-only-line-then-number.csv, found by `cargo fuzz run csv`:
        // the line `"` has no field; it became an empty row and `r[value_col]` panicked.
        let r = parse_record(b"\"\n000.03554\n", Format::Csv, &opts(Some(1.0), None), "t").unwrap();
        assert_eq!(r.samples, vec![0.03554]);
        let r = parse_record(b"\"  \"\n1\n2\n", Format::Csv, &opts(Some(1.0), None), "t").unwrap();
        assert_eq!(r.samples, vec![1.0, 2.0]);
    }
}
