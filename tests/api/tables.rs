//! Tables where the machines run, through the API on both stores: a gearbox described without
//! `nominal_input_hz` whose machine is configured at 40 Hz gets a table over 34–46 Hz; a
//! machine configuration that would need a table past the simulation limit is a 422 and
//! nothing is stored; a record at a speed outside the table is answered `table-in-progress`,
//! the table is extended in the background (and stays ready meanwhile), and the record is read
//! again: its latest diagnosis has a reading, replaces the first, and goes to the webhooks as
//! `diagnosis.created`.

use std::time::{Duration, Instant};

use serde_json::{Value, json};

use gearwear::gearbox::Gearbox;
use gearwear::signature::SensorQuantity;
use gearwear::signature::precompute::{MeasurementSpec, simulate_measurement};

use crate::both_stores;
use crate::helpers::*;

both_stores!(a_table_is_laid_where_the_machines_run_and_extended_to_a_record);

const SPUR: &str = include_str!("../../configs/gearboxes/phm09-spur.toml");

/// The PHM 2009 spur gearbox described without its nominal rate.
pub(crate) fn spur_without_nominal() -> String {
    SPUR.lines()
        .filter(|l| !l.starts_with("nominal_input_hz"))
        .collect::<Vec<_>>()
        .join("\n")
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

async fn gearbox(app: &TestApp, id: &str) -> Value {
    get_json(
        app,
        &format!("/v1/gearboxes/{id}"),
        "/v1/gearboxes/{gearbox_id}",
    )
    .await
}

/// Poll gearbox `id` until `done` holds (or fail on a failed table / timeout).
pub(crate) async fn wait_gearbox(
    app: &TestApp,
    id: &str,
    what: &str,
    limit: Duration,
    done: impl Fn(&Value) -> bool,
) -> Value {
    let t0 = Instant::now();
    loop {
        let g = gearbox(app, id).await;
        assert_ne!(g["status"], "failed", "{g}");
        assert_ne!(g["extension"]["status"], "failed", "{g}");
        if done(&g) {
            return g;
        }
        assert!(t0.elapsed() < limit, "{what}: not after {limit:?}: {g}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Whether gearbox view `g` is ready with no extension pending and covers `lo`–`hi` Hz.
pub(crate) fn covers(g: &Value, lo: f64, hi: f64) -> bool {
    let c = &g["covers"];
    g["status"] == "ready"
        && g["extension"].is_null()
        && c["lo_hz"].as_f64().is_some_and(|l| l <= lo + 1e-3)
        && c["hi_hz"].as_f64().is_some_and(|h| h >= hi - 1e-3)
}

/// A simulated 1 s record of `gb` at input rate `hz` (wear 0.3), as a JSON body.
fn record_at(gb: &Gearbox, hz: f64, seed: u64) -> Value {
    let rec = simulate_measurement(
        gb,
        &MeasurementSpec {
            ea: 0.3,
            omega1: gb.f1_hz(hz) / gb.reference_frequency_hz(),
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

async fn a_table_is_laid_where_the_machines_run_and_extended_to_a_record(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let text = spur_without_nominal();
    assert_eq!(put_gearbox(&app, "spur", &text).await, 201);
    // A webhook that hears every new diagnosis (its receiver is not there: the deliveries
    // are listed all the same).
    let req = app
        .client
        .post(app.url("/v1/webhooks"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"url": "http://127.0.0.1:9/hook", "events": ["diagnosis.created"]}));
    let (s, _, hook) = checked(req, "POST", "/v1/webhooks").await;
    assert_eq!(s, 201);
    let hook = json(&hook);

    // The machine at 40 Hz: the table is laid over 34–46 Hz (± 15 %).
    let t0 = Instant::now();
    let (s, m) = put_machine(
        &app,
        "m40",
        json!({"gearbox": "spur", "input_shaft_hz": 40.0}),
    )
    .await;
    assert_eq!(s, 201, "{m}");
    assert_eq!(m["speed_range_hz"], Value::Null, "{m}");
    let g = wait_gearbox(
        &app,
        "spur",
        "a table over 34–46 Hz",
        Duration::from_secs(120),
        |g| covers(g, 34.0, 46.0),
    )
    .await;
    eprintln!(
        "{b:?}: a table over {:.2}–{:.2} Hz ({} columns) {:.1} s after the machine's PUT",
        g["covers"]["lo_hz"],
        g["covers"]["hi_hz"],
        g["covers"]["columns"],
        t0.elapsed().as_secs_f64()
    );

    // A speed range the table could not cover within the simulation limit: 422, nothing stored.
    let (s, p) = put_machine(
        &app,
        "m40",
        json!({"gearbox": "spur", "input_shaft_hz": 40.0, "speed_range_hz": [1.0, 400.0]}),
    )
    .await;
    assert_eq!(s, 422, "{p}");
    assert_eq!(p["type"], "urn:gearwear:problem:table-too-large", "{p}");
    assert_eq!(p["member"], "speed_range_hz", "{p}");
    assert!(p["detail"].as_str().unwrap().contains("simulations"), "{p}");
    assert!(
        p["simulations"].as_u64().unwrap() > p["limit"].as_u64().unwrap(),
        "{p}"
    );
    let view = get_json(&app, "/v1/machines/m40", "/v1/machines/{machine_id}").await;
    assert_eq!(
        view["configuration"]["speed_range_hz"],
        Value::Null,
        "{view}"
    );
    // Nor is a range the wrong way round.
    let (s, p) = put_machine(
        &app,
        "m40",
        json!({"gearbox": "spur", "speed_range_hz": [46.0, 34.0]}),
    )
    .await;
    assert_eq!(
        (s, p["member"].as_str()),
        (422, Some("speed_range_hz")),
        "{p}"
    );
    // A range within the limit is kept (and the table covers it already).
    let (s, m) = put_machine(
        &app,
        "m40",
        json!({"gearbox": "spur", "input_shaft_hz": 40.0, "speed_range_hz": [36.0, 44.0]}),
    )
    .await;
    assert_eq!(
        (s, &m["speed_range_hz"]),
        (200, &json!([36.0, 44.0])),
        "{m}"
    );

    // A record at 56 Hz, outside the table: no wear figure yet, its speed queued.
    let gb = Gearbox::parse(&text, "test").unwrap();
    let (s, first) = post_record(&app, "m40", "?shaft_hz=56", &record_at(&gb, 56.0, 7)).await;
    assert_eq!(s, 201, "{first}");
    assert_eq!(first["wear_withheld"], "table-in-progress", "{first}");
    assert_eq!(first["wear_degree"], Value::Null, "{first}");
    let note = first["wear_note"].as_str().unwrap();
    assert!(
        note.contains("being extended") && note.contains("extension is"),
        "{note}"
    );
    assert!(
        !note.contains("gearwear "),
        "no CLI command in an answer: {note}"
    );
    let record_id = first["record_id"].as_str().unwrap().to_string();

    // The table is extended to it (56 Hz ± 7.5 %) and stays ready meanwhile.
    let g = wait_gearbox(
        &app,
        "spur",
        "an extension to 56 Hz",
        Duration::from_secs(180),
        |g| {
            assert_eq!(g["status"], "ready", "{g}");
            covers(g, 34.0, 56.0 * 1.075)
        },
    )
    .await;
    eprintln!(
        "{b:?}: extended to {:.2}–{:.2} Hz ({} columns)",
        g["covers"]["lo_hz"], g["covers"]["hi_hz"], g["covers"]["columns"]
    );

    // The record read again: its latest diagnosis has a reading and replaces the first.
    let t0 = Instant::now();
    let again = loop {
        let r = get_json(
            &app,
            &format!("/v1/records/{record_id}"),
            "/v1/records/{record_id}",
        )
        .await;
        if r["id"] != first["id"] {
            break r;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "not read again: {r}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    assert_eq!(again["replaces"], first["id"], "{again}");
    let d = &again["diagnosis"];
    assert!(
        d["f1_hz"]
            .as_f64()
            .is_some_and(|f| (f / (32.0 * 56.0) - 1.0).abs() < 0.02),
        "{d}"
    );
    assert_ne!(d["wear_withheld"], "table-in-progress", "{d}");
    assert!(
        d["wear_degree"]["estimate"].is_number() || d["wear_note"].is_string(),
        "a reading: {d}"
    );
    let list = get_json(
        &app,
        "/v1/machines/m40/diagnoses",
        "/v1/machines/{machine_id}/diagnoses",
    )
    .await;
    let items = list["items"].as_array().unwrap();
    assert_eq!(items.len(), 2, "{list}");
    assert_eq!(items[0]["reread"], "done", "{list}");
    assert_eq!(items[1]["replaces"], first["id"], "{list}");
    // The machine's view and trend show the re-read one only.
    let view = get_json(&app, "/v1/machines/m40", "/v1/machines/{machine_id}").await;
    assert_eq!(view["latest"]["id"], again["id"], "{view}");
    assert_eq!(view["trend"].as_array().unwrap().len(), 1, "{view}");
    // Both went to the webhook as `diagnosis.created`, the second saying what it replaces.
    let hook_id = hook["id"].as_str().unwrap();
    let t0 = Instant::now();
    loop {
        let (s, _, body) = checked(
            app.client
                .get(app.url(&format!("/v1/webhooks/{hook_id}/deliveries")))
                .bearer_auth(&app.admin_key),
            "GET",
            "/v1/webhooks/{webhook_id}/deliveries",
        )
        .await;
        assert_eq!(s, 200);
        let ds = json(&body);
        let ds = ds["deliveries"].as_array().unwrap().clone();
        let replaced = ds
            .iter()
            .filter(|d| d["event"] == "diagnosis.created")
            .filter(|d| d["payload"]["replaces"] == first["id"])
            .count();
        if ds.len() == 2 && replaced == 1 {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "{ds:?}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}
