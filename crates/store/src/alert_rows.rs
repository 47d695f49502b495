//! An alert episode's row: what the alert store keeps and its events carry.

use gearwear_core::assessment::Level;
use gearwear_core::assessment::episodes::AlertState;
use serde::{Deserialize, Serialize};

/// One episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlertRow {
    pub id: String,
    pub machine_id: String,
    /// `warning` or `alarm`.
    pub level: Level,
    pub state: AlertState,
    pub opened_at: i64,
    /// The record that opened it.
    pub record_id: String,
    pub acknowledged_at: Option<i64>,
    /// The API key (id) that acknowledged it.
    pub acknowledged_by: Option<String>,
    pub note: Option<String>,
    pub closed_at: Option<i64>,
    pub closed_record_id: Option<String>,
    pub peak_severity: f64,
    /// When the service stored it (unix ms, wall clock).
    pub created_at: i64,
}
