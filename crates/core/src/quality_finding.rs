//! One defect a record's inspection found ([`crate::record::quality`]). A leaf of its own,
//! below both users: the crate's [`Error::RecordQuality`](crate::Error::RecordQuality) carries
//! it, and the inspection returns that error.

use serde::Serialize;

/// One defect found in a record: what, where (0-based samples `first..=last`, seconds from the
/// record's start), and what was done.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QualityFinding {
    /// `spike`, `impulses`, `absurd-value`, `dropout`, `dc-step` or `sample-rate`.
    pub defect: &'static str,
    /// The channel, in a record of several channels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub channel: Option<String>,
    pub first_sample: usize,
    pub last_sample: usize,
    /// `first_sample / fs`, s.
    pub start_s: f64,
    /// `(last_sample + 1) / fs`, s.
    pub end_s: f64,
    /// `repaired`, `refused` or `warned`.
    pub action: &'static str,
    pub message: String,
}
