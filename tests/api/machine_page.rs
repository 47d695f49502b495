//! A real machine's page and the overview agree with its alert, in a real headless Chromium:
//! the described two-stage gearbox with a tachometer (the records of `operating_state.rs`),
//! a baseline of healthy records, two records with a damaged idler shaft (an alert opens),
//! then a quiet record. The page must show the alert's level as the machine's state ("open
//! since … — last record ok"), the findings of the record that opened or escalated it beside
//! the latest record's (none), the novelty as the main chart (these records have no wear
//! figure) with the baseline records marked and a legend, and a trend verdict that does not
//! project a crossing the alert already holds; acknowledging through the page's button shows
//! the key's label in the page and in the audit trail. Screenshots of both pages go to
//! `target/screenshots/` (for the docs).

use std::path::PathBuf;

use gearwear::keys::Scope;
use serde_json::{Value, json};

use crate::browser::start_driver;
use crate::helpers::*;
use crate::operating_state::{HELICAL, record, wait_ready};

/// `2026-11-02T<hour>:00:00Z`: the records' measurement times, an hour apart.
fn at(hour: u32) -> String {
    format!("2026-11-{:02}T{:02}:00:00.000Z", 2 + hour / 24, hour % 24)
}

async fn post_at(app: &TestApp, query: &str, mut body: Value, hour: u32) -> Value {
    body["recorded_at"] = at(hour).into();
    let r = app
        .client
        .post(app.url(&format!("/v1/machines/gb/records{query}")))
        .bearer_auth(&app.ingest_key)
        .json(&body)
        .send()
        .await
        .unwrap();
    let s = r.status();
    let v = json(&r.bytes().await.unwrap());
    assert_eq!(s, 201, "{v}");
    v
}

async fn get(app: &TestApp, path: &str) -> Value {
    json(&app.get(path).await.bytes().await.unwrap())
}

/// A WebDriver screenshot to `target/screenshots/<name>` (the docs show them).
async fn screenshot(d: &crate::browser::Driver, name: &str) {
    use base64::Engine;
    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(png.as_str().unwrap())
        .unwrap();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/screenshots");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(name), bytes).unwrap();
    eprintln!("screenshot: {}", dir.join(name).display());
}

