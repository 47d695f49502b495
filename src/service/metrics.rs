//! Prometheus text exposition (format 0.0.4) from in-process counters: no registry crate, the
//! handful of series the service needs.
//!
//! Hand-written, not `prometheus-client` (checked with 0.26.0): its encoder writes OpenMetrics,
//! not the 0.0.4 text `/metrics` serves (`text/plain; version=0.0.4`, `health.rs`) and
//! openapi.yaml and docs/service.md describe. Its output differs in the series' own lines: a
//! counter's `# TYPE`/`# HELP` name the family without `_total` (`# TYPE
//! gearwear_http_requests counter`), every help text gets a `.` appended, the histogram's
//! bounds are written `le="1.0"`/`le="10.0"` where these are `le="1"`/`le="10"` (a new series
//! to anything keyed on the label), and the text ends in `# EOF`. Moving to it is a change of
//! the exposition format, to be made as one, not under a refactoring. The MQTT series
//! (`mqtt/metrics.rs`) are written the same way, into the same text.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Upper bounds (seconds) of the request-duration histogram.
const BUCKETS: [f64; 12] = [
    0.001, 0.0025, 0.005, 0.01, 0.02, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0,
];

#[derive(Default)]
struct Histogram {
    counts: [u64; BUCKETS.len()],
    sum: f64,
    count: u64,
}

/// The service's counters.
#[derive(Default)]
pub struct Metrics {
    requests: Mutex<BTreeMap<(String, String, u16), u64>>,
    durations: Mutex<BTreeMap<String, Histogram>>,
    pub records_accepted: AtomicU64,
    pub records_replayed: AtomicU64,
    rejected: Mutex<BTreeMap<String, u64>>,
    deliveries: Mutex<BTreeMap<String, u64>>,
    /// CPU seconds the record path spent in each stage, and how many times it ran.
    stages: Mutex<BTreeMap<&'static str, (f64, u64)>>,
    /// MQTT ingest's connection and messages.
    pub mqtt: super::mqtt::metrics::MqttMetrics,
}

/// CPU time of the calling thread, in seconds (`CLOCK_THREAD_CPUTIME_ID`): what a stage of
/// the record path costs, unlike wall time, does not count time the thread waited for a core.
pub fn thread_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant the kernel knows.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0.0;
    }
    ts.tv_sec as f64 + 1e-9 * ts.tv_nsec as f64
}

/// Times one stage of the record path on the current thread: [`StageClock::lap`] books the CPU
/// time since the previous lap to a stage.
pub struct StageClock {
    last: f64,
    laps: Vec<(&'static str, f64)>,
}

impl Default for StageClock {
    fn default() -> Self {
        Self::new()
    }
}

impl StageClock {
    pub fn new() -> Self {
        StageClock {
            last: thread_cpu_seconds(),
            laps: Vec::new(),
        }
    }

    /// Book the CPU time since the last lap (or since [`StageClock::new`]) to `stage`.
    pub fn lap(&mut self, stage: &'static str) {
        let now = thread_cpu_seconds();
        self.laps.push((stage, (now - self.last).max(0.0)));
        self.last = now;
    }

    /// Restart without booking (time spent waiting or elsewhere).
    pub fn skip(&mut self) {
        self.last = thread_cpu_seconds();
    }

    /// Add another clock's laps (one from a blocking task).
    pub fn absorb(&mut self, other: StageClock) {
        self.laps.extend(other.laps);
    }
}

impl Metrics {
    pub fn observe(&self, method: &str, route: &str, status: u16, elapsed: Duration) {
        *self
            .requests
            .lock()
            .unwrap()
            .entry((method.to_string(), route.to_string(), status))
            .or_default() += 1;
        let s = elapsed.as_secs_f64();
        let mut d = self.durations.lock().unwrap();
        let h = d.entry(route.to_string()).or_default();
        for (i, b) in BUCKETS.iter().enumerate() {
            if s <= *b {
                h.counts[i] += 1;
            }
        }
        h.sum += s;
        h.count += 1;
    }

    /// Book a finished record's stage times.
    pub fn stages(&self, clock: &StageClock) {
        let mut m = self.stages.lock().unwrap();
        for (stage, secs) in &clock.laps {
            let e = m.entry(stage).or_default();
            e.0 += secs;
            e.1 += 1;
        }
    }

    pub fn rejected(&self, reason: &str) {
        *self
            .rejected
            .lock()
            .unwrap()
            .entry(reason.to_string())
            .or_default() += 1;
    }

    pub fn delivery(&self, outcome: &str) {
        *self
            .deliveries
            .lock()
            .unwrap()
            .entry(outcome.to_string())
            .or_default() += 1;
    }

