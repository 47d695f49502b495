//! Trends and measurement time, on both stores: a machine whose wear
//! rises over twelve days of `recorded_at` has a significant trend and a projected alarm; the
//! same records back-filled in another order give the same series and the same trend; the
//! machine view's `trend_summary` and the webhook payload's are the wear trend; bad queries are refused naming the
//! parameter.

use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    a_rising_wear_gives_a_projected_alarm_and_back_filling_gives_the_same_trend,
    trend_queries_are_checked,
);

/// Days of history, one record a day.
const DAYS: usize = 12;

/// A record the rig's model explains (Ω1 = 1.07, gain 2, 25 dB) at wear `ea`, measured at
/// 08:00 on day `day` of November 2026.
fn record(ea: f64, day: usize, seed: u64) -> Value {
    let mut v = rig_record(ea, seed);
    v["recorded_at"] = format!("2026-11-{:02}T08:00:00Z", day + 1).into();
    v
}

async fn get_trend(app: &TestApp, machine: &str, query: &str) -> (u16, Value) {
    let (s, _, b) = checked(
        app.client
            .get(app.url(&format!("/v1/machines/{machine}/trend{query}")))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}/trend",
    )
    .await;
    (s, json(&b))
}

/// POST a record, which must be accepted: the answer.
async fn post(app: &TestApp, machine: &str, body: &Value) -> Value {
    let r = app.post_json(machine, body).await;
    assert_eq!(r.status().as_u16(), 201);
    r.json().await.unwrap()
}

