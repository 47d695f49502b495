//! The API on both stores: ingest and read back, formats, idempotency, auth, limits (bad
//! records: `bad_records.rs`).

use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    health_ready_and_metrics,
    ingest_json_then_read_everything_back,
    every_body_format_is_accepted,
    idempotency_key_never_creates_a_record_twice,
    keys_and_scopes_are_enforced,
    rate_limit_and_open_dashboard,
);

async fn health_ready_and_metrics(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let (s, _, body) = checked(app.client.get(app.url("/healthz")), "GET", "/healthz").await;
    assert_eq!(s, 200);
    assert_eq!(json(&body)["status"], "ok");
    let (s, _, body) = checked(app.client.get(app.url("/readyz")), "GET", "/readyz").await;
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    let r = json(&body);
    assert_eq!(
        r["checks"]["store"]["kind"],
        if b == Backend::Sqlite {
            "sqlite"
        } else {
            "postgres"
        }
    );
    let (s, _, body) = checked(app.client.get(app.url("/metrics")), "GET", "/metrics").await;
    assert_eq!(s, 200);
    let text = String::from_utf8(body).unwrap();
    assert!(text.contains("gearwear_signature_table_loaded 1"), "{text}");
    assert!(
        text.contains(
            "gearwear_http_requests_total{method=\"GET\",route=\"/readyz\",status=\"200\"} 1"
        ),
        "{text}"
    );
}

