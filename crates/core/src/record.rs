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

/// A file's bytes (decompressed when the name ends in `.gz`), its format (`opts.format`, else
/// from the name) and its name for errors.
fn read_file(path: &Path, opts: &ReadOptions) -> Result<(Vec<u8>, Format, String)> {
    let name = path.display().to_string();
    let mut bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: name.clone(),
        source,
    })?;
    if name.to_ascii_lowercase().ends_with(".gz") {
        bytes = gunzip(&bytes, &name, MAX_DECOMPRESSED_BYTES)?;
    }
    let format = opts.format.unwrap_or_else(|| Format::from_path(path));
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

/// One channel of a record: its name (a CSV header's, else its 0-based index as text) and its
/// samples, in the record's units.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    pub name: String,
    pub samples: Vec<f64>,
}

/// A record of one or more channels sampled together: every channel has the same length and
/// `sample_rate` (Hz).
#[derive(Debug, Clone, PartialEq)]
pub struct MultiRecord {
    /// Samples per second.
    pub sample_rate: f64,
    /// In file order; at least one; names differ.
    pub channels: Vec<Channel>,
}

impl MultiRecord {
    /// The channel named `name_or_index`, else (a number) the one at that 0-based index, else
    /// [`Error::UnknownChannel`] listing the channels. Names match exactly (no trimming); a
    /// name wins over an index: in a CSV whose header is `2,1` (unusual, but legal), `"1"` is
    /// the second column.
    pub fn channel(&self, name_or_index: &str) -> Result<&Channel> {
        let names: Vec<&str> = self.channels.iter().map(|c| c.name.as_str()).collect();
        Ok(&self.channels[find_channel(&names[..], name_or_index)?])
    }

    /// The channels' names, in order.
    pub fn names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.name.clone()).collect()
    }

    /// One channel as a single-channel [`Record`] (a copy of its samples), chosen as by
    /// [`MultiRecord::channel`]: what the diagnosis takes.
    pub fn record(&self, name_or_index: &str) -> Result<Record> {
        Ok(Record {
            samples: self.channel(name_or_index)?.samples.clone(),
            sample_rate: self.sample_rate,
        })
    }
}

/// [`check_signal`] on one channel, its error wrapped in [`Error::InChannel`] naming the
/// channel (for channels that did not come through [`parse_record_channels`], e.g. a JSON
/// body's).
pub fn check_channel(channel: &Channel) -> Result<()> {
    check_signal(&channel.samples).map_err(|e| e.in_channel(&channel.name))
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
        check_channel(c)?;
    }
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

/// A CSV file's numbers: `rows` rows of `width` numbers, row after row, and the header if the
/// first row held a field that is not a number.
struct CsvTable {
    header: Option<Vec<String>>,
    // All numbers row after row, `width` per row: 8 bytes a number in one allocation, not a
    // `Vec` per row (a heap block plus a 24-byte header for every line, many times the 2 bytes
    // of a one-column line; see docs/reliability/fuzzing.md).
    cells: Vec<f64>,
    width: usize,
    rows: usize,
}

impl CsvTable {
    fn at(&self, row: usize, col: usize) -> f64 {
        self.cells[row * self.width + col]
    }

    fn column(&self, col: usize) -> Vec<f64> {
        (0..self.rows).map(|k| self.at(k, col)).collect()
    }

    /// The sample rate: `given`, else from the time column `time_col` (uniform steps within
    /// 1 % of the mean), else [`Error::MissingSampleRate`].
    fn sample_rate(
        &self,
        time_col: Option<usize>,
        given: Option<f64>,
        origin: &str,
        voice: Voice,
    ) -> Result<f64> {
        let give = voice.give_rate();
        match (given, time_col) {
            (Some(fs), _) => Ok(fs),
            (None, Some(t)) if self.rows >= 2 => {
                let n = self.rows;
                let t0 = self.at(0, t);
                let t1 = self.at(n - 1, t);
                let dt = (t1 - t0) / (n - 1) as f64;
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(fmt_err(
                        origin,
                        format!("the time column does not increase ({t0} … {t1}); {give}"),
                    ));
                }
                // Uniform sampling check: every step within 1 % of the mean step.
                let step = |k: usize| self.at(k, t) - self.at(k - 1, t);
                if let Some(k) = (1..n).find(|&k| (step(k) - dt).abs() > 0.01 * dt) {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "non-uniform time column at row {k}: step {} vs mean {dt}; \
                             resample or {give}",
                            step(k)
                        ),
                    ));
                }
                // A step below 1/f64::MAX (e.g. 5e-324 s) is positive but has no finite rate.
                let rate = 1.0 / dt;
                if !rate.is_finite() {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "the time column's step {dt} s gives no finite sample rate; {give}"
                        ),
                    ));
                }
                Ok(rate)
            }
            (None, _) => Err(voice.missing_rate("a CSV without a time column")),
        }
    }
}

