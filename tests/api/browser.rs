//! The dashboard end to end in a real headless Chromium (Debian `chromium` +
//! `chromium-driver`), driven over the W3C WebDriver protocol with plain HTTP: load the page,
//! POST a record, see the machine, its wear estimate and the marked spectrum appear.
//!
//! Skips (with a message) only when chromium/chromedriver are absent and `CI` is not set.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine;
use serde_json::{Value, json};

use crate::helpers::*;

fn find(names: &[&str]) -> Option<PathBuf> {
    for n in names {
        for dir in ["/usr/bin", "/usr/local/bin", "/usr/lib/chromium"] {
            let p = PathBuf::from(dir).join(n);
            if p.exists() {
                return Some(p);
            }
        }
    }
    None
}

struct Driver {
    child: Child,
    base: String,
    session: String,
    http: reqwest::Client,
}

impl Driver {
    async fn cmd(&self, method: reqwest::Method, path: &str, body: Option<Value>) -> Value {
        let url = format!("{}/session/{}{path}", self.base, self.session);
        let mut r = self.http.request(method, url);
        if let Some(b) = body {
            r = r.json(&b);
        }
        let v: Value = r.send().await.unwrap().json().await.unwrap();
        v["value"].clone()
    }

    async fn script(&self, js: &str) -> Value {
        self.cmd(
            reqwest::Method::POST,
            "/execute/sync",
            Some(json!({"script": js, "args": []})),
        )
        .await
    }

