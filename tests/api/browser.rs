//! The dashboard end to end in a real headless Chromium (Debian `chromium` +
//! `chromium-driver`), driven over the W3C WebDriver protocol with plain HTTP: load the page,
//! POST a record, see the machine, its wear estimate and the marked spectrum appear (and go
//! when the machine is deleted); a fleet in every alert state sorted by severity, a machine
//! opened from the URL, the wear and novelty charts on a time axis; the read-key prompt.
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

pub struct Driver {
    child: Child,
    base: String,
    session: String,
    http: reqwest::Client,
}

impl Driver {
    pub async fn cmd(&self, method: reqwest::Method, path: &str, body: Option<Value>) -> Value {
        let url = format!("{}/session/{}{path}", self.base, self.session);
        let mut r = self.http.request(method, url);
        if let Some(b) = body {
            r = r.json(&b);
        }
        let v: Value = r.send().await.unwrap().json().await.unwrap();
        v["value"].clone()
    }

    pub async fn script(&self, js: &str) -> Value {
        self.cmd(
            reqwest::Method::POST,
            "/execute/sync",
            Some(json!({"script": js, "args": []})),
        )
        .await
    }

    /// Navigate the browser to `url` (WebDriver `POST /url`).
    pub async fn open(&self, url: &str) {
        self.cmd(reqwest::Method::POST, "/url", Some(json!({ "url": url })))
            .await;
    }

