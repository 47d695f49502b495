//! What is kept of an assessment with its record: [`StoredFeatures`], the one layout the
//! service's ingest writes and its baselines read (a machine's baseline is fitted from the
//! `novelty_features` of its baseline records computed with its current gearbox description).
//!
//! The layout is versioned ([`STORED_FEATURES_VERSION`]); rows written before the version was
//! recorded are version 1 (a migration writes the number into them). A [`RecordFeatures`] is
//! stored whole through serde, so a field it gains (`#[serde(default)]`) flows through without
//! another migration.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::{Assessment, Level};
use crate::novelty::RecordFeatures;

/// The layout version [`StoredFeatures`] are written with.
pub const STORED_FEATURES_VERSION: u32 = 1;

fn version_one() -> u32 {
    1
}

/// The features stored with a record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredFeatures {
    /// The layout ([`STORED_FEATURES_VERSION`]).
    #[serde(default = "version_one")]
    pub version: u32,
    /// The gearbox description the features were computed with: its id and hash.
    pub gearbox_id: String,
    pub gearbox_hash: String,
    /// Each assessed channel's novelty features (what a baseline is fitted from) and level.
    pub channels: BTreeMap<String, StoredChannel>,
    /// The deciding channel's reading, when its gearbox's table gave one (for people and
    /// exports; nothing reads it back): matched lines, condition indicators, f1 (Hz) and the
    /// dimensionless speed Ω1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lines: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition_indicators: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f1_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega1: Option<f64>,
}

/// One channel's stored features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredChannel {
    pub novelty_features: RecordFeatures,
    pub alert_level: Level,
}

impl Assessment {
    /// What is stored with the record ([`StoredFeatures`]).
    pub fn stored_features(&self) -> StoredFeatures {
        let reading = self
            .deciding_channel()
            .reading
            .as_ref()
            .map(|r| &r.diagnosis);
        let value = |v: Result<Value, serde_json::Error>| v.ok();
        StoredFeatures {
            version: STORED_FEATURES_VERSION,
            gearbox_id: self.gearbox.id.clone(),
            gearbox_hash: self.gearbox.hash.clone(),
            channels: self
                .assessed
                .iter()
                .map(|c| {
                    let stored = StoredChannel {
                        novelty_features: c.features.clone(),
                        alert_level: c.alert.level,
                    };
                    (c.name.clone(), stored)
                })
                .collect(),
            lines: reading.and_then(|d| value(serde_json::to_value(&d.lines))),
            condition_indicators: reading
                .and_then(|d| value(serde_json::to_value(&d.condition_indicators))),
            f1_hz: reading.map(|d| d.f1_hz),
            omega1: reading.map(|d| d.omega1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_from_before_the_version_reads_as_version_one() {
        let old = r#"{"gearbox_id": "wang2019", "gearbox_hash": "h",
            "channels": {"a1": {"novelty_features": {"values": {"x": 1.5}, "indicators": null},
                                "alert_level": "warning"}},
            "lines": [], "f1_hz": 500.0, "omega1": 1.0}"#;
        let f: StoredFeatures = serde_json::from_str(old).unwrap();
        assert_eq!(f.version, 1);
        assert_eq!(f.channels["a1"].alert_level, Level::Warning);
        assert_eq!(f.f1_hz, Some(500.0));
        let again: StoredFeatures =
            serde_json::from_str(&serde_json::to_string(&f).unwrap()).unwrap();
        assert_eq!(again, f);
    }

    #[test]
    fn a_row_without_its_channels_does_not_read() {
        assert!(serde_json::from_str::<StoredFeatures>(r#"{"gearbox_hash": "h"}"#).is_err());
    }
}