/// Read a CSV file's numbers; [`Error::EmptyRecord`] when it holds no row of numbers.
fn csv_table(bytes: &[u8], origin: &str, voice: Voice) -> Result<CsvTable> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let hint = match voice {
            Voice::Cli => "wrong --format?",
            Voice::Neutral => "wrong format?",
        };
        fmt_err(origin, format!("not UTF-8 text ({e}); {hint}"))
    })?;
    let mut t = CsvTable {
        header: None,
        cells: Vec::new(),
        width: 0,
        rows: 0,
    };
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
        if t.rows == 0 && t.header.is_none() && nums.iter().any(|v| v.is_none()) {
            t.header = Some(fields.iter().map(|s| s.to_string()).collect());
            t.width = fields.len();
            continue;
        }
        if t.width == 0 {
            t.width = fields.len();
        }
        if fields.len() != t.width {
            return Err(fmt_err(
                origin,
                format!(
                    "line {}: {} fields, expected {} (as on the first line)",
                    lineno + 1,
                    fields.len(),
                    t.width
                ),
            ));
        }
        for (f, v) in fields.iter().zip(nums) {
            match v {
                Some(v) => t.cells.push(v),
                None => {
                    return Err(fmt_err(
                        origin,
                        format!("line {}: `{f}` is not a number", lineno + 1),
                    ));
                }
            }
        }
        t.rows += 1;
    }
    if t.rows == 0 {
        // Empty, or only a header and comments: a record without samples, not a format error.
        return Err(Error::EmptyRecord);
    }
    Ok(t)
}

/// A header name that marks a time column: `t`, `t_s`, `seconds`, `time…`.
fn is_time_name(s: &str) -> bool {
    let s = s.to_ascii_lowercase();
    s == "t" || s.starts_with("time") || s == "t_s" || s == "seconds"
}

