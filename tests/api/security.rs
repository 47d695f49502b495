//! Item 5 of the reliability issue, "Security", on both stores
//! (`cargo test --release --test api security`; docs/reliability/security.md):
//!
//! * every route of the service's one route list (`gearwear::service::routes`), with the access
//!   it declares — checked against `openapi.yaml`'s `security` and `x-scope` — with no key, malformed headers, unknown, tampered
//!   and revoked keys, each scope; refusals store nothing; `--dashboard-without-key` opens reads only;
//! * keys stored hashed (the secret is nowhere in the SQLite file or the PostgreSQL tables);
//! * body size, sample count and rate limits per key;
//! * no secret in the logs of the real binary at debug/trace;
//! * a webhook delivery verified with the recipe of docs/service.md, taken literally;
//! * a non-loopback address refused without an active key;
//! * webhook URLs aimed at link-local / metadata / unspecified addresses refused.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gearwear::keys::Scope;
use gearwear::service::routes::{Access as Need, routes};
use gearwear::store::{CalibrationRow, WebhookRow};
use reqwest::header::{HeaderMap, HeaderValue};
use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;
use crate::webhooks::{create_hook, start_receiver};

both_stores!(
    every_route_needs_a_key_of_its_scope,
    open_dashboard_opens_reads_only,
    keys_are_stored_hashed,
    limits_are_per_key,
    no_secret_in_the_logs,
    webhook_signature_follows_the_documented_recipe,
    non_loopback_address_needs_an_active_key,
    webhook_urls_are_restricted,
);

// ---------- The scope table ----------

/// Every route as `(METHOD, template, access)`, from the service's route list.
fn route_list() -> Vec<(String, &'static str, Need)> {
    routes()
        .into_iter()
        .map(|r| (r.method.to_string(), r.path, r.access))
        .collect()
}

/// A route is public exactly when openapi.yaml gives it `security: []`, and a keyed route's
/// scope is the spec's `x-scope`.
#[test]
fn the_route_list_s_access_is_the_spec_s() {
    for (m, p, n) in route_list() {
        let op = &spec()["paths"][p][m.to_ascii_lowercase()];
        let public_in_spec = op["security"].as_array().is_some_and(|a| a.is_empty());
        assert_eq!(
            public_in_spec,
            n == Need::Public,
            "{m} {p}: the route list says {n:?}, openapi.yaml's `security` says otherwise"
        );
        if let Need::Key(scope) = n {
            assert_eq!(
                op["x-scope"].as_str(),
                Some(scope.as_str()),
                "{m} {p}: the route list needs scope `{}`, openapi.yaml's `x-scope` differs",
                scope.as_str()
            );
        }
    }
}

/// The ids the route templates are filled with.
struct Fixture {
    machine: String,
    diagnosis: String,
    webhook: String,
    record: String,
}

impl Fixture {
    /// A machine with a diagnosis and a calibration, and a webhook.
    async fn new(app: &TestApp) -> Fixture {
        let machine = "m-sec".to_string();
        let r = app
            .client
            .post(app.url(&format!("/v1/machines/{machine}/records?baseline=true")))
            .bearer_auth(&app.ingest_key)
            .json(&json_record(11))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
        let d = json(&r.bytes().await.unwrap());
        let diagnosis = d["id"].as_str().unwrap().to_string();
        let record = d["record_id"].as_str().unwrap().to_string();
        // A calibration row, so that a refused DELETE has something to (not) delete. Written
        // to the store directly: a real calibration runs simulations for a minute.
        app.store
            .put_calibration(&CalibrationRow {
                machine_id: machine.clone(),
                id: gearwear::store::new_id(),
                created_at: gearwear::store::now_ms(),
                effects: "[]".into(),
                report: json!({"effects": []}).to_string(),
            })
            .await
            .unwrap();
        let webhook = create_hook(app, "http://127.0.0.1:9/fixture").await["id"]
            .as_str()
            .unwrap()
            .to_string();
        Fixture {
            machine,
            diagnosis,
            webhook,
            record,
        }
    }

    fn path(&self, template: &str) -> String {
        template
            .replace("{machine_id}", &self.machine)
            .replace("{diagnosis_id}", &self.diagnosis)
            .replace("{webhook_id}", &self.webhook)
            .replace("{record_id}", &self.record)
            .replace("{gearbox_id}", "sec-gearbox")
            .replace("{alert_id}", "no-such-alert")
    }
}

/// A request for a route. `full`: a body the route would act on (a real record for a
/// calibration, so a refusal that let it through would be seen); otherwise a cheap one.
fn request(
    app: &TestApp,
    method: &str,
    template: &str,
    path: &str,
    full: bool,
) -> reqwest::RequestBuilder {
    let url = app.url(path);
    match (method, template) {
        ("POST", "/v1/machines/{machine_id}/records") => app.client.post(url).json(&json_record(3)),
        ("POST", "/v1/machines/{machine_id}/calibration") => {
            if full {
                app.client.post(url).json(&json_record(4))
            } else {
                // Empty: refused with a 422 before any simulation runs.
                app.client
                    .post(url)
                    .json(&json!({"sample_rate_hz": 25600, "samples": []}))
            }
        }
        ("POST", "/v1/webhooks") => app
            .client
            .post(url)
            .json(&json!({"url": "http://127.0.0.1:9/matrix", "events": ["diagnosis.created"]})),
        ("PUT", "/v1/machines/{machine_id}") => app
            .client
            .put(url)
            .json(&json!({"gearbox": "wang2019", "input_shaft_hz": 31.0})),
        ("POST", "/v1/machines/{machine_id}/baseline") => app
            .client
            .post(url)
            .json(&json!({"record_ids": ["no-such-record"]})),
        ("PUT", "/v1/gearboxes/{gearbox_id}") => app
            .client
            .put(url)
            .header("content-type", "application/toml")
            .body(include_str!("../../configs/gearboxes/spur-pair.toml")),
        ("POST", "/v1/alerts/{alert_id}/acknowledge") => app
            .client
            .post(url)
            .json(&json!({"note": "checked the gearbox"})),
        ("GET", _) => app.client.get(url),
        ("DELETE", _) => app.client.delete(url),
        (m, t) => panic!("no request written for {m} {t}: add one to `request`"),
    }
}