async fn ingest_json_then_read_everything_back(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let req = app
        .client
        .post(app.url("/v1/machines/press-7/records"))
        .bearer_auth(&app.ingest_key)
        .json(&json_record(1));
    let (s, h, body) = checked(req, "POST", "/v1/machines/{machine_id}/records").await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    let d = json(&body);
    let id = d["id"].as_str().unwrap().to_string();
    assert_eq!(h["location"], format!("/v1/diagnoses/{id}").as_str());
    assert_eq!(d["machine_id"], "press-7");
    let w = &d["wear_degree"];
    assert!(w["lower"].as_f64().unwrap() <= w["estimate"].as_f64().unwrap());
    // The simulated record's f1 is Ω1 · f_ref of the rig (1.07 · 870 Hz); found tacho-less.
    let f1 = d["f1_hz"].as_f64().unwrap();
    assert!((f1 / (1.07 * 870.0) - 1.0).abs() < 1e-3, "f1 {f1} Hz: {d}");
    assert_eq!(d["alert"]["basis"], "wear", "a record the model fits: {d}");

    // Two more, for the trend and pagination.
    for seed in [2, 3] {
        assert_eq!(
            app.post_json("press-7", &json_record(seed)).await.status(),
            201
        );
    }

    let (s, _, body) = checked(
        app.client
            .get(app.url("/v1/machines"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines",
    )
    .await;
    assert_eq!(s, 200);
    let ms = json(&body);
    assert_eq!(ms["machines"][0]["id"], "press-7");
    assert_eq!(ms["machines"][0]["record_count"], 3);

    let (s, h, body) = checked(
        app.client
            .get(app.url("/v1/machines/press-7"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}",
    )
    .await;
    assert_eq!(s, 200);
    let m = json(&body);
    assert_eq!(m["trend"].as_array().unwrap().len(), 3);
    assert!(m["latest"]["f1_hz"].as_f64().unwrap() > 0.0);
    // ETag → 304.
    let etag = h["etag"].to_str().unwrap().to_string();
    let r = app
        .client
        .get(app.url("/v1/machines/press-7"))
        .bearer_auth(&app.read_key)
        .header("if-none-match", &etag)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);

    // Pagination: 2 + 1.
    let (s, _, body) = checked(
        app.client
            .get(app.url("/v1/machines/press-7/diagnoses?limit=2"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}/diagnoses",
    )
    .await;
    assert_eq!(s, 200);
    let p1 = json(&body);
    assert_eq!(p1["items"].as_array().unwrap().len(), 2);
    assert_eq!(p1["items"][0]["id"], id.as_str());
    let cursor = p1["next_cursor"].as_str().unwrap();
    let (_, h2, body) = checked(
        app.client
            .get(app.url(&format!(
                "/v1/machines/press-7/diagnoses?limit=2&cursor={cursor}"
            )))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}/diagnoses",
    )
    .await;
    let p2 = json(&body);
    assert_eq!(p2["items"].as_array().unwrap().len(), 1);
    assert_eq!(p2["next_cursor"], Value::Null);
    let r = app
        .client
        .get(app.url(&format!(
            "/v1/machines/press-7/diagnoses?limit=2&cursor={cursor}"
        )))
        .bearer_auth(&app.read_key)
        .header("if-none-match", h2["etag"].to_str().unwrap())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304, "an unchanged page is cheap to poll");
    // `since` in the future: empty.
    let r = app
        .get("/v1/machines/press-7/diagnoses?since=2999-01-01T00:00:00Z")
        .await;
    assert_eq!(json(&r.bytes().await.unwrap())["items"], json!([]));

    // One diagnosis with its spectrum.
    let (s, _, body) = checked(
        app.client
            .get(app.url(&format!("/v1/diagnoses/{id}")))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/diagnoses/{diagnosis_id}",
    )
    .await;
    assert_eq!(s, 200);
    let dd = json(&body);
    let sp = &dd["spectrum"];
    let f = sp["f_over_f1"].as_array().unwrap();
    let l = sp["level_db"].as_array().unwrap();
    assert_eq!(f.len(), l.len());
    assert!(f.len() > 100 && f.len() <= 1200);
    // The f1 line is the 0 dB reference: the loudest point near f/f1 = 1 reads ≈ 0 dB.
    let near1 = f
        .iter()
        .zip(l)
        .filter(|(f, _)| (f.as_f64().unwrap() - 1.0).abs() < 0.01)
        .map(|(_, l)| l.as_f64().unwrap())
        .fold(f64::MIN, f64::max);
    assert!(near1.abs() < 0.5, "f1 level {near1} dB");
    let marks: Vec<&str> = sp["marks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert!(
        marks.contains(&"f1") && marks.contains(&"f2") && marks.contains(&"f3"),
        "{marks:?}"
    );

    // The same answer by the record's id (alerts and trend points name records).
    let record_id = d["record_id"].as_str().unwrap();
    let (s, _, body) = checked(
        app.client
            .get(app.url(&format!("/v1/records/{record_id}")))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/records/{record_id}",
    )
    .await;
    assert_eq!(s, 200);
    let by_record = json(&body);
    assert_eq!(by_record["id"], id.as_str());
    assert_eq!(by_record["record_id"], record_id);
    assert_eq!(by_record["diagnosis"], dd["diagnosis"]);
}

async fn every_body_format_is_accepted(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let (x, fs) = record_samples(1.07, 1.0, 9);
    let url = app.url("/v1/machines/m1/records?sample_rate_hz=25600");
    let csv: String = x.iter().map(|v| format!("{v:.7}\n")).collect();
    let f32le: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
    let wav = gearwear::record::encode_wav(&x, fs as u32, true);
    for (ct, body) in [
        ("text/csv", csv.into_bytes()),
        ("application/octet-stream", f32le),
        ("audio/wav", wav),
    ] {
        let req = app
            .client
            .post(&url)
            .bearer_auth(&app.ingest_key)
            .header("content-type", ct)
            .body(body);
        let (s, _, body) = checked(req, "POST", "/v1/machines/{machine_id}/records").await;
        assert_eq!(s, 201, "{ct}: {}", String::from_utf8_lossy(&body));
        assert!(
            (json(&body)["f1_hz"].as_f64().unwrap() / (1.07 * 870.0) - 1.0).abs() < 1e-3,
            "{ct}"
        );
    }
    // 16-bit PCM WAV without sample_rate_hz: the header's rate. Scaled into PCM's ±1 range
    // (the record peaks near 1.6; clamped it would be a clipped record, refused).
    let half: Vec<f64> = x.iter().map(|v| 0.5 * v).collect();
    let wav = gearwear::record::encode_wav(&half, fs as u32, false);
    let r = app
        .client
        .post(app.url("/v1/machines/m1/records"))
        .bearer_auth(&app.ingest_key)
        .header("content-type", "audio/wav")
        .body(wav)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let m = json(&app.get("/v1/machines/m1").await.bytes().await.unwrap());
    assert_eq!(m["record_count"], 4);
}

async fn idempotency_key_never_creates_a_record_twice(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let send = |body: Value, key: &'static str| {
        app.client
            .post(app.url("/v1/machines/m2/records"))
            .bearer_auth(&app.ingest_key)
            .header("idempotency-key", key)
            .json(&body)
            .send()
    };
    let r1 = send(json_record(5), "k-1").await.unwrap();
    assert_eq!(r1.status(), 201);
    let d1 = json(&r1.bytes().await.unwrap());
    // The same request again, and two at once: one record, the same answer.
    let (r2, r3) = tokio::join!(send(json_record(5), "k-1"), send(json_record(5), "k-1"));
    for r in [r2.unwrap(), r3.unwrap()] {
        assert_eq!(r.status(), 201);
        assert_eq!(r.headers()["idempotent-replayed"], "true");
        assert_eq!(json(&r.bytes().await.unwrap())["id"], d1["id"]);
    }
    // Concurrent first use of a new key: one wins, the other replays.
    let (a, c) = tokio::join!(send(json_record(6), "k-2"), send(json_record(6), "k-2"));
    let (a, c) = (a.unwrap(), c.unwrap());
    assert_eq!(
        (a.status(), c.status()),
        (reqwest::StatusCode::CREATED, reqwest::StatusCode::CREATED)
    );
    assert_eq!(
        json(&a.bytes().await.unwrap())["id"],
        json(&c.bytes().await.unwrap())["id"]
    );
    // The same key with another body: refused.
    let r = send(json_record(7), "k-1").await.unwrap();
    assert_eq!(r.status(), 422);
    assert_eq!(
        json(&r.bytes().await.unwrap())["type"],
        "urn:gearwear:problem:idempotency-key-reused"
    );
    let m = json(&app.get("/v1/machines/m2").await.bytes().await.unwrap());
    assert_eq!(m["record_count"], 2);
}