fn parse_csv(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
    let t = csv_table(bytes, origin, Voice::Cli)?;
    let width = t.width;
    let names = t.header.clone().unwrap_or_default();
    let time_col = if width == 2 {
        Some(0)
    } else {
        names.iter().position(|n| is_time_name(n))
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
    let samples = t.column(value_col);
    let sample_rate = t.sample_rate(
        time_col.filter(|&c| c != value_col),
        opts.sample_rate,
        origin,
        Voice::Cli,
    )?;
    Ok(Record {
        samples,
        sample_rate,
    })
}

/// The position in `names` of the channel `key` names: the channel of that name, else (a
/// number) the channel of that 0-based index, else [`Error::UnknownChannel`].
fn find_channel<S: AsRef<str>>(names: &[S], key: &str) -> Result<usize> {
    names
        .iter()
        .position(|n| n.as_ref() == key)
        .or_else(|| key.parse::<usize>().ok().filter(|&i| i < names.len()))
        .ok_or_else(|| Error::UnknownChannel {
            requested: key.to_string(),
            available: names.iter().map(|n| n.as_ref().to_string()).collect(),
        })
}

/// `opts.column` as a channel key for [`find_channel`].
fn channel_key(column: &Column) -> String {
    match column {
        Column::Index(i) => i.to_string(),
        Column::Name(n) => n.clone(),
    }
}

/// Unnamed channels' names: `"0"`, `"1"`, ….
fn index_names(n: usize) -> Vec<String> {
    (0..n).map(|i| i.to_string()).collect()
}

fn csv_channels(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<MultiRecord> {
    let t = csv_table(bytes, origin, Voice::Neutral)?;
    // The time column: by its header name; without a header, the first of exactly two
    // columns (`time,value`, as the single-channel reader). One column is always a channel.
    let time_col = match &t.header {
        _ if t.width < 2 => None,
        Some(h) => h.iter().position(|n| is_time_name(n)),
        None => (t.width == 2).then_some(0),
    };
    let cols: Vec<usize> = (0..t.width).filter(|&c| Some(c) != time_col).collect();
    let names: Vec<String> = match &t.header {
        None => index_names(cols.len()),
        Some(h) => {
            let names: Vec<String> = cols.iter().map(|&c| h[c].clone()).collect();
            for (k, name) in names.iter().enumerate() {
                if name.is_empty() {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "column {} has an empty name in the header; name every channel",
                            cols[k]
                        ),
                    ));
                }
                if let Some(j) = names[..k].iter().position(|m| m == name) {
                    return Err(fmt_err(
                        origin,
                        format!(
                            "the header names two columns `{name}` ({} and {}); channel names \
                             must differ",
                            cols[j], cols[k]
                        ),
                    ));
                }
            }
            names
        }
    };
    let chosen: Vec<usize> = match &opts.column {
        None => (0..cols.len()).collect(),
        Some(c) => vec![find_channel(&names[..], &channel_key(c))?],
    };
    let sample_rate = t.sample_rate(time_col, opts.sample_rate, origin, Voice::Neutral)?;
    Ok(MultiRecord {
        sample_rate,
        channels: chosen
            .into_iter()
            .map(|k| Channel {
                name: names[k].clone(),
                samples: t.column(cols[k]),
            })
            .collect(),
    })
}

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

fn parse_f32(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
    let fs = opts
        .sample_rate
        .ok_or_else(|| Voice::Cli.missing_rate("raw f32 (no header)"))?;
    Ok(Record {
        samples: f32_samples(bytes, origin)?,
        sample_rate: fs,
    })
}