/// What the store holds that a write could change.
#[derive(Debug, PartialEq)]
struct Snapshot {
    records: i64,
    webhooks: Vec<String>,
    calibrated: bool,
    gearboxes: usize,
    baseline: usize,
    machine_gearbox: Option<(Option<String>, Option<f64>)>,
}

async fn snapshot(app: &TestApp, machine: &str) -> Snapshot {
    let records = app
        .store
        .list_machines()
        .await
        .unwrap()
        .iter()
        .map(|m| m.record_count)
        .sum();
    let mut webhooks: Vec<String> = app
        .store
        .list_webhooks()
        .await
        .unwrap()
        .into_iter()
        .map(|w| w.id)
        .collect();
    webhooks.sort();
    let calibrated = app.store.get_calibration(machine).await.unwrap().is_some();
    let gearboxes = app.store.list_gearboxes().await.unwrap().len();
    let baseline = app.store.baseline_records(machine).await.unwrap().len();
    let machine_gearbox = app
        .store
        .get_machine(machine)
        .await
        .unwrap()
        .map(|m| (m.gearbox_id, m.input_shaft_hz));
    Snapshot {
        records,
        webhooks,
        calibrated,
        gearboxes,
        baseline,
        machine_gearbox,
    }
}

/// Send; the status, the headers and the body.
async fn send(req: reqwest::RequestBuilder) -> (u16, HeaderMap, Vec<u8>) {
    let r = req.send().await.unwrap();
    let s = r.status().as_u16();
    let h = r.headers().clone();
    (s, h, r.bytes().await.unwrap().to_vec())
}

/// A 401 or 403 problem, as documented for the route; returns the problem.
fn assert_refusal(
    what: &str,
    method: &str,
    template: &str,
    want: u16,
    (status, headers, body): &(u16, HeaderMap, Vec<u8>),
) -> Value {
    assert_eq!(
        *status,
        want,
        "{what} on {method} {template}: {}",
        String::from_utf8_lossy(body)
    );
    let ct = headers
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    assert_eq!(
        ct, "application/problem+json",
        "{what} on {method} {template}"
    );
    check_response(method, template, *status, ct, body);
    let p = json(body);
    let slug = if want == 401 {
        "unauthorized"
    } else {
        "forbidden"
    };
    assert_eq!(
        p["type"],
        format!("urn:gearwear:problem:{slug}"),
        "{what} on {method} {template}: {p}"
    );
    assert_eq!(p["status"], want);
    if want == 401 {
        assert!(
            headers.contains_key("www-authenticate"),
            "{what} on {method} {template}: 401 without WWW-Authenticate"
        );
    }
    p
}

/// Credentials that must all get a 401, whatever the route: `(what, Authorization value)`.
async fn bad_credentials(app: &TestApp) -> Vec<(&'static str, Option<HeaderValue>)> {
    let hv = |s: String| Some(HeaderValue::from_str(&s).unwrap());
    // A key with every scope, then revoked.
    let (row, revoked) =
        gearwear::service::cli::create_key(app.store.as_ref(), &[Scope::Admin], "revoked")
            .await
            .unwrap();
    assert!(
        app.store
            .revoke_key(&row.id, gearwear::store::now_ms())
            .await
            .unwrap()
    );
    // A real admin key with its last character changed.
    let mut tampered = app.admin_key.clone();
    let last = tampered.pop().unwrap();
    tampered.push(if last == 'A' { 'B' } else { 'A' });
    vec![
        ("no key", None),
        ("Basic credentials", hv("Basic dXNlcjpwYXNz".into())),
        ("Bearer without a key", hv("Bearer".into())),
        (
            "a bearer token that is not a key",
            hv("Bearer hunter2".into()),
        ),
        (
            "a non-UTF-8 header",
            Some(HeaderValue::from_bytes(b"Bearer gw_\xff\xfe").unwrap()),
        ),
        (
            "an unknown key",
            hv(format!("Bearer gw_0123456789abcdef_{}", "x".repeat(43))),
        ),
        (
            "an admin key with a wrong secret",
            hv(format!("Bearer {tampered}")),
        ),
        ("a revoked admin key", hv(format!("Bearer {revoked}"))),
    ]
}

