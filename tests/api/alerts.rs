//! Alerts as events: an alert opens after N records at warning (not after
//! N − 1), is acknowledged with a note (a key with the `acknowledge` scope; a read key gets
//! 403; twice is 409), closes after M low records, keeps its audit trail, and webhooks fire on
//! transitions only — a machine hovering at the threshold opens one alert, not one per record.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use gearwear::configuration::EpisodePolicy;
use gearwear::keys::Scope;
use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(alert_lifecycle, hovering_machine_opens_one_alert);

/// A record the rig's model explains, simulated at wear degree `ea` (like [`json_record`]),
/// measured at minute `minute` of 2026-03-01 (its `recorded_at`).
fn wear_record(ea: f64, seed: u64, minute: u32) -> Value {
    static CACHE: OnceLock<Mutex<HashMap<(u64, u64), Value>>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = (ea.to_bits(), seed);
    let cached = cache.lock().unwrap().get(&key).cloned();
    let mut v = cached.unwrap_or_else(|| {
        let v = rig_record(ea, seed);
        cache.lock().unwrap().insert(key, v.clone());
        v
    });
    v["recorded_at"] = recorded_at(minute).into();
    v
}

fn recorded_at(minute: u32) -> String {
    format!("2026-03-01T{:02}:{:02}:00.000Z", minute / 60, minute % 60)
}

/// The wear degree above the warning threshold (0.5) and one well below its close threshold.
const HIGH: f64 = 0.75;
const LOW: f64 = 0.1;

/// Post a record; its answer.
async fn post(app: &TestApp, machine: &str, rec: &Value) -> Value {
    let r = app.post_json(machine, rec).await;
    assert_eq!(r.status(), 201);
    r.json().await.unwrap()
}

async fn get_checked(app: &TestApp, path: &str, template: &str) -> (u16, Value) {
    let (s, _, body) = checked(
        app.client.get(app.url(path)).bearer_auth(&app.read_key),
        "GET",
        template,
    )
    .await;
    (s, json(&body))
}

async fn open_alerts(app: &TestApp, machine: &str) -> Vec<Value> {
    let (s, v) = get_checked(
        app,
        &format!("/v1/alerts?state=open&machine_id={machine}"),
        "/v1/alerts",
    )
    .await;
    assert_eq!(s, 200, "{v}");
    v["alerts"].as_array().unwrap().clone()
}

async fn ack(app: &TestApp, key: &str, id: &str, note: &str) -> (u16, Value) {
    let (s, _, body) = checked(
        app.client
            .post(app.url(&format!("/v1/alerts/{id}/acknowledge")))
            .bearer_auth(key)
            .json(&json!({ "note": note })),
        "POST",
        "/v1/alerts/{alert_id}/acknowledge",
    )
    .await;
    (s, json(&body))
}

const POLICY: EpisodePolicy = EpisodePolicy {
    open_after: 3,
    close_after: 2,
    close_below: 0.8,
};

