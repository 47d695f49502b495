//! Physical units through the API, on both stores: a machine whose channel is
//! declared in volts with an accelerometer's sensitivity and an ISO 20816-3 class answers a
//! synthetic record with the analytic acceleration, velocity and zone (and `gearwear diagnose`
//! with the same flags prints the same figures); units that cannot be converted are refused
//! with a 422 that names the member, and nothing is stored.

use std::f64::consts::TAU;

use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    a_machine_with_units_answers_in_physical_units,
    units_that_cannot_be_converted_are_refused,
);

/// Volts per unit of [`record_samples`], and the accelerometer's sensitivity (mV/g).
const VOLTS: f64 = 0.12;
const MV_PER_G: f64 = 100.0;
const G: f64 = 9.806_65;

fn close(measured: &Value, truth: f64, tol: f64, what: &str) {
    let m = measured
        .as_f64()
        .unwrap_or_else(|| panic!("{what}: {measured}"));
    assert!(
        (m / truth - 1.0).abs() < tol,
        "{what}: {m} vs analytic {truth}"
    );
}

async fn a_machine_with_units_answers_in_physical_units(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let config = json!({
        "channels": ["a1"],
        "channel_units": {"a1": {"unit": "V", "sensitivity_mv_per_g": MV_PER_G}},
        "iso_20816": {"group": 2, "support": "rigid"},
    });
    let (s, m) = put_machine(&app, "u-1", config.clone()).await;
    assert_eq!(s, 201, "{m}");
    assert_eq!(m["channel_units"], config["channel_units"]);
    assert_eq!(m["iso_20816"], config["iso_20816"]);

    // The rig's kinematic lines at Ω1 = 1.07 (f1 = 930.9 Hz), in volts.
    let omega1 = 1.07;
    let (x, fs) = record_samples(omega1, 1.0, 5);
    let volts: Vec<f64> = x.iter().map(|v| VOLTS * v).collect();
    let (s, _, body) = checked(
        app.client
            .post(app.url("/v1/machines/u-1/records"))
            .bearer_auth(&app.ingest_key)
            .json(&json!({"sample_rate_hz": fs, "channels": {"a1": volts}})),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    let d = json(&body);
    assert_eq!(s, 201, "{d}");

    // The analytic figures: 1 V is 10 g; the lines' acceleration RMS in quadrature; each line
    // in 10–1000 Hz (all but 2 f1 = 1862 Hz) integrated, A / (2πf).
    let per_unit = VOLTS * 1000.0 / MV_PER_G * G;
    let f1 = omega1 * 870.0;
    let accel_rms = per_unit * (RECORD_LINES.iter().map(|(_, a)| a * a / 2.0).sum::<f64>()).sqrt();
    let velocity_mm_s = 1000.0
        * per_unit
        * RECORD_LINES
            .iter()
            .filter(|(r, _)| r * f1 <= 1000.0)
            .map(|(r, a)| (a / (TAU * r * f1)).powi(2) / 2.0)
            .sum::<f64>()
            .sqrt();
    let mean = volts.iter().sum::<f64>() / volts.len() as f64;
    let peak = volts.iter().fold(0.0_f64, |m, v| m.max((v - mean).abs())) * 1000.0 / MV_PER_G * G;
    let v = &d["vibration"];
    assert_eq!(v["unit"], "V");
    assert_eq!(v["sensitivity_mv_per_g"], MV_PER_G);
    // The noise (±0.01 uniform) adds 3e-5 to the acceleration's power and 2e-4 to the
    // velocity's.
    close(
        &v["acceleration_rms_m_s2"],
        accel_rms,
        1e-3,
        "acceleration RMS",
    );
    close(
        &v["acceleration_rms_g"],
        accel_rms / G,
        1e-3,
        "acceleration RMS (g)",
    );
    close(
        &v["acceleration_peak_m_s2"],
        peak,
        1e-12,
        "acceleration peak",
    );
    close(
        &v["acceleration_peak_g"],
        peak / G,
        1e-12,
        "acceleration peak (g)",
    );
    close(&v["velocity_rms_mm_s"], velocity_mm_s, 1e-3, "velocity RMS");
    assert_eq!(v["velocity_band_hz"], json!([10.0, 1000.0]));
    // 1.96 mm/s: zone B of a medium machine on a rigid support (1.4 to 2.8 mm/s).
    assert!((1.4..2.8).contains(&velocity_mm_s), "{velocity_mm_s}");
    let zone = &v["iso_20816_3"];
    assert_eq!(zone["zone"], "B", "{zone}");
    assert_eq!(
        zone["boundaries_mm_s"],
        json!({"a_b": 1.4, "b_c": 2.8, "c_d": 4.5})
    );
    // The wear degree in µm: the built-in rig's reference length is 5 µm.
    if let Some(ea) = d["wear_degree"]["estimate"].as_f64() {
        close(
            &d["wear_degree_um"]["estimate"],
            5.0 * ea,
            1e-12,
            "wear in µm",
        );
        assert_eq!(d["wear_degree_um"]["reference_length_um"], 5.0);
    } else {
        assert!(d.get("wear_degree_um").is_none(), "{d}");
    }

    // The machine's view: its configuration and the latest figures.
    let (s, _, body) = checked(
        app.client
            .get(app.url("/v1/machines/u-1"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}",
    )
    .await;
    assert_eq!(s, 200);
    let mv = json(&body);
    assert_eq!(
        mv["configuration"]["channel_units"],
        config["channel_units"]
    );
    assert_eq!(mv["configuration"]["iso_20816"], config["iso_20816"]);
    assert_eq!(mv["latest"]["vibration"], d["vibration"]);

    // `gearwear diagnose` with the same flags on the same samples prints the same figures.
    let dir = std::env::temp_dir().join(format!("gearwear-units-{}", uuid::Uuid::new_v4()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("a1.csv");
    let text: String = volts.iter().map(|v| format!("{v:?}\n")).collect();
    std::fs::write(&csv, text).unwrap();
    let cli: Value = serde_json::from_str(&gearwear_ok(&[
        "diagnose",
        "--input",
        csv.to_str().unwrap(),
        "--sample-rate",
        "25600",
        "--unit",
        "V",
        "--sensitivity",
        "100mV/g",
        "--iso-group",
        "2",
        "--iso-support",
        "rigid",
    ]))
    .unwrap();
    assert_eq!(cli["vibration"], d["vibration"]);
    assert_eq!(cli.get("wear_degree_um"), d.get("wear_degree_um"));
    std::fs::remove_dir_all(dir).ok();

    // A machine without units answers as before: no `vibration` at all; a record the rig's
    // model explains has its wear in µm (the built-in rig's reference length is 5 µm).
    let (s, _, body) = checked(
        app.client
            .post(app.url("/v1/machines/plain/records"))
            .bearer_auth(&app.ingest_key)
            .json(&json_record(2)),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 201);
    let plain = json(&body);
    assert!(plain.get("vibration").is_none(), "{plain}");
    assert!(plain["channels"].is_null());
    let ea = &plain["wear_degree"];
    let um = &plain["wear_degree_um"];
    assert_eq!(um["reference_length_um"], 5.0, "{plain}");
    for k in ["estimate", "lower", "upper"] {
        close(&um[k], 5.0 * ea[k].as_f64().unwrap(), 1e-12, k);
    }
}

async fn units_that_cannot_be_converted_are_refused(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let unit = |u: Value| json!({"channel_units": {"a1": u}});
    for (body, slug, member, says) in [
        (
            unit(json!({"unit": "V"})),
            "invalid-unit",
            "channel_units.a1",
            "sensitivity_mv_per_g",
        ),
        (
            unit(json!({"unit": "furlong/s"})),
            "invalid-unit",
            "channel_units.a1",
            "not a unit gearwear converts",
        ),
        (
            unit(json!({"unit": "µm"})),
            "invalid-unit",
            "channel_units.a1",
            "displacement",
        ),
        (
            unit(json!({"unit": "g", "sensitivity_mv_per_g": 100})),
            "invalid-unit",
            "channel_units.a1",
            "remove the sensitivity",
        ),
        (
            unit(json!({"unit": "V", "sensitivity_mv_per_g": 0})),
            "invalid-unit",
            "channel_units.a1",
            "0 mV/g",
        ),
        (
            unit(json!({"unit": "V", "sensitivity_mv_per_g": 100, "sensitivity_mv_per_mm_s": 4})),
            "invalid-unit",
            "channel_units.a1",
            "one sensitivity",
        ),
        (
            json!({"channels": ["a1"], "channel_units": {"a2": {"unit": "g"}}}),
            "invalid-machine",
            "channel_units.a2",
            "never be used",
        ),
        (
            json!({"tacho_channel": "tacho", "channel_units": {"tacho": {"unit": "g"}}}),
            "invalid-machine",
            "channel_units.tacho",
            "tachometer",
        ),
        (
            json!({"channel_units": {"*": {"unit": "g"}}, "iso_20816": {"group": 3, "support": "rigid"}}),
            "invalid-machine",
            "iso_20816",
            "group 3",
        ),
        (
            json!({"channel_units": {"*": {"unit": "g"}}, "iso_20816": {"group": 1, "support": "soft"}}),
            "invalid-machine",
            "iso_20816",
            "`soft`",
        ),
        (
            json!({"iso_20816": {"group": 1, "support": "rigid"}}),
            "invalid-machine",
            "iso_20816",
            "channel_units",
        ),
    ] {
        let (s, p) = put_machine(&app, "u-2", body.clone()).await;
        assert_eq!(s, 422, "{body}: {p}");
        assert_eq!(p["type"], format!("urn:gearwear:problem:{slug}"), "{p}");
        assert_eq!(p["member"], member, "{p}");
        let detail = p["detail"].as_str().unwrap();
        assert!(
            detail.starts_with(&format!("`{member}`")) && detail.contains(says),
            "{detail}"
        );
    }
    // Not the schema at all: 400.
    let (s, p) = put_machine(&app, "u-2", unit(json!({"unit": "V", "sensitivity": 100}))).await;
    assert_eq!(
        (s, p["type"].as_str()),
        (400, Some("urn:gearwear:problem:invalid-machine"))
    );
    // Nothing was stored.
    let r = app.get("/v1/machines/u-2").await;
    assert_eq!(r.status(), 404);
    // A channel list without units keeps working, and "*" declares every channel.
    let (s, m) = put_machine(&app, "u-2", json!({"channels": ["a1"]})).await;
    assert_eq!(s, 201, "{m}");
    assert!(m["channel_units"].is_null() && m["iso_20816"].is_null());
    let all = json!({"channel_units": {"*": {"unit": "mm/s"}}, "iso_20816": {"group": 1, "support": "flexible"}});
    let (s, m) = put_machine(&app, "u-2", all.clone()).await;
    assert_eq!(s, 200, "{m}");
    assert_eq!(m["channel_units"], all["channel_units"]);
}