async fn every_route_needs_a_key_of_its_scope(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let fx = Fixture::new(&app).await;
    let bad = bad_credentials(&app).await;
    // A planner's key: acknowledges alerts, nothing else (not even reads).
    let (_, ack_key) =
        gearwear::service::cli::create_key(app.store.as_ref(), &[Scope::Acknowledge], "planner")
            .await
            .unwrap();
    let keys = [
        ("ingest key", app.ingest_key.clone(), vec![Scope::Ingest]),
        ("read key", app.read_key.clone(), vec![Scope::Read]),
        ("acknowledge key", ack_key, vec![Scope::Acknowledge]),
        ("admin key", app.admin_key.clone(), vec![Scope::Admin]),
    ];
    let before = snapshot(&app, &fx.machine).await;
    let (mut n401, mut n403, mut n_ok, mut n_public) = (0, 0, 0, 0);

    // Refusals first: nothing may change in the store.
    let list = route_list();
    for (method, template, access) in &list {
        let (method, template) = (method.as_str(), *template);
        let path = fx.path(template);
        let Need::Key(scope) = *access else {
            // Public: answered without a key, and a bad key changes nothing.
            for (what, auth) in &bad {
                let mut req = request(&app, method, template, &path, true);
                if let Some(a) = auth {
                    req = req.header("authorization", a.clone());
                }
                let (s, _, body) = send(req).await;
                assert_eq!(
                    s,
                    200,
                    "{what} on public {method} {template}: {}",
                    String::from_utf8_lossy(&body)
                );
                n_public += 1;
            }
            continue;
        };
        for (what, auth) in &bad {
            let mut req = request(&app, method, template, &path, true);
            if let Some(a) = auth {
                req = req.header("authorization", a.clone());
            }
            assert_refusal(what, method, template, 401, &send(req).await);
            n401 += 1;
        }
        for (what, key, scopes) in &keys {
            if gearwear::keys::grants(scopes, scope) {
                continue;
            }
            let req = request(&app, method, template, &path, true).bearer_auth(key);
            let p = assert_refusal(what, method, template, 403, &send(req).await);
            assert_eq!(p["required_scope"], scope.as_str(), "{method} {template}");
            n403 += 1;
        }
    }
    assert_eq!(
        snapshot(&app, &fx.machine).await,
        before,
        "a refused request changed the store"
    );

    // Then every key that grants the scope gets through (whatever the answer, it is not a
    // refusal for the key).
    for (method, template, access) in &list {
        let (method, template) = (method.as_str(), *template);
        let Need::Key(scope) = *access else {
            continue;
        };
        for (what, key, scopes) in &keys {
            if !gearwear::keys::grants(scopes, scope) {
                continue;
            }
            let path = if template == "/v1/webhooks/{webhook_id}" && method == "DELETE" {
                // Delete a webhook of its own, not the fixture's.
                let id = create_hook(&app, "http://127.0.0.1:9/delete-me").await["id"]
                    .as_str()
                    .unwrap()
                    .to_string();
                format!("/v1/webhooks/{id}")
            } else if template == "/v1/machines/{machine_id}" && method == "DELETE" {
                // Delete a machine of its own, not the fixture's.
                let r = app
                    .client
                    .put(app.url("/v1/machines/delete-me"))
                    .bearer_auth(&app.admin_key)
                    .json(&json!({"gearbox": "wang2019"}))
                    .send()
                    .await
                    .unwrap();
                assert!(r.status().is_success(), "{}", r.status());
                "/v1/machines/delete-me".to_string()
            } else {
                fx.path(template)
            };
            let req = request(&app, method, template, &path, false).bearer_auth(key);
            let (s, _, body) = send(req).await;
            assert!(
                !matches!(s, 401 | 403 | 429) && s < 500,
                "{what} on {method} {template}: {s} {}",
                String::from_utf8_lossy(&body)
            );
            n_ok += 1;
        }
    }
    let keyed = list.iter().filter(|r| r.2 != Need::Public).count();
    eprintln!(
        "{b:?}: {} routes ({keyed} keyed, {} public): {n401} × 401, {n403} × 403, {n_ok} allowed \
         with the right scope, {n_public} public answers",
        list.len(),
        list.len() - keyed
    );
    assert_eq!(n401, keyed * bad.len());
}

async fn open_dashboard_opens_reads_only(b: Backend) {
    let Some(app) = spawn_app(b, |s| s.open_dashboard = true).await else {
        return;
    };
    let fx = Fixture::new(&app).await;
    let bad = bad_credentials(&app).await;
    let before = snapshot(&app, &fx.machine).await;
    let (mut reads, mut writes) = (0, 0);
    for (method, template, access) in &route_list() {
        let (method, template) = (method.as_str(), *template);
        let path = fx.path(template);
        match *access {
            Need::Public => {}
            Need::Key(Scope::Read) => {
                // No key: answered (200, or 404 for an id with nothing behind it).
                let (s, _, body) = send(request(&app, method, template, &path, false)).await;
                assert!(
                    s == 200 || s == 404,
                    "open dashboard, no key, {method} {template}: {s} {}",
                    String::from_utf8_lossy(&body)
                );
                // A key that is presented is still checked.
                for (what, auth) in bad.iter().filter(|(_, a)| a.is_some()) {
                    let req = request(&app, method, template, &path, false)
                        .header("authorization", auth.clone().unwrap());
                    assert_refusal(what, method, template, 401, &send(req).await);
                }
                reads += 1;
            }
            Need::Key(_) => {
                let (s, h, body) = send(request(&app, method, template, &path, true)).await;
                assert_refusal(
                    "open dashboard, no key",
                    method,
                    template,
                    401,
                    &(s, h, body),
                );
                writes += 1;
            }
        }
    }
    assert_eq!(
        snapshot(&app, &fx.machine).await,
        before,
        "a refused request changed the store"
    );
    eprintln!(
        "{b:?}: open dashboard: {reads} reads answered without a key, {writes} admin/ingest routes still 401"
    );
    assert!(reads >= 5 && writes >= 6);
}

// ---------- Keys stored hashed ----------

