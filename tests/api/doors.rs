//! The three doors a record comes in by — `POST …/records`, an MQTT message, `gearwear
//! diagnose` — give one assessment, on both stores: a machine with a described two-stage
//! gearbox (its table computed by the service, handed to the CLI as a file) and a tachometer,
//! a state-aware baseline of twelve healthy records at three speeds and two loads (posted with
//! `?baseline=true`; the CLI reads the same records through a manifest), and a record with a
//! damaged idler shaft sent through each door. The answers are compared field by field (the
//! CLI's output against the service's diagnosis, every field but the ids and the time the
//! service adds). Without mosquitto the MQTT door is left out (and said so) outside CI.

use std::path::Path;
use std::time::Duration;

use rumqttc::QoS;
use serde_json::{Value, json};

use crate::assessment::{assert_same_assessment, tmpdir};
use crate::both_stores;
use crate::helpers::*;
use crate::mqtt::{Broker, client, mqtt_settings, wait_connected};
use crate::operating_state::{FS, HELICAL, PPR, channels, get, record, wait_ready};
use crate::tables::{covers, wait_gearbox};

both_stores!(http_mqtt_and_the_cli_assess_a_record_alike);

/// [`channels`] as a CSV file (`tacho,a1,a2`, no time column): the same numbers as the JSON
/// body, which both read exactly.
fn write_csv(path: &Path, input_hz: f64, seed: u64, damaged: bool) {
    let [(_, t), (_, a1), (_, a2)] = channels(input_hz, seed, damaged);
    let mut s = String::from("tacho,a1,a2\n");
    for i in 0..t.len() {
        s.push_str(&format!("{},{},{}\n", t[i], a1[i], a2[i]));
    }
    std::fs::write(path, s).unwrap();
}