async fn a_rising_wear_gives_a_projected_alarm_and_back_filling_gives_the_same_trend(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    // Wear rising by 0.04 a day from 0.3: 0.74 on the last day, alarm (0.8) ~1.5 days later.
    let records: Vec<Value> = (0..DAYS)
        .map(|d| record(0.3 + 0.04 * d as f64, d, 40 + d as u64))
        .collect();
    let (rx, url, _task) = crate::webhooks::start_receiver(0, 0).await;
    crate::webhooks::create_hook(&app, &url).await;
    let mut last_id = Value::Null;
    for r in &records {
        last_id = post(&app, "live", r).await["id"].clone();
    }
    // The same records back-filled: newest first, then the rest shuffled.
    let order = [11, 0, 7, 3, 10, 1, 5, 9, 2, 8, 4, 6];
    for &i in &order {
        post(&app, "backfill", &records[i]).await;
    }

    let (s, live) = get_trend(&app, "live", "?series=wear").await;
    assert_eq!(s, 200, "{live}");
    assert_eq!(live["series"], "wear");
    assert_eq!(live["unit"], "ea (reference lengths)");
    let pts = live["points"].as_array().unwrap();
    assert_eq!(pts.len(), DAYS, "{live}");
    let times: Vec<&str> = pts
        .iter()
        .map(|p| p["measured_at"].as_str().unwrap())
        .collect();
    assert_eq!(times[0], "2026-11-01T08:00:00.000Z");
    assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    let fit = &live["fit"];
    assert_eq!(fit["significant"], true, "{live}");
    let slope = fit["slope_per_day"].as_f64().unwrap();
    assert!((0.02..0.07).contains(&slope), "slope {slope}: {live}");
    let alarm = &live["projection"]["alarm"];
    assert!(alarm["days"].as_f64().unwrap() < 10.0, "{live}");
    assert!(
        live["verdict"].as_str().unwrap().contains("alarm"),
        "{live}"
    );

    // The last record's webhook payload carries the trend with it: the same.
    let payload_of_last = || -> Option<Value> {
        rx.got.lock().unwrap().iter().find_map(|(_, b)| {
            let p: Value = serde_json::from_slice(b).ok()?;
            (p["diagnosis_id"] == last_id && p["event"] == "diagnosis.created").then_some(p)
        })
    };
    crate::webhooks::wait_for("the last record's delivery", || payload_of_last().is_some()).await;
    let p = payload_of_last().unwrap();
    assert_eq!(p["measured_at"], "2026-11-12T08:00:00.000Z");
    for k in ["fit", "projection", "verdict"] {
        assert_eq!(p["trend_summary"][k], live[k], "{k}");
    }

    // Back-filled in another order: the same points in measurement order, the same trend.
    let (_, back) = get_trend(&app, "backfill", "?series=wear").await;
    let values = |t: &Value| -> Vec<(Value, Value)> {
        t["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| (p["measured_at"].clone(), p["value"].clone()))
            .collect()
    };
    assert_eq!(values(&live), values(&back));
    for k in ["fit", "projection", "thresholds"] {
        assert_eq!(live[k], back[k], "{k}");
    }
    // The verdicts agree with each machine's open alert, whose episode follows the order the
    // records came in (back-filled, it opened at another record): they differ only in since
    // when it is open, and project no crossing of the level it holds.
    let after_open = |t: &Value| -> String {
        let v = t["verdict"].as_str().unwrap();
        assert!(v.starts_with("warning open since 2026-11-"), "{v}");
        v.split_once("; ")
            .map(|(_, rest)| rest.to_string())
            .unwrap_or_default()
    };
    assert_eq!(after_open(&live), after_open(&back));
    assert!(after_open(&live).starts_with("alarm in "), "{live}");

    // The machine view: its trend in measurement order and its trend summary.
    let (s, _, m) = checked(
        app.client
            .get(app.url("/v1/machines/backfill"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}",
    )
    .await;
    assert_eq!(s, 200);
    let m = json(&m);
    let mt: Vec<&str> = m["trend"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["measured_at"].as_str().unwrap())
        .collect();
    assert_eq!(mt, times);
    assert_eq!(m["trend_summary"]["series"], "wear");
    for k in ["fit", "projection", "verdict"] {
        assert_eq!(m["trend_summary"][k], back[k], "{k}");
    }
    // The latest diagnosis is the last one received (the machine's state), measured first.
    assert_eq!(m["latest"]["measured_at"], "2026-11-07T08:00:00.000Z");
}

async fn trend_queries_are_checked(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let (s, p) = get_trend(&app, "nobody", "").await;
    assert_eq!(
        (s, p["type"].as_str()),
        (404, Some("urn:gearwear:problem:unknown-machine")),
        "{p}"
    );
    post(&app, "m1", &json_record(1)).await;
    let (s, p) = get_trend(&app, "m1", "?series=temperature").await;
    assert_eq!(s, 400, "{p}");
    assert_eq!(p["parameter"], "series", "{p}");
    // A finding kind the service does not write is named, with the kinds it does.
    let (s, p) = get_trend(&app, "m1", "?series=finding:gear@output").await;
    assert_eq!(s, 400, "{p}");
    let detail = p["detail"].as_str().unwrap();
    assert!(
        detail.contains("`gear`") && detail.contains("`gear-local-damage`"),
        "{p}"
    );
    // One point: a series, no trend yet.
    let (s, t) = get_trend(&app, "m1", "").await;
    assert_eq!(s, 200, "{t}");
    assert_eq!(t["points"].as_array().unwrap().len(), 1, "{t}");
    assert_eq!(t["fit"], Value::Null);
    assert_eq!(t["projection"], Value::Null);
    assert!(
        t["verdict"]
            .as_str()
            .unwrap()
            .starts_with("not enough points")
    );
    // No baseline, no finding of that kind, no such channel: empty series, no thresholds for
    // a finding.
    for q in ["?series=novelty", "?series=finding:bearing", "?channel=a9"] {
        let (s, t) = get_trend(&app, "m1", q).await;
        assert_eq!(s, 200, "{q}: {t}");
        assert_eq!(t["points"], json!([]), "{q}");
    }
    let (_, t) = get_trend(&app, "m1", "?series=finding:bearing@output").await;
    assert_eq!(t["series"], "finding:bearing@output");
    assert_eq!(t["thresholds"], Value::Null);
}