    pub async fn wait_for(&self, what: &str, js: &str) -> Value {
        let t = Instant::now();
        loop {
            let v = self.script(js).await;
            if !(v.is_null() || v == json!(false)) {
                return v;
            }
            // Generous: on the 2-core CI machine the browser tests share it with every
            // other test; the page polls every 2 s.
            assert!(
                t.elapsed() < Duration::from_secs(60),
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
pub async fn start_driver() -> Option<(Driver, PathBuf)> {
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
    d.open(&app.url("/")).await;
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
    // `/` is the planner's overview: the machine appears there; its link opens its page.
    d.wait_for(
        "the new machine in the overview",
        "const a = document.querySelector('#fleet-rows tr[data-id=\"gearbox-1\"] a.machine-link'); \
         if (!a) return null; a.click(); return true",
    )
    .await;
    let est = d
        .wait_for(
            "the new machine and its wear estimate",
            "const li = document.querySelector('#machines li[data-id=\"gearbox-1\"]'); \
             const e = document.getElementById('wear-estimate').textContent; \
             return li && e !== '–' ? e : null",
        )
        .await;
    // The number first; a note may follow it ("(poor fit: not used for the alert)").
    let est: f64 = est
        .as_str()
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
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

    // Deleted (DELETE /v1/machines/{id}): the machine leaves the list — the last one too — and
    // the page left open on it says it is not there, without a reload.
    let r = app
        .client
        .delete(app.url("/v1/machines/gearbox-1"))
        .bearer_auth(&app.admin_key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    d.wait_for(
        "the deleted machine gone from the list and from the page",
        "return document.querySelectorAll('#machines li[data-id]').length === 0 && \
         document.getElementById('machine').hidden && \
         document.getElementById('placeholder').textContent.includes('gearbox-1')",
    )
    .await;
    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}

/// Reads need a key (no `--dashboard-without-key`): the page asks for one on the 401, keeps it in
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
    d.open(&app.url("/")).await;
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

/// POST a JSON record; its answer.
pub async fn post(app: &TestApp, machine: &str, query: &str, body: &Value) -> Value {
    let r = app
        .client
        .post(app.url(&format!("/v1/machines/{machine}/records{query}")))
        .bearer_auth(&app.ingest_key)
        .json(body)
        .send()
        .await
        .unwrap();
    let s = r.status();
    let v = json(&r.bytes().await.unwrap());
    assert_eq!(s, 201, "{v}");
    v
}

/// Severity order of the fleet list.
fn rank(level: &str) -> u8 {
    match level {
        "alarm" => 0,
        "warning" => 1,
        "unknown" => 2,
        "ok" => 3,
        other => panic!("alert level {other}"),
    }
}

/// A fleet in every state, in the real browser: the list sorted by severity with `unknown`
/// visibly its own state, a machine opened from the URL and moved between with links and
/// back/forward, the wear and novelty charts on a time axis with the threshold drawn, the
/// gearbox's table status, the baseline, per-channel levels, and nothing breaking on a machine
/// without a record or a diagnosis without a wear degree.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_shows_the_fleet_by_severity_and_a_machine_from_the_url() {
    let Some(app) = spawn_app(Backend::Sqlite, |s| s.open_dashboard = true).await else {
        return;
    };
    // The fleet, through the API.
    // * real-healthy / real-broken: records the rig's model does not fit, each machine with
    //   a baseline of 3 healthy ones; then a healthy record (ok by novelty) or a broken-tooth
    //   one (warning or alarm by novelty);
    // * real-unknown: such a record and no baseline → unknown;
    // * rig-1: records of the built-in rig (whatever level the wear gives);
    // * two-ch: a two-channel CSV without a baseline (per-channel levels);
    // * configured: a machine PUT with no record yet.
    for (machine, last) in [("real-healthy", false), ("real-broken", true)] {
        for seed in 2..=4 {
            post(
                &app,
                machine,
                "?baseline=true",
                &foreign_record(seed, false),
            )
            .await;
        }
        post(&app, machine, "", &foreign_record(5, false)).await;
        if last {
            post(&app, machine, "", &foreign_record(6, true)).await;
        }
    }
    let d = post(&app, "real-unknown", "", &foreign_record(1, false)).await;
    assert_eq!(d["alert_level"], "unknown", "{d}");
    post(&app, "rig-1", "", &json_record(3)).await;
    let mut csv = String::from("a1,a2\n");
    let (c1, c2) = (foreign_samples(11, false), foreign_samples(12, true));
    for i in 0..c1.len() {
        csv.push_str(&format!("{},{}\n", c1[i], 1.3 * c2[i]));
    }
    let r = app
        .client
        .post(app.url("/v1/machines/two-ch/records?sample_rate_hz=25600"))
        .bearer_auth(&app.ingest_key)
        .header("content-type", "text/csv")
        .body(csv)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201, "{}", r.text().await.unwrap());
    let r = app
        .client
        .put(app.url("/v1/machines/configured"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"gearbox": "wang2019"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);

    let fleet = json(&app.get("/v1/machines").await.bytes().await.unwrap());
    let mut expected: Vec<(u8, String)> = fleet["machines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                rank(m["alert_level"].as_str().unwrap()),
                m["id"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    expected.sort();
    let level_of = |id: &str| {
        fleet["machines"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["id"] == id)
            .unwrap()["alert_level"]
            .clone()
    };
    assert_eq!(level_of("real-healthy"), "ok", "{fleet}");
    assert!(
        matches!(level_of("real-broken").as_str(), Some("warning" | "alarm")),
        "{fleet}"
    );
    assert_eq!(level_of("configured"), "unknown");

    let Some((d, profile)) = start_driver().await else {
        return;
    };
    // Opened from the URL (the query form, rewritten to the hash form).
    d.open(&app.url("/?machine=real-broken")).await;
    d.wait_for(
        "real-broken opened from the URL",
        "return document.getElementById('machine-name').textContent === 'real-broken' && \
         !document.getElementById('machine').hidden",
    )
    .await;
    assert_eq!(
        d.script("return location.hash").await,
        json!("#/machines/real-broken")
    );
    d.wait_for(
        "the whole fleet",
        &format!(
            "return document.querySelectorAll('#machines li[data-id]').length === {}",
            expected.len()
        ),
    )
    .await;

    // The fleet, most severe first, then by id.
    let order = d
        .script("return [...document.querySelectorAll('#machines li[data-id]')].map(li => li.dataset.id)")
        .await;
    let want: Vec<&str> = expected.iter().map(|(_, id)| id.as_str()).collect();
    assert_eq!(order, json!(want), "the fleet list's order");
    // `unknown` is its own state: its own icon, a colour that is neither ok's nor alarm's, and
    // a tooltip saying what to do.
    let unk = d
        .script(
            "const li = document.querySelector('#machines li[data-id=\"real-unknown\"]'); \
             const dot = li.querySelector('.dot'); const s = getComputedStyle(dot); \
             const ok = getComputedStyle(document.querySelector('#machines li[data-level=\"ok\"] .dot')); \
             return {level: li.dataset.level, cls: dot.className, icon: dot.textContent, title: li.title, \
                     bg: s.backgroundColor, border: s.borderTopColor, color: s.color, okBg: ok.backgroundColor, \
                     visible: dot.getBoundingClientRect().width > 8}",
        )
        .await;
    assert_eq!(unk["level"], "unknown", "{unk}");
    assert_eq!(unk["cls"], "dot unknown", "{unk}");
    assert_eq!(unk["icon"], "?", "{unk}");
    assert_eq!(unk["visible"], true, "{unk}");
    let title = unk["title"].as_str().unwrap();
    assert!(
        title.contains("baseline") && title.contains("gearbox"),
        "the tooltip says what to do: {title}"
    );
    let green = "rgb(46, 157, 79)";
    let red = "rgb(210, 53, 43)";
    assert_eq!(unk["okBg"], green, "{unk}");
    for k in ["bg", "border", "color"] {
        assert!(
            unk[k] != green && unk[k] != red,
            "unknown is not green or red: {unk}"
        );
    }

    // real-broken: gearbox and table status, baseline, the alert with its reason.
    let facts = d
        .script(
            "const t = (id) => document.getElementById(id).textContent; \
             return {gb: t('gearbox-id'), status: t('gearbox-status'), progress: document.getElementById('gearbox-progress').hidden, \
                     bcount: t('baseline-count'), bstate: t('baseline-state'), bwhen: t('baseline-when'), \
                     alert: document.getElementById('alert').dataset.level, reason: t('alert-reason'), basis: t('alert-basis'), \
                     badge: t('machine-level')}",
        )
        .await;
    assert!(
        facts["gb"].as_str().unwrap().contains("wang2019"),
        "{facts}"
    );
    assert_eq!(facts["status"], "ready", "{facts}");
    assert_eq!(
        facts["progress"], true,
        "no progress bar when ready: {facts}"
    );
    assert_eq!(facts["bcount"], "3 records", "{facts}");
    assert_eq!(facts["bstate"], "ready", "{facts}");
    assert!(
        facts["bwhen"].as_str().unwrap().starts_with("since "),
        "{facts}"
    );
    assert_eq!(facts["alert"], level_of("real-broken"), "{facts}");
    assert!(
        facts["reason"].as_str().unwrap().contains("novelty"),
        "{facts}"
    );
    assert!(
        facts["basis"]
            .as_str()
            .unwrap()
            .contains("based on: novelty"),
        "{facts}"
    );

    // Both charts on a time axis: tick labels are clock times (or dates), placed at times
    // within the records' span; the points are placed by time.
    let api_m = json(
        &app.get("/v1/machines/real-broken")
            .await
            .bytes()
            .await
            .unwrap(),
    );
    let times: Vec<i64> = api_m["trend"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            time::OffsetDateTime::parse(
                p["created_at"].as_str().unwrap(),
                &time::format_description::well_known::Rfc3339,
            )
            .unwrap()
            .unix_timestamp()
        })
        .collect();
    assert_eq!(times.len(), 5);
    // A wear degree the model's poor fit keeps out of the alert says so.
    let poor_fit = api_m["latest"]["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w.as_str().unwrap().starts_with("poor fit"));
    let wear = d
        .script("return document.getElementById('wear-estimate').textContent")
        .await;
    assert_eq!(
        wear.as_str().unwrap().contains("poor fit"),
        poor_fit,
        "{wear} / {api_m}"
    );
    // The second chart (novelty beside a wear trend) is there only when the records have
    // wear figures; otherwise the main chart is the novelty.
    let with_wear = trend_count(&api_m, "estimate");
    let charts: &[&str] = if with_wear > 0 {
        &["trend", "novelty"]
    } else {
        &["trend"]
    };
    for chart in charts {
        let ticks = d
            .script(&format!(
                "return [...document.querySelectorAll('#{chart} .tick-x')].map(t => [t.textContent, Date.parse(t.dataset.t) / 1000])"
            ))
            .await;
        let ticks = ticks.as_array().unwrap();
        assert!(ticks.len() >= 2, "{chart}: {ticks:?}");
        let clock = labels_are_times(ticks);
        assert!(clock, "{chart}: tick labels are times: {ticks:?}");
        for t in ticks {
            let s = t[1].as_f64().unwrap() as i64;
            assert!(
                s >= times[0] - 120 && s <= times[4] + 120,
                "{chart}: a tick at {s} outside the records' time {times:?}"
            );
        }
        let label = d
            .script(&format!(
                "return document.querySelector('#{chart} .axis-label').textContent"
            ))
            .await;
        assert!(label.as_str().unwrap().starts_with("local time"), "{label}");
    }
    // The main chart: the wear figures when there are any (a point each, no mark at 0 for a
    // record without one); else the novelty, a point per scored diagnosis in time order.
    let scored = trend_count(&api_m, "novelty");
    let main = d
        .script(
            "const svg = document.getElementById('trend'); \
             return {series: svg.dataset.series, nowear: svg.querySelectorAll('.trend-nowear').length, \
                     wear: svg.querySelectorAll('.trend-point').length, \
                     xs: [...svg.querySelectorAll('.novelty-point')].map(c => +c.getAttribute('cx')), \
                     legend: [...document.querySelectorAll('#trend-legend li')].map(li => li.textContent), \
                     second: !document.getElementById('novelty-fig').hidden}",
        )
        .await;
    assert_eq!(main["nowear"], 0, "{main}");
    if with_wear > 0 {
        assert_eq!(main["series"], "wear", "{main}");
        assert_eq!(main["wear"], json!(with_wear), "{api_m}");
        assert_eq!(main["second"], true, "{main}");
    } else {
        assert_eq!(main["series"], "novelty", "{main}");
        assert_eq!(main["second"], false, "{main}");
        let xs: Vec<f64> = main["xs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(xs.len(), scored, "a point per scored diagnosis: {main}");
        assert!(xs.windows(2).all(|w| w[0] <= w[1]), "{xs:?}");
        assert!(
            main["legend"]
                .as_array()
                .unwrap()
                .iter()
                .any(|l| l == "novelty score"),
            "{main}"
        );
    }
    // The novelty: a score for the baseline's later records and the broken one, drawn in the
    // second chart beside a wear trend, else in the main one: a point each, the threshold,
    // each baseline record marked.
    assert!(scored >= 2, "{api_m}");
    let chart = if with_wear > 0 { "novelty" } else { "trend" };
    let nov = d
        .script(&format!(
            "return {{points: document.querySelectorAll('#{chart} .novelty-point').length, \
                     anomalous: document.querySelectorAll('#{chart} .novelty-point.anomalous').length, \
                     threshold: document.querySelectorAll('#{chart} .novelty-threshold').length, \
                     baseline: document.querySelectorAll('#{chart} .baseline-point, #{chart} .baseline-mark').length}}"
        ))
        .await;
    assert_eq!(nov["points"], json!(scored), "{nov}");
    assert!(nov["anomalous"].as_u64().unwrap() >= 1, "{nov}");
    assert!(nov["threshold"].as_u64().unwrap() >= 1, "{nov}");
    assert_eq!(nov["baseline"], api_m["baseline"]["count"], "{nov}");
    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    let png = base64::engine::general_purpose::STANDARD
        .decode(png.as_str().unwrap())
        .unwrap();
    let out = std::env::temp_dir().join("gearwear-dashboard-fleet.png");
    std::fs::write(&out, png).unwrap();
    eprintln!("dashboard screenshot: {}", out.display());

    // A link opens another machine and updates the URL; back and forward move between them.
    d.script(
        "document.querySelector('#machines li[data-id=\"real-unknown\"] a').click(); return true",
    )
    .await;
    d.wait_for(
        "real-unknown after its link",
        "return document.getElementById('machine-name').textContent === 'real-unknown' && \
         location.hash === '#/machines/real-unknown' && \
         document.querySelector('#machines li.selected').dataset.id === 'real-unknown'",
    )
    .await;
    let alert = d
        .script(
            "const a = document.getElementById('alert'); \
             return {level: a.dataset.level, bg: getComputedStyle(a).borderLeftColor, \
                     text: a.textContent, novelty: (document.querySelector('#novelty-fig:not([hidden]) .chart-note') || document.querySelector('#trend .chart-note'))?.textContent}",
        )
        .await;
    assert_eq!(alert["level"], "unknown", "{alert}");
    assert!(
        alert["text"].as_str().unwrap().contains("baseline"),
        "{alert}"
    );
    assert!(alert["bg"] != green && alert["bg"] != red, "{alert}");
    assert!(
        alert["novelty"]
            .as_str()
            .unwrap_or("")
            .contains("needs 3 more"),
        "{alert}"
    );
    assert_eq!(
        d.script("return document.getElementById('baseline-state').textContent")
            .await,
        json!("needs 3 more")
    );
    d.cmd(reqwest::Method::POST, "/back", Some(json!({}))).await;
    d.wait_for(
        "real-broken again after back",
        "return document.getElementById('machine-name').textContent === 'real-broken' && \
         location.hash === '#/machines/real-broken'",
    )
    .await;
    d.cmd(reqwest::Method::POST, "/forward", Some(json!({})))
        .await;
    d.wait_for(
        "real-unknown again after forward",
        "return document.getElementById('machine-name').textContent === 'real-unknown'",
    )
    .await;

    // Several channels: each one's level, the deciding one marked.
    d.script("location.hash = '#/machines/two-ch'; return true")
        .await;
    let rows = d
        .wait_for(
            "the per-channel table",
            "const t = document.getElementById('channels'); \
             return document.getElementById('machine-name').textContent === 'two-ch' && !t.hidden \
               ? [...t.querySelectorAll('tbody tr')].map(r => [r.dataset.channel, r.dataset.level, r.className]) : null",
        )
        .await;
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 2, "{rows:?}");
    let two = json(&app.get("/v1/machines/two-ch").await.bytes().await.unwrap());
    let decides = two["latest"]["channel"].as_str().unwrap();
    for r in rows {
        let api_level = two["latest"]["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["name"] == r[0])
            .unwrap()["alert_level"]
            .clone();
        assert_eq!(r[1], api_level, "{rows:?}");
        assert_eq!(r[2] == "deciding", r[0] == decides, "{rows:?}");
    }
    let basis = d
        .script("return document.getElementById('alert-basis').textContent")
        .await;
    assert!(
        basis
            .as_str()
            .unwrap()
            .contains(&format!("deciding channel: {decides}")),
        "{basis}"
    );

    // A machine without a record: shown, nothing broken.
    d.script("location.hash = '#/machines/configured'; return true")
        .await;
    let empty = d
        .wait_for(
            "the machine without a record",
            "return document.getElementById('machine-name').textContent === 'configured' \
               ? {alert: document.getElementById('alert-title').textContent, wear: document.getElementById('wear-estimate').textContent, \
                  trend: document.querySelector('#trend .chart-note')?.textContent, status: document.getElementById('status').textContent} : null",
        )
        .await;
    assert_eq!(empty["alert"], "No record yet.", "{empty}");
    assert_eq!(empty["wear"], "–", "{empty}");
    assert_eq!(empty["trend"], "no diagnosis yet", "{empty}");
    assert!(
        empty["status"].as_str().unwrap().starts_with("updated"),
        "{empty}"
    );
    // An id no machine has.
    d.script("location.hash = '#/machines/no-such-machine'; return true")
        .await;
    d.wait_for(
        "the unknown machine's message",
        "return document.getElementById('machine').hidden && \
         document.getElementById('placeholder').textContent.includes('no machine')",
    )
    .await;

    // Null-safety of the drawing itself, with answers the API gives in states this fleet does
    // not reach: diagnoses without a wear degree (a table not ready) break the wear line into
    // runs, and a table being computed shows its progress.
    let drawn = d
        .script(
            "const t = (s, e) => ({created_at: s, estimate: e, lower: e === null ? null : e - 0.1, \
                                   upper: e === null ? null : e + 0.1, alert_level: 'ok', novelty: null, novelty_threshold: null}); \
             const m = {thresholds: {warning: 0.5, alarm: 0.8}, trend: [t('2026-11-20T08:00:00Z', 0.2), t('2026-11-21T08:00:00Z', null), \
                        t('2026-11-22T08:00:00Z', 0.3), t('2026-11-23T08:00:00Z', 0.35)]}; \
             renderTrend(m, timeDomain(m.trend)); \
             const days = [...document.querySelectorAll('#trend .tick-x')].map(x => x.textContent); \
             const out = {runs: document.querySelectorAll('#trend .trend-line').length, \
                          points: document.querySelectorAll('#trend .trend-point').length, \
                          gaps: document.querySelectorAll('#trend .trend-nowear').length, days}; \
             renderGearbox({gearbox: {id: 'gb', name: 'two-stage', status: 'running', progress: 0.4}}); \
             out.running = document.getElementById('gearbox-status').textContent; \
             out.bar = !document.getElementById('gearbox-progress').hidden; \
             renderGearbox({gearbox: {id: 'gb', status: 'failed', error: 'no mesh'}}); \
             out.failed = document.getElementById('gearbox-note').textContent; \
             return out",
        )
        .await;
    assert_eq!(drawn["runs"], 2, "{drawn}");
    assert_eq!(drawn["points"], 3, "{drawn}");
    assert_eq!(
        drawn["gaps"], 0,
        "no mark at 0 for the record without a figure: {drawn}"
    );
    assert!(
        drawn["days"]
            .as_array()
            .unwrap()
            .iter()
            .any(|d| d.as_str().unwrap().ends_with(" Nov")),
        "a span of days is labelled with dates: {drawn}"
    );
    assert_eq!(drawn["running"], "running 40 %", "{drawn}");
    assert_eq!(drawn["bar"], true, "{drawn}");
    assert!(
        drawn["failed"].as_str().unwrap().contains("no mesh"),
        "{drawn}"
    );

    // A real machine's latest diagnosis: its measured speed and load, its findings
    // in words, and no wear number when the model does not fit.
    let real = d
        .script(
            "const m = {id: 'real', record_count: 3, gearbox: {status: 'ready'}, latest: {\
               created_at: '2026-11-23T08:00:00Z', wear_degree: null, motion_state: 'period-1', warnings: [], \
               wear_note: 'no wear figure: the model does not fit this record', wear_withheld: 'poor-fit', \
               operating_state: {shaft_hz: 35.0012, source: 'tachometer', speed_variation: 0.002, load: 'low'}, \
               findings: [{kind: 'gear-local-damage', shaft: 'idler', strength: 12.5, \
                           summary: 'gear 24T (stage 2 pinion) on shaft `idler`: the envelope repeats at `idler`\\'s rate +42.6 dB', \
                           evidence: [{feature: 'env.idler', change: '+42.6 dB', z: 12.5, why: 'impulses once per revolution'}]}, \
                          {kind: 'shaft', shaft: 'idler', strength: 4.3, summary: 'shaft `idler` (bent shaft or misalignment): its 1× line up +9.9 dB', evidence: []}]}}; \
             renderLatest(m); renderFindings(m); \
             const out = {wear: document.getElementById('wear-estimate').textContent, \
                          speed: document.getElementById('speed').textContent, \
                          load: document.getElementById('load').textContent, \
                          shown: !document.getElementById('findings-box').hidden, \
                          findings: [...document.querySelectorAll('#findings > li')].map(li => li.textContent), \
                          code: [...document.querySelectorAll('#findings > li:first-child > code')].map(c => c.textContent), \
                          why: document.querySelector('#findings li .evidence').textContent}; \
             m.latest.findings = []; m.latest.operating_state = null; m.latest.state_note = 'no hint'; \
             renderLatest(m); renderFindings(m); \
             out.unmeasured = document.getElementById('speed').textContent; \
             out.none = document.getElementById('findings-box').hidden; \
             return out",
        )
        .await;
    assert_eq!(
        real["wear"], "no wear figure (poor fit: the model does not fit this record)",
        "{real}"
    );
    assert_eq!(real["speed"], "35.00 Hz input shaft (tachometer)", "{real}");
    assert_eq!(real["load"], "low", "{real}");
    assert_eq!(real["shown"], true, "{real}");
    let shown = real["findings"].as_array().unwrap();
    assert_eq!(shown.len(), 2, "{real}");
    assert!(
        shown[0].as_str().unwrap().starts_with(
            "gear 24T (stage 2 pinion) on shaft idler: the envelope repeats at idler's rate"
        ),
        "{real}"
    );
    assert_eq!(real["code"], json!(["idler", "idler"]), "{real}");
    // The evidence in sentences, not feature codes.
    assert_eq!(
        real["why"], "impulses once per revolution: +42.6 dB",
        "{real}"
    );
    assert_eq!(real["unmeasured"], "not measured: no hint", "{real}");
    assert_eq!(real["none"], true, "{real}");

    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}

/// Are these tick labels clock times (`HH:MM`, `HH:MM:SS`) or dates (`23 Nov`)?
fn labels_are_times(ticks: &[Value]) -> bool {
    ticks.iter().all(|t| {
        let s = t[0].as_str().unwrap_or("");
        let b = s.as_bytes();
        let clock = |b: &[u8]| {
            b.len() >= 5
                && b.len() <= 8
                && b.iter().enumerate().all(|(i, c)| {
                    if i % 3 == 2 {
                        *c == b':'
                    } else {
                        c.is_ascii_digit()
                    }
                })
        };
        let date = s.split_once(' ').is_some_and(|(d, m)| {
            d.parse::<u8>().is_ok_and(|d| (1..=31).contains(&d)) && m.len() == 3
        });
        clock(b) || date
    })
}
