//! `/v1/machines/{machine_id}/calibration` on both stores: calibrate a virtual-rig record
//! that carries an effect (only this test knows which), read it back, a later record of the
//! machine is diagnosed with the stored effects, DELETE clears them; scopes and bad input.

use std::sync::OnceLock;

use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
use gearwear::gearbox::Gearbox;
use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    calibrate_keep_use_and_clear,
    calibration_scopes_and_bad_input
);

const EA: f64 = 0.3;
const CAL: &str = "/v1/machines/{machine_id}/calibration";
const REC: &str = "/v1/machines/{machine_id}/records";

fn model() -> &'static Gearbox {
    static M: OnceLock<Gearbox> = OnceLock::new();
    M.get_or_init(|| {
        gearwear::signature::SignatureTable::load(&gearwear::configuration::default_signatures())
            .expect("table")
            .gearbox()
            .clone()
    })
}

/// A 0.6 s, 16 kHz virtual-rig record with shaft-rate modulation (eccentricity 0.1 b).
pub fn eccentric_record(seed: u64) -> (Vec<f64>, f64) {
    let spec = RigSpec {
        ea: EA,
        omega1: 1.0,
        sample_rate: 16000.0,
        duration: 0.6,
        gain: 40.0,
        snr_db: 20.0,
        seed,
        effects: RigEffects {
            eccentricity: Some(0.1),
            ..Default::default()
        },
    };
    let r = generate(model(), &spec).expect("rig record");
    (r.samples, r.sample_rate)
}

fn f32_body(x: &[f64]) -> Vec<u8> {
    x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect()
}

fn names(v: &Value) -> Vec<&str> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect()
}

async fn calibrate_keep_use_and_clear(b: Backend) {
    // A calibration runs simulations (seconds of CPU); on a shared, loaded machine it can pass
    // the service's default 15 s request timeout. The timeout is not under test here.
    let Some(app) = spawn_app(b, |s| {
        s.limits.request_timeout = std::time::Duration::from_secs(180)
    })
    .await
    else {
        return;
    };
    let url = app.url("/v1/machines/gb-1/calibration");

    // None yet.
    let (s, _, body) = checked(app.client.get(&url).bearer_auth(&app.read_key), "GET", CAL).await;
    assert_eq!(s, 404);
    assert_eq!(json(&body)["type"], "urn:gearwear:problem:no-calibration");

    // Calibrate: binary f32 + query on one store, JSON on the other (the records endpoint's
    // body parsing serves both).
    let (x, fs) = eccentric_record(3001);
    let req = if b == Backend::Sqlite {
        app.client
            .post(format!("{url}?sample_rate_hz={fs}"))
            .bearer_auth(&app.admin_key)
            .header("content-type", "application/octet-stream")
            .body(f32_body(&x))
    } else {
        app.client
            .post(&url)
            .bearer_auth(&app.admin_key)
            .json(&json!({"sample_rate_hz": fs, "samples": x}))
    };
    let (s, h, body) = checked(req, "POST", CAL).await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    assert_eq!(h["location"], "/v1/machines/gb-1/calibration");
    let rep = json(&body);
    assert_eq!(names(&rep["effects"]), vec!["shaft-modulation"]);
    // Behind the claim, the record's own sidebands: at the input shaft's rate (1/29 f1).
    let checks = rep["sideband_checks"].as_array().expect("sideband_checks");
    assert!(
        checks.iter().any(|c| {
            c["at_rate"] == true && (c["shaft_ratio"].as_f64().unwrap() - 1.0 / 29.0).abs() < 1e-9
        }),
        "{checks:?}"
    );
    let (e0, e1) = (
        rep["error_before"].as_f64().unwrap(),
        rep["error_after"].as_f64().unwrap(),
    );
    assert!(e1 < 0.7 * e0, "error {e0} → {e1}");
    let cal_id = rep["id"].as_str().unwrap().to_string();

    // Kept.
    let (s, _, body) = checked(app.client.get(&url).bearer_auth(&app.read_key), "GET", CAL).await;
    assert_eq!(s, 200);
    let got = json(&body);
    assert_eq!(got["id"], cal_id.as_str());
    assert_eq!(got["machine_id"], "gb-1");
    assert_eq!(got["effects"], rep["effects"]);
    assert_eq!(got["sideband_checks"], rep["sideband_checks"]);
    // The level over time: a steady record, nothing to report, and the field is kept.
    assert_eq!(
        rep["unexplained_in_time"],
        json!([]),
        "{}",
        rep["unexplained_in_time"]
    );
    assert_eq!(got["unexplained_in_time"], rep["unexplained_in_time"]);
    assert_eq!(got["error_after"], rep["error_after"]);

    // A later record of the machine (another seed, same gearbox) is diagnosed with the
    // stored effect held fixed.
    let (x2, fs2) = eccentric_record(3002);
    let later = json!({"sample_rate_hz": fs2, "samples": x2});
    let req = app
        .client
        .post(app.url("/v1/machines/gb-1/records"))
        .bearer_auth(&app.ingest_key)
        .json(&later);
    let (s, _, body) = checked(req, "POST", REC).await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    let d = json(&body);
    let c = &d["calibration"];
    assert_eq!(c["id"], cal_id.as_str());
    assert_eq!(names(&c["effects"]), vec!["shaft-modulation"]);
    assert!(c["path_correction"].is_null());
    let refit = &c["wear_refit"];
    let (ea_table, ea_refit) = (
        d["wear_degree"]["estimate"].as_f64().unwrap(),
        refit["ea"].as_f64().unwrap(),
    );
    eprintln!(
        "{b:?}: table ea {ea_table:.3}, refit ea {ea_refit:.3}, error {:.2} dB with the \
         effect, {:.2} dB without",
        refit["error_db"].as_f64().unwrap(),
        refit["error_plain_db"].as_f64().unwrap()
    );
    assert!(
        refit["error_db"].as_f64().unwrap() < refit["error_plain_db"].as_f64().unwrap(),
        "{refit}"
    );
    assert!(
        (ea_refit - EA).abs() < (ea_table - EA).abs(),
        "refit {ea_refit} not closer to {EA} than the table's {ea_table}"
    );
    // An element effect is held: the refit is continuous with an interval, and the alert level
    // follows it when it lies outside the table's credible interval (inside, the table's
    // reading stands).
    let (lo, hi) = (
        refit["ea_lower"].as_f64().unwrap(),
        refit["ea_upper"].as_f64().unwrap(),
    );
    assert!(lo <= ea_refit && ea_refit <= hi && hi > lo, "{refit}");
    let (t_lo, t_hi) = (
        d["wear_degree"]["lower"].as_f64().unwrap(),
        d["wear_degree"]["upper"].as_f64().unwrap(),
    );
    let outside = !(t_lo..=t_hi).contains(&ea_refit);
    assert_eq!(
        c["alert_follows"],
        if outside { "wear_refit" } else { "wear_degree" },
        "refit {ea_refit} against the table's [{t_lo}, {t_hi}]"
    );
    // Stored with the diagnosis too.
    let id = d["id"].as_str().unwrap();
    let r = app.get(&format!("/v1/diagnoses/{id}")).await;
    let full: Value = r.json().await.unwrap();
    assert_eq!(full["diagnosis"]["calibration"]["id"], cal_id.as_str());

    // DELETE clears it; the next diagnosis is the plain one.
    let (s, _, _) = checked(
        app.client.delete(&url).bearer_auth(&app.admin_key),
        "DELETE",
        CAL,
    )
    .await;
    assert_eq!(s, 204);
    let (s, _, _) = checked(app.client.get(&url).bearer_auth(&app.read_key), "GET", CAL).await;
    assert_eq!(s, 404);
    let (s, _, body) = checked(
        app.client.delete(&url).bearer_auth(&app.admin_key),
        "DELETE",
        CAL,
    )
    .await;
    assert_eq!(s, 404);
    assert_eq!(json(&body)["type"], "urn:gearwear:problem:no-calibration");
    let r = app.post_json("gb-1", &json_record(7)).await;
    assert_eq!(r.status(), 201);
    let d: Value = r.json().await.unwrap();
    assert!(d.get("calibration").is_none(), "{}", d["calibration"]);
}