async fn alert_lifecycle(b: Backend) {
    let Some(app) = spawn_app(b, |s| s.alerts = POLICY).await else {
        return;
    };
    let (rx, url, _t) = crate::webhooks::start_receiver(0, 0).await;
    let (s, _, _) = checked(
        app.client
            .post(app.url("/v1/webhooks"))
            .bearer_auth(&app.admin_key)
            .json(
                &json!({"url": url, "events": ["alert.opened", "alert.acknowledged",
                                                  "alert.closed", "wear.threshold_crossed"]}),
            ),
        "POST",
        "/v1/webhooks",
    )
    .await;
    assert_eq!(s, 201);
    let m = "m-alert";
    let mut minute = 0;
    let mut next = |ea: f64| {
        minute += 1;
        wear_record(ea, minute as u64, minute)
    };

    // N − 1 records at warning or above: no alert.
    for _ in 0..2 {
        let a = post(&app, m, &next(HIGH)).await;
        assert!(
            matches!(a["alert_level"].as_str(), Some("warning" | "alarm")),
            "{}",
            a["alert"]
        );
        assert!(open_alerts(&app, m).await.is_empty());
    }
    // The N-th opens it, at that record's measurement time.
    let third = post(&app, m, &next(HIGH)).await;
    let open = open_alerts(&app, m).await;
    assert_eq!(open.len(), 1, "{open:?}");
    let alert = &open[0];
    let id = alert["id"].as_str().unwrap().to_string();
    assert_eq!(alert["state"], "open");
    assert_eq!(alert["machine_id"], m);
    assert_eq!(alert["record_id"], third["record_id"]);
    assert_eq!(alert["opened_at"], recorded_at(3));
    assert!(alert["peak_severity"].as_f64().unwrap() >= 1.0, "{alert}");
    assert!(alert["acknowledged_at"].is_null() && alert["closed_at"].is_null());

    // Hovering while open (low, high, low, high): no new alert, no webhook.
    for ea in [LOW, HIGH, LOW, HIGH] {
        post(&app, m, &next(ea)).await;
    }
    assert_eq!(open_alerts(&app, m).await.len(), 1);

    // Acknowledging: a read key may not (403), a key with `acknowledge` may, once (409).
    let (s, p) = ack(&app, &app.read_key, &id, "looked at it").await;
    assert_eq!(s, 403, "{p}");
    assert_eq!(p["required_scope"], "acknowledge");
    let planner =
        gearwear::service::cli::create_key(app.store.as_ref(), &[Scope::Acknowledge], "planner")
            .await
            .unwrap();
    let (s, acked) = ack(&app, &planner.1, &id, "oil changed, bearing ordered").await;
    assert_eq!(s, 200, "{acked}");
    assert_eq!(acked["state"], "acknowledged");
    assert_eq!(acked["note"], "oil changed, bearing ordered");
    assert_eq!(acked["acknowledged_by"], planner.0.id.as_str());
    assert!(acked["acknowledged_at"].is_string());
    let (s, p) = ack(&app, &planner.1, &id, "again").await;
    assert_eq!(s, 409, "{p}");
    assert_eq!(p["state"], "acknowledged");
    // An acknowledged alert still counts as open.
    assert_eq!(open_alerts(&app, m).await[0]["state"], "acknowledged");
    // A read key cannot acknowledge, and an acknowledge key cannot post records.
    let r = app
        .client
        .post(app.url(&format!("/v1/machines/{m}/records")))
        .bearer_auth(&planner.1)
        .json(&next(LOW))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 403);

    // M − 1 low records: still open; the M-th closes it at its measurement time.
    post(&app, m, &next(LOW)).await;
    assert_eq!(open_alerts(&app, m).await.len(), 1);
    let closing = post(&app, m, &next(LOW)).await;
    assert!(open_alerts(&app, m).await.is_empty());
    let (s, detail) = get_checked(&app, &format!("/v1/alerts/{id}"), "/v1/alerts/{alert_id}").await;
    assert_eq!(s, 200, "{detail}");
    assert_eq!(detail["state"], "closed");
    assert_eq!(detail["closed_at"], recorded_at(minute));
    assert_eq!(detail["closed_record_id"], closing["record_id"]);
    assert_eq!(detail["note"], "oil changed, bearing ordered");
    let audit: Vec<&str> = detail["audit"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["event"].as_str().unwrap())
        .collect();
    let escalations = audit.iter().filter(|e| **e == "escalated").count();
    assert_eq!(audit.first(), Some(&"opened"), "{detail}");
    assert_eq!(audit.last(), Some(&"closed"), "{detail}");
    assert!(audit.contains(&"acknowledged"), "{detail}");
    assert_eq!(audit.len(), 3 + escalations, "{detail}");
    let acked_line = detail["audit"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["event"] == "acknowledged")
        .unwrap();
    assert_eq!(acked_line["by"], planner.0.id.as_str());
    assert_eq!(acked_line["note"], "oil changed, bearing ordered");
    // Closed: nothing to acknowledge (409); listed as closed; unknown ids are 404.
    let (s, p) = ack(&app, &planner.1, &id, "late").await;
    assert_eq!(s, 409, "{p}");
    let (s, v) = get_checked(&app, "/v1/alerts?state=closed", "/v1/alerts").await;
    assert_eq!(s, 200);
    assert_eq!(v["alerts"].as_array().unwrap().len(), 1);
    let (s, _) = get_checked(&app, "/v1/alerts/nope", "/v1/alerts/{alert_id}").await;
    assert_eq!(s, 404);
    let (s, p) = get_checked(&app, "/v1/alerts?state=shut", "/v1/alerts").await;
    assert_eq!((s, p["parameter"].as_str()), (400, Some("state")), "{p}");

    // Webhooks: one per transition — opened, acknowledged, closed, and the older
    // `wear.threshold_crossed` once when it opened (and once per escalation) — not per record.
    let want = 3 + 1 + escalations;
    crate::webhooks::wait_for("the alert webhooks", || {
        rx.got.lock().unwrap().len() >= want
    })
    .await;
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let got = rx.got.lock().unwrap().clone();
    let mut events: Vec<String> = got
        .iter()
        .map(|(_, body)| {
            let p: Value = serde_json::from_slice(body).unwrap();
            if p["event"].as_str().unwrap().starts_with("alert.") {
                assert_eq!(p["alert"]["id"], id.as_str(), "{p}");
            }
            p["event"].as_str().unwrap().to_string()
        })
        .collect();
    events.sort();
    let mut expected = vec!["alert.acknowledged", "alert.closed", "alert.opened"];
    expected.extend(std::iter::repeat_n(
        "wear.threshold_crossed",
        1 + escalations,
    ));
    assert_eq!(events, expected);
}