/// The machine through the API: gearbox, machine, baseline, damage, a quiet record. The
/// machine's view afterwards.
async fn seed(app: &TestApp) -> Value {
    assert_eq!(put_gearbox(app, "helical", HELICAL).await, 201);
    let (s, m) = put_machine(
        app,
        "gb",
        json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": 10,
               "channel_units": {"a1": {"unit": "g"}, "a2": {"unit": "g"}}}),
    )
    .await;
    assert_eq!(s, 201, "{m}");
    wait_ready(app, "helical").await;
    // Healthy records at three speeds, two each, marked as the baseline.
    for (i, hz) in [30.0, 30.0, 35.0, 35.0, 40.0, 40.0].into_iter().enumerate() {
        let i = i as u32;
        post_at(
            app,
            "?baseline=true",
            record(hz, 1 + i as u64, false, Some("low")),
            i,
        )
        .await;
    }
    post_at(app, "", record(35.0, 100, false, Some("low")), 8).await;
    // The damaged idler shaft, twice: the alert opens (and may escalate).
    for (k, seed) in [(10, 102), (11, 103)] {
        let bad = post_at(app, "", record(35.0, seed, true, Some("low")), k).await;
        let lv = bad["alert"]["level"].as_str().unwrap();
        assert!(matches!(lv, "warning" | "alarm"), "{}", bad["alert"]);
    }
    // A quiet record: the latest record is ok, the alert stays open.
    let quiet = post_at(app, "", record(35.0, 104, false, Some("low")), 12).await;
    assert_eq!(quiet["alert"]["level"], "ok", "{}", quiet["alert"]);
    get(app, "/v1/machines/gb").await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn machine_page_agrees_with_the_open_alert() {
    let Some(app) = spawn_app(Backend::Sqlite, |s| s.alerts.open_after = 1).await else {
        return;
    };
    let view = seed(&app).await;
    // The view: the state is the alert's, and says so; the alert's findings are the damaged
    // record's; the latest record has none.
    let st = &view["state"];
    let oa = &view["open_alert"];
    let level = oa["level"].as_str().unwrap().to_string();
    assert_eq!(st["level"], level.as_str(), "{st}");
    assert_eq!(
        (st["source"].as_str(), st["record_level"].as_str()),
        (Some("alert"), Some("ok")),
        "{st}"
    );
    let ev = &oa["evidence"];
    let findings = ev["findings"].as_array().unwrap();
    assert!(!findings.is_empty(), "{oa}");
    assert_eq!(view["latest"]["findings"], json!([]), "{view}");
    assert!(
        ev["measured_at"] == at(10) || ev["measured_at"] == at(11),
        "{ev}"
    );
    // The baseline's span is its records' measurement times, not when they were received.
    assert_eq!(view["baseline"]["first_at"], at(0), "{}", view["baseline"]);
    assert_eq!(view["baseline"]["last_at"], at(5), "{}", view["baseline"]);
    // No wear figure on these records: the summary is the novelty's, and does not project a
    // crossing of a level the alert holds.
    let ts = &view["trend_summary"];
    assert_eq!(ts["series"], "novelty", "{ts}");
    let verdict = ts["verdict"].as_str().unwrap();
    assert!(
        verdict.starts_with(&format!("{level} open since 2026-11-02")),
        "{verdict}"
    );
    assert!(!verdict.contains(&format!("{level} in ")), "{verdict}");
    let tr = get(&app, "/v1/machines/gb/trend?series=novelty").await;
    assert_eq!(tr["verdict"], ts["verdict"], "{tr}");
    assert!(
        tr["projection"].is_null() || tr["projection"][&level].is_null(),
        "{tr}"
    );

    // The page, with a key that may read and acknowledge.
    let key = gearwear::service::cli::create_key(
        app.store.as_ref(),
        &[Scope::Read, Scope::Acknowledge],
        "planner tablet",
    )
    .await
    .unwrap()
    .1;
    let Some((d, profile)) = start_driver().await else {
        return;
    };
    d.open(&app.url("/#/machines/gb")).await;
    d.wait_for(
        "the key prompt",
        "return !document.getElementById('keyform').hidden",
    )
    .await;
    d.script(&format!(
        "document.getElementById('key').value = '{key}'; \
         document.getElementById('keyform').requestSubmit(); return true"
    ))
    .await;
    let page = d
        .wait_for(
            "the machine page with its alert and an acknowledge button",
            "const t = (id) => document.getElementById(id).textContent; \
             return document.getElementById('machine-name').textContent === 'gb' && \
                    document.querySelector('#machine-alerts .ack-form') && \
                    document.querySelectorAll('#trend .finding-series').length > 0 \
               ? {badge: t('machine-level'), alert: document.getElementById('alert').dataset.level, title: t('alert-title'), \
                  reason: t('alert-reason'), \
                  alertFindings: [...document.querySelectorAll('#alert-findings > li')].map(li => li.textContent), \
                  alertShown: !document.getElementById('alert-findings-box').hidden, \
                  latestNote: t('findings-note'), latestCount: document.querySelectorAll('#findings > li').length, \
                  series: document.getElementById('trend').dataset.series, \
                  note: document.querySelector('#trend .chart-note')?.textContent ?? null, \
                  points: document.querySelectorAll('#trend .novelty-point').length, \
                  baseline: document.querySelectorAll('#trend .baseline-point, #trend .baseline-mark').length, \
                  legend: [...document.querySelectorAll('#trend-legend li')].map(li => li.textContent), \
                  verdict: t('machine-verdict'), why: t('channels')} : null",
        )
        .await;
    assert_eq!(page["badge"], format!("{} {level}", icon(&level)), "{page}");
    assert_eq!(page["alert"], level.as_str(), "{page}");
    let title = page["title"].as_str().unwrap();
    assert!(
        title.contains("open since") && title.ends_with("— last record ok."),
        "{page}"
    );
    assert_eq!(page["alertShown"], true, "{page}");
    let shown = page["alertFindings"].as_array().unwrap();
    assert_eq!(shown.len(), findings.len(), "{page}");
    // The first finding's sentence as the API gives it (the page sets part names in code).
    let first = findings[0]["summary"].as_str().unwrap().replace('`', "");
    let first_shown = d
        .script("return document.querySelector('#alert-findings > li').textContent")
        .await;
    assert!(
        first_shown.as_str().unwrap().starts_with(&first),
        "{first_shown} / {first}"
    );
    assert_eq!(page["latestCount"], 0, "{page}");
    assert!(
        page["latestNote"].as_str().unwrap().contains("none"),
        "{page}"
    );
    // The main chart is the novelty, not an empty wear chart.
    assert_eq!(page["series"], "novelty", "{page}");
    assert_eq!(page["note"], Value::Null, "{page}");
    let scored = trend_count(&view, "novelty");
    assert!(scored >= 4, "{view}");
    assert_eq!(page["points"], json!(scored), "{page}");
    assert_eq!(page["baseline"], 6, "each baseline record marked: {page}");
    let legend: Vec<&str> = page["legend"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    assert!(
        legend.contains(&"novelty score") && legend.iter().any(|l| l.ends_with("(strength)")),
        "{legend:?}"
    );
    let verdict_shown = page["verdict"].as_str().unwrap();
    assert!(
        verdict_shown.contains("open since") && !verdict_shown.contains(&format!("{level} in ")),
        "{page}"
    );
    // The "why" column in words, not feature codes like `shaft.in.1x z 4.9`.
    let why = page["why"].as_str().unwrap();
    assert!(!why.contains(" z "), "{why}");
    screenshot(&d, "machine-page.png").await;
    d.script("document.getElementById('trend-fig').scrollIntoView(); return true")
        .await;
    screenshot(&d, "machine-page-chart.png").await;
    d.script("window.scrollTo(0, 0); return true").await;

    // Acknowledge through the page's button, with a note.
    d.script(
        "const f = document.querySelector('#machine-alerts .ack-form'); \
         f.querySelector('input').value = 'idler bearing ordered'; \
         f.querySelector('button').click(); return true",
    )
    .await;
    let acked = d
        .wait_for(
            "the acknowledged alert",
            "const li = document.querySelector('#machine-alerts li'); \
             return li && li.dataset.state === 'acknowledged' ? li.textContent : null",
        )
        .await;
    let acked = acked.as_str().unwrap();
    assert!(
        acked.contains("acknowledged by planner tablet")
            && acked.ends_with(": idler bearing ordered"),
        "{acked}"
    );
    let id = oa["id"].as_str().unwrap();
    let detail = get(&app, &format!("/v1/alerts/{id}")).await;
    assert_eq!(
        detail["acknowledged_by_label"], "planner tablet",
        "{detail}"
    );
    let line = detail["audit"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["event"] == "acknowledged")
        .cloned()
        .unwrap();
    assert_eq!(line["by_label"], "planner tablet", "{detail}");

    // The overview: the machine's state and findings are the alert's.
    d.script("location.hash = '#/'; return true").await;
    let row = d
        .wait_for(
            "the machine's row",
            "const r = document.querySelector('#fleet-rows tr[data-id=\"gb\"]'); \
             return r ? {level: r.dataset.level, findings: r.querySelector('.findings-cell').textContent, \
                         alertFindings: r.querySelectorAll('.alert-finding').length, \
                         latest: r.querySelector('.latest-finding')?.textContent ?? null} : null",
        )
        .await;
    assert_eq!(row["level"], level.as_str(), "{row}");
    assert!(
        row["findings"].as_str().unwrap().contains(&first),
        "{row} / {first}"
    );
    assert!(row["alertFindings"].as_u64().unwrap() >= 1, "{row}");
    assert_eq!(row["latest"], "latest: no finding", "{row}");
    screenshot(&d, "overview.png").await;

    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}

fn icon(level: &str) -> &'static str {
    match level {
        "alarm" => "✕",
        "warning" => "!",
        "ok" => "✓",
        _ => "?",
    }
}

