//! Gearboxes, machines and baselines through the API, on both stores: a described
//! gearbox's table precomputed in the background (and resumed after a restart), a machine
//! pointed at it, a record diagnosed before and after the table is ready, a baseline that makes
//! a machine the model does not fit judgeable, and the `unknown` state when nothing vouches.

use std::time::{Duration, Instant};

use serde_json::{Value, json};

use gearwear::gearbox::Gearbox;
use gearwear::signature::SensorQuantity;
use gearwear::signature::precompute::{MeasurementSpec, simulate_measurement};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    a_described_gearbox_is_tabled_in_the_background_and_diagnoses_its_machine,
    a_baseline_makes_a_machine_the_model_does_not_fit_judgeable,
    a_baseline_changed_through_one_replica_is_used_by_the_other,
    a_table_job_interrupted_by_a_restart_resumes,
    every_channel_is_diagnosed_and_the_worst_decides,
);

const SPUR: &str = include_str!("../../configs/gearboxes/spur-pair.toml");
const TWO_STAGE: &str = include_str!("../../configs/gearboxes/two-stage-parallel.toml");

pub(crate) async fn put_gearbox(app: &TestApp, id: &str, key: &str, text: &str) -> (u16, Value) {
    let (s, _, body) = checked(
        app.client
            .put(app.url(&format!("/v1/gearboxes/{id}")))
            .bearer_auth(key)
            .header("content-type", "application/toml")
            .body(text.to_string()),
        "PUT",
        "/v1/gearboxes/{gearbox_id}",
    )
    .await;
    (s, json(&body))
}

async fn get_json(app: &TestApp, path: &str, template: &str) -> Value {
    let (s, _, b) = checked(
        app.client.get(app.url(path)).bearer_auth(&app.read_key),
        "GET",
        template,
    )
    .await;
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&b));
    json(&b)
}