    /// The exposition text.
    pub fn render(&self, table_loaded: bool, store_kind: &str) -> String {
        let mut o = String::new();
        let _ = writeln!(o, "# HELP gearwear_build_info Version and store backend.");
        let _ = writeln!(o, "# TYPE gearwear_build_info gauge");
        let _ = writeln!(
            o,
            "gearwear_build_info{{version=\"{}\",store=\"{store_kind}\"}} 1",
            env!("CARGO_PKG_VERSION")
        );
        let _ = writeln!(
            o,
            "# HELP gearwear_signature_table_loaded 1 when the table is loaded."
        );
        let _ = writeln!(o, "# TYPE gearwear_signature_table_loaded gauge");
        let _ = writeln!(o, "gearwear_signature_table_loaded {}", table_loaded as u8);
        let _ = writeln!(
            o,
            "# HELP gearwear_http_requests_total HTTP requests by route and status."
        );
        let _ = writeln!(o, "# TYPE gearwear_http_requests_total counter");
        for ((m, r, s), n) in self.requests.lock().unwrap().iter() {
            let _ = writeln!(
                o,
                "gearwear_http_requests_total{{method=\"{m}\",route=\"{r}\",status=\"{s}\"}} {n}"
            );
        }
        let _ = writeln!(
            o,
            "# HELP gearwear_http_request_duration_seconds Request latency."
        );
        let _ = writeln!(o, "# TYPE gearwear_http_request_duration_seconds histogram");
        for (r, h) in self.durations.lock().unwrap().iter() {
            for (i, b) in BUCKETS.iter().enumerate() {
                let _ = writeln!(
                    o,
                    "gearwear_http_request_duration_seconds_bucket{{route=\"{r}\",le=\"{b}\"}} {}",
                    h.counts[i]
                );
            }
            let _ = writeln!(
                o,
                "gearwear_http_request_duration_seconds_bucket{{route=\"{r}\",le=\"+Inf\"}} {}",
                h.count
            );
            let _ = writeln!(
                o,
                "gearwear_http_request_duration_seconds_sum{{route=\"{r}\"}} {}",
                h.sum
            );
            let _ = writeln!(
                o,
                "gearwear_http_request_duration_seconds_count{{route=\"{r}\"}} {}",
                h.count
            );
        }
        let _ = writeln!(
            o,
            "# HELP gearwear_records_accepted_total Records stored and diagnosed."
        );
        let _ = writeln!(o, "# TYPE gearwear_records_accepted_total counter");
        let _ = writeln!(
            o,
            "gearwear_records_accepted_total {}",
            self.records_accepted.load(Ordering::Relaxed)
        );
        let _ = writeln!(
            o,
            "# HELP gearwear_records_replayed_total Idempotent replays answered from the store."
        );
        let _ = writeln!(o, "# TYPE gearwear_records_replayed_total counter");
        let _ = writeln!(
            o,
            "gearwear_records_replayed_total {}",
            self.records_replayed.load(Ordering::Relaxed)
        );
        let _ = writeln!(
            o,
            "# HELP gearwear_records_rejected_total Records refused, by problem type."
        );
        let _ = writeln!(o, "# TYPE gearwear_records_rejected_total counter");
        for (r, n) in self.rejected.lock().unwrap().iter() {
            let _ = writeln!(o, "gearwear_records_rejected_total{{reason=\"{r}\"}} {n}");
        }
        let _ = writeln!(
            o,
            "# HELP gearwear_webhook_attempts_total Webhook delivery attempts by outcome."
        );
        let _ = writeln!(o, "# TYPE gearwear_webhook_attempts_total counter");
        for (r, n) in self.deliveries.lock().unwrap().iter() {
            let _ = writeln!(o, "gearwear_webhook_attempts_total{{outcome=\"{r}\"}} {n}");
        }
        let _ = writeln!(
            o,
            "# HELP gearwear_record_stage_cpu_seconds_total CPU time of the accepted records' \
             path by stage (thread CPU time; the store's own threads, the HTTP layer and the \
             kernel's network work are not in it)."
        );
        let _ = writeln!(o, "# TYPE gearwear_record_stage_cpu_seconds_total counter");
        let stages = self.stages.lock().unwrap();
        for (s, (secs, _)) in stages.iter() {
            let _ = writeln!(
                o,
                "gearwear_record_stage_cpu_seconds_total{{stage=\"{s}\"}} {secs}"
            );
        }
        let _ = writeln!(
            o,
            "# HELP gearwear_record_stage_runs_total How many times each stage ran (once per \
             record, or once per channel of a multichannel record)."
        );
        let _ = writeln!(o, "# TYPE gearwear_record_stage_runs_total counter");
        for (s, (_, n)) in stages.iter() {
            let _ = writeln!(o, "gearwear_record_stage_runs_total{{stage=\"{s}\"}} {n}");
        }
        self.mqtt.render(&mut o);
        o
    }
}
