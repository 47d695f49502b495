//! One assessment: the service's answer to a record (`POST …/records`) and `gearwear diagnose`
//! on the same record, with the same baseline records (`--baseline`) and the same calibration
//! (`--calibration`, the JSON of `GET …/calibration`), are the same assessment — compared field
//! by field, every field but the ids and the time the service adds.

use serde_json::{Value, json};

use crate::helpers::*;

/// The fields only the service's answer has: the ids and time it gives the record, and the
/// alert level repeated at the top (compared through `alert.level`).
const SERVICE_ONLY: [&str; 5] = ["id", "machine_id", "record_id", "created_at", "alert_level"];

/// Numbers agree to 1e-9 relative, not bit for bit: the closed loop's refit is not
/// bit-reproducible on a loaded machine (its simulations' last digits vary: seen as
/// `0.3328604327386207` against `0.33286043273862065`), and the explainer's shares and the
/// evidence's z were seen to differ in the 15th digit between the service and the CLI in a
/// full test run (not in a run of this test alone).
fn close(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * a.abs().max(b.abs()),
        _ => false,
    }
}

/// Every path where `a` and `b` differ (`$.x.y[2]: a vs b`), recursively.
pub(crate) fn differences(path: &str, a: &Value, b: &Value, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for k in x.keys().chain(y.keys().filter(|k| !x.contains_key(*k))) {
                let (u, v) = (
                    x.get(k).unwrap_or(&Value::Null),
                    y.get(k).unwrap_or(&Value::Null),
                );
                if x.contains_key(k) != y.contains_key(k) {
                    out.push(format!(
                        "{path}.{k}: only in the {}",
                        if x.contains_key(k) {
                            "service's"
                        } else {
                            "CLI's"
                        }
                    ));
                } else {
                    differences(&format!("{path}.{k}"), u, v, out);
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                differences(&format!("{path}[{i}]"), u, v, out);
            }
        }
        _ if a == b => {}
        (Value::Number(x), Value::Number(y)) if close(x.as_f64(), y.as_f64()) => {}
        _ => out.push(format!("{path}: service {a} vs CLI {b}")),
    }
}

/// The service's answer and the CLI's output, field by field.
pub(crate) fn assert_same_assessment(service: &Value, cli: &Value) {
    let mut s = service.clone();
    for k in SERVICE_ONLY {
        assert!(s.get(k).is_some(), "the service's answer has no `{k}`");
        s.as_object_mut().unwrap().remove(k);
    }
    assert_eq!(service["alert_level"], cli["alert"]["level"]);
    let mut diffs = Vec::new();
    differences("$", &s, cli, &mut diffs);
    assert!(
        diffs.is_empty(),
        "the CLI and the service disagree on {} field(s):\n{}",
        diffs.len(),
        diffs.join("\n")
    );
}