pub(crate) async fn post(app: &TestApp, query: &str, body: &Value) -> Value {
    let r = app
        .client
        .post(app.url(&format!("/v1/machines/gb/records{query}")))
        .bearer_auth(&app.ingest_key)
        .json(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    r.json().await.unwrap()
}

/// The diagnosis the service stored for the `n`-th record of machine `gb` (waits for it).
async fn stored_diagnosis(app: &TestApp, n: i64) -> Value {
    for _ in 0..240 {
        let m: Value = app.get("/v1/machines/gb").await.json().await.unwrap();
        if m["record_count"].as_i64() == Some(n) {
            let id = m["last_diagnosis_id"].as_str().unwrap().to_string();
            let d: Value = app
                .get(&format!("/v1/diagnoses/{id}"))
                .await
                .json()
                .await
                .unwrap();
            return d["diagnosis"].clone();
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    panic!("the MQTT record was not stored");
}

async fn http_mqtt_and_the_cli_assess_a_record_alike(b: Backend) {
    let broker = Broker::start();
    let settings = broker
        .as_ref()
        .map(|br| mqtt_settings(br, "gearwear-doors"));
    let Some(app) = spawn_app(b, |s| s.mqtt = settings).await else {
        return;
    };
    let dir = tmpdir("doors");
    let gearbox = dir.join("helical.toml");
    std::fs::write(&gearbox, HELICAL).unwrap();
    let r = app
        .client
        .put(app.url("/v1/gearboxes/helical"))
        .bearer_auth(&app.admin_key)
        .header("content-type", "application/toml")
        .body(HELICAL)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let (s, m) = put_machine(
        &app,
        "gb",
        // Its speeds: the table covers them before any record comes (none is read again
        // after an extension, so the table handed to the CLI is the one every record met).
        json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": PPR,
               "speed_range_hz": [27.0, 44.0]}),
    )
    .await;
    assert_eq!(s, 201, "{m}");
    wait_ready(&app, "helical").await;
    wait_gearbox(
        &app,
        "helical",
        "the table over 27–44 Hz",
        Duration::from_secs(300),
        |g| covers(g, 27.0, 44.0),
    )
    .await;
    let row = app.store.get_gearbox("helical").await.unwrap().unwrap();
    let table = app
        .store
        .gearbox_table("helical", &row.hash)
        .await
        .unwrap()
        .expect("the service's table");
    let table_path = dir.join("helical-table.json");
    std::fs::write(&table_path, table).unwrap();

    // The baseline: two records at each of three speeds, at two loads.
    let mut manifest = String::from("file,shaft_hz,load\n");
    let mut seed = 0;
    for load in ["low", "high"] {
        for hz in [30.0, 30.0, 35.0, 35.0, 40.0, 40.0] {
            seed += 1;
            let a = post(
                &app,
                &format!("?baseline=true&load={load}"),
                &record(hz, seed, false, None),
            )
            .await;
            assert_eq!(a["baseline"]["this_record"], true, "{a}");
            let file = format!("h{seed}.csv");
            write_csv(&dir.join(&file), hz, seed, false);
            manifest.push_str(&format!("{file},,{load}\n"));
        }
    }
    std::fs::write(dir.join("manifest.csv"), manifest).unwrap();

    // The machine's own model, fitted by the service in the background: every door reads the
    // damaged record against it (or, refused, through the calibrated path).
    let t0 = std::time::Instant::now();
    let physics = loop {
        let b = get(
            &app,
            "/v1/machines/gb/baseline",
            "/v1/machines/{machine_id}/baseline",
        )
        .await;
        let p = b["physics"].clone();
        match p["status"].as_str() {
            Some("ready" | "refused") if p["current"] == true => break p,
            Some("failed") => panic!("{p}"),
            _ => {}
        }
        assert!(t0.elapsed() < Duration::from_secs(400), "not done: {p}");
        tokio::time::sleep(Duration::from_millis(500)).await;
    };
    eprintln!("the machine's own model: {}", physics["status"]);

    // The damaged record through each door.
    let damaged = record(35.0, 102, true, Some("low"));
    let http = post(&app, "", &damaged).await;
    let rec = dir.join("damaged.csv");
    write_csv(&rec, 35.0, 102, true);
    let cli: Value = serde_json::from_str(&gearwear_ok(&[
        "diagnose",
        "--input",
        rec.to_str().unwrap(),
        "--sample-rate",
        &FS.to_string(),
        "--gearbox",
        gearbox.to_str().unwrap(),
        "--table",
        table_path.to_str().unwrap(),
        "--tacho-column",
        "tacho",
        "--tacho-ppr",
        &PPR.to_string(),
        "--load",
        "low",
        "--baseline-manifest",
        dir.join("manifest.csv").to_str().unwrap(),
        "--model-report",
        dir.join("model.json").to_str().unwrap(),
    ]))
    .unwrap();

    // The machine's calibrated model: the CLI's report and the service's baseline agree.
    let baseline = get(
        &app,
        "/v1/machines/gb/baseline",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    let cli_model: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model.json")).unwrap()).unwrap();
    for ch in ["a1", "a2"] {
        let served = &baseline["channels"][ch]["model"];
        assert!(served["status"].is_string(), "{served}");
        assert_eq!(&cli_model[ch], served, "channel {ch}");
    }

    // Not a vacuous comparison: state-aware, with findings and an alert.
    assert_eq!(http["baseline"]["records"], 12, "{http}");
    assert!(http["state_reference"].is_object(), "{http}");
    assert!(
        !http["findings"].as_array().unwrap().is_empty(),
        "{}",
        http["findings"]
    );
    assert!(
        matches!(http["alert"]["level"].as_str(), Some("warning" | "alarm")),
        "{}",
        http["alert"]
    );
    assert_same_assessment(&http, &cli);

    match &broker {
        Some(broker) => {
            wait_connected(&app).await;
            let (publisher, _) = client(broker, "doors-publisher");
            let mut payload = damaged.clone();
            payload["record_id"] = "damaged-1".into();
            publisher
                .publish(
                    "plant/gb/vibration",
                    QoS::AtLeastOnce,
                    false,
                    payload.to_string().into_bytes(),
                )
                .await
                .unwrap();
            let mqtt = stored_diagnosis(&app, 14).await;
            let mut diffs = Vec::new();
            crate::assessment::differences("$", &mqtt, &cli, &mut diffs);
            assert!(
                diffs.is_empty(),
                "MQTT and the CLI disagree on {} field(s):\n{}",
                diffs.len(),
                diffs.join("\n")
            );
        }
        None => eprintln!("SKIP: no MQTT broker; the MQTT door was not compared"),
    }
    std::fs::remove_dir_all(dir).ok();
}