async fn calibration_scopes_and_bad_input(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let url = app.url("/v1/machines/gb-2/calibration");
    let rec = json_record(1);
    // POST and DELETE need admin; GET needs read.
    for (key, want) in [
        (None, 401),
        (Some(&app.read_key), 403),
        (Some(&app.ingest_key), 403),
    ] {
        let mut req = app.client.post(&url).json(&rec);
        if let Some(k) = key {
            req = req.bearer_auth(k);
        }
        let (s, h, _) = checked(req, "POST", CAL).await;
        assert_eq!(s, want);
        assert!(
            h["content-type"]
                .to_str()
                .unwrap()
                .starts_with("application/problem+json")
        );
        let mut req = app.client.delete(&url);
        if let Some(k) = key {
            req = req.bearer_auth(k);
        }
        assert_eq!(checked(req, "DELETE", CAL).await.0, want);
    }
    assert_eq!(checked(app.client.get(&url), "GET", CAL).await.0, 401);
    assert_eq!(
        checked(
            app.client.get(&url).bearer_auth(&app.ingest_key),
            "GET",
            CAL
        )
        .await
        .0,
        403
    );

    // Bad input: each an exact problem, nothing stored.
    let admin = |req: reqwest::RequestBuilder| req.bearer_auth(&app.admin_key);
    let cases: Vec<(reqwest::RequestBuilder, u16, &str)> = vec![
        (
            admin(app.client.post(&url))
                .header("content-type", "text/plain")
                .body("1\n2\n"),
            415,
            "unsupported-media-type",
        ),
        (
            admin(app.client.post(&url))
                .header("content-type", "application/json")
                .body("{\"samples\": [1, 2]}"),
            400,
            "invalid-json",
        ),
        (
            admin(app.client.post(&url))
                .header("content-type", "application/octet-stream")
                .body(vec![0u8; 64]),
            422,
            "missing-sample-rate",
        ),
        (
            admin(app.client.post(&url)).json(&json!({"sample_rate_hz": 16000.0, "samples": []})),
            422,
            "empty-record",
        ),
        (
            admin(app.client.post(app.url("/v1/machines/bad%20id/calibration"))).json(&rec),
            400,
            "invalid-machine-id",
        ),
        (
            admin(app.client.post(&url)).json(
                &json!({"sample_rate_hz": 16000.0, "samples": (0..200).map(|i| (i as f64).sin()).collect::<Vec<_>>()}),
            ),
            422,
            "",
        ),
    ];
    for (req, want, slug) in cases {
        let (s, h, body) = checked(req, "POST", CAL).await;
        assert_eq!(s, want, "{}", String::from_utf8_lossy(&body));
        assert!(
            h["content-type"]
                .to_str()
                .unwrap()
                .starts_with("application/problem+json")
        );
        if !slug.is_empty() {
            assert_eq!(
                json(&body)["type"],
                format!("urn:gearwear:problem:{slug}").as_str()
            );
        }
    }
    let (s, _, _) = checked(app.client.get(&url).bearer_auth(&app.read_key), "GET", CAL).await;
    assert_eq!(s, 404);
}
