//! Multichannel records and choosing one channel by name or index.

use super::{Column, Record};
use crate::error::{Error, Result};

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

/// The position in `names` of the channel `key` names: the channel of that name, else (a
/// number) the channel of that 0-based index, else [`Error::UnknownChannel`].
pub(super) fn find_channel<S: AsRef<str>>(names: &[S], key: &str) -> Result<usize> {
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
pub(super) fn channel_key(column: &Column) -> String {
    match column {
        Column::Index(i) => i.to_string(),
        Column::Name(n) => n.clone(),
    }
}

/// Unnamed channels' names: `"0"`, `"1"`, ….
pub(super) fn index_names(n: usize) -> Vec<String> {
    (0..n).map(|i| i.to_string()).collect()
}
