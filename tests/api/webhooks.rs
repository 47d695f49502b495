//! Webhooks: signed deliveries, retries with back-off, at-least-once across a restart, the
//! delivery log over the API.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use axum::Router;
use axum::body::Bytes;
use axum::http::{HeaderMap, StatusCode};
use axum::routing::post;
use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    signed_delivery_with_retries,
    deliveries_survive_a_restart,
    receiver_down_then_back
);

/// A receiver that fails the first `fail_first` requests with 500, then answers 204 — or 500
/// while `failing` is set.
#[derive(Clone, Default)]
pub struct Receiver {
    /// The requests answered 2xx, in order.
    pub got: Arc<Mutex<Vec<(HeaderMap, Bytes)>>>,
    fail_first: Arc<Mutex<usize>>,
    pub failing: Arc<AtomicBool>,
}

pub async fn start_receiver(
    fail_first: usize,
    port: u16,
) -> (Receiver, String, tokio::task::JoinHandle<()>) {
    let rx = Receiver {
        got: Default::default(),
        fail_first: Arc::new(Mutex::new(fail_first)),
        failing: Default::default(),
    };
    let r2 = rx.clone();
    let app = Router::new().route(
        "/hook",
        post(move |h: HeaderMap, b: Bytes| {
            let r = r2.clone();
            async move {
                let mut f = r.fail_first.lock().unwrap();
                if *f > 0 {
                    *f -= 1;
                    return StatusCode::INTERNAL_SERVER_ERROR;
                }
                if r.failing.load(Ordering::SeqCst) {
                    return StatusCode::INTERNAL_SERVER_ERROR;
                }
                r.got.lock().unwrap().push((h, b));
                StatusCode::NO_CONTENT
            }
        }),
    );
    let l = tokio::net::TcpListener::bind(("127.0.0.1", port))
        .await
        .unwrap();
    let url = format!("http://{}/hook", l.local_addr().unwrap());
    let task = tokio::spawn(async move {
        axum::serve(l, app).await.unwrap();
    });
    (rx, url, task)
}

pub async fn create_hook(app: &TestApp, url: &str) -> Value {
    let req = app
        .client
        .post(app.url("/v1/webhooks"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"url": url, "events": ["diagnosis.created", "wear.threshold_crossed"]}));
    let (s, _, body) = checked(req, "POST", "/v1/webhooks").await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    json(&body)
}

pub async fn wait_for<F: Fn() -> bool>(what: &str, f: F) {
    for _ in 0..200 {
        if f() {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(25)).await;
    }
    panic!("timed out waiting for {what}");
}