pub(crate) fn tmpdir(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!(
        "gearwear-assess-{tag}-{}",
        uuid::Uuid::new_v4().simple()
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `gearwear synth` to a WAV file: its path.
fn synth(dir: &std::path::Path, name: &str, ea: &str, seed: &str) -> String {
    let p = dir.join(name);
    gearwear_ok(&[
        "synth",
        "--ea",
        ea,
        "--seed",
        seed,
        "--output",
        p.to_str().unwrap(),
    ]);
    p.to_str().unwrap().to_string()
}

async fn post_wav(app: &TestApp, machine: &str, query: &str, path: &str) -> Value {
    let r = app
        .client
        .post(app.url(&format!("/v1/machines/{machine}/records{query}")))
        .bearer_auth(&app.ingest_key)
        .header("content-type", "audio/wav")
        .body(std::fs::read(path).unwrap())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    r.json().await.unwrap()
}

/// A machine with a baseline of three healthy records: the record's wear, interval, fit,
/// novelty (score, threshold, top features), indicators and alert agree, and so does every
/// other field.
#[tokio::test]
async fn the_cli_and_the_service_assess_a_record_against_a_baseline_alike() {
    let Some(app) = spawn_app(Backend::Sqlite, |_| {}).await else {
        return;
    };
    let dir = tmpdir("baseline");
    let base: Vec<String> = (1..=3)
        .map(|k| synth(&dir, &format!("h{k}.wav"), "0.3", &k.to_string()))
        .collect();
    let rec = synth(&dir, "t.wav", "0.7", "9");
    for b in &base {
        post_wav(&app, "m-1", "?baseline=true&shaft_hz=30", b).await;
    }
    let service = post_wav(&app, "m-1", "?shaft_hz=30", &rec).await;

    let mut args = vec!["diagnose", "--input", &rec, "--shaft-hz", "30"];
    for b in &base {
        args.extend(["--baseline", b.as_str()]);
    }
    let cli: Value = serde_json::from_str(&gearwear_ok(&args)).unwrap();

    // Not a vacuous comparison: the assessment has a wear degree, a novelty and an alert.
    assert!(
        service["wear_degree"]["estimate"].as_f64().is_some(),
        "{service}"
    );
    assert!(service["novelty"]["score"].as_f64().is_some(), "{service}");
    assert_eq!(service["baseline"]["records"], 3);
    assert_eq!(
        service["alert"]["basis"], "wear+novelty",
        "{}",
        service["alert"]
    );
    assert_same_assessment(&service, &cli);

    // Without a baseline the two still agree.
    let alone = post_wav(&app, "m-2", "?shaft_hz=30", &rec).await;
    let cli: Value = serde_json::from_str(&gearwear_ok(&[
        "diagnose",
        "--input",
        &rec,
        "--shaft-hz",
        "30",
    ]))
    .unwrap();
    assert!(alone["novelty"].is_null());
    assert_same_assessment(&alone, &cli);
    std::fs::remove_dir_all(dir).ok();
}

/// The comparison fails when the two disagree.
#[test]
fn a_disagreement_is_caught() {
    let service = json!({"id": "d", "machine_id": "m", "record_id": "r", "created_at": "t",
        "alert_level": "ok", "alert": {"level": "ok"}, "wear_degree": {"estimate": 0.5}});
    let cli = json!({"alert": {"level": "ok"}, "wear_degree": {"estimate": 0.5}});
    assert_same_assessment(&service, &cli);
    for other in [
        json!({"alert": {"level": "ok"}, "wear_degree": {"estimate": 0.5000001}}),
        json!({"alert": {"level": "warning"}, "wear_degree": {"estimate": 0.5}}),
        json!({"alert": {"level": "ok"}, "wear_degree": {"estimate": 0.5}, "novelty": null}),
        json!({"alert": {"level": "ok"}}),
    ] {
        let r = std::panic::catch_unwind(|| assert_same_assessment(&service, &other));
        assert!(r.is_err(), "{other}");
    }
    // The refit's numbers to 1e-9, and no further.
    let with_refit =
        |ea: f64| json!({"alert": {"level": "ok"}, "calibration": {"wear_refit": {"ea": ea}}});
    let mut s = with_refit(0.3328604327386207);
    for k in SERVICE_ONLY {
        s[k] = json!("x");
    }
    s["alert_level"] = json!("ok");
    assert_same_assessment(&s, &with_refit(0.33286043273862065));
    let r = std::panic::catch_unwind(|| assert_same_assessment(&s, &with_refit(0.3329)));
    assert!(r.is_err());
}

/// A calibrated machine (a virtual-rig record with an eccentricity, the effect the calibration
/// finds): the CLI given the machine's calibration (the JSON of GET `…/calibration`) reads a
/// later record with the same effect held fixed as the service — the same refit, the same
/// wear the alert follows.
#[tokio::test]
async fn the_cli_and_the_service_assess_a_calibrated_machine_alike() {
    // A calibration runs simulations (seconds of CPU): the default 15 s request timeout is
    // not under test here.
    let Some(app) = spawn_app(Backend::Sqlite, |s| {
        s.limits.request_timeout = std::time::Duration::from_secs(180)
    })
    .await
    else {
        return;
    };
    let dir = tmpdir("calibration");
    let (x, fs) = crate::calibration::eccentric_record(3001);
    let r = app
        .client
        .post(app.url("/v1/machines/c-1/calibration"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"sample_rate_hz": fs, "samples": x}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let got: Value = app
        .get("/v1/machines/c-1/calibration")
        .await
        .json()
        .await
        .unwrap();
    let cal = dir.join("cal.json");
    std::fs::write(&cal, got.to_string()).unwrap();

    // The later record as JSON to the service and as a one-column CSV to the CLI: both
    // texts round-trip every sample exactly.
    let (x2, fs2) = crate::calibration::eccentric_record(3002);
    let service: Value = app
        .post_json("c-1", &json!({"sample_rate_hz": fs2, "samples": x2}))
        .await
        .json()
        .await
        .unwrap();
    let csv = dir.join("later.csv");
    let text: String = x2.iter().map(|v| format!("{v}\n")).collect();
    std::fs::write(&csv, text).unwrap();
    let cli: Value = serde_json::from_str(&gearwear_ok(&[
        "diagnose",
        "--input",
        csv.to_str().unwrap(),
        "--sample-rate",
        &fs2.to_string(),
        "--calibration",
        cal.to_str().unwrap(),
    ]))
    .unwrap();
    assert_eq!(service["calibration"]["id"], got["id"], "{service}");
    assert!(
        service["calibration"]["wear_refit"]["ea"]
            .as_f64()
            .is_some(),
        "{service}"
    );
    assert_same_assessment(&service, &cli);
    std::fs::remove_dir_all(dir).ok();
}
