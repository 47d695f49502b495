//! The planner's dashboard in a real headless Chromium (see `browser.rs` for the driver): a
//! fleet seeded through the API — a machine at alarm, one at warning, one whose wear rises
//! below the thresholds (back-filled over two weeks with `recorded_at`), one ok — is listed by
//! urgency with its state as colour and word, its figures in units and its trend; the open
//! alerts are listed (when the service has the alerts API); a deep link opens a machine's page
//! with its wear plot and projection, and another a record's diagnosis.

use serde_json::{Value, json};

use crate::browser::{post, start_driver};
use crate::helpers::*;

/// The wear thresholds of this fleet (ea): ok below 0.45, alarm from 0.75.
const WARNING: f64 = 0.45;
const ALARM: f64 = 0.75;

/// The back-filled history of `press-trend`: (days before now, simulated ea), rising 0.015 a
/// day and staying below warning (the estimates' error is about 0.02: `docs/accuracy.md`).
const RISING: [(i64, f64); 8] = [
    (16, 0.10),
    (14, 0.13),
    (12, 0.16),
    (10, 0.19),
    (8, 0.22),
    (6, 0.25),
    (4, 0.28),
    (2, 0.31),
];

fn days_ago(days: i64) -> String {
    (time::OffsetDateTime::now_utc() - time::Duration::days(days))
        .format(&time::format_description::well_known::Rfc3339)
        .unwrap()
}