/// A measurement, not a timed assertion: how long the overview takes to draw 200 machines in
/// headless Chromium (the page's own `renderOverview` and fleet list, on views shaped like the
/// API's: two findings each, every tenth machine with an open alarm and its evidence). Run
/// with `cargo test --release --test api -- --ignored overview_draws_200_machines --nocapture`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "a measurement: prints the drawing time"]
async fn overview_draws_200_machines() {
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
    let ms = d
        .script(
            "const finding = (k) => ({kind: 'gear-local-damage', shaft: 'idler', strength: 9.5, \
               summary: 'gear 24T on shaft `idler`: sidebands at the idler\\'s rate around mesh 2 +9.1 dB ' + k, \
               evidence: [{feature: 'lines.own.idler.near.m2', change: '+9.1 dB', z: 9.5, why: 'first sidebands'}]}); \
             const machines = [], alerts = []; \
             for (let i = 0; i < 200; i++) { \
               const id = 'm-' + String(i).padStart(3, '0'); \
               const stamp = '2026-11-02T10:00:00.000Z'; \
               machines.push({id, alert_level: i % 10 ? 'ok' : 'warning', record_count: 40, updated_at: stamp, \
                              last_diagnosis_id: 'd' + i, gearbox: 'helical'}); \
               const latest = {id: 'd' + i, record_id: 'r' + i, measured_at: stamp, alert_level: 'ok', findings: [finding(1), finding(2)], \
                               vibration: {velocity_rms_mm_s: 2.1, acceleration_rms_m_s2: 3.2, acceleration_peak_m_s2: 12.0}}; \
               const view = {id, latest, configuration: {}, trend_summary: {series: 'novelty', verdict: 'no significant trend', projection: null}, \
                             open_alert: null}; \
               if (i % 10 === 0) { \
                 const a = {id: 'a' + i, machine_id: id, level: 'alarm', state: 'open', opened_at: stamp, record_id: 'r0' + i}; \
                 alerts.push(a); \
                 view.open_alert = {...a, evidence: {event: 'opened', record_id: 'r0' + i, measured_at: stamp, findings: [finding(3)]}}; \
               } \
               views.set(id, {stamp: viewStamp(machines[i]), view}); \
             } \
             openAlerts = alerts; \
             const t0 = performance.now(); \
             renderMachines({machines}, []); \
             renderOverview(machines); \
             document.body.offsetHeight; \
             const t1 = performance.now(); \
             return {ms: t1 - t0, rows: document.querySelectorAll('#fleet-rows tr').length}",
        )
        .await;
    assert_eq!(ms["rows"], 200, "{ms}");
    eprintln!(
        "overview of 200 machines drawn in {:.1} ms (renderMachines + renderOverview + layout)",
        ms["ms"].as_f64().unwrap()
    );
    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}