async fn keys_are_stored_hashed(b: Backend) {
    use sha2::{Digest, Sha256};
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let url = app.db.as_ref().unwrap().url.clone();
    // The real command, as an operator runs it.
    let out = gearwear_bin()
        .args([
            "keys",
            "create",
            "--scope",
            "ingest,read",
            "--label",
            "hash-test",
            "--database-url",
            url.as_str(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let token = String::from_utf8(out.stdout).unwrap().trim().to_string();
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains(&token),
        "the key goes to stdout only"
    );
    let (id, secret) = gearwear::keys::split_token(&token).expect("a key");
    let row = app.store.get_key(id).await.unwrap().expect("stored");
    assert_eq!(row.hash, hex::encode(Sha256::digest(secret.as_bytes())));
    assert_ne!(row.hash, secret);
    // Every key the fixture made, too.
    let mut secrets = vec![secret.to_string()];
    for k in [&app.admin_key, &app.ingest_key, &app.read_key] {
        secrets.push(gearwear::keys::split_token(k).unwrap().1.to_string());
    }
    match b {
        Backend::Sqlite => {
            // The file and its WAL, byte for byte.
            let mut bytes = Vec::new();
            for suffix in ["", "-wal", "-shm"] {
                bytes.extend(std::fs::read(format!("{url}{suffix}")).unwrap_or_default());
            }
            assert!(bytes.len() > 4096, "read the database files");
            for s in &secrets {
                assert!(
                    !bytes.windows(s.len()).any(|w| w == s.as_bytes()),
                    "a key secret is in the SQLite files"
                );
            }
        }
        Backend::Postgres => {
            // Every row of every table, as text.
            let pool = sqlx::PgPool::connect(&url).await.unwrap();
            let tables: Vec<String> = sqlx::query_scalar(
                "SELECT table_name::text FROM information_schema.tables \
                 WHERE table_schema = 'public' AND table_type = 'BASE TABLE'",
            )
            .fetch_all(&pool)
            .await
            .unwrap();
            assert!(tables.iter().any(|t| t == "api_keys"), "{tables:?}");
            let mut rows = 0;
            for t in &tables {
                let texts: Vec<String> = sqlx::query_scalar(sqlx::AssertSqlSafe(format!(
                    "SELECT t::text FROM \"{t}\" t"
                )))
                .fetch_all(&pool)
                .await
                .unwrap();
                for text in &texts {
                    for s in &secrets {
                        assert!(!text.contains(s.as_str()), "a key secret in table {t}");
                    }
                }
                rows += texts.len();
            }
            let hash: String = sqlx::query_scalar("SELECT hash FROM api_keys WHERE id = $1")
                .bind(id)
                .fetch_one(&pool)
                .await
                .unwrap();
            assert_eq!(hash, row.hash);
            eprintln!("Postgres: {rows} rows in {} tables searched", tables.len());
            pool.close().await;
        }
    }
}

// ---------- Limits per key ----------

async fn limits_are_per_key(b: Backend) {
    const BURST: usize = 8;
    let Some(app) = spawn_app(b, |s| {
        s.limits.max_body_bytes = 256 << 10;
        s.limits.max_samples = 10_000;
        s.limits.rate_per_second = 0.5;
        s.limits.rate_burst = BURST as f64;
    })
    .await
    else {
        return;
    };
    let key = |scopes: &'static [Scope]| {
        let store = app.store.clone();
        async move {
            gearwear::service::cli::create_key(store.as_ref(), scopes, "limits")
                .await
                .unwrap()
                .1
        }
    };
    let (big, read_a, read_b, ingest) = (
        key(&[Scope::Ingest]).await,
        key(&[Scope::Read]).await,
        key(&[Scope::Read]).await,
        key(&[Scope::Ingest]).await,
    );
    let template = "/v1/machines/{machine_id}/records";
    let post = |ct: &'static str, body: Vec<u8>| {
        app.client
            .post(app.url("/v1/machines/lim/records?sample_rate_hz=25600"))
            .bearer_auth(&big)
            .header("content-type", ct)
            .body(body)
    };
    let expect = |what: &str, (s, h, body): (u16, HeaderMap, Vec<u8>), status: u16, slug: &str| {
        let ct = h
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_string();
        assert_eq!(ct, "application/problem+json", "{what}");
        check_response("POST", template, s, &ct, &body);
        let p = json(&body);
        assert_eq!(
            (s, p["type"].as_str().unwrap()),
            (status, format!("urn:gearwear:problem:{slug}").as_str()),
            "{what}: {p}"
        );
        p
    };
    // Body over the limit, declared (Content-Length) and streamed (chunked, no length).
    let p = expect(
        "CSV body of 300 KiB",
        send(post("text/csv", b"0.5\n".repeat(75 << 10))).await,
        413,
        "body-too-large",
    );
    assert!(p["detail"].as_str().unwrap().len() > 20, "{p}");
    let (s, raw) = chunked_post(
        &app.addr,
        "/v1/machines/lim/records?sample_rate_hz=25600",
        &big,
        300 << 10,
    )
    .await;
    assert_eq!(s, 413, "chunked body of 300 KiB: {raw}");
    assert!(raw.contains("body-too-large"), "{raw}");
    // Sample count over the limit, in each format (each body under the byte limit).
    let n = 10_001;
    let f32le: Vec<u8> = (0..n)
        .flat_map(|i| ((i as f32) * 1e-4).to_le_bytes())
        .collect();
    let csv: String = (0..n).map(|i| format!("{}\n", i as f64 * 1e-4)).collect();
    let js = serde_json::to_vec(&json!({"sample_rate_hz": 25600, "samples": (0..n).map(|i| i as f64 * 1e-4).collect::<Vec<_>>()})).unwrap();
    assert!(js.len() < 256 << 10);
    for (ct, body) in [
        ("application/octet-stream", f32le),
        ("text/csv", csv.into_bytes()),
        ("application/json", js),
    ] {
        let p = expect(
            &format!("{n} samples as {ct}"),
            send(post(ct, body)).await,
            413,
            "too-many-samples",
        );
        assert_eq!(p["limit_samples"], 10_000, "{p}");
    }

    // Rate: a key gets its burst, then 429 with Retry-After; another key is not limited.
    let get = |k: &str| {
        app.client
            .get(app.url("/v1/machines"))
            .bearer_auth(k)
            .send()
    };
    for i in 0..BURST {
        assert_eq!(
            get(&read_a).await.unwrap().status(),
            200,
            "request {i} of the burst"
        );
    }
    let r = get(&read_a).await.unwrap();
    let retry: u64 = r
        .headers()
        .get("retry-after")
        .expect("Retry-After on a 429")
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        (1..=3).contains(&retry),
        "Retry-After {retry} s at 0.5 per second"
    );
    let (s, h, body) = (
        r.status().as_u16(),
        r.headers().clone(),
        r.bytes().await.unwrap().to_vec(),
    );
    let ct = h["content-type"].to_str().unwrap().to_string();
    check_response("GET", "/v1/machines", s, &ct, &body);
    let p = json(&body);
    assert_eq!(
        (s, p["type"].as_str().unwrap()),
        (429, "urn:gearwear:problem:rate-limited")
    );
    // The other key, right now.
    assert_eq!(
        get(&read_b).await.unwrap().status(),
        200,
        "one key's exhaustion limited another"
    );
    // Retry-After is honest: after it, the key is served again.
    tokio::time::sleep(Duration::from_secs(retry)).await;
    assert_eq!(
        get(&read_a).await.unwrap().status(),
        200,
        "served again after Retry-After"
    );

    // An ingest key out of tokens: the record is refused and nothing is stored.
    let empty = json!({"sample_rate_hz": 25600, "samples": []});
    for _ in 0..BURST {
        let r = app
            .client
            .post(app.url("/v1/machines/lim/records"))
            .bearer_auth(&ingest)
            .json(&empty)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 422);
    }
    let r = app
        .client
        .post(app.url("/v1/machines/lim/records"))
        .bearer_auth(&ingest)
        .json(&json_record(1))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 429);
    assert!(
        app.store.list_machines().await.unwrap().is_empty(),
        "a refused record was stored"
    );
}