async fn post_record(app: &TestApp, machine: &str, query: &str, body: &Value) -> (u16, Value) {
    let (s, _, b) = checked(
        app.client
            .post(app.url(&format!("/v1/machines/{machine}/records{query}")))
            .bearer_auth(&app.ingest_key)
            .json(body),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    (s, json(&b))
}

/// Poll a gearbox until its table is ready (or fail on `failed` / timeout).
async fn wait_ready(app: &TestApp, id: &str, limit: Duration) -> Value {
    let t0 = Instant::now();
    loop {
        let g = get_json(
            app,
            &format!("/v1/gearboxes/{id}"),
            "/v1/gearboxes/{gearbox_id}",
        )
        .await;
        match g["status"].as_str().unwrap() {
            "ready" => return g,
            "failed" => panic!("table job failed: {g}"),
            _ => {}
        }
        assert!(t0.elapsed() < limit, "table not ready after {limit:?}: {g}");
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

/// A simulated 1 s record of a described gearbox at its nominal input rate.
fn described_record(text: &str, ea: f64, seed: u64) -> Value {
    let gb = Gearbox::parse(text, "test").unwrap();
    let hz = gb.description.nominal_input_hz.unwrap();
    let omega1 = gb.f1_hz(hz) / gb.reference_frequency_hz();
    let rec = simulate_measurement(
        &gb,
        &MeasurementSpec {
            ea,
            omega1,
            sample_rate: 25_600.0,
            duration: 1.0,
            gain: 3.0,
            snr_db: Some(25.0),
            seed,
            sensor: SensorQuantity::Accel,
            planetary: None,
        },
    )
    .unwrap();
    json!({"sample_rate_hz": rec.sample_rate, "samples": rec.samples})
}

async fn a_described_gearbox_is_tabled_in_the_background_and_diagnoses_its_machine(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    // The built-in rig is there from the start.
    let list = get_json(&app, "/v1/gearboxes", "/v1/gearboxes").await;
    let rig = &list["gearboxes"][0];
    assert_eq!(
        (rig["id"].as_str(), rig["status"].as_str()),
        (Some("wang2019"), Some("ready"))
    );
    assert_eq!(rig["builtin"], true);

    // A description's own mistake comes back as a 422 naming it; only admin may PUT.
    let bad = SPUR.replace("teeth = 67", "teeth = 0");
    let (s, p) = put_gearbox(&app, "spur", &app.admin_key, &bad).await;
    assert_eq!(s, 422, "{p}");
    assert!(p["detail"].as_str().unwrap().contains("teeth"), "{p}");
    let (s, _) = put_gearbox(&app, "spur", &app.ingest_key, SPUR).await;
    assert_eq!(s, 403);
    let (s, _) = put_gearbox(&app, "wang2019", &app.admin_key, SPUR).await;
    assert_eq!(s, 409);

    let (s, g) = put_gearbox(&app, "spur", &app.admin_key, SPUR).await;
    assert_eq!(s, 201, "{g}");
    assert!(
        matches!(g["status"].as_str(), Some("queued" | "running")),
        "{g}"
    );
    assert_eq!(g["name"], "spur-pair");
    assert!(
        g["assumed"].as_array().is_some_and(|a| !a.is_empty()),
        "{g}"
    );
    // 25 teeth at 25 Hz: the mesh at 625 Hz.
    let meshes = &g["kinematics"]["rates"]["meshes"];
    assert!(
        (meshes[0]["hz"].as_f64().unwrap() - 625.0).abs() < 1e-9,
        "{g}"
    );
    let (s, again) = put_gearbox(&app, "spur", &app.admin_key, SPUR).await;
    assert_eq!((s, &again["hash"]), (200, &g["hash"]));

    // Machines point at stored gearboxes only.
    let (s, p) = put_machine(&app, "m-x", json!({"gearbox": "nope"})).await;
    assert_eq!(
        (s, p["type"].as_str()),
        (422, Some("urn:gearwear:problem:unknown-gearbox"))
    );
    let (s, m) = put_machine(
        &app,
        "m-spur",
        json!({"gearbox": "spur", "input_shaft_hz": 25.0}),
    )
    .await;
    assert_eq!((s, m["gearbox"].as_str()), (201, Some("spur")), "{m}");
    let (s, _) = put_machine(
        &app,
        "m-spur",
        json!({"gearbox": "spur", "input_shaft_hz": 25.0}),
    )
    .await;
    assert_eq!(s, 200);

    // A record before the table is ready is stored and judged without a wear degree; with no
    // baseline either, nothing vouches for the machine: `unknown`, with what to do.
    let early = app.store.get_gearbox("spur").await.unwrap().unwrap();
    if early.status != gearwear::signature::TableStatus::Ready {
        let (s, d) = post_record(&app, "m-spur", "", &described_record(SPUR, 0.3, 1)).await;
        assert_eq!(s, 201, "{d}");
        if d["gearbox"]["table_status"] != "ready" {
            assert!(d["wear_degree"].is_null(), "{d}");
            assert_eq!(d["alert_level"], "unknown", "{d}");
            // The gearbox is described and its table is being computed: the reason says to
            // add a baseline, never to describe the gearbox.
            let reason = d["alert"]["reason"].as_str().unwrap();
            assert!(reason.contains("baseline"), "{d}");
            assert!(
                reason.contains("is being computed") && !reason.contains("PUT /v1/gearboxes"),
                "{reason}"
            );
            assert!(
                d["warnings"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|w| w.as_str().unwrap().contains("is being computed")),
                "{d}"
            );
        }
    }

    let g = wait_ready(&app, "spur", Duration::from_secs(600)).await;
    assert_eq!(g["progress"], 1.0);
    let (s, d) = post_record(&app, "m-spur", "", &described_record(SPUR, 0.3, 2)).await;
    assert_eq!(s, 201, "{d}");
    assert_eq!(d["gearbox"]["id"], "spur");
    assert_eq!(d["gearbox"]["hash"], g["hash"]);
    let w = d["wear_degree"]["estimate"]
        .as_f64()
        .expect("a wear degree once ready");
    assert!((0.0..=1.2).contains(&w), "{d}");
    assert!(
        (d["f1_hz"].as_f64().unwrap() / 625.0 - 1.0).abs() < 0.02,
        "{d}"
    );
    // The machine names its gearbox: its baseline features carry the order analysis, the one
    // the diagnosis made (not a second tracking of the record, which could also disagree).
    let track = &d["indicators"]["order_tracking"];
    assert!(track["tracked_shaft"].is_string(), "{d}");
    assert_eq!(track, &d["order"], "{d}");
    let m = get_json(&app, "/v1/machines/m-spur", "/v1/machines/{machine_id}").await;
    assert_eq!(m["gearbox"]["id"], "spur");
    assert_eq!(m["configuration"]["input_shaft_hz"], 25.0);

    // The record path's CPU by stage is in /metrics, once per diagnosed record.
    let text = app
        .client
        .get(app.url("/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    let runs = |stage: &str| -> f64 {
        let k = format!("gearwear_record_stage_runs_total{{stage=\"{stage}\"}} ");
        text.lines()
            .find_map(|l| l.strip_prefix(k.as_str()))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0)
    };
    let posted = if early.status != gearwear::signature::TableStatus::Ready {
        2.0
    } else {
        1.0
    };
    assert_eq!(runs("features"), posted, "{text}");
    assert!(runs("diagnosis") >= 1.0, "{text}");
    assert!(
        text.contains("gearwear_record_stage_cpu_seconds_total{stage=\"diagnosis\"}"),
        "{text}"
    );
}

async fn a_baseline_makes_a_machine_the_model_does_not_fit_judgeable(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    // No description, no baseline, a record the rig's model does not fit: not `ok`.
    let (s, d) = post_record(&app, "real-1", "", &foreign_record(1, false)).await;
    assert_eq!(s, 201, "{d}");
    assert_eq!(
        d["fit"]["inflated"], true,
        "the test record should not fit the rig: {d}"
    );
    assert_eq!(d["alert_level"], "unknown", "{d}");
    assert!(d["novelty"].is_null());
    let first_record = d["record_id"].as_str().unwrap().to_string();

    // Three healthy records as the baseline; the third one's answer still has no novelty
    // (it was scored before it joined), later ones have.
    for seed in 2..=4 {
        let (s, d) = post_record(
            &app,
            "real-1",
            "?baseline=true",
            &foreign_record(seed, false),
        )
        .await;
        assert_eq!(s, 201, "{d}");
        assert_eq!(d["baseline"]["this_record"], true);
        assert_eq!(
            (d["alert_level"].as_str(), d["alert"]["basis"].as_str()),
            (Some("ok"), Some("baseline")),
            "{d}"
        );
    }
    let (s, d) = post_record(&app, "real-1", "", &foreign_record(5, false)).await;
    assert_eq!(s, 201, "{d}");
    let n = &d["novelty"];
    assert_eq!(n["baseline_records"], 3, "{d}");
    assert_eq!(n["anomalous"], false, "a healthy record flagged: {d}");
    assert_eq!(
        (d["alert_level"].as_str(), d["alert"]["basis"].as_str()),
        (Some("ok"), Some("novelty")),
        "{d}"
    );

    let (s, d) = post_record(&app, "real-1", "", &foreign_record(6, true)).await;
    assert_eq!(s, 201, "{d}");
    assert_eq!(
        d["novelty"]["anomalous"], true,
        "a broken tooth not flagged: {d}"
    );
    assert!(
        matches!(d["alert_level"].as_str(), Some("warning" | "alarm")),
        "{d}"
    );
    assert!(!d["novelty"]["top_features"].as_array().unwrap().is_empty());

    // The machine view: its baseline, novelty over time.
    let m = get_json(&app, "/v1/machines/real-1", "/v1/machines/{machine_id}").await;
    assert_eq!(m["baseline"]["count"], 3);
    assert_eq!(m["baseline"]["ready"], true);
    let trend = m["trend"].as_array().unwrap();
    assert_eq!(trend.len(), 6);
    assert!(trend[0]["novelty"].is_null() && trend[5]["novelty"].as_f64().unwrap() > 0.0);
    assert_eq!(m["alert_level"], d["alert_level"]);

    // Marking afterwards (admin), unmarking, clearing.
    let mark = |ids: Value, key: String| {
        app.client
            .post(app.url("/v1/machines/real-1/baseline"))
            .bearer_auth(key)
            .json(&json!({"record_ids": ids}))
    };
    let (s, _, _) = checked(
        mark(json!([first_record]), app.ingest_key.clone()),
        "POST",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(s, 403);
    let (s, _, body) = checked(
        mark(json!(["no-such-record"]), app.admin_key.clone()),
        "POST",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(s, 422, "{}", String::from_utf8_lossy(&body));
    let (s, _, body) = checked(
        mark(json!([first_record]), app.admin_key.clone()),
        "POST",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    assert_eq!(json(&body)["count"], 4);
    let (s, _, _) = checked(
        app.client
            .delete(app.url(&format!("/v1/machines/real-1/baseline/{first_record}")))
            .bearer_auth(&app.admin_key),
        "DELETE",
        "/v1/machines/{machine_id}/baseline/{record_id}",
    )
    .await;
    assert_eq!(s, 204);
    let bl = get_json(
        &app,
        "/v1/machines/real-1/baseline",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(bl["count"], 3);
    let (s, _, _) = checked(
        app.client
            .delete(app.url("/v1/machines/real-1/baseline"))
            .bearer_auth(&app.admin_key),
        "DELETE",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(s, 204);
    let (s, d) = post_record(&app, "real-1", "", &foreign_record(7, false)).await;
    assert_eq!(
        (s, d["alert_level"].as_str()),
        (201, Some("unknown")),
        "{d}"
    );
}

/// Each replica keeps the baselines it fitted and refits only when the machine's baseline
/// changed: a change made through one replica (records posted as healthy, the baseline
/// cleared, records marked again) is what the other judges the next record by.
async fn a_baseline_changed_through_one_replica_is_used_by_the_other(b: Backend) {
    let Some(a) = spawn_app(b, |_| {}).await else {
        return;
    };
    let mut other = a.replica().await;
    let mut ids = Vec::new();
    for seed in 2..=4 {
        let (s, d) =
            post_record(&a, "shared", "?baseline=true", &foreign_record(seed, false)).await;
        assert_eq!(s, 201, "{d}");
        ids.push(d["record_id"].clone());
    }
    let judged = |d: &Value| {
        (
            d["baseline"]["records"].clone(),
            d["novelty"]["score"].clone(),
        )
    };
    let (s, first) = post_record(&other, "shared", "", &foreign_record(5, false)).await;
    assert_eq!(s, 201, "{first}");
    assert_eq!(first["baseline"]["records"], 3, "{first}");
    assert!(first["novelty"]["score"].as_f64().is_some(), "{first}");
    // Cleared through the first replica: the other has no baseline for the next record.
    let r = a
        .client
        .delete(a.url("/v1/machines/shared/baseline"))
        .bearer_auth(&a.admin_key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 204);
    let (_, d) = post_record(&other, "shared", "", &foreign_record(5, false)).await;
    assert_eq!(judged(&d), (json!(0), Value::Null), "{d}");
    // Marked again through the first: the same baseline, the same judgement as before.
    let r = a
        .client
        .post(a.url("/v1/machines/shared/baseline"))
        .bearer_auth(&a.admin_key)
        .json(&json!({"record_ids": ids}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);
    let (_, d) = post_record(&other, "shared", "", &foreign_record(5, false)).await;
    assert_eq!(judged(&d), judged(&first), "{d}");
    // A fourth healthy record posted through the other replica counts at once on the first.
    let (s, d) = post_record(
        &other,
        "shared",
        "?baseline=true",
        &foreign_record(8, false),
    )
    .await;
    assert_eq!(s, 201, "{d}");
    let (_, d) = post_record(&a, "shared", "", &foreign_record(5, false)).await;
    assert_eq!(d["baseline"]["records"], 4, "{d}");
    other.stop().await;
}

async fn a_table_job_interrupted_by_a_restart_resumes(b: Backend) {
    let Some(mut app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let id = format!("two-stage-{}", gearwear::store::new_id());
    let (s, _) = put_gearbox(&app, &id, &app.admin_key.clone(), TWO_STAGE).await;
    assert_eq!(s, 201);
    // Wait until a replica runs it, then stop that replica mid-job and start another.
    let t0 = Instant::now();
    loop {
        let g = app.store.get_gearbox(&id).await.unwrap().unwrap();
        if g.status == gearwear::signature::TableStatus::Running {
            break;
        }
        assert!(
            g.status == gearwear::signature::TableStatus::Queued,
            "{g:?}"
        );
        assert!(t0.elapsed() < Duration::from_secs(60), "never started");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    app.restart(|_| {}).await;
    let g = wait_ready(&app, &id, Duration::from_secs(600)).await;
    assert!(g["attempts"].as_i64().unwrap() >= 2, "{g}");
}

/// A four-channel CSV (header a1..a4) of foreign records; channel a3 carries the broken tooth
/// when `broken`.
fn four_channel_csv(seed: u64, broken: bool) -> String {
    let cols: Vec<Vec<f64>> = (0..4)
        .map(|c| {
            let r = foreign_record(seed * 10 + c, broken && c == 2);
            r["samples"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap() * (1.0 + 0.3 * c as f64))
                .collect()
        })
        .collect();
    let mut out = String::from("a1,a2,a3,a4\n");
    let rows = cols[0].iter().zip(&cols[1]).zip(&cols[2]).zip(&cols[3]);
    for (((a, b), c), d) in rows {
        out.push_str(&format!("{a},{b},{c},{d}\n"));
    }
    out
}

async fn every_channel_is_diagnosed_and_the_worst_decides(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let post = |query: &str, csv: String| {
        app.client
            .post(app.url(&format!(
                "/v1/machines/multi/records?sample_rate_hz=25600{query}"
            )))
            .bearer_auth(&app.ingest_key)
            .header("content-type", "text/csv")
            .body(csv)
    };
    // The four-column CSV that failed over HTTP ("choose one with --column") is diagnosed
    // channel by channel; no error names a CLI flag.
    let (s, _, body) = checked(
        post("", four_channel_csv(1, false)),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    let d = json(&body);
    let names: Vec<&str> = d["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["a1", "a2", "a3", "a4"]);
    assert!(names.contains(&d["channel"].as_str().unwrap()));
    let (s, _, body) = checked(
        post("&channel=a9", four_channel_csv(1, false)),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 422);
    let p = json(&body);
    assert!(
        p["detail"].as_str().unwrap().contains("a4")
            && !p["detail"].as_str().unwrap().contains("--"),
        "{p}"
    );
    let (s, _, body) = checked(
        post("&channel=a2", four_channel_csv(2, false)),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 201);
    let d = json(&body);
    assert_eq!(d["channel"], "a2");
    assert!(d.get("channels").is_none(), "one channel asked for: {d}");

    // A baseline per channel; then the broken tooth on a3 decides.
    for seed in 3..=5 {
        let (s, _, _) = checked(
            post("&baseline=true", four_channel_csv(seed, false)),
            "POST",
            "/v1/machines/{machine_id}/records",
        )
        .await;
        assert_eq!(s, 201);
    }
    let bl = get_json(
        &app,
        "/v1/machines/multi/baseline",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(bl["channels"]["a1"]["records"], 3, "{bl}");
    assert_eq!(bl["channels"]["a2"]["records"], 3, "{bl}");
    let (s, _, body) = checked(
        post("", four_channel_csv(6, true)),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 201);
    let d = json(&body);
    assert_eq!(d["channel"], "a3", "{}", d["channels"]);
    assert!(
        matches!(d["alert_level"].as_str(), Some("warning" | "alarm")),
        "{d}"
    );
    for c in d["channels"].as_array().unwrap() {
        if c["name"] != "a3" {
            assert_eq!(c["alert_level"], "ok", "{c}");
        }
    }
    // A gzip-compressed body (Content-Encoding: gzip) is the same record.
    let gz = {
        use std::io::Write;
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(four_channel_csv(1, false).as_bytes()).unwrap();
        e.finish().unwrap()
    };
    let (s, _, body) = checked(
        app.client
            .post(app.url("/v1/machines/multi-gz/records?sample_rate_hz=25600"))
            .bearer_auth(&app.ingest_key)
            .header("content-type", "text/csv")
            .header("content-encoding", "gzip")
            .body(gz),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    assert_eq!(json(&body)["channels"].as_array().unwrap().len(), 4);
    // JSON channels too.
    let r = foreign_record(9, false);
    let body =
        json!({"sample_rate_hz": 25600.0, "channels": {"a1": r["samples"], "a2": r["samples"]}});
    let (s, d) = post_record(&app, "multi-json", "", &body).await;
    assert_eq!(s, 201, "{d}");
    assert_eq!(d["channels"].as_array().unwrap().len(), 2);
}