    async fn wait_for(&self, what: &str, js: &str) -> Value {
        let t = Instant::now();
        loop {
            let v = self.script(js).await;
            if !(v.is_null() || v == json!(false)) {
                return v;
            }
            assert!(
                t.elapsed() < Duration::from_secs(20),
                "the page never showed {what}"
            );
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// chromedriver + a headless Chromium session; `None` (after saying why) when they are not
/// installed and `CI` is not set.
async fn start_driver() -> Option<(Driver, PathBuf)> {
    let (Some(chromium), Some(chromedriver)) = (
        find(&["chromium", "chromium-browser"]),
        find(&["chromedriver"]),
    ) else {
        let msg = "chromium and/or chromedriver not found (apt-get install chromium chromium-driver); the browser test did NOT run";
        if in_ci() {
            panic!("{msg} (CI is set, so this is a failure)");
        }
        eprintln!("SKIP: {msg}");
        return None;
    };
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let child = Command::new(&chromedriver)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver starts");
    let http = reqwest::Client::new();
    let base = format!("http://127.0.0.1:{port}");
    let t = Instant::now();
    while http.get(format!("{base}/status")).send().await.is_err() {
        assert!(
            t.elapsed() < Duration::from_secs(15),
            "chromedriver did not come up"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let profile =
        std::env::temp_dir().join(format!("gearwear-chrome-{}", uuid::Uuid::new_v4().simple()));
    let caps = json!({"capabilities": {"alwaysMatch": {
        "browserName": "chrome",
        "goog:chromeOptions": {
            "binary": chromium,
            "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                     "--disable-background-networking", "--disable-component-update", "--disable-sync",
                     "--disable-dev-shm-usage", "--window-size=1280,1500",
                     format!("--user-data-dir={}", profile.display())]
        }
    }}});
    let v: Value = http
        .post(format!("{base}/session"))
        .json(&caps)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let session = v["value"]["sessionId"]
        .as_str()
        .unwrap_or_else(|| panic!("no session: {v}"))
        .to_string();
    let d = Driver {
        child,
        base,
        session,
        http,
    };

    Some((d, profile))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_updates_when_a_record_arrives() {
    let Some(app) = spawn_app(Backend::Sqlite, |s| s.open_dashboard = true).await else {
        return;
    };
    let Some((d, profile)) = start_driver().await else {
        return;
    };
    d.cmd(
        reqwest::Method::POST,
        "/url",
        Some(json!({"url": app.url("/")})),
    )
    .await;
    d.wait_for(
        "its first poll",
        "return document.getElementById('status').textContent.startsWith('updated')",
    )
    .await;
    let before = d
        .script("return document.querySelectorAll('#machines li[data-id]').length")
        .await;
    assert_eq!(before, json!(0));

    assert_eq!(
        app.post_json("gearbox-1", &json_record(3)).await.status(),
        201
    );
    let est = d
        .wait_for(
            "the new machine and its wear estimate",
            "const li = document.querySelector('#machines li[data-id=\"gearbox-1\"]'); \
             const e = document.getElementById('wear-estimate').textContent; \
             return li && e !== '–' ? e : null",
        )
        .await;
    let est: f64 = est.as_str().unwrap().parse().unwrap();
    let api = json(
        &app.get("/v1/machines/gearbox-1")
            .await
            .bytes()
            .await
            .unwrap(),
    );
    assert!((api["latest"]["wear_degree"]["estimate"].as_f64().unwrap() - est).abs() < 1e-3);
    let marks = d
        .wait_for("the spectrum marks", "const n = document.querySelectorAll('#spectrum .mark').length; return n > 0 ? n : null")
        .await;
    assert!(marks.as_u64().unwrap() >= 3);
    let names = d
        .script("return [...document.querySelectorAll('#spectrum .mark')].map(m => m.dataset.name)")
        .await;
    for n in ["f1", "f2", "f3"] {
        assert!(
            names.as_array().unwrap().contains(&json!(n)),
            "{n} marked: {names}"
        );
    }
    assert_eq!(
        d.script("return document.querySelectorAll('#trend .trend-point').length")
            .await,
        json!(1)
    );
    let level = d
        .script(
            "return document.querySelector('#machines li[data-id=\"gearbox-1\"] .dot').className",
        )
        .await;
    assert!(level.as_str().unwrap().starts_with("dot "), "{level}");

    // A second record: the trend grows without a reload.
    assert_eq!(
        app.post_json("gearbox-1", &json_record(4)).await.status(),
        201
    );
    d.wait_for(
        "the second trend point",
        "return document.querySelectorAll('#trend .trend-point').length === 2",
    )
    .await;

    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    let png = base64::engine::general_purpose::STANDARD
        .decode(png.as_str().unwrap())
        .unwrap();
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("dashboard.png");
    std::fs::write(&out, png).unwrap();
    eprintln!("dashboard screenshot: {}", out.display());
    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}

/// Reads need a key (no `--open-dashboard`): the page asks for one on the 401, keeps it in
/// sessionStorage (not localStorage), sends it, and shows the machines; a wrong key is asked
/// for again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_asks_for_a_read_key() {
    let Some(app) = spawn_app(Backend::Sqlite, |_| {}).await else {
        return;
    };
    let Some((d, profile)) = start_driver().await else {
        return;
    };
    assert_eq!(
        app.post_json("gearbox-k", &json_record(3)).await.status(),
        201
    );
    d.cmd(
        reqwest::Method::POST,
        "/url",
        Some(json!({"url": app.url("/")})),
    )
    .await;
    d.wait_for(
        "the key prompt",
        "return !document.getElementById('keyform').hidden",
    )
    .await;
    let status = d
        .script("return document.getElementById('status').textContent")
        .await;
    assert!(
        status.as_str().unwrap().contains("read"),
        "the page says a read key is needed: {status}"
    );
    let submit = |key: &str| {
        format!(
            "document.getElementById('key').value = {}; \
             document.getElementById('keyform').requestSubmit(); return true",
            json!(key)
        )
    };
    // A wrong key: refused, asked for again, not kept.
    d.script(&submit("gw_0123456789abcdef_nope")).await;
    d.wait_for(
        "the prompt again after a wrong key",
        "return !document.getElementById('keyform').hidden && \
         sessionStorage.getItem('gearwear-key') === null",
    )
    .await;
    // The read key: the machines appear, the key is in sessionStorage only.
    d.script(&submit(&app.read_key)).await;
    d.wait_for(
        "the machine after the key",
        "return document.querySelector('#machines li[data-id=\"gearbox-k\"]') !== null",
    )
    .await;
    assert_eq!(
        d.script("return sessionStorage.getItem('gearwear-key')")
            .await,
        json!(app.read_key)
    );
    assert_eq!(
        d.script("return localStorage.getItem('gearwear-key')")
            .await,
        Value::Null
    );
    assert_eq!(
        d.script("return document.getElementById('keyform').hidden")
            .await,
        json!(true)
    );
    assert_eq!(
        d.script("return document.getElementById('key').value")
            .await,
        json!(""),
        "the field does not keep the key"
    );
    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}
