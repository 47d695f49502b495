//! The record page's evidence plot is drawn off the record path, on both stores: a machine
//! with the PHM 2009 helical gearbox described and a tachometer, two healthy records and a
//! damaged one. Right after each POST its stored diagnosis holds no plot; the first
//! `GET /v1/diagnoses/{id}` draws the record's plot and its healthy reference's from the stored
//! samples and stores them; a second GET answers the same. The plot is the one the record path
//! draws when no raw samples are kept (`--raw-retention-days 0`, drawn and stored on the path):
//! the record's samples are f32-exact, so the stored samples are the posted ones.

use serde_json::{Value, json};

use crate::both_stores;
use crate::gearboxes::put_gearbox;
use crate::helpers::*;
use crate::operating_state::{FS, HELICAL, PPR, channels};

both_stores!(the_evidence_plot_is_drawn_when_first_asked_for);

/// [`channels`] as a JSON record body at low load, every sample f32-exact.
fn record(seed: u64, idler_damage: bool) -> Value {
    let chans: serde_json::Map<String, Value> = channels(35.0, seed, idler_damage)
        .into_iter()
        .map(|(n, x)| {
            let x: Vec<f64> = x.iter().map(|v| *v as f32 as f64).collect();
            (n.to_string(), json!(x))
        })
        .collect();
    json!({"sample_rate_hz": FS, "channels": chans, "load": "low"})
}

/// The stored `evidence` of diagnosis `id`, parsed.
async fn stored(app: &TestApp, id: &str) -> Value {
    let d = app.store.get_diagnosis(id).await.unwrap().unwrap();
    serde_json::from_str(&d.evidence).unwrap()
}

/// A machine `gb` of the helical gearbox with its tachometer; the diagnosis ids of two healthy
/// records and a damaged one.
async fn machine_with_records(app: &TestApp) -> [String; 3] {
    let (s, g) = put_gearbox(app, "helical", &app.admin_key, HELICAL).await;
    assert_eq!(s, 201, "{g}");
    let config = json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": PPR});
    let (s, m) = put_machine(app, "gb", config).await;
    assert_eq!(s, 201, "{m}");
    let mut ids = Vec::new();
    for (query, seed, damaged) in [
        ("?baseline=true", 1, false),
        ("?baseline=true", 2, false),
        ("", 102, true),
    ] {
        let (s, _, b) = checked(
            app.client
                .post(app.url(&format!("/v1/machines/gb/records{query}")))
                .bearer_auth(&app.ingest_key)
                .json(&record(seed, damaged)),
            "POST",
            "/v1/machines/{machine_id}/records",
        )
        .await;
        let b = json(&b);
        assert_eq!(s, 201, "{b}");
        ids.push(b["id"].as_str().unwrap().to_string());
    }
    ids.try_into().unwrap()
}

/// `GET /v1/diagnoses/{id}`'s `evidence`.
async fn evidence(app: &TestApp, id: &str) -> Value {
    let (s, _, b) = checked(
        app.client
            .get(app.url(&format!("/v1/diagnoses/{id}")))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/diagnoses/{diagnosis_id}",
    )
    .await;
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&b));
    json(&b)["evidence"].clone()
}

async fn the_evidence_plot_is_drawn_when_first_asked_for(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let ids = machine_with_records(&app).await;
    for id in &ids {
        let ev = stored(&app, id).await;
        assert!(
            ev.get("orders").is_none(),
            "no plot is stored with the record: {}",
            &ev.to_string()[..ev.to_string().len().min(300)]
        );
    }
    let [healthy_a, healthy_b, damaged] = &ids;

    let ev = evidence(&app, damaged).await;
    assert!(
        ev["orders"]["level_db"]
            .as_array()
            .is_some_and(|l| !l.is_empty()),
        "a plot"
    );
    assert!(
        ev["lines"].as_array().is_some_and(|l| !l.is_empty()),
        "marked lines"
    );
    let reference = &ev["reference"];
    assert!(reference["orders"].is_object(), "a healthy reference");
    assert_eq!(reference["same_load"], true);
    // Drawn once, then stored: the record's plot and the reference's.
    let mut plot = ev.clone();
    plot.as_object_mut().unwrap().remove("reference");
    assert!(
        stored(&app, damaged).await == plot,
        "the plot answered is stored"
    );
    let reference_id = reference["diagnosis_id"].as_str().unwrap();
    assert!(
        [healthy_a, healthy_b]
            .iter()
            .any(|h| h.as_str() == reference_id)
    );
    assert!(
        stored(&app, reference_id).await["orders"] == reference["orders"],
        "the reference's plot is stored"
    );
    assert!(
        evidence(&app, damaged).await == ev,
        "the second GET answers the same"
    );

    // Without raw samples the path draws the plot and stores it: the same plot.
    let Some(path) = spawn_app(b, |s| s.raw_retention = std::time::Duration::ZERO).await else {
        return;
    };
    let on_path = machine_with_records(&path).await;
    let drawn = stored(&path, &on_path[2]).await;
    assert!(
        drawn["orders"].is_object(),
        "drawn on the path without raw samples"
    );
    assert!(drawn == plot, "the plot drawn when asked for is the path's");
    let ev_path = evidence(&path, &on_path[2]).await;
    assert!(
        ev_path["reference"]["orders"] == reference["orders"],
        "the reference's orders"
    );
    assert!(
        ev_path["reference"]["envelope"] == reference["envelope"],
        "the reference's envelope"
    );
}