/// The target through the service: a machine alternating around the warning threshold
/// for 200 records opens at most one alert.
async fn hovering_machine_opens_one_alert(b: Backend) {
    let Some(app) = spawn_app(b, |s| {
        s.alerts = EpisodePolicy {
            open_after: 1,
            close_after: 2,
            close_below: 0.8,
        }
    })
    .await
    else {
        return;
    };
    let m = "m-hover";
    for i in 0..200u32 {
        let ea = if i % 2 == 0 { HIGH } else { LOW };
        post(&app, m, &wear_record(ea, 100 + i as u64 % 4, i)).await;
    }
    let (s, v) = get_checked(
        &app,
        &format!("/v1/alerts?state=all&machine_id={m}"),
        "/v1/alerts",
    )
    .await;
    assert_eq!(s, 200);
    assert_eq!(v["alerts"].as_array().unwrap().len(), 1, "{v}");

    // The command line sees the same alert and acknowledges it, once.
    let url = app.settings.database_url.clone();
    let listed = gearwear_ok(&["alerts", "list", "--machine", m, "--database-url", &url]);
    let row: Value = serde_json::from_str(listed.lines().next().unwrap()).unwrap();
    assert_eq!(row["id"], v["alerts"][0]["id"]);
    let id = row["id"].as_str().unwrap();
    let args = [
        "alerts",
        "ack",
        id,
        "--note",
        "gearbox inspected",
        "--by",
        "ann",
    ];
    let acked: Value = serde_json::from_str(&gearwear_ok(
        &[&args[..], &["--database-url", &url]].concat(),
    ))
    .unwrap();
    assert_eq!(
        (&acked["state"], &acked["acknowledged_by"]),
        (&json!("acknowledged"), &json!("ann"))
    );
    let again = gearwear_bin()
        .args(args)
        .args(["--database-url", &url])
        .output()
        .unwrap();
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("acknowledged already"));
}