async fn problem(r: reqwest::Response) -> (u16, Value) {
    let s = r.status().as_u16();
    assert_eq!(
        r.headers().get("content-type").map(|v| v.to_str().unwrap()),
        Some("application/problem+json"),
        "status {s}"
    );
    (s, json(&r.bytes().await.unwrap()))
}

async fn keys_and_scopes_are_enforced(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let post = |key: Option<&str>| {
        let mut r = app
            .client
            .post(app.url("/v1/machines/m3/records"))
            .json(&json_record(1));
        if let Some(k) = key {
            r = r.bearer_auth(k);
        }
        r.send()
    };
    // No key.
    let r = post(None).await.unwrap();
    assert!(r.headers().contains_key("www-authenticate"));
    let (s, p) = problem(r).await;
    assert_eq!(
        (s, p["type"].as_str().unwrap()),
        (401, "urn:gearwear:problem:unauthorized")
    );
    // Wrong scope.
    let (s, p) = problem(post(Some(&app.read_key)).await.unwrap()).await;
    assert_eq!((s, p["required_scope"].as_str().unwrap()), (403, "ingest"));
    // Unknown and malformed keys.
    let fake = format!("gw_{}_{}", "0123456789abcdef", "x".repeat(43));
    assert_eq!(problem(post(Some(&fake)).await.unwrap()).await.0, 401);
    assert_eq!(problem(post(Some("hunter2")).await.unwrap()).await.0, 401);
    // A tampered secret of a real key.
    let tampered = format!("{}x", app.ingest_key);
    assert_eq!(problem(post(Some(&tampered)).await.unwrap()).await.0, 401);
    // Reads need a read key; an ingest key is not one; admin is.
    let get = |k: &str| {
        app.client
            .get(app.url("/v1/machines"))
            .bearer_auth(k)
            .send()
    };
    assert_eq!(problem(get(&app.ingest_key).await.unwrap()).await.0, 403);
    assert_eq!(get(&app.admin_key).await.unwrap().status(), 200);
    let r = app
        .client
        .get(app.url("/v1/machines"))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, 401);
    // Webhooks need admin.
    let r = app
        .client
        .get(app.url("/v1/webhooks"))
        .bearer_auth(&app.read_key)
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, 403);
    // Revocation takes effect at once.
    let (row, key) = gearwear::service::cli::create_key(
        app.store.as_ref(),
        &[gearwear::keys::Scope::Ingest],
        "t",
    )
    .await
    .unwrap();
    assert_eq!(post(Some(&key)).await.unwrap().status(), 201);
    assert!(app.store.revoke_key(&row.id, 1).await.unwrap());
    assert_eq!(problem(post(Some(&key)).await.unwrap()).await.0, 401);
    // The dashboard shell and health are public.
    for p in ["/", "/app.js", "/style.css", "/healthz"] {
        assert_eq!(
            app.client.get(app.url(p)).send().await.unwrap().status(),
            200,
            "{p}"
        );
    }
}

async fn rate_limit_and_open_dashboard(b: Backend) {
    let Some(app) = spawn_app(b, |s| {
        s.limits.rate_per_second = 1.0;
        s.limits.rate_burst = 2.0;
        s.open_dashboard = true;
    })
    .await
    else {
        return;
    };
    // Open dashboard: reads need no key…
    assert_eq!(
        app.client
            .get(app.url("/v1/machines"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    // …writes still do.
    let r = app
        .client
        .post(app.url("/v1/machines/x/records"))
        .json(&json_record(1))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 401);
    // Burst of 2, then 429 with Retry-After.
    let get = || {
        app.client
            .get(app.url("/v1/machines"))
            .bearer_auth(&app.read_key)
            .send()
    };
    assert_eq!(get().await.unwrap().status(), 200);
    assert_eq!(get().await.unwrap().status(), 200);
    let r = get().await.unwrap();
    assert!(r.headers().contains_key("retry-after"));
    let (s, p) = problem(r).await;
    assert_eq!(
        (s, p["type"].as_str().unwrap()),
        (429, "urn:gearwear:problem:rate-limited")
    );
}
