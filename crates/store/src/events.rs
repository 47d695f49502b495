//! Webhook events as the store queues them: typed and versioned. The store writes one
//! [`QueuedEvent`] per delivery (as JSON in `deliveries.payload`) inside the transaction that
//! raised it; the service's webhook worker renders the documented payload from it.

use gearwear_core::assessment::Level;
use serde::{Deserialize, Serialize};

use crate::alert_rows::AlertRow;
use crate::machines::MachineDeletion;

/// The version of [`QueuedEvent`] this build writes and reads.
pub const EVENT_VERSION: u32 = 1;

/// One queued event: its id (the payload's `event_id`) and what happened.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QueuedEvent {
    pub version: u32,
    pub event_id: String,
    pub event: Event,
}

impl QueuedEvent {
    pub fn new(event_id: String, event: Event) -> Self {
        QueuedEvent {
            version: EVENT_VERSION,
            event_id,
            event,
        }
    }

    /// A stored payload read back: `None` when it is not a queued event of this version (a
    /// payload queued already rendered, by an earlier build).
    pub fn parse(stored: &str) -> Option<QueuedEvent> {
        serde_json::from_str::<QueuedEvent>(stored)
            .ok()
            .filter(|q| q.version == EVENT_VERSION)
    }
}

/// What happened.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Event {
    /// A record was diagnosed.
    DiagnosisCreated { diagnosis: DiagnosisEvent },
    /// An alert episode opened, with the record that opened it.
    AlertOpened { alert: AlertRow, by: RecordRef },
    /// An open episode was acknowledged.
    AlertAcknowledged { alert: AlertRow },
    /// An episode closed, with the record that closed it.
    AlertClosed { alert: AlertRow, by: RecordRef },
    /// A record opened or escalated an episode: the record's diagnosis, the level before and
    /// the episode.
    WearThresholdCrossed {
        diagnosis: DiagnosisEvent,
        previous_alert_level: Level,
        alert_id: String,
    },
    /// A machine and everything of it was deleted at `deleted_at` (unix ms).
    MachineDeleted {
        deletion: MachineDeletion,
        deleted_at: i64,
    },
}

impl Event {
    /// The event's name, as subscriptions ask for it.
    pub fn name(&self) -> &'static str {
        match self {
            Event::DiagnosisCreated { .. } => "diagnosis.created",
            Event::AlertOpened { .. } => "alert.opened",
            Event::AlertAcknowledged { .. } => "alert.acknowledged",
            Event::AlertClosed { .. } => "alert.closed",
            Event::WearThresholdCrossed { .. } => "wear.threshold_crossed",
            Event::MachineDeleted { .. } => "machine.deleted",
        }
    }
}

/// The record (and its diagnosis) behind an alert transition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordRef {
    pub record_id: String,
    pub diagnosis_id: String,
}

/// A diagnosis as its events carry it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisEvent {
    pub machine_id: String,
    pub diagnosis_id: String,
    pub record_id: String,
    /// Unix ms.
    pub created_at: i64,
    /// Unix ms.
    pub measured_at: i64,
    /// The wear degree and its interval, when the diagnosis has one.
    pub wear: Option<Interval>,
    pub alert_level: Level,
    pub motion_state: String,
    /// Novelty score and threshold, when the machine has a baseline.
    pub novelty: Option<Novelty>,
    pub channel: Option<String>,
    /// Members the service adds to the payload as it answered them (`findings`,
    /// `operating_state`, `trend_summary`), carried as given.
    pub extras: serde_json::Map<String, serde_json::Value>,
}

/// An estimate and its interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    pub estimate: f64,
    pub lower: f64,
    pub upper: f64,
}

/// A novelty score against its threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Novelty {
    pub score: f64,
    pub threshold: f64,
}

impl DiagnosisEvent {
    /// The record behind it.
    pub fn record(&self) -> RecordRef {
        RecordRef {
            record_id: self.record_id.clone(),
            diagnosis_id: self.diagnosis_id.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_queued_event_reads_back_and_an_old_payload_does_not() {
        let q = QueuedEvent::new(
            "e1".into(),
            Event::MachineDeleted {
                deletion: MachineDeletion {
                    machine_id: "m".into(),
                    records: 3,
                    diagnoses: 3,
                    calibration: false,
                    idempotency_answers: 0,
                    alert_level: Some(Level::Alarm),
                },
                deleted_at: 1_700_000_000_000,
            },
        );
        let text = serde_json::to_string(&q).unwrap();
        assert_eq!(QueuedEvent::parse(&text), Some(q));
        assert_eq!(
            QueuedEvent::parse(r#"{"event":"machine.deleted","event_id":"e1"}"#),
            None
        );
    }
}