/// POST `len` bytes with `Transfer-Encoding: chunked` (no Content-Length) over a plain TCP
/// connection; the status and the raw answer.
async fn chunked_post(addr: &str, path: &str, key: &str, len: usize) -> (u16, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let hostport = addr.trim_start_matches("http://");
    let mut s = tokio::net::TcpStream::connect(hostport).await.unwrap();
    let head = format!(
        "POST {path} HTTP/1.1\r\nHost: {hostport}\r\nAuthorization: Bearer {key}\r\n\
         Content-Type: text/csv\r\nTransfer-Encoding: chunked\r\nConnection: close\r\n\r\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    let chunk = b"0.5\n".repeat(4096);
    let mut sent = 0;
    while sent < len {
        let mut frame = format!("{:x}\r\n", chunk.len()).into_bytes();
        frame.extend_from_slice(&chunk);
        frame.extend_from_slice(b"\r\n");
        // The server may answer and close before everything is sent.
        if s.write_all(&frame).await.is_err() {
            break;
        }
        sent += chunk.len();
    }
    let _ = s.write_all(b"0\r\n\r\n").await;
    let mut out = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(20), s.read_to_end(&mut out)).await;
    let text = String::from_utf8_lossy(&out).to_string();
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, text)
}

// ---------- The real binary ----------

/// `gearwear serve …` with its stdout and stderr captured, line by line.
struct Server {
    child: Child,
    out: Arc<Mutex<Vec<u8>>>,
}

impl Server {
    fn start(args: &[&str], envs: &[(&str, &str)]) -> Server {
        let mut child = gearwear_bin()
            .arg("serve")
            .args(args)
            .envs(envs.iter().copied())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let out = Arc::new(Mutex::new(Vec::new()));
        let streams: Vec<Box<dyn Read + Send>> = vec![
            Box::new(child.stdout.take().unwrap()),
            Box::new(child.stderr.take().unwrap()),
        ];
        for s in streams {
            let out = out.clone();
            std::thread::spawn(move || {
                let mut r = BufReader::new(s);
                let mut line = Vec::new();
                while r
                    .read_until(b'\n', &mut line)
                    .map(|n| n > 0)
                    .unwrap_or(false)
                {
                    out.lock().unwrap().extend_from_slice(&line);
                    line.clear();
                }
            });
        }
        Server { child, out }
    }

    fn text(&self) -> String {
        String::from_utf8_lossy(&self.out.lock().unwrap()).to_string()
    }