/// The fleet, through the API; the machines' views.
async fn seed_fleet(app: &TestApp) -> Value {
    // press-alarm declares its unit (g) and ISO class: its row has velocity and zone.
    let (s, m) = put_machine(
        app,
        "press-alarm",
        json!({"channel_units": {"*": {"unit": "g"}}, "iso_20816": {"group": 2, "support": "rigid"}}),
    )
    .await;
    assert_eq!(s, 201, "{m}");
    // Several records at a level, so that an alert's on-delay passes.
    for (machine, ea, seed) in [("press-alarm", 0.9, 1), ("press-warning", 0.6, 2)] {
        let rec = rig_record(ea, seed);
        for _ in 0..4 {
            post(app, machine, "", &rec).await;
        }
    }
    for (i, (ago, ea)) in RISING.iter().enumerate() {
        let mut rec = rig_record(*ea, 10 + i as u64);
        rec["recorded_at"] = json!(days_ago(*ago));
        post(app, "press-trend", "", &rec).await;
    }
    post(app, "press-ok", "", &rig_record(0.1, 3)).await;
    let mut views = json!({});
    for id in ["press-alarm", "press-warning", "press-trend", "press-ok"] {
        views[id] = json(
            &app.get(&format!("/v1/machines/{id}"))
                .await
                .bytes()
                .await
                .unwrap(),
        );
    }
    views
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_planner_reads_the_fleet_by_urgency() {
    let Some(app) = spawn_app(Backend::Sqlite, |s| {
        s.open_dashboard = true;
        s.thresholds.warning = WARNING;
        s.thresholds.alarm = ALARM;
    })
    .await
    else {
        return;
    };
    let views = seed_fleet(&app).await;
    let level = |id: &str| views[id]["alert_level"].as_str().unwrap().to_string();
    assert_eq!(
        level("press-alarm"),
        "alarm",
        "{}",
        views["press-alarm"]["latest"]
    );
    assert_eq!(
        level("press-warning"),
        "warning",
        "{}",
        views["press-warning"]["latest"]
    );
    assert_eq!(
        level("press-trend"),
        "ok",
        "{}",
        views["press-trend"]["latest"]
    );
    assert_eq!(level("press-ok"), "ok", "{}", views["press-ok"]["latest"]);
    // The rising machine has a projected crossing: third, before the ok one.
    let projected = &views["press-trend"]["trend_summary"]["projection"];
    assert!(
        projected.is_object(),
        "{}",
        views["press-trend"]["trend_summary"]
    );
    let want = ["press-alarm", "press-warning", "press-trend", "press-ok"];
    // Both levelled machines have an open alert (their 4 records pass the on-delay); the
    // warning one is acknowledged with a note.
    let alerts = json(
        &app.get("/v1/alerts?state=open")
            .await
            .bytes()
            .await
            .unwrap(),
    );
    let alert_of = |m: &str| {
        alerts["alerts"]
            .as_array()
            .unwrap()
            .iter()
            .find(|a| a["machine_id"] == m)
            .unwrap_or_else(|| panic!("an open alert for {m}: {alerts}"))
            .clone()
    };
    assert_eq!(alert_of("press-alarm")["level"], "alarm", "{alerts}");
    let warning_alert = alert_of("press-warning")["id"]
        .as_str()
        .unwrap()
        .to_string();
    let r = app
        .client
        .post(app.url(&format!("/v1/alerts/{warning_alert}/acknowledge")))
        .bearer_auth(&app.admin_key)
        .json(&json!({"note": "lubricated, re-check Friday"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "{}", r.text().await.unwrap());

    let Some((d, profile)) = start_driver().await else {
        return;
    };
    d.open(&app.url("/")).await;
    let rows = d
        .wait_for(
            "the four machines in the overview",
            "const rows = [...document.querySelectorAll('#fleet-rows tr')]; \
             return rows.length === 4 ? rows.map(r => ({id: r.dataset.id, level: r.dataset.level, tier: r.dataset.tier, \
               word: r.querySelector('.state .word').textContent, \
               colour: getComputedStyle(r.querySelector('.state .dot')).backgroundColor, \
               figures: r.querySelector('.figures').textContent, verdict: r.querySelector('.verdict').textContent, \
               findings: r.querySelector('.findings-cell').textContent, \
               record: r.querySelector('a.record-link')?.getAttribute('href')})) : null",
        )
        .await;
    let rows = rows.as_array().unwrap();
    let order: Vec<&str> = rows.iter().map(|r| r["id"].as_str().unwrap()).collect();
    assert_eq!(order, want, "the overview's order: {rows:?}");
    let row = |id: &str| rows.iter().find(|r| r["id"] == id).unwrap();
    // The state at a glance: colour and word.
    for id in want {
        assert_eq!(row(id)["word"], level(id), "{rows:?}");
        let latest = &views[id]["latest"];
        assert_eq!(
            row(id)["record"],
            format!("#/diagnoses/{}", latest["id"].as_str().unwrap()),
            "{rows:?}"
        );
        // Every machine here has a wear figure: it reads in µm.
        let um = latest["wear_degree_um"]["estimate"].as_f64().unwrap();
        assert!(
            row(id)["figures"]
                .as_str()
                .unwrap()
                .contains(&format!("wear {um:.1} µm")),
            "{id}: {rows:?}"
        );
    }
    let colours: std::collections::HashSet<&str> = ["press-alarm", "press-warning", "press-ok"]
        .iter()
        .map(|id| row(id)["colour"].as_str().unwrap())
        .collect();
    assert_eq!(
        colours.len(),
        3,
        "alarm, warning and ok in three colours: {rows:?}"
    );
    // Units: press-alarm's velocity and ISO zone as the API gives them.
    let v = &views["press-alarm"]["latest"]["vibration"];
    let fig = row("press-alarm")["figures"].as_str().unwrap();
    assert!(
        fig.contains(&format!(
            "{:.2} mm/s RMS",
            v["velocity_rms_mm_s"].as_f64().unwrap()
        )) && fig.contains(&format!(
            "ISO zone {}",
            v["iso_20816_3"]["zone"].as_str().unwrap()
        )),
        "{fig} / {v}"
    );
    assert!(
        row("press-ok")["figures"]
            .as_str()
            .unwrap()
            .find("mm/s")
            .is_none(),
        "{rows:?}"
    );
    let days = projected["alarm"]["days"].as_f64().unwrap();
    let verdict = row("press-trend")["verdict"].as_str().unwrap();
    assert!(
        verdict.starts_with(&format!("alarm in {} day", days.round())),
        "{verdict} / {projected}"
    );
    assert_eq!(row("press-trend")["tier"], "2", "{rows:?}");

    // The open alerts as the API lists them, the alarm first, the acknowledged one with its note.
    let listed = d
        .wait_for(
            "the open alerts, one acknowledged",
            "const lis = [...document.querySelectorAll('#alerts li')]; \
             return !document.getElementById('alerts-box').hidden && lis.some(li => li.dataset.state === 'acknowledged') \
               ? lis.map(li => ({id: li.dataset.id, machine: li.dataset.machine, word: li.querySelector('.state .word').textContent, \
                                 ack: li.querySelector('.ack').textContent, record: li.querySelector('a.record-link')?.getAttribute('href')})) \
               : null",
        )
        .await;
    let listed = listed.as_array().unwrap();
    let shown: Vec<&str> = listed
        .iter()
        .map(|a| a["machine"].as_str().unwrap())
        .collect();
    assert_eq!(shown, ["press-alarm", "press-warning"], "{listed:?}");
    assert_eq!(listed[0]["word"], "alarm", "{listed:?}");
    assert_eq!(listed[0]["id"], alert_of("press-alarm")["id"], "{listed:?}");
    assert_eq!(listed[0]["ack"], "not acknowledged", "{listed:?}");
    assert_eq!(
        listed[0]["record"],
        format!(
            "#/records/{}",
            alert_of("press-alarm")["record_id"].as_str().unwrap()
        ),
        "{listed:?}"
    );
    assert_eq!(listed[1]["word"], "warning", "{listed:?}");
    let ack = listed[1]["ack"].as_str().unwrap();
    assert!(
        ack.starts_with("acknowledged by ") && ack.ends_with(": lubricated, re-check Friday"),
        "{ack}"
    );
    let note = d
        .script("return document.querySelector('#fleet-rows tr[data-id=\"press-warning\"] .alert-note').textContent")
        .await;
    assert!(
        note.as_str().unwrap().starts_with("alert open since ")
            && note.as_str().unwrap().ends_with(", acknowledged"),
        "{note}"
    );

    urgency_rules_hold(&d).await;
    deep_links_open_a_machine_and_a_record(&d, &app, &views).await;
    d.cmd(reqwest::Method::DELETE, "", None).await;
    let _ = std::fs::remove_dir_all(&profile);
}

/// The ordering rules on answers this fleet does not reach (page-side, on the real script):
/// an open alarm alert outranks a latest record at warning, a machine with an open alert comes
/// first within its tier, and projected crossings are ordered by their days to alarm.
async fn urgency_rules_hold(d: &crate::browser::Driver) {
    let order = d
        .script(
            "const saved = [openAlerts, new Map(views)]; \
             const m = (id, l) => ({id, alert_level: l, record_count: 3}); \
             const proj = (days) => ({view: {trend_summary: {verdict: 'x', projection: {alarm: {days, interval_90: [days - 1, days + 1], at: '2030-01-01T00:00:00Z'}}}}}); \
             openAlerts = [{id: 'a1', machine_id: 'acked', level: 'alarm', state: 'acknowledged', opened_at: '2026-11-01T00:00:00Z'}, \
                           {id: 'a2', machine_id: 'w-alert', level: 'warning', state: 'open', opened_at: '2026-11-01T00:00:00Z'}]; \
             views.clear(); views.set('far', proj(90)); views.set('near', proj(12)); \
             const out = byUrgency([m('ok-1', 'ok'), m('far', 'ok'), m('w-plain', 'warning'), m('unk', 'unknown'), \
                                    m('near', 'ok'), m('w-alert', 'warning'), m('acked', 'ok'), m('a-now', 'alarm')]) \
                .map(x => x.m.id + ':' + x.u.tier); \
             openAlerts = saved[0]; views.clear(); for (const [k, v] of saved[1]) views.set(k, v); \
             return out",
        )
        .await;
    assert_eq!(
        order,
        json!([
            "acked:0",
            "a-now:0",
            "w-alert:1",
            "w-plain:1",
            "near:2",
            "far:2",
            "unk:3",
            "ok-1:3"
        ]),
        "urgency order"
    );
}

/// `#/machines/{id}` opened as a URL: the page with its wear plot on a time axis, the fitted
/// line and the projected crossings; its latest record opened from it;
/// `#/records/{id}` opened as a URL.
async fn deep_links_open_a_machine_and_a_record(
    d: &crate::browser::Driver,
    app: &TestApp,
    views: &Value,
) {
    d.open(&app.url("/#/machines/press-trend")).await;
    let page = d
        .wait_for(
            "press-trend's page with its plot",
            "return document.getElementById('machine-name').textContent === 'press-trend' && \
               document.querySelectorAll('#trend .trend-point').length === 8 \
               ? {overview: document.getElementById('overview').hidden, \
                  projection: !document.getElementById('projection-fig').hidden, \
                  points: document.querySelectorAll('#projection .proj-point').length, \
                  fit: document.querySelectorAll('#projection .fit-line').length, \
                  crossings: [...document.querySelectorAll('#projection .crossing-label')].map(c => c.dataset.name), \
                  ticks: document.querySelectorAll('#trend .tick-x').length, \
                  verdict: document.getElementById('machine-verdict').textContent} : null",
        )
        .await;
    assert_eq!(page["overview"], true, "{page}");
    assert!(page["ticks"].as_u64().unwrap() >= 2, "{page}");
    let crossings = d
        .wait_for(
            "the projection",
            "return document.querySelectorAll('#projection .proj-point').length === 8 && \
               document.querySelectorAll('#projection .fit-line').length === 1 \
             ? [...document.querySelectorAll('#projection .crossing-label')].map(c => c.dataset.name) : null",
        )
        .await;
    assert_eq!(crossings, json!(["warning", "alarm"]), "{crossings}");
    assert!(
        page["verdict"]
            .as_str()
            .unwrap()
            .starts_with("Wear trend: alarm in "),
        "{page}"
    );
    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    save_png(&png, "gearwear-planner-machine.png");
    projection_draws_the_documented_answer(d).await;

    // Its latest record, from the page's link.
    let latest = &views["press-trend"]["latest"];
    d.script("document.getElementById('latest-link').click(); return true")
        .await;
    let rec = d
        .wait_for(
            "the record's diagnosis",
            &format!(
                "const r = document.getElementById('record'); \
                 return !r.hidden && r.dataset.id === {} && document.querySelectorAll('#record-spectrum .mark').length > 0 \
                   ? {{machine: document.getElementById('record-machine').textContent, hash: location.hash, \
                      wear: document.querySelector('#record-facts dd.wear').textContent}} : null",
                json!(latest["id"])
            ),
        )
        .await;
    assert_eq!(rec["machine"], "press-trend", "{rec}");
    assert_eq!(
        rec["hash"],
        format!("#/diagnoses/{}", latest["id"].as_str().unwrap()),
        "{rec}"
    );
    let ea = latest["wear_degree"]["estimate"].as_f64().unwrap();
    assert!(
        rec["wear"]
            .as_str()
            .unwrap()
            .starts_with(&format!("{ea:.3}")),
        "{rec}"
    );
    // The same record by its record id, as a URL (alerts and trend points link so).
    d.open(&app.url(&format!(
        "/#/records/{}",
        latest["record_id"].as_str().unwrap()
    )))
    .await;
    d.wait_for(
        "the record by its record id",
        &format!(
            "const r = document.getElementById('record'); \
             return !r.hidden && r.dataset.id === {} && document.getElementById('detail').hidden",
            json!(latest["id"])
        ),
    )
    .await;
    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    save_png(&png, "gearwear-planner-record.png");
    // Back to the overview from the header.
    d.script("document.querySelector('header h1 a').click(); return true")
        .await;
    d.wait_for(
        "the overview again",
        "return !document.getElementById('overview').hidden && document.querySelectorAll('#fleet-rows tr').length === 4",
    )
    .await;
    let png = d.cmd(reqwest::Method::GET, "/screenshot", None).await;
    save_png(&png, "gearwear-planner-overview.png");
}

/// The projection chart on an answer of the documented shape (page-side, on the real script):
/// ten points over 18 days rising 0.02/day, the fit, both crossings with their intervals; the
/// dashed fit meets the alarm line where the alarm crossing is drawn.
async fn projection_draws_the_documented_answer(d: &crate::browser::Driver) {
    let drawn = d
        .script(
            "const day = 86400000, t0 = Date.parse('2026-11-01T00:00:00Z'); \
             const iso = (t) => new Date(t).toISOString(); \
             const points = [...Array(10).keys()].map((i) => ({measured_at: iso(t0 + 2 * i * day), value: 0.1 + 0.04 * i, record_id: 'r' + i})); \
             const last = t0 + 18 * day; \
             const tr = {machine_id: 'x', series: 'wear', channel: null, unit: 'ea (reference lengths)', points, \
               fit: {slope_per_day: 0.02, slope_interval_90: [0.015, 0.025], level: 0.46, significant: true}, \
               thresholds: {warning: 0.5, alarm: 0.8}, \
               projection: {warning: {days: 2, interval_90: [1.5, 3], at: iso(last + 2 * day)}, \
                            alarm: {days: 17, interval_90: [13, 23], at: iso(last + 17 * day)}}, \
               verdict: 'alarm in 17 days (90 % interval 13–23)'}; \
             renderProjection(tr); \
             const q = (s) => [...document.querySelectorAll('#projection ' + s)]; \
             const proj = q('.fit-projection')[0]; \
             const alarmMark = q('.crossing-mark[data-name=alarm]')[0]; \
             const out = {shown: !document.getElementById('projection-fig').hidden, points: q('.proj-point').length, \
               links: q('a .proj-point').length, fit: q('.fit-line').length, \
               marks: q('.crossing-mark').map((c) => c.dataset.name), intervals: q('.crossing-interval').length, \
               verdict: document.getElementById('projection-verdict').textContent, \
               end: [+proj.getAttribute('x2'), +proj.getAttribute('y2')], \
               alarm: [+alarmMark.getAttribute('cx'), +alarmMark.getAttribute('cy')]}; \
             return out",
        )
        .await;
    assert_eq!(drawn["shown"], true, "{drawn}");
    assert_eq!(drawn["points"], 10, "{drawn}");
    assert_eq!(
        drawn["links"], 10,
        "each point links to its record: {drawn}"
    );
    assert_eq!(drawn["fit"], 1, "{drawn}");
    assert_eq!(drawn["marks"], json!(["warning", "alarm"]), "{drawn}");
    assert_eq!(drawn["intervals"], 2, "{drawn}");
    assert!(
        drawn["verdict"]
            .as_str()
            .unwrap()
            .starts_with("alarm in 17 days"),
        "{drawn}"
    );
    for k in 0..2 {
        let (a, b) = (
            drawn["end"][k].as_f64().unwrap(),
            drawn["alarm"][k].as_f64().unwrap(),
        );
        assert!(
            (a - b).abs() < 1.0,
            "the fit ends at the alarm crossing: {drawn}"
        );
    }
}

/// A WebDriver screenshot into the temporary directory (to look at, not compared).
fn save_png(png: &Value, name: &str) {
    use base64::Engine;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(png.as_str().unwrap())
        .unwrap();
    let out = std::env::temp_dir().join(name);
    std::fs::write(&out, bytes).unwrap();
    eprintln!("planner screenshot: {}", out.display());
}
