//! Webhooks: signed deliveries, retries with back-off, at-least-once across a restart, the
//! delivery log over the API.

use std::sync::{Arc, Mutex};

use axum::Router;
use axum::body::Bytes;
use axum::http::{HeaderMap, StatusCode};
use axum::routing::post;
use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(signed_delivery_with_retries, deliveries_survive_a_restart);

/// A receiver that fails the first `fail_first` requests with 500, then answers 204.
#[derive(Clone, Default)]
struct Receiver {
    got: Arc<Mutex<Vec<(HeaderMap, Bytes)>>>,
    fail_first: Arc<Mutex<usize>>,
}

async fn start_receiver(
    fail_first: usize,
    port: u16,
) -> (Receiver, String, tokio::task::JoinHandle<()>) {
    let rx = Receiver {
        got: Default::default(),
        fail_first: Arc::new(Mutex::new(fail_first)),
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

async fn create_hook(app: &TestApp, url: &str) -> Value {
    let req = app
        .client
        .post(app.url("/v1/webhooks"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"url": url, "events": ["diagnosis.created", "wear.threshold_crossed"]}));
    let (s, _, body) = checked(req, "POST", "/v1/webhooks").await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    json(&body)
}

async fn wait_for<F: Fn() -> bool>(what: &str, f: F) {
    for _ in 0..200 {
        if f() {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(25)).await;
    }
    panic!("timed out waiting for {what}");
}

async fn signed_delivery_with_retries(b: Backend) {
    // Thresholds at 0 so the first record also crosses into `alarm`.
    let Some(app) = spawn_app(b, |s| {
        s.thresholds.warning = 0.0;
        s.thresholds.alarm = 0.0;
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

    // The log shows the failed attempts before the success.
    let (s, _, body) = checked(
        app.client
            .get(app.url(&format!("/v1/webhooks/{id}/deliveries")))
            .bearer_auth(&app.admin_key),
        "GET",
        "/v1/webhooks/{webhook_id}/deliveries",
    )
    .await;
    assert_eq!(s, 200);
    let log = json(&body);
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
    create_hook(&app, &url).await;
    assert_eq!(
        app.post_json("m-restart", &json_record(1)).await.status(),
        201
    );
    // Let it fail at least once, then stop the service with the delivery pending.
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    app.restart(|_| {}).await;
    let (rx, _, _t) = start_receiver(0, port).await;
    wait_for("the delivery after the restart", || {
        !rx.got.lock().unwrap().is_empty()
    })
    .await;
    let p: Value = serde_json::from_slice(&rx.got.lock().unwrap()[0].1).unwrap();
    assert_eq!(p["event"], "diagnosis.created");
    assert_eq!(p["machine_id"], "m-restart");
}
