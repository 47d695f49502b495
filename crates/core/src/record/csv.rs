//! CSV records: one value per line, `time,value`, or several columns, with an optional header.

use super::channels::{channel_key, find_channel, index_names};
use super::{Channel, Column, MultiRecord, ReadOptions, Record, Voice, fmt_err};
use crate::error::{Error, Result};

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

pub(super) fn parse_csv(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<Record> {
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

pub(super) fn csv_channels(bytes: &[u8], opts: &ReadOptions, origin: &str) -> Result<MultiRecord> {
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
