//! Measured records and the file formats they come in.
//!
//! | format | layout | sample rate |
//! | --- | --- | --- |
//! | `csv` | one value per line, or `time,value`, or several columns (pick one with `column`); header optional; `,` `;` tab or spaces; `#` comments; gzip when the name ends in `.gz` | `sample_rate`, else from a time column |
//! | `f32` | raw little-endian IEEE-754 `f32`, no header | `sample_rate` (required) |
//! | `wav` | RIFF/WAVE, PCM 8/16/24/32-bit integer or 32/64-bit float (also `WAVE_FORMAT_EXTENSIBLE`), any channel count (pick one with `column`, default 0) | the header (overridden by `sample_rate` if given) |
//!
//! Two readers share these parsers: [`parse_record`] / [`read_record`] return one channel (the
//! CLI's, its messages name `--column` and `--sample-rate`), [`parse_record_channels`] /
//! [`read_record_channels`] every channel of the record as a [`MultiRecord`] (each CSV value
//! column, each WAV channel), with messages that name no CLI flag, for the HTTP service.
//!
//! Integer WAV samples are scaled to `[−1, 1)`; the unit does not matter to the diagnosis
//! (every matching feature is gain-invariant). Nothing here panics on malformed input: every
//! problem comes back as [`Error::RecordFormat`] (or [`Error::NonFiniteSample`]) naming the
//! file and what is wrong.

mod channels;
mod checks;
mod csv;
mod gzip;
pub mod quality;
mod raw_f32;
mod wav;

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

pub use self::channels::{Channel, MultiRecord};
pub use self::checks::{
    CLIP_MIN_COUNT, CLIP_MIN_FRACTION, CLIP_MIN_RUN, CLIP_PILE_UP, MAX_SAMPLE_RATE_HZ,
    check_channel, check_pulses, check_sample_rate, check_signal,
};
use self::csv::{csv_channels, parse_csv};
pub use self::gzip::{MAX_DECOMPRESSED_BYTES, gunzip};
pub use self::quality::{Inspection, QualityFinding, inspect};
use self::raw_f32::{f32_channels, parse_f32};
pub use self::wav::{encode_wav, encode_wav_channels};
use self::wav::{parse_wav, wav_channels};

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

/// A file's bytes (decompressed when the name ends in `.gz`), its format (`opts.format`, else
/// from the name) and its name for errors.
fn read_file(path: &Path, opts: &ReadOptions) -> Result<(Vec<u8>, Format, String)> {
    let name = path.display().to_string();
    let mut bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: name.clone(),
        source,
    })?;
    // By the name, else by the bytes: a gzip file is inflated whatever it is called.
    if name.to_ascii_lowercase().ends_with(".gz") || bytes.starts_with(&[0x1f, 0x8b]) {
        bytes = gunzip(&bytes, &name, MAX_DECOMPRESSED_BYTES)?;
    }
    // A RIFF/WAVE file is read as WAV unless a format was chosen: never as text or raw f32.
    let riff = bytes.len() >= 12 && &bytes[..4] == b"RIFF" && &bytes[8..12] == b"WAVE";
    let format = opts.format.unwrap_or_else(|| {
        if riff {
            Format::Wav
        } else {
            Format::from_path(path)
        }
    });
    Ok((bytes, format, name))
}

/// Read a record file (gzip-compressed when the name ends in `.gz`).
pub fn read_record(path: &Path, opts: &ReadOptions) -> Result<Record> {
    let (bytes, format, name) = read_file(path, opts)?;
    parse_record(&bytes, format, opts, &name)
}

/// Read every channel of a record file (gzip-compressed when the name ends in `.gz`): see
/// [`parse_record_channels`].
pub fn read_record_channels(path: &Path, opts: &ReadOptions) -> Result<MultiRecord> {
    let (bytes, format, name) = read_file(path, opts)?;
    parse_record_channels(&bytes, format, opts, &name)
}