async fn signed_delivery_with_retries(b: Backend) {
    // Thresholds at 0 so the first record also crosses into `alarm`, and an alert that opens
    // on one record, so that `wear.threshold_crossed` goes out with it.
    let Some(app) = spawn_app(b, |s| {
        s.thresholds.warning = 0.0;
        s.thresholds.alarm = 0.0;
        s.alerts.open_after = 1;
    })
    .await
    else {
        return;
    };
    let (rx, url, _t) = start_receiver(2, 0).await;
    let hook = create_hook(&app, &url).await;
    let secret = hook["secret"].as_str().unwrap().to_string();
    let id = hook["id"].as_str().unwrap().to_string();
    let (s, _, body) = checked(
        app.client
            .get(app.url("/v1/webhooks"))
            .bearer_auth(&app.admin_key),
        "GET",
        "/v1/webhooks",
    )
    .await;
    assert_eq!(s, 200);
    assert!(
        !String::from_utf8_lossy(&body).contains(&secret),
        "the secret is shown once"
    );

    assert_eq!(app.post_json("m-hook", &json_record(1)).await.status(), 201);
    wait_for("two deliveries", || rx.got.lock().unwrap().len() >= 2).await;
    let got = rx.got.lock().unwrap().clone();
    let mut events = Vec::new();
    for (h, body) in &got {
        // The documented recipe: HMAC-SHA256(secret, "<t>." + body), hex.
        let sig = h["gearwear-signature"].to_str().unwrap();
        let (t, v1) = sig.split_once(',').unwrap();
        let t: i64 = t.strip_prefix("t=").unwrap().parse().unwrap();
        assert_eq!(
            v1.strip_prefix("v1=").unwrap(),
            gearwear::keys::webhook_mac(&secret, t, body)
        );
        let p: Value = serde_json::from_slice(body).unwrap();
        assert_eq!(p["machine_id"], "m-hook");
        assert_eq!(
            h["gearwear-event"].to_str().unwrap(),
            p["event"].as_str().unwrap()
        );
        events.push(p["event"].as_str().unwrap().to_string());
    }
    events.sort();
    assert_eq!(events, ["diagnosis.created", "wear.threshold_crossed"]);

    // The log shows the failed attempts before the success. The receiver can see the second
    // success a moment before the worker has written it to the log (it records an attempt once
    // the answer is in), so wait for the log to catch up, bounded.
    let mut log = serde_json::Value::Null;
    for _ in 0..100 {
        let (s, _, body) = checked(
            app.client
                .get(app.url(&format!("/v1/webhooks/{id}/deliveries")))
                .bearer_auth(&app.admin_key),
            "GET",
            "/v1/webhooks/{webhook_id}/deliveries",
        )
        .await;
        assert_eq!(s, 200);
        log = json(&body);
        let done = log["deliveries"]
            .as_array()
            .is_some_and(|ds| ds.iter().all(|d| d["status"] == "delivered"));
        if done {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    let ds = log["deliveries"].as_array().unwrap();
    assert_eq!(ds.len(), 2);
    let attempts: usize = ds
        .iter()
        .map(|d| d["attempts"].as_array().unwrap().len())
        .sum();
    assert_eq!(attempts, 4, "2 failures + 2 successes: {log:#}");
    assert!(ds.iter().all(|d| d["status"] == "delivered"));
    assert!(ds.iter().any(|d| d["attempts"][0]["status_code"] == 500));

    // Delete: 204, then 404.
    let del = || {
        app.client
            .delete(app.url(&format!("/v1/webhooks/{id}")))
            .bearer_auth(&app.admin_key)
    };
    let (s, _, _) = checked(del(), "DELETE", "/v1/webhooks/{webhook_id}").await;
    assert_eq!(s, 204);
    let (s, _, _) = checked(del(), "DELETE", "/v1/webhooks/{webhook_id}").await;
    assert_eq!(s, 404);
    // A bad subscription.
    let r = app
        .client
        .post(app.url("/v1/webhooks"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"url": "ftp://x", "events": ["diagnosis.created"]}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 422);
}

async fn deliveries_survive_a_restart(b: Backend) {
    let Some(mut app) = spawn_app(b, |_| {}).await else {
        return;
    };
    // A port nobody listens on yet.
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let url = format!("http://127.0.0.1:{port}/hook");
    let hook = create_hook(&app, &url).await;
    let hook_id = hook["id"].as_str().unwrap();
    assert_eq!(
        app.post_json("m-restart", &json_record(1)).await.status(),
        201
    );
    // Let it fail at least once, then stop the service with the delivery pending.
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    app.restart(|_| {}).await;
    let (rx, _, _t) = start_receiver(0, port).await;
    // The record's events (`diagnosis.created`, and `wear.threshold_crossed` when an alert
    // opens) are both pending across the restart; they may arrive in either order.
    let created = || {
        rx.got.lock().unwrap().iter().find_map(|(_, body)| {
            let p: Value = serde_json::from_slice(body).unwrap();
            (p["event"] == "diagnosis.created").then_some(p)
        })
    };
    wait_for("the diagnosis.created delivery after the restart", || {
        created().is_some()
    })
    .await;
    let p = created().unwrap();
    assert_eq!(p["machine_id"], "m-restart");
    // The log spans the restart: the refused attempts before it (saying why), the success
    // after it; each delivery received once.
    let log = delivery_log_when_settled(&app, hook_id).await;
    let ds = log["deliveries"].as_array().unwrap();
    assert!(!ds.is_empty(), "{log:#}");
    for d in ds {
        assert_eq!(d["status"], "delivered", "{log:#}");
        let att = d["attempts"].as_array().unwrap();
        assert!(att.len() >= 2, "{log:#}");
        assert!(att[0]["status_code"].is_null(), "{log:#}");
        assert!(
            att[0]["error"]
                .as_str()
                .is_some_and(|e| e.to_ascii_lowercase().contains("refused")),
            "the error names the cause: {log:#}"
        );
        assert!(
            att.last().unwrap()["status_code"]
                .as_u64()
                .is_some_and(|c| (200..300).contains(&c)),
            "{log:#}"
        );
    }
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let got = rx.got.lock().unwrap().clone();
    let ids: std::collections::HashSet<_> = got
        .iter()
        .map(|(h, _)| h["gearwear-delivery"].to_str().unwrap().to_string())
        .collect();
    assert_eq!(got.len(), ds.len(), "each delivery received once");
    assert_eq!(ids.len(), ds.len());
}

/// The delivery log once no delivery is pending any more.
async fn delivery_log_when_settled(app: &TestApp, hook_id: &str) -> Value {
    for _ in 0..200 {
        let (s, _, body) = checked(
            app.client
                .get(app.url(&format!("/v1/webhooks/{hook_id}/deliveries")))
                .bearer_auth(&app.admin_key),
            "GET",
            "/v1/webhooks/{webhook_id}/deliveries",
        )
        .await;
        assert_eq!(s, 200);
        let log = json(&body);
        if log["deliveries"]
            .as_array()
            .unwrap()
            .iter()
            .all(|d| d["status"] != "pending")
        {
            return log;
        }
        tokio::time::sleep(std::time::Duration::from_millis(25)).await;
    }
    panic!("deliveries still pending");
}

/// The receiver is down (port closed), then up but failing (500), then well: every delivery
/// retries with a growing back-off, arrives once it is back, and the log over the API shows
/// every attempt with its error or status. At least once, and no duplicate here.
async fn receiver_down_then_back(b: Backend) {
    use std::time::{Duration, Instant};
    let base = Duration::from_millis(100);
    let max = Duration::from_millis(1600);
    let Some(app) = spawn_app(b, |s| {
        s.webhooks.base_backoff = base;
        s.webhooks.max_backoff = max;
        s.webhooks.max_attempts = 20;
        // Thresholds out of reach: one `diagnosis.created` per record, nothing else.
        s.thresholds.warning = 10.0;
        s.thresholds.alarm = 20.0;
    })
    .await
    else {
        return;
    };
    // A port nobody listens on yet.
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let hook = create_hook(&app, &format!("http://127.0.0.1:{port}/hook")).await;
    let id = hook["id"].as_str().unwrap().to_string();
    let mut diagnoses = Vec::new();
    for seed in 0..4 {
        let r = app.post_json("m-down", &json_record(seed)).await;
        assert_eq!(r.status(), 201);
        diagnoses.push(
            json(&r.bytes().await.unwrap())["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
    }
    // Down (connection refused) for 1.2 s, then 500 for 2.5 s (longer than the largest
    // back-off, so every delivery meets it), then 204.
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let (rx, _, _t) = start_receiver(0, port).await;
    rx.failing.store(true, Ordering::SeqCst);
    tokio::time::sleep(Duration::from_millis(2500)).await;
    rx.failing.store(false, Ordering::SeqCst);
    let up = Instant::now();
    wait_for("every event after the receiver came back", || {
        let got = rx.got.lock().unwrap();
        let ids: std::collections::HashSet<String> = got
            .iter()
            .map(|(_, b)| serde_json::from_slice::<Value>(b).unwrap()["diagnosis_id"].to_string())
            .collect();
        diagnoses.iter().all(|d| ids.contains(&format!("\"{d}\"")))
    })
    .await;
    eprintln!(
        "{b:?}: all {} events delivered {:.2} s after the receiver came back",
        diagnoses.len(),
        up.elapsed().as_secs_f64()
    );
    // At least once, and here exactly once: one 2xx per delivery id.
    let got = rx.got.lock().unwrap().clone();
    let mut per_delivery = std::collections::HashMap::<String, usize>::new();
    for (h, _) in &got {
        *per_delivery
            .entry(h["gearwear-delivery"].to_str().unwrap().to_string())
            .or_default() += 1;
    }
    let duplicates: usize = per_delivery.values().map(|n| n - 1).sum();
    assert_eq!(per_delivery.len(), diagnoses.len(), "{per_delivery:?}");
    assert_eq!(duplicates, 0, "{per_delivery:?}");

    // The log: every attempt, its error or status, growing gaps.
    let log = delivery_log_when_settled(&app, &id).await;
    let ds = log["deliveries"].as_array().unwrap();
    assert_eq!(ds.len(), diagnoses.len(), "{log:#}");
    let ms = |t: &Value| gearwear::time::parse_rfc3339(t.as_str().unwrap()).unwrap();
    let mut summary = Vec::new();
    for d in ds {
        assert_eq!(d["status"], "delivered", "{d:#}");
        assert!(per_delivery.contains_key(d["id"].as_str().unwrap()));
        let att = d["attempts"].as_array().unwrap();
        assert_eq!(d["attempt_count"].as_u64().unwrap() as usize, att.len());
        let n = att.len();
        assert!(n >= 3, "refused, 500, delivered at least: {d:#}");
        for (k, a) in att.iter().enumerate() {
            assert_eq!(a["attempt"].as_u64().unwrap() as usize, k + 1, "{d:#}");
            let code = a["status_code"].as_u64();
            if k + 1 < n {
                // A failure says why: no answer (the error) or the status.
                assert!(
                    !a["error"].as_str().unwrap_or("").is_empty(),
                    "a failed attempt without its error: {a}"
                );
                assert!(code.is_none() || code == Some(500), "{a}");
            } else {
                assert!(code.is_some_and(|c| (200..300).contains(&c)), "{a}");
            }
        }
        assert!(
            att[0]["status_code"].is_null(),
            "first attempt: port closed: {d:#}"
        );
        assert!(
            att[0]["error"]
                .as_str()
                .is_some_and(|e| e.to_ascii_lowercase().contains("refused")),
            "the error names the cause: {d:#}"
        );
        assert!(
            att.iter().any(|a| a["status_code"] == 500),
            "an attempt met the 500s: {d:#}"
        );
        // Attempt k+1 waits at least base · 2^(k−1) (capped) after attempt k ended.
        let mut gaps = Vec::new();
        for k in 1..n {
            let gap = ms(&att[k]["attempted_at"]) - ms(&att[k - 1]["attempted_at"]);
            let want = gearwear::service::webhooks::backoff(base, max, k as i64).as_millis() as i64;
            assert!(
                gap >= want - 1,
                "attempt {} came {gap} ms after the previous one, back-off is {want} ms: {d:#}",
                k + 1
            );
            assert!(
                gap <= want + 1500,
                "attempt {} came {gap} ms late (back-off {want} ms): {d:#}",
                k + 1
            );
            gaps.push(gap);
        }
        summary.push(format!(
            "{} attempts, errors {:?}, gaps {gaps:?} ms",
            n,
            att.iter()
                .map(|a| a["status_code"]
                    .as_u64()
                    .map(|c| c.to_string())
                    .unwrap_or_else(|| "no answer".into()))
                .collect::<Vec<_>>()
        ));
    }
    eprintln!("{b:?} delivery log:\n  {}", summary.join("\n  "));
}