    /// The port from the "serving" log line, or `Err(output)` if the process exited first.
    async fn port(&mut self, within: Duration) -> Result<u16, String> {
        let t = Instant::now();
        while t.elapsed() < within {
            let text = self.text();
            if let Some(i) = text.find("dashboard at http://") {
                let rest = &text[i + "dashboard at http://".len()..];
                let hostport = &rest[..rest.find('/').unwrap()];
                return Ok(hostport.rsplit(':').next().unwrap().parse().unwrap());
            }
            if self.child.try_wait().unwrap().is_some() {
                // Let the readers drain.
                tokio::time::sleep(Duration::from_millis(200)).await;
                return Err(self.text());
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        panic!("no `serving` line within {within:?}:\n{}", self.text());
    }

    /// Exit status (waiting up to `within`).
    async fn exit(&mut self, within: Duration) -> std::process::ExitStatus {
        let t = Instant::now();
        loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                tokio::time::sleep(Duration::from_millis(200)).await;
                return st;
            }
            assert!(
                t.elapsed() < within,
                "still running after {within:?}:\n{}",
                self.text()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// SIGTERM (a graceful stop), then the exit status.
    async fn terminate(&mut self) -> std::process::ExitStatus {
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        self.exit(Duration::from_secs(30)).await
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

async fn no_secret_in_the_logs(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let ingest = cli_key(&db.url, "ingest");
    let read = cli_key(&db.url, "read");
    let admin = cli_key(&db.url, "admin");
    let revoked = cli_key(&db.url, "ingest,read");
    let revoked_id = gearwear::keys::split_token(&revoked).unwrap().0.to_string();
    let out = gearwear_bin()
        .args([
            "keys",
            "revoke",
            revoked_id.as_str(),
            "--database-url",
            db.url.as_str(),
        ])
        .output()
        .unwrap();
    assert!(out.status.success());

    // PostgreSQL: a password in the database URL (the test server trusts every local
    // connection, so any password works); it must not be logged either.
    let db_password = format!("pw-{}", uuid::Uuid::new_v4().simple());
    let serve_url = match (b, db.url.find("://"), db.url.find('@')) {
        (Backend::Postgres, Some(s), Some(at)) if !db.url[s + 3..at].contains(':') => {
            format!("{}:{db_password}{}", &db.url[..at], &db.url[at..])
        }
        _ => db.url.clone(),
    };
    let filter = "debug,gearwear=trace,tower_http=trace,reqwest=trace,hyper=trace,hyper_util=trace";
    let mut srv = Server::start(
        &[
            "--address",
            "127.0.0.1:0",
            "--database-url",
            &serve_url,
            "--log-json",
            "--allow-stale-table",
        ],
        &[("RUST_LOG", filter), ("NO_COLOR", "1")],
    );
    let port = srv
        .port(Duration::from_secs(120))
        .await
        .expect("serve started");
    let base = format!("http://127.0.0.1:{port}");
    let c = reqwest::Client::new();
    let mut tampered = read.clone();
    let last = tampered.pop().unwrap();
    tampered.push(if last == 'A' { 'B' } else { 'A' });
    let not_a_key = format!("hunter2-{}", uuid::Uuid::new_v4().simple());
    let unknown = format!("gw_0123456789abcdef_{}", uuid::Uuid::new_v4().simple());

    // Good keys.
    let rec = |k: &str| {
        c.post(format!("{base}/v1/machines/logs/records"))
            .bearer_auth(k)
            .json(&json_record(2))
            .send()
    };
    assert_eq!(rec(&ingest).await.unwrap().status(), 201);
    let r = c
        .get(format!("{base}/v1/machines"))
        .bearer_auth(&read)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    // Bad ones.
    for k in [&tampered, &not_a_key, &unknown, &revoked] {
        let r = c
            .get(format!("{base}/v1/machines"))
            .bearer_auth(k)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 401, "{k}");
    }
    assert_eq!(rec(&revoked).await.unwrap().status(), 401);
    assert_eq!(rec(&read).await.unwrap().status(), 403);
    // A webhook (its secret is in the answer), a delivery that fails once then succeeds.
    let (rx, hook_url, _t) = start_receiver(1, 0).await;
    // Some receivers put a token in the URL; it must not reach the logs either.
    let url_token = format!("whtok-{}", uuid::Uuid::new_v4().simple());
    let hook_url = format!("{hook_url}?token={url_token}");
    let r = c
        .post(format!("{base}/v1/webhooks"))
        .bearer_auth(&admin)
        .json(&json!({"url": hook_url, "events": ["diagnosis.created"]}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let hook = json(&r.bytes().await.unwrap());
    let whsec = hook["secret"].as_str().unwrap().to_string();
    assert_eq!(rec(&ingest).await.unwrap().status(), 201);
    let t = Instant::now();
    while rx.got.lock().unwrap().is_empty() {
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "no delivery:\n{}",
            srv.text()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let r = c
        .get(format!(
            "{base}/v1/webhooks/{}/deliveries",
            hook["id"].as_str().unwrap()
        ))
        .bearer_auth(&admin)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(srv.terminate().await.success(), "{}", srv.text());
    let logs = srv.text();
    // Kept for reading: target/tmp/security-logs-<store>.jsonl.
    let _ = std::fs::write(
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("security-logs-{b:?}.jsonl")),
        &logs,
    );

    // The filter was in force: the logs have what the secrets would be next to.
    for want in [
        "record accepted",
        "webhook attempt",
        "tower_http",
        "API key refused",
        gearwear::keys::split_token(&ingest).unwrap().0, // the key id is logged
    ] {
        assert!(logs.contains(want), "`{want}` not in the logs:\n{logs}");
    }
    let lines = logs.lines().count();
    // Every line is a JSON event whose `level` is a log level (a field named `level` once
    // overwrote it: "record accepted" came out as `"level":"warning"`).
    for line in logs.lines() {
        let v: Value = serde_json::from_str(line)
            .unwrap_or_else(|e| panic!("a log line that is not JSON ({e}): {line}"));
        assert!(
            matches!(
                v["level"].as_str(),
                Some("TRACE" | "DEBUG" | "INFO" | "WARN" | "ERROR")
            ),
            "{line}"
        );
    }
    let mut secrets: Vec<(&str, String)> = vec![
        ("webhook secret", whsec.clone()),
        (
            "webhook secret body",
            whsec.trim_start_matches("whsec_").to_string(),
        ),
        ("not-a-key token", not_a_key.clone()),
        ("token in the webhook URL", url_token.clone()),
        ("database password", db_password.clone()),
        ("unknown key", unknown.clone()),
        ("tampered key", tampered.clone()),
    ];
    for (what, k) in [
        ("ingest", &ingest),
        ("read", &read),
        ("admin", &admin),
        ("revoked", &revoked),
    ] {
        secrets.push((what, k.to_string()));
        secrets.push((what, gearwear::keys::split_token(k).unwrap().1.to_string()));
        secrets.push((what, format!("Bearer {k}")));
    }
    let tampered_secret = gearwear::keys::split_token(&tampered)
        .unwrap()
        .1
        .to_string();
    secrets.push(("tampered secret", tampered_secret));
    for (what, s) in &secrets {
        assert!(!logs.contains(s.as_str()), "the {what} is in the logs");
    }
    assert!(
        !logs.to_ascii_lowercase().contains("authorization"),
        "an Authorization header is in the logs"
    );
    eprintln!(
        "{b:?}: {lines} log lines ({} bytes, RUST_LOG={filter}) searched for {} secrets: none found",
        logs.len(),
        secrets.len()
    );
}

// ---------- Webhook signature, the documented recipe ----------

/// docs/service.md's recipe, in Rust, literally: split the header on `,`, take what follows
/// the first `=` of each part as `t` and `v1`, and compare `v1` with hex
/// `HMAC-SHA256(secret, "<t>." + body)` in constant time.
fn documented_verify(header: &str, secret: &str, body: &[u8]) -> bool {
    use hmac::{KeyInit, Mac};
    use subtle::ConstantTimeEq;
    let parts: Vec<&str> = header
        .split(',')
        .map(|p| p.split_once('=').map(|(_, v)| v).unwrap_or(""))
        .collect();
    let [t, v1] = parts[..] else {
        return false;
    };
    let mut mac = hmac::Hmac::<sha2::Sha256>::new_from_slice(secret.as_bytes()).unwrap();
    mac.update(format!("{t}.").as_bytes());
    mac.update(body);
    let expected = hex::encode(mac.finalize().into_bytes());
    expected.as_bytes().ct_eq(v1.as_bytes()).into()
}

/// The Python block of docs/service.md, run as written; `None` without python3.
fn python_verify(header: &str, secret: &str, body: &[u8]) -> Option<bool> {
    let doc =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/service.md")).unwrap();
    let start = doc
        .find("```python\n")
        .expect("a python block in docs/service.md")
        + 10;
    let snippet = &doc[start..start + doc[start..].find("```").unwrap()];
    assert!(snippet.contains("ok = "), "the recipe sets `ok`: {snippet}");
    let dir = std::env::temp_dir().join(format!("gw-sig-{}", uuid::Uuid::new_v4().simple()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("body"), body).unwrap();
    let script = format!(
        "import sys\nheader, secret = sys.argv[1], sys.argv[2]\nbody = open(sys.argv[3], 'rb').read()\n{snippet}\nprint('OK' if ok else 'BAD')\n"
    );
    std::fs::write(dir.join("verify.py"), script).unwrap();
    let out = Command::new("python3")
        .arg(dir.join("verify.py"))
        .args([header, secret])
        .arg(dir.join("body"))
        .output();
    let _ = std::fs::remove_dir_all(&dir);
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            eprintln!("SKIP: python3 not runnable ({e}); the Python recipe was not run");
            return None;
        }
    };
    let text = String::from_utf8_lossy(&out.stdout).trim().to_string();
    assert!(
        text == "OK" || text == "BAD",
        "the recipe failed to run: {text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(text == "OK")
}

async fn webhook_signature_follows_the_documented_recipe(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let (rx, url, _t) = start_receiver(0, 0).await;
    let hook = create_hook(&app, &url).await;
    let secret = hook["secret"].as_str().unwrap().to_string();
    let other = create_hook(&app, "http://127.0.0.1:9/other").await["secret"]
        .as_str()
        .unwrap()
        .to_string();
    assert_ne!(secret, other);
    assert_eq!(app.post_json("m-sig", &json_record(5)).await.status(), 201);
    let t0 = Instant::now();
    while rx.got.lock().unwrap().is_empty() {
        assert!(t0.elapsed() < Duration::from_secs(30), "no delivery");
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    let (h, body) = rx.got.lock().unwrap()[0].clone();
    let header = h["gearwear-signature"].to_str().unwrap().to_string();
    // The documented shape: t=<unix s>,v1=<64 hex>, t current.
    let (t, v1) = header.split_once(',').unwrap();
    let t: i64 = t.strip_prefix("t=").expect("t= first").parse().unwrap();
    let v1 = v1.strip_prefix("v1=").expect("v1= second");
    assert!(
        v1.len() == 64 && v1.bytes().all(|c| c.is_ascii_hexdigit()),
        "{header}"
    );
    let now = gearwear::store::now_ms() / 1000;
    assert!(
        (now - t).abs() <= 300,
        "t={t} is not the time of sending ({now})"
    );

    let mut tampered = body.to_vec();
    let i = tampered.iter().position(|c| *c == b'm').unwrap();
    tampered[i] = b'n';
    let later = format!("t={},v1={v1}", t + 1);
    let cases: [(&str, &str, &[u8], bool); 4] = [
        ("the delivery as received", secret.as_str(), &body[..], true),
        (
            "a body changed in one byte",
            secret.as_str(),
            &tampered[..],
            false,
        ),
        ("another webhook's secret", other.as_str(), &body[..], false),
        ("a changed timestamp", secret.as_str(), &body[..], false),
    ];
    let mut python_ran = false;
    for (what, key, payload, want) in cases {
        let hdr = if what == "a changed timestamp" {
            later.as_str()
        } else {
            header.as_str()
        };
        assert_eq!(
            documented_verify(hdr, key, payload),
            want,
            "Rust recipe: {what}"
        );
        if let Some(ok) = python_verify(hdr, key, payload) {
            assert_eq!(ok, want, "docs/service.md's Python recipe: {what}");
            python_ran = true;
        }
    }
    eprintln!(
        "{b:?}: signature verified with the documented recipe (Rust{}); 3 forgeries refused",
        if python_ran {
            " and docs/service.md's Python, run as written"
        } else {
            " only"
        }
    );
}

// ---------- Non-loopback addresses ----------

async fn non_loopback_address_needs_an_active_key(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let refused = |addr: &'static str| {
        let url = db.url.clone();
        async move {
            let mut s = Server::start(
                &[
                    "--address",
                    addr,
                    "--database-url",
                    &url,
                    "--allow-stale-table",
                ],
                &[],
            );
            let st = s.exit(Duration::from_secs(60)).await;
            let text = s.text();
            assert!(
                !st.success(),
                "{addr} without an active key started:\n{text}"
            );
            assert!(
                text.contains("not a loopback address") && text.contains("gearwear keys create"),
                "{addr}: the refusal says what to do:\n{text}"
            );
        }
    };
    // No key at all.
    refused("0.0.0.0:0").await;
    refused("[::]:0").await;
    // A key: it starts, answers on the port, and still wants keys.
    let key = cli_key(&db.url, "read");
    let mut s = Server::start(
        &[
            "--address",
            "0.0.0.0:0",
            "--database-url",
            &db.url,
            "--allow-stale-table",
        ],
        &[],
    );
    let port = s
        .port(Duration::from_secs(120))
        .await
        .expect("serve on 0.0.0.0 with a key");
    let c = reqwest::Client::new();
    let h = c
        .get(format!("http://127.0.0.1:{port}/healthz"))
        .send()
        .await
        .unwrap();
    assert_eq!(h.status(), 200);
    let r = c
        .get(format!("http://127.0.0.1:{port}/v1/machines"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 401);
    let r = c
        .get(format!("http://127.0.0.1:{port}/v1/machines"))
        .bearer_auth(&key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(s.terminate().await.success());
    // Only a revoked key left: refused again.
    let id = gearwear::keys::split_token(&key).unwrap().0.to_string();
    assert!(
        gearwear_bin()
            .args([
                "keys",
                "revoke",
                id.as_str(),
                "--database-url",
                db.url.as_str()
            ])
            .output()
            .unwrap()
            .status
            .success()
    );
    refused("0.0.0.0:0").await;
}

// ---------- Webhook URLs ----------

async fn webhook_urls_are_restricted(b: Backend) {
    let Some(app) = spawn_app(b, |s| {
        // Out of reach: one `diagnosis.created` per record.
        s.thresholds.warning = 10.0;
        s.thresholds.alarm = 20.0;
    })
    .await
    else {
        return;
    };
    let create = |url: &str| {
        app.client
            .post(app.url("/v1/webhooks"))
            .bearer_auth(&app.admin_key)
            .json(&json!({"url": url, "events": ["diagnosis.created"]}))
    };
    let refused = [
        ("http://169.254.169.254/latest/meta-data/", "link-local"),
        ("http://2852039166/latest/meta-data/", "link-local"),
        ("http://[::ffff:169.254.169.254]/", "link-local"),
        ("http://[fe80::1%25eth0]/hook", ""),
        ("http://[fe80::1]/hook", "link-local"),
        ("http://0.0.0.0:8080/hook", "unspecified"),
        ("http://[::]/hook", "unspecified"),
        ("http://100.100.100.200/", "metadata"),
        ("ftp://files.example/hook", "http:// or https://"),
        ("file:///etc/passwd", "http:// or https://"),
        ("/relative/hook", "absolute"),
    ];
    for (url, says) in refused {
        let (s, _, body) = checked(create(url), "POST", "/v1/webhooks").await;
        let p = json(&body);
        assert_eq!(
            (s, p["type"].as_str().unwrap()),
            (422, "urn:gearwear:problem:invalid-webhook"),
            "{url}: {p}"
        );
        let detail = p["detail"].as_str().unwrap();
        assert!(detail.contains(says), "{url}: {detail}");
        if !says.is_empty() && says != "http:// or https://" && says != "absolute" {
            assert!(
                detail.contains("loopback"),
                "{url}: the detail says what is allowed: {detail}"
            );
        }
    }
    let allowed = [
        "http://127.0.0.1:9/hook",
        "http://[::1]:9/hook",
        "http://localhost:9/hook",
        "http://10.20.30.40:9/hook",
        "http://192.168.1.20/hook",
        "http://172.16.5.4/hook",
        "https://cmms.example.com/hooks/wear",
    ];
    for url in allowed {
        let (s, _, body) = checked(create(url), "POST", "/v1/webhooks").await;
        assert_eq!(s, 201, "{url}: {}", String::from_utf8_lossy(&body));
    }
    // Only the allowed ones were stored.
    let ws = app.store.list_webhooks().await.unwrap();
    assert_eq!(ws.len(), allowed.len());
    for w in &ws {
        assert!(allowed.contains(&w.url.as_str()), "{}", w.url);
    }
    // A subscription stored before these rules (written to the store directly) is not
    // connected to: its delivery fails at once, saying why.
    let old = WebhookRow {
        id: gearwear::store::new_id(),
        url: "http://169.254.169.254/latest/meta-data/iam/".into(),
        secret: gearwear::keys::webhook_secret(),
        events: vec!["diagnosis.created".into()],
        created_at: gearwear::store::now_ms(),
    };
    app.store.insert_webhook(&old).await.unwrap();
    assert_eq!(app.post_json("m-url", &json_record(1)).await.status(), 201);
    let t = Instant::now();
    loop {
        let r = app
            .client
            .get(app.url(&format!("/v1/webhooks/{}/deliveries", old.id)))
            .bearer_auth(&app.admin_key)
            .send()
            .await
            .unwrap();
        let log = json(&r.bytes().await.unwrap());
        let d = &log["deliveries"][0];
        if d["status"] == "failed" {
            let att = d["attempts"].as_array().unwrap();
            assert_eq!(att.len(), 1, "refused at once, no retry: {log:#}");
            assert!(att[0]["status_code"].is_null());
            assert!(
                att[0]["error"].as_str().unwrap().contains("link-local"),
                "{log:#}"
            );
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(20), "{log:#}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}
