//! MQTT ingest against a real broker: Debian's `mosquitto`, one instance per test on a free
//! port (persistence on, so the QoS 1 sessions survive its restarts), published to with
//! rumqttc. Skips (with a message) only when mosquitto is absent and `CI` is not set.

use std::path::PathBuf;
use std::process::{Child, Command};
use std::time::Duration;

use gearwear::service::mqtt::MqttSettings;
use gearwear::service::mqtt::payload::with_header;
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};

use crate::helpers::*;

/// A mosquitto of the test's own.
pub(crate) struct Broker {
    port: u16,
    dir: PathBuf,
    child: Option<Child>,
}

/// Debian's mosquitto binary.
const MOSQUITTO: &str = "/usr/sbin/mosquitto";

impl Broker {
    /// A broker of the test's own; `None` (after saying why) when mosquitto is not installed
    /// and `CI` is not set. Under `CI` a missing broker is a failure.
    pub(crate) fn start() -> Option<Broker> {
        if !std::path::Path::new(MOSQUITTO).exists() {
            let msg = format!(
                "{MOSQUITTO} not found (apt-get install -y mosquitto); the MQTT test did NOT run"
            );
            if in_ci() {
                panic!("{msg} (CI is set, so this is a failure)");
            }
            eprintln!("SKIP: {msg}");
            return None;
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let dir =
            std::env::temp_dir().join(format!("gearwear-mqtt-{}", uuid::Uuid::new_v4().simple()));
        std::fs::create_dir_all(&dir).unwrap();
        // Started as root, mosquitto drops to its own user, which must write its database here.
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
        // Room for every message queued for a session (mosquitto's default, 1000, would drop
        // the rest while the service is away; `0`, "no limit", is mishandled by some releases,
        // 2.0.16 and 2.0.21). Everything is logged, to a file kept when the test fails.
        let conf = format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\n\
             persistence_location {d}/\nmax_queued_messages 1000000\n\
             log_dest file {d}/mosquitto.log\nlog_type all\n",
            d = dir.display()
        );
        std::fs::write(dir.join("mosquitto.conf"), conf).unwrap();
        let mut b = Broker {
            port,
            dir,
            child: None,
        };
        b.spawn();
        Some(b)
    }

    fn spawn(&mut self) {
        let child = Command::new(MOSQUITTO)
            .arg("-c")
            .arg(self.dir.join("mosquitto.conf"))
            .spawn()
            .expect("mosquitto starts");
        self.child = Some(child);
        for _ in 0..200 {
            if std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok() {
                return;
            }
            std::thread::sleep(Duration::from_millis(25));
        }
        panic!("mosquitto did not listen on {}", self.port);
    }

    /// SIGTERM (it saves its sessions and queued messages), wait, start again on the port.
    fn restart(&mut self) {
        self.stop();
        self.spawn();
    }

    fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
            c.wait().unwrap();
        }
    }

    fn url(&self) -> String {
        format!("mqtt://127.0.0.1:{}", self.port)
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        if let Some(c) = &mut self.child {
            let _ = c.kill();
            let _ = c.wait();
        }
        if std::thread::panicking() {
            eprintln!("mosquitto's log kept: {}/mosquitto.log", self.dir.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

pub(crate) fn mqtt_settings(broker: &Broker, client_id: &str) -> MqttSettings {
    MqttSettings::parse(
        &broker.url(),
        "plant/+/vibration",
        client_id,
        "gearwear/errors",
    )
    .unwrap()
}

/// A publisher (or listener) with a persistent session whose event loop runs in a task that
/// reconnects; incoming publishes go to the returned channel.
pub(crate) fn client(
    broker: &Broker,
    id: &str,
) -> (
    AsyncClient,
    tokio::sync::mpsc::UnboundedReceiver<rumqttc::Publish>,
) {
    let mut o = MqttOptions::new(id, "127.0.0.1", broker.port);
    o.set_clean_session(false)
        .set_max_packet_size(1 << 20, 1 << 20);
    let (c, mut ev) = AsyncClient::new(o, 100);
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    tokio::spawn(async move {
        loop {
            match ev.poll().await {
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    let _ = tx.send(p);
                }
                Ok(_) => {}
                Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
            }
        }
    });
    (c, rx)
}

async fn count(url: &str, sql: &'static str) -> i64 {
    if url.starts_with("postgres") {
        let pool = sqlx::PgPool::connect(url).await.unwrap();
        let n: (i64,) = sqlx::query_as(sql).fetch_one(&pool).await.unwrap();
        pool.close().await;
        n.0
    } else {
        let pool = sqlx::SqlitePool::connect(&format!("sqlite://{url}"))
            .await
            .unwrap();
        let n: (i64,) = sqlx::query_as(sql).fetch_one(&pool).await.unwrap();
        pool.close().await;
        n.0
    }
}

/// Record `i`: small (0.08 s at 25.6 kHz, 2048 samples), every other one JSON with `record_id`, the rest
/// f32 after a GWR1 header.
fn payload(i: usize) -> Vec<u8> {
    let (x, fs) = record_samples(1.0, 0.08, i as u64);
    if i.is_multiple_of(2) {
        serde_json::json!({"sample_rate_hz": fs, "samples": x, "shaft_hz": 30.0,
                           "record_id": format!("r{i}")})
        .to_string()
        .into_bytes()
    } else {
        let f: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        with_header(
            &format!("sample_rate_hz={fs}&shaft_hz=30&record_id=r{i}"),
            &f,
        )
    }
}

const MACHINES: usize = 4;

/// `n` records over [`MACHINES`] machines, QoS 1, the broker restarted after a third and
/// after two thirds were handed to the publisher: every record stored exactly once.
async fn records_survive_broker_restarts(backend: Backend, n: usize) {
    let Some(mut broker) = Broker::start() else {
        return;
    };
    let settings = mqtt_settings(&broker, "gearwear-test");
    let Some(mut app) = spawn_app(backend, |s| s.mqtt = Some(settings)).await else {
        return;
    };
    // The broker drops what is published before any subscription matches it: publish once
    // the service has subscribed (otherwise the first few dozen records are lost).
    wait_connected(&app).await;
    let started = std::time::Instant::now();
    let (publisher, _) = client(&broker, "test-publisher");
    for i in 0..n {
        let topic = format!("plant/m{}/vibration", i % MACHINES);
        publisher
            .publish(topic, QoS::AtLeastOnce, false, payload(i))
            .await
            .unwrap();
        if i == n / 3 || i == 2 * n / 3 {
            broker.restart();
        }
    }
    let url = app.settings.database_url.clone();
    // A generous bound, so that a stall fails instead of hanging CI.
    let mut stored = 0;
    for k in 0..1200 {
        stored = count(&url, "SELECT COUNT(*) FROM records").await;
        if stored >= n as i64 {
            break;
        }
        if k % 40 == 39 {
            eprintln!("{:.0?}: {stored} of {n} stored", started.elapsed());
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    let took = started.elapsed();
    assert_eq!(stored, n as i64, "records stored of {n} published");
    let metrics: Vec<String> = app
        .get("/metrics")
        .await
        .text()
        .await
        .unwrap()
        .lines()
        .filter(|l| l.starts_with("gearwear_mqtt_"))
        .map(str::to_string)
        .collect();
    // Anything redelivered late is de-duplicated, and the count stays.
    app.stop().await;
    assert_eq!(count(&url, "SELECT COUNT(*) FROM records").await, n as i64);
    assert_eq!(
        count(
            &url,
            "SELECT COUNT(*) FROM idempotency_keys WHERE key_id LIKE 'mqtt:%'"
        )
        .await,
        n as i64,
        "one record id per record"
    );
    for m in 0..MACHINES {
        let row = app
            .store
            .get_machine(&format!("m{m}"))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(
            row.record_count as usize,
            n / MACHINES + usize::from(m < n % MACHINES)
        );
    }
    eprintln!(
        "{backend:?}: {n} records stored once across 2 broker restarts in {took:.1?}; {metrics:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn mqtt_records_are_stored_once_across_broker_restarts_sqlite() {
    records_survive_broker_restarts(Backend::Sqlite, 5000).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn mqtt_records_are_stored_once_across_broker_restarts_postgres() {
    records_survive_broker_restarts(Backend::Postgres, 5000).await;
}

/// A bad payload: its problem on the error topic, and the next good record is stored.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_bad_payload_goes_to_the_error_topic() {
    let Some(broker) = Broker::start() else {
        return;
    };
    let settings = mqtt_settings(&broker, "gearwear-bad");
    let Some(app) = spawn_app(Backend::Sqlite, |s| s.mqtt = Some(settings)).await else {
        return;
    };
    let (listener, mut errors) = client(&broker, "test-errors");
    listener
        .subscribe("gearwear/errors", QoS::AtLeastOnce)
        .await
        .unwrap();
    let (publisher, _) = client(&broker, "test-bad-publisher");
    // Wait for the service's subscription: the metrics say so.
    wait_connected(&app).await;
    // And for the listener's: a probe published to the error topic comes back (on a loaded
    // machine its first connection can fail, and the subscription with it).
    let probe = b"probe".to_vec();
    let mut heard = false;
    for _ in 0..60 {
        publisher
            .publish("gearwear/errors", QoS::AtLeastOnce, false, probe.clone())
            .await
            .unwrap();
        if let Ok(Some(_)) = tokio::time::timeout(Duration::from_secs(1), errors.recv()).await {
            heard = true;
            break;
        }
    }
    assert!(heard, "the listener never heard its probe");
    let bad: [(&str, Vec<u8>); 3] = [
        (
            "plant/m1/vibration",
            b"\x00\x01\x02\x03 not a record".to_vec(),
        ),
        (
            "plant/m1/vibration",
            br#"{"sample_rate_hz": 100, "samples": [1, "x"]}"#.to_vec(),
        ),
        ("plant/bad id/vibration", payload(0)),
    ];
    for (topic, p) in &bad {
        publisher
            .publish(*topic, QoS::AtLeastOnce, false, p.clone())
            .await
            .unwrap();
    }
    let mut slugs = Vec::new();
    while slugs.len() < bad.len() {
        let p = tokio::time::timeout(Duration::from_secs(60), errors.recv())
            .await
            .expect("a problem on gearwear/errors")
            .unwrap();
        if p.payload[..] == probe[..] {
            continue;
        }
        let v: serde_json::Value = serde_json::from_slice(&p.payload).unwrap();
        assert!(v["detail"].as_str().is_some_and(|d| !d.is_empty()), "{v}");
        assert!(v["topic"].as_str().unwrap().starts_with("plant/"), "{v}");
        slugs.push(v["type"].as_str().unwrap().to_string());
    }
    slugs.sort();
    assert_eq!(
        slugs,
        [
            "urn:gearwear:problem:invalid-json",
            "urn:gearwear:problem:invalid-machine-id",
            "urn:gearwear:problem:invalid-mqtt-payload"
        ]
    );
    // Still ingesting: a good record, then the same one again (stored once).
    for _ in 0..2 {
        publisher
            .publish("plant/m1/vibration", QoS::AtLeastOnce, false, payload(1))
            .await
            .unwrap();
    }
    let url = app.settings.database_url.clone();
    let mut stored = 0;
    for _ in 0..240 {
        stored = count(&url, "SELECT COUNT(*) FROM records").await;
        let m = app.get("/metrics").await.text().await.unwrap();
        if stored == 1 && m.contains("gearwear_mqtt_messages_total{outcome=\"duplicate\"} 1") {
            assert!(
                m.contains("gearwear_mqtt_messages_total{outcome=\"refused\"} 3"),
                "{m}"
            );
            break;
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    let mut more = Vec::new();
    while let Ok(p) = errors.try_recv() {
        more.push(String::from_utf8_lossy(&p.payload).to_string());
    }
    assert_eq!(stored, 1, "problems: {more:?}");
}

pub(crate) async fn wait_connected(app: &TestApp) {
    for _ in 0..400 {
        let m = app.get("/metrics").await.text().await.unwrap();
        if m.contains("gearwear_mqtt_connected 1") {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("the service did not subscribe");
}