fn f32_channels(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<MultiRecord> {
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

fn parse_wav(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
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

fn wav_channels(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<MultiRecord> {
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

    // ---- multichannel ----

    /// `rows` rows of `cols` distinct values: row k, column c holds `c + k/100` (sin-free and
    /// never flat or clipped).
    fn table_csv(header: Option<&str>, cols: usize, rows: usize) -> String {
        let mut s = header.map(|h| format!("{h}\n")).unwrap_or_default();
        for k in 0..rows {
            let row: Vec<String> = (0..cols)
                .map(|c| format!("{}", c as f64 + ((k * 7) % 11) as f64 / 100.0))
                .collect();
            s.push_str(&row.join(","));
            s.push('\n');
        }
        s
    }

    fn channels(csv: &str, fs: Option<f64>, col: Option<&str>) -> Result<MultiRecord> {
        parse_record_channels(csv.as_bytes(), Format::Csv, &opts(fs, col), "t")
    }

    #[test]
    fn csv_channels_named_by_the_header() {
        let csv = table_csv(Some("a1,a2,a3,a4"), 4, 20);
        let r = channels(&csv, Some(12_800.0), None).unwrap();
        assert_eq!(r.names(), ["a1", "a2", "a3", "a4"]);
        assert_eq!(r.sample_rate, 12_800.0);
        for (c, ch) in r.channels.iter().enumerate() {
            assert_eq!(ch.samples.len(), 20);
            // The same column as the single-channel reader picks.
            let one = parse_record(
                csv.as_bytes(),
                Format::Csv,
                &opts(Some(12_800.0), Some(&c.to_string())),
                "t",
            )
            .unwrap();
            assert_eq!(ch.samples, one.samples, "{}", ch.name);
        }
        // The single-channel reader still asks the CLI user for --column.
        let e = parse_record(csv.as_bytes(), Format::Csv, &opts(Some(1.0), None), "t")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("choose one with --column") && e.contains("(a1, a2, a3, a4)"),
            "{e}"
        );
    }

    #[test]
    fn csv_channels_without_a_header_are_numbered() {
        let r = channels(&table_csv(None, 3, 10), Some(100.0), None).unwrap();
        assert_eq!(r.names(), ["0", "1", "2"]);
        assert_eq!(r.channels[2].samples[1], 2.07);
        let r = channels("1\n2\n3\n", Some(100.0), None).unwrap();
        assert_eq!(r.names(), ["0"]);
        assert_eq!(r.channels[0].samples, [1.0, 2.0, 3.0]);
        // Two columns without a header are `time,value`, as for the single-channel reader.
        let r = channels("0,1\n0.5,2\n1.0,3\n", None, None).unwrap();
        assert_eq!(r.names(), ["0"]);
        assert_eq!(r.channels[0].samples, [1.0, 2.0, 3.0]);
        assert!((r.sample_rate - 2.0).abs() < 1e-12);
    }

    #[test]
    fn csv_time_column_gives_the_rate_and_is_no_channel() {
        let csv = "Time,a1,a2\n0,1,5\n0.001,2,4\n0.002,3,6\n0.003,1,4\n";
        let r = channels(csv, None, None).unwrap();
        assert_eq!(r.names(), ["a1", "a2"]);
        assert!((r.sample_rate - 1000.0).abs() < 1e-9, "{}", r.sample_rate);
        assert_eq!(r.channels[1].samples, [5.0, 4.0, 6.0, 4.0]);
        // A given rate wins; the time column is still not a channel.
        let r = channels(csv, Some(50.0), None).unwrap();
        assert_eq!(
            (r.sample_rate, r.names()),
            (50.0, vec!["a1".to_string(), "a2".to_string()])
        );
        // `time,acc`: one channel.
        let r = channels("t,acc\n0,1\n0.5,2\n1.0,3\n", None, None).unwrap();
        assert_eq!(r.names(), ["acc"]);
        // Two named columns that are not a time are two channels (the single-channel reader
        // takes the first of two columns as the time whatever its name).
        let r = channels("a1,a2\n1,2\n3,5\n", Some(10.0), None).unwrap();
        assert_eq!(r.names(), ["a1", "a2"]);
        // No time column, no rate: asked for without naming a CLI flag.
        let e = channels("a1,a2\n1,2\n3,5\n", None, None).unwrap_err();
        assert!(matches!(e, Error::MissingSampleRate { .. }), "{e:?}");
        assert!(e.to_string().ends_with("give the sample rate in Hz"), "{e}");
        let e = channels("time,a1,a2\n0,1,5\n0.001,2,4\n0.005,3,6\n", None, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("non-uniform time column")
                && e.ends_with("resample or give the sample rate"),
            "{e}"
        );
    }

    #[test]
    fn one_channel_chosen_by_name_or_index() {
        let csv = table_csv(Some("time,a1,a2,a3,a4"), 5, 16);
        let all = channels(&csv, Some(1000.0), None).unwrap();
        for key in ["a3", "2"] {
            assert_eq!(all.channel(key).unwrap().name, "a3", "{key}");
        }
        assert_eq!(all.record("a3").unwrap().samples, all.channels[2].samples);
        assert_eq!(all.record("a3").unwrap().sample_rate, 1000.0);
        // `opts.column` keeps just that channel, chosen the same way (the index counts
        // channels, not the time column).
        for key in ["a3", "2"] {
            let one = channels(&csv, Some(1000.0), Some(key)).unwrap();
            assert_eq!(one.channels, [all.channel("a3").unwrap().clone()], "{key}");
        }
        // WAV and f32: names are indices.
        let (x, y) = (sine(64, 16.0, 0.5), sine(64, 5.0, 0.25));
        let wav = encode_wav_channels(&[&x, &y], 8000, true);
        let one = parse_record_channels(&wav, Format::Wav, &opts(None, Some("1")), "t").unwrap();
        assert_eq!(one.names(), ["1"]);
        let raw: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
        let r =
            parse_record_channels(&raw, Format::F32, &opts(Some(100.0), Some("0")), "t").unwrap();
        assert_eq!(r.names(), ["0"]);
        assert!(
            parse_record_channels(&raw, Format::F32, &opts(Some(1.0), Some("1")), "t").is_err()
        );
    }

    #[test]
    fn an_unknown_channel_lists_the_channels() {
        let csv = table_csv(Some("a1,a2,a3,a4"), 4, 8);
        let all = channels(&csv, Some(1.0), None).unwrap();
        for key in ["a9", "4", "time"] {
            let e = all.channel(key).unwrap_err();
            assert!(matches!(&e, Error::UnknownChannel { requested, available }
                if requested == key && available.len() == 4));
            let e = e.to_string();
            assert!(
                e.contains(&format!("no channel `{key}`"))
                    && e.contains("`a1`, `a2`, `a3`, `a4`")
                    && !e.contains("--"),
                "{e}"
            );
        }
        let e = channels(&csv, Some(1.0), Some("a9")).unwrap_err();
        assert!(matches!(e, Error::UnknownChannel { .. }), "{e:?}");
        // Many channels: the first 16 and the count.
        let many = MultiRecord {
            sample_rate: 1.0,
            channels: (0..40)
                .map(|i| Channel {
                    name: i.to_string(),
                    samples: vec![0.0, 1.0],
                })
                .collect(),
        };
        let e = many.channel("x").unwrap_err().to_string();
        assert!(
            e.contains("`15`, … (40 in all)") && !e.contains("`16`"),
            "{e}"
        );
    }

    #[test]
    fn a_bad_channel_is_named_in_the_error() {
        let csv = "a1,a2,a3\n1,2,3\n2,nan,4\n3,1,5\n";
        let e = channels(csv, Some(10.0), None).unwrap_err();
        match &e {
            Error::InChannel { channel, error } => {
                assert_eq!(channel, "a2");
                assert!(matches!(**error, Error::NonFiniteSample { index: 1, .. }));
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            e.to_string(),
            "channel `a2`: sample 1 of the record is NaN; the record must contain only finite \
             numbers"
        );
        let (ch, inner) = e.split_channel();
        assert_eq!(ch, Some("a2"));
        assert!(matches!(inner, Error::NonFiniteSample { .. }));
        // Only the channel asked for is checked.
        assert!(channels(csv, Some(10.0), Some("a3")).is_ok());
        // A dead (flat) channel.
        let e = channels("x,y\n1,0\n2,0\n3,0\n", Some(10.0), None).unwrap_err();
        assert!(
            matches!(&e, Error::InChannel { channel, error }
                if channel == "y" && matches!(**error, Error::FlatRecord { samples: 3, .. })),
            "{e:?}"
        );
        // A WAV's second channel.
        let x = sine(64, 16.0, 0.5);
        let wav = encode_wav_channels(&[&x, &[0.0; 64]], 8000, false);
        let e = parse_record_channels(&wav, Format::Wav, &opts(None, None), "t").unwrap_err();
        assert!(
            e.to_string().starts_with("channel `1`: all 64 samples"),
            "{e}"
        );
        assert_eq!(
            check_channel(&Channel {
                name: "j".into(),
                samples: vec![]
            })
            .unwrap_err()
            .to_string(),
            "channel `j`: the record holds no samples; send at least one second of signal"
        );
    }

    #[test]
    fn wav_two_channels() {
        let (x, y) = (sine(200, 16.0, 0.5), sine(200, 7.0, 0.8));
        for float in [false, true] {
            let w = encode_wav_channels(&[&x, &y], 8000, float);
            let r = parse_record_channels(&w, Format::Wav, &opts(None, None), "t").unwrap();
            assert_eq!(
                (r.sample_rate, r.names()),
                (8000.0, vec!["0".to_string(), "1".to_string()])
            );
            for (ch, want) in r.channels.iter().zip([&x, &y]) {
                assert_eq!(ch.samples.len(), 200);
                let err = ch.samples.iter().zip(want).map(|(a, b)| (a - b).abs());
                assert!(err.fold(0.0, f64::max) < 1e-4, "{}", ch.name);
            }
            // The single-channel reader's channel 1 is the same.
            let one = parse_record(&w, Format::Wav, &opts(None, Some("1")), "t").unwrap();
            assert_eq!(one.samples, r.channels[1].samples);
            let e = parse_record_channels(&w, Format::Wav, &opts(None, Some("a1")), "t")
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("no channel `a1`") && e.contains("`0`, `1`"),
                "{e}"
            );
        }
        // A mono file encodes as before.
        assert_eq!(
            encode_wav(&x, 8000, false),
            encode_wav_channels(&[&x], 8000, false)
        );
    }

    #[test]
    fn csv_header_names_must_be_unique_and_non_empty() {
        let e = channels("a,b,a\n1,2,3\n2,3,4\n", Some(1.0), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("two columns `a` (0 and 2)"), "{e}");
        let e = channels("t,a,\"\"\n0,2,3\n1,3,4\n", None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("column 2 has an empty name"), "{e}");
    }

    /// Over HTTP there is no command line: no multichannel error names a flag.
    #[test]
    fn multichannel_errors_name_no_cli_flag() {
        let wav = encode_wav(&sine(64, 16.0, 0.5), 0, true);
        let cases: Vec<(&[u8], Format, ReadOptions)> = vec![
            (&b"a1,a2,a3\n1,2,3\n"[..], Format::Csv, opts(None, None)),
            (&b"1,2,3\n4,5,6\n"[..], Format::Csv, opts(None, Some("7"))),
            (&b"time,a\n1,2\n0,3\n"[..], Format::Csv, opts(None, None)),
            (
                &b"time,a\n0,2\n5e-324,3\n"[..],
                Format::Csv,
                opts(None, None),
            ),
            (&b"\xff\xfe"[..], Format::Csv, opts(Some(1.0), None)),
            (&b"1,2\n3\n"[..], Format::Csv, opts(Some(1.0), None)),
            (&b"\x00\x00\x80\x3f"[..], Format::F32, opts(None, None)),
            (&wav[..], Format::Wav, opts(None, None)),
            (&wav[..], Format::Wav, opts(Some(8000.0), Some("x"))),
            (&b"1\n2\n"[..], Format::Csv, opts(Some(0.0), None)),
        ];
        for (bytes, format, o) in cases {
            let e = parse_record_channels(bytes, format, &o, "body")
                .unwrap_err()
                .to_string();
            assert!(!e.contains("--"), "{format:?} {o:?}: {e}");
        }
        // The same inputs through the single-channel reader keep the CLI's wording.
        let e = parse_record(&wav, Format::Wav, &opts(None, None), "f").unwrap_err();
        assert!(e.to_string().ends_with("give --sample-rate"), "{e}");
        let e = parse_record(b"1\n2\n", Format::Csv, &opts(None, None), "f").unwrap_err();
        assert_eq!(
            e.to_string(),
            "a CSV without a time column carries no sample rate: give it (--sample-rate HZ)"
        );
    }

    #[test]
    fn gzip_csv_channels_from_a_file() {
        use flate2::{Compression, write::GzEncoder};
        use std::io::Write;
        let csv = table_csv(Some("time,a1,a2,a3,a4"), 5, 0)
            + &(0..100)
                .map(|k| {
                    let t = k as f64 / 12_800.0;
                    format!("{t},{},{},{},{}\n", k % 7, k % 5, k % 3, (k * k) % 11)
                })
                .collect::<String>();
        let mut enc = GzEncoder::new(Vec::new(), Compression::default());
        enc.write_all(csv.as_bytes()).unwrap();
        let dir = std::env::temp_dir().join(format!("gearwear-multich-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("rec.csv.gz");
        std::fs::write(&path, enc.finish().unwrap()).unwrap();
        let r = read_record_channels(&path, &ReadOptions::default());
        let one = read_record_channels(
            &path,
            &ReadOptions {
                column: Some(Column::Name("a4".into())),
                ..ReadOptions::default()
            },
        );
        std::fs::remove_dir_all(&dir).ok();
        let r = r.unwrap();
        assert_eq!(r.names(), ["a1", "a2", "a3", "a4"]);
        assert!((r.sample_rate - 12_800.0).abs() < 1e-6, "{}", r.sample_rate);
        assert_eq!(r.channels[1].samples[..6], [0.0, 1.0, 2.0, 3.0, 4.0, 0.0]);
        assert_eq!(one.unwrap().channels, [r.channels[3].clone()]);
    }
}
