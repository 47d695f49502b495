//! The MQTT series of `/metrics`: connection state and messages by outcome, written by hand
//! into the service's 0.0.4 text (why not `prometheus-client`: `service/metrics.rs`).

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The MQTT series of `/metrics`.
#[derive(Default)]
pub struct MqttMetrics {
    pub(super) enabled: AtomicBool,
    connected: AtomicBool,
    pub(super) connections: AtomicU64,
    messages: Mutex<BTreeMap<&'static str, u64>>,
}

impl MqttMetrics {
    pub(super) fn message(&self, outcome: &'static str) {
        *self.messages.lock().unwrap().entry(outcome).or_default() += 1;
    }

    pub(super) fn set_connected(&self, up: bool) {
        self.connected.store(up, Ordering::Relaxed);
    }

    /// The series, when MQTT ingest is on.
    pub fn render(&self, o: &mut String) {
        if !self.enabled.load(Ordering::Relaxed) {
            return;
        }
        let _ = writeln!(
            o,
            "# HELP gearwear_mqtt_connected 1 while connected and subscribed to the broker."
        );
        let _ = writeln!(o, "# TYPE gearwear_mqtt_connected gauge");
        let _ = writeln!(
            o,
            "gearwear_mqtt_connected {}",
            self.connected.load(Ordering::Relaxed) as u8
        );
        let _ = writeln!(
            o,
            "# HELP gearwear_mqtt_connections_total Connections made to the broker."
        );
        let _ = writeln!(o, "# TYPE gearwear_mqtt_connections_total counter");
        let _ = writeln!(
            o,
            "gearwear_mqtt_connections_total {}",
            self.connections.load(Ordering::Relaxed)
        );
        let _ = writeln!(
            o,
            "# HELP gearwear_mqtt_messages_total MQTT messages by outcome (stored, duplicate, \
             refused)."
        );
        let _ = writeln!(o, "# TYPE gearwear_mqtt_messages_total counter");
        for (k, n) in self.messages.lock().unwrap().iter() {
            let _ = writeln!(o, "gearwear_mqtt_messages_total{{outcome=\"{k}\"}} {n}");
        }
    }
}