/// [`read_record_channels`], except that the channel `pulses` names (a tachometer's) passes
/// [`check_pulses`] instead of [`check_signal`] ([`parse_record_channels_with_pulses`]).
pub fn read_record_channels_with_pulses(
    path: &Path,
    opts: &ReadOptions,
    pulses: Option<&str>,
) -> Result<MultiRecord> {
    let (bytes, format, name) = read_file(path, opts)?;
    parse_record_channels_with_pulses(&bytes, format, opts, &name, pulses)
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

/// Parse every channel of a record from bytes (already decompressed); `origin` names it in
/// errors.
///
/// - CSV: every column is a channel, named by the header or, without one, `"0"`, `"1"`, … in
///   order, except a time column: the column whose header name is `t`, `t_s`, `seconds` or
///   starts with `time` (case-insensitive), or, without a header, the first of exactly two
///   columns (`time,value`, as [`parse_record`] reads it). Unlike [`parse_record`], a header
///   of two columns that is not a time name (`a1,a2`) gives two channels. Header names must
///   be non-empty and differ.
/// - WAV: channel *i* is named `"i"`; raw `f32`: one channel, `"0"`.
/// - `opts.column`, if given, keeps only that channel, chosen as by [`MultiRecord::channel`]
///   (by name, else by 0-based index among the channels: in `time,a1,a2` index 0 is `a1`,
///   where [`parse_record`]'s index counts the time column). Unknown: [`Error::UnknownChannel`].
/// - The sample rate: `opts.sample_rate`, else the WAV header or the CSV time column, else
///   [`Error::MissingSampleRate`]; it must pass [`check_sample_rate`].
/// - Every channel kept must pass [`check_signal`]; the first that does not fails the whole
///   record with [`Error::InChannel`] naming it.
///
/// The messages name no CLI flag (they say "channel", "the sample rate"), so they can go to
/// an HTTP client as they are; [`parse_record`]'s speak to the CLI user.
pub fn parse_record_channels(
    bytes: &[u8],
    format: Format,
    opts: &ReadOptions,
    origin: &str,
) -> Result<MultiRecord> {
    parse_record_channels_with_pulses(bytes, format, opts, origin, None)
}

/// [`parse_record_channels`], except that the channel named `pulses` (a tachometer's, when
/// the record has it) passes [`check_pulses`] instead of [`check_signal`]: pulses at a
/// supply rail are not a clipped record.
pub fn parse_record_channels_with_pulses(
    bytes: &[u8],
    format: Format,
    opts: &ReadOptions,
    origin: &str,
    pulses: Option<&str>,
) -> Result<MultiRecord> {
    if let Some(fs) = opts.sample_rate {
        check_sample_rate(fs)?;
    }
    let rec = match format {
        Format::Csv => csv_channels(bytes, opts, origin)?,
        Format::F32 => f32_channels(bytes, opts, origin)?,
        Format::Wav => wav_channels(bytes, opts, origin)?,
    };
    check_sample_rate(rec.sample_rate)?;
    for c in &rec.channels {
        if pulses == Some(c.name.as_str()) {
            check_pulses(&c.samples).map_err(|e| e.in_channel(&c.name))?;
        } else {
            check_channel(c)?;
        }
    }
    Ok(rec)
}
/// Who reads a parser's messages: the single-channel reader speaks to the CLI user (it names
/// `--sample-rate`, `--format`, `--column`), the multichannel one to any caller, an HTTP client
/// included, and names no flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Voice {
    Cli,
    Neutral,
}

impl Voice {
    /// The end of a message about a sample rate the record does not state usably.
    fn give_rate(self) -> &'static str {
        match self {
            Voice::Cli => "give --sample-rate",
            Voice::Neutral => "give the sample rate",
        }
    }

    fn missing_rate(self, format: &'static str) -> Error {
        Error::MissingSampleRate {
            format,
            give: match self {
                Voice::Cli => "give it (--sample-rate HZ)",
                Voice::Neutral => "give the sample rate in Hz",
            },
        }
    }
}

#[cfg(test)]
mod tests;
