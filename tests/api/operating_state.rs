//! Real machines through the API, on both stores: a machine with a described
//! two-stage gearbox and a tachometer channel, its healthy records posted at three speeds and
//! two loads; the baseline's coverage of operating states, a healthy record judged at its
//! state, a record at a speed the baseline does not cover (`unknown`, naming the state), and
//! a damaged idler shaft whose findings name parts — in the answer, the stored diagnosis, the
//! machine view and the webhook. No wear figure is ever stored as a number when the model does
//! not fit.
//!
//! The records are synthetic (CI has no real data): a 10-pulse-per-revolution tachometer
//! square wave and two accelerometers with the two mesh tones (16× and 8× the input rate),
//! their harmonics, a little shaft modulation and noise, 1.5 s at 20 kHz. Every feature the
//! baseline tracks has some content of its own: features that are pure noise floor vary from
//! record to record enough to raise a false alarm against a baseline of a dozen records.
//! Healthy records are checked at a covered speed only: between the baseline's speeds these
//! synthetic records' TSA and sideband features do not follow the interpolation.

use std::f64::consts::TAU;
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(a_tachometer_machine_is_judged_at_its_operating_state);

pub(crate) const HELICAL: &str = include_str!("../../configs/gearboxes/phm09-helical.toml");
pub(crate) const FS: f64 = 20_000.0;
const SECONDS: f64 = 1.5;
pub(crate) const PPR: usize = 10;

/// The machine's three channels at input rate `input_hz` (Hz), everything locked to the input
/// shaft's angle θ (a random start angle per `seed`): `tacho` a square wave of [`PPR`]
/// pulses a revolution whose pulses sit exactly at the 5 V rail between noisy lows (an open
/// collector pulled up: a vibration channel like that is refused as clipped); `a1` and `a2`
/// the stage-1 (16θ) and stage-2 (8θ) mesh tones with two harmonics each, a few per cent of
/// modulation by the shafts carrying each gear (in: θ, idler: θ/3, out: θ/5), small shaft
/// lines and noise. `idler_damage` adds a ringing impulse once per revolution of the idler
/// shaft, as a cracked tooth on it would.
pub(crate) fn channels(
    input_hz: f64,
    seed: u64,
    idler_damage: bool,
) -> [(&'static str, Vec<f64>); 3] {
    let n = (FS * SECONDS) as usize;
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(11);
    let mut uniform = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let theta0 = TAU * uniform();
    let round = |v: f64| (v * 1e5).round() / 1e5;
    // (gain, phase) of each channel's view of the same sources.
    let views = [(1.0, 0.0), (0.7, 1.1)];
    let mut out = [
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    ];
    for i in 0..n {
        let th = TAU * input_hz * i as f64 / FS + theta0;
        let pulse = (PPR as f64 * th / TAU).fract() < 0.3;
        let low = round(0.02 * (uniform() - 0.5));
        out[0].push(if pulse { 5.0 } else { low });
        let (idler, output) = (th / 3.0, th / 5.0);
        let ring = if idler_damage {
            let since = (idler / TAU).fract() / (input_hz / 3.0);
            3.0 * (-since * 800.0).exp() * (TAU * 3000.0 * since).sin()
        } else {
            0.0
        };
        for (c, (g, p)) in views.iter().enumerate() {
            let mesh1 = (1.0 + 0.05 * th.cos() + 0.04 * (idler + 0.2).cos())
                * ((16.0 * th + p).sin()
                    + 0.3 * (32.0 * th + 0.7 + p).sin()
                    + 0.1 * (48.0 * th + 1.3).sin());
            let mesh2 = (1.0 + 0.05 * (idler + 0.5).cos() + 0.03 * (output + 0.9).cos())
                * (0.6 * (8.0 * th + 0.3 * p).sin()
                    + 0.2 * (16.0 * th + 2.0).sin()
                    + 0.07 * (24.0 * th + 0.4).sin());
            let shafts = 0.02 * (th + 0.5).sin()
                + 0.01 * (2.0 * th).sin()
                + 0.02 * (idler + 0.9).sin()
                + 0.01 * (2.0 * idler + 0.3).sin()
                + 0.02 * (output + 1.7).sin()
                + 0.01 * (2.0 * output + 1.1).sin();
            let x = g * (mesh1 + (1.4 - g) * mesh2 + shafts) + ring * g + 0.02 * (uniform() - 0.5);
            out[c + 1].push(round(x));
        }
    }
    let [t, a1, a2] = out;
    [("tacho", t), ("a1", a1), ("a2", a2)]
}

/// [`channels`] as a JSON record body (`load`, when given, in the body).
pub(crate) fn record(input_hz: f64, seed: u64, idler_damage: bool, load: Option<&str>) -> Value {
    let chans: serde_json::Map<String, Value> = channels(input_hz, seed, idler_damage)
        .into_iter()
        .map(|(n, x)| (n.to_string(), json!(x)))
        .collect();
    let mut v = json!({"sample_rate_hz": FS, "channels": chans});
    if let Some(l) = load {
        v["load"] = l.into();
    }
    v
}

/// [`channels`] as a CSV body (`tacho,a1,a2` header, no time column).
fn csv_record(input_hz: f64, seed: u64) -> String {
    let [(_, t), (_, a1), (_, a2)] = channels(input_hz, seed, false);
    let mut s = String::from("tacho,a1,a2\n");
    for i in 0..t.len() {
        s.push_str(&format!("{},{},{}\n", t[i], a1[i], a2[i]));
    }
    s
}

async fn put(app: &TestApp, path: &str, template: &str, body: Value) -> (u16, Value) {
    let (s, _, b) = checked(
        app.client
            .put(app.url(path))
            .bearer_auth(&app.admin_key)
            .json(&body),
        "PUT",
        template,
    )
    .await;
    (s, json(&b))
}

pub(crate) async fn get(app: &TestApp, path: &str, template: &str) -> Value {
    let (s, _, b) = checked(
        app.client.get(app.url(path)).bearer_auth(&app.read_key),
        "GET",
        template,
    )
    .await;
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&b));
    json(&b)
}

async fn post(app: &TestApp, machine: &str, query: &str, body: &Value) -> (u16, Value) {
    let (s, _, b) = checked(
        app.client
            .post(app.url(&format!("/v1/machines/{machine}/records{query}")))
            .bearer_auth(&app.ingest_key)
            .json(body),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    (s, json(&b))
}

/// Within 0.5 % of `want`.
fn near(got: &Value, want: f64) -> bool {
    got.as_f64().is_some_and(|g| (g / want - 1.0).abs() < 0.005)
}

/// The answer's measured state: from the tachometer, at `hz` and `load`; and the tachometer
/// is not among the channels diagnosed.
fn assert_state(a: &Value, hz: f64, load: &str) {
    let st = &a["operating_state"];
    assert_eq!(st["source"], "tachometer", "{st}");
    assert!(near(&st["shaft_hz"], hz), "measured {st}, want {hz} Hz");
    assert_eq!(st["load"], load, "{st}");
    let names: Vec<&str> = a["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["a1", "a2"], "the tachometer is not diagnosed");
}

pub(crate) async fn wait_ready(app: &TestApp, id: &str) {
    let t0 = Instant::now();
    loop {
        let g = get(
            app,
            &format!("/v1/gearboxes/{id}"),
            "/v1/gearboxes/{gearbox_id}",
        )
        .await;
        match g["status"].as_str().unwrap() {
            "ready" => return,
            "failed" => panic!("table job failed: {g}"),
            _ => {}
        }
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "table not ready: {g}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

async fn a_tachometer_machine_is_judged_at_its_operating_state(b: Backend) {
    // An alert opens on the first record at warning, so the damaged record's
    // `wear.threshold_crossed` goes out (by default it takes two).
    let Some(app) = spawn_app(b, |s| s.alerts.open_after = 1).await else {
        return;
    };
    let (s, _, body) = checked(
        app.client
            .put(app.url("/v1/gearboxes/helical"))
            .bearer_auth(&app.admin_key)
            .header("content-type", "application/toml")
            .body(HELICAL),
        "PUT",
        "/v1/gearboxes/{gearbox_id}",
    )
    .await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));

    // The tachometer's configuration is checked like the rest of the machine's.
    let machine = "/v1/machines/{machine_id}";
    for bad in [
        json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": 0}),
        json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": 2.5}),
        json!({"gearbox": "helical", "tacho_channel": "", "tacho_ppr": 10}),
        json!({"gearbox": "helical", "tacho_channel": "a1", "channels": ["a1", "a2"]}),
    ] {
        let (s, p) = put(&app, "/v1/machines/gb", machine, bad.clone()).await;
        assert_eq!(s, 422, "{bad} → {p}");
        assert_eq!(p["type"], "urn:gearwear:problem:invalid-machine", "{p}");
        assert!(p["detail"].as_str().unwrap().contains("tacho_"), "{p}");
    }
    let (s, m) = put(
        &app,
        "/v1/machines/gb",
        machine,
        json!({"gearbox": "helical", "tacho_channel": "tacho", "tacho_ppr": PPR}),
    )
    .await;
    assert_eq!(s, 201, "{m}");
    assert_eq!(
        (m["tacho_channel"].as_str(), m["tacho_ppr"].as_i64()),
        (Some("tacho"), Some(10))
    );
    // With its table ready the records get a reading: their wear figure is withheld (the
    // spur-gear model does not fit these tones), which must not become a stored 0.
    wait_ready(&app, "helical").await;

    // Healthy records, two at each of 30, 35 and 40 Hz and two loads: `low` in the query,
    // `high` in the body. 30 Hz is outside the table's speeds (34–46 Hz): still taken as
    // healthy. (Two a state: one gives the baseline's scale too few residuals to be steady.)
    let speeds = [30.0, 30.0, 35.0, 35.0, 40.0, 40.0];
    let mut seed = 0;
    for load in ["low", "high"] {
        for hz in speeds {
            seed += 1;
            let (q, body_load) = if load == "low" {
                ("?baseline=true&load=low", None)
            } else {
                ("?baseline=true", Some(load))
            };
            let (s, a) = post(&app, "gb", q, &record(hz, seed, false, body_load)).await;
            assert_eq!(s, 201, "{a}");
            assert_state(&a, hz, load);
        }
    }

    // (a) The baseline covers those states, per channel.
    let bl = get(
        &app,
        "/v1/machines/gb/baseline",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    for ch in ["a1", "a2"] {
        let c = &bl["channels"][ch];
        assert_eq!(c["state_aware"], true, "{bl}");
        let cov = &c["coverage"];
        assert_eq!(cov["records"], 12, "{cov}");
        let loads = cov["loads"].as_array().unwrap();
        assert_eq!(loads.len(), 2, "{cov}");
        for l in loads {
            assert!(matches!(l["load"].as_str(), Some("low" | "high")), "{l}");
            let got = l["speeds_hz"].as_array().unwrap();
            assert_eq!(got.len(), 6, "{l}");
            for (g, want) in got.iter().zip(speeds) {
                assert!(near(g, want), "coverage speed {g}, want {want} Hz: {l}");
            }
            assert!(near(&l["min_hz"], 30.0) && near(&l["max_hz"], 40.0), "{l}");
        }
        // The machine's model, calibrated on the records' line levels at three speeds (or
        // refused, saying against what): never missing for records that carry them.
        let model = &c["model"];
        match model["status"].as_str() {
            Some("calibrated") => {
                let r = &model["report"];
                assert_eq!(r["records"], 12, "{r}");
                assert!(r["lines"].as_u64().unwrap() > 0, "{r}");
                assert_eq!(r["speeds_hz"].as_array().unwrap().len(), 3, "{r}");
            }
            Some("refused") => {
                let why = model["reason"].as_str().unwrap();
                assert!(why.contains("smooth curve"), "{why}");
            }
            _ => panic!("{model}"),
        }
        // The transfer path through the table: the 35 and 40 Hz records carry line ratios, so
        // a path is calibrated or refused with the reason. (30 Hz lies outside the table: its
        // records carry ratios once the table is extended to it and they are read again, in
        // the background — two speeds, or three when that was quicker than these records.)
        let path = &c["path"];
        match path["status"].as_str() {
            Some("calibrated") => {
                let speeds = path["f1_hz"].as_array().unwrap().len();
                assert!(matches!(speeds, 2 | 3), "{path}");
                assert!(
                    path["residual_db"].as_f64().unwrap()
                        < path["plain_residual_db"].as_f64().unwrap(),
                    "{path}"
                );
            }
            Some("refused") => assert!(
                path["reason"].as_str().unwrap().contains("plain model"),
                "{path}"
            ),
            _ => panic!("{path}"),
        }
        eprintln!("channel {ch}: path {}", path["status"]);
    }
    assert!(bl["channels"].get("tacho").is_none(), "{bl}");

    // (b) A healthy record at a covered state.
    let (s, ok) = post(&app, "gb", "?load=low", &record(35.0, 100, false, None)).await;
    assert_eq!(s, 201, "{ok}");
    assert_state(&ok, 35.0, "low");
    assert_eq!(ok["novelty"]["anomalous"], false, "{ok}");
    assert_eq!(ok["alert"]["level"], "ok", "{}", ok["alert"]);
    assert_eq!(ok["state_reference"]["reference"], "same-state", "{ok}");
    assert_eq!(ok["findings"], json!([]), "{ok}");

    // (c) A speed the baseline does not cover: unknown, and the reason names the state.
    let (s, far) = post(&app, "gb", "?load=low", &record(50.0, 101, false, None)).await;
    assert_eq!(s, 201, "{far}");
    assert_state(&far, 50.0, "low");
    assert_eq!(far["alert"]["level"], "unknown", "{}", far["alert"]);
    let why = far["alert"]["reason"].as_str().unwrap();
    assert!(
        why.contains("not covered") && why.contains("50.0") && why.contains("low"),
        "{why}"
    );

    // (d) A damaged idler shaft (one impulse per idler revolution): an alert, findings that
    // name parts — in the answer, the stored diagnosis, the machine view and the webhook.
    let (rx, url, _t) = crate::webhooks::start_receiver(0, 0).await;
    let (s, _, _) = checked(
        app.client
            .post(app.url("/v1/webhooks"))
            .bearer_auth(&app.admin_key)
            .json(&json!({"url": url, "events": ["wear.threshold_crossed"]})),
        "POST",
        "/v1/webhooks",
    )
    .await;
    assert_eq!(s, 201);
    let (s, bad) = post(&app, "gb", "", &record(35.0, 102, true, Some("low"))).await;
    assert_eq!(s, 201, "{bad}");
    assert_state(&bad, 35.0, "low");
    let level = bad["alert"]["level"].as_str().unwrap();
    assert!(matches!(level, "warning" | "alarm"), "{}", bad["alert"]);
    let findings = bad["findings"].as_array().unwrap();
    assert!(!findings.is_empty(), "{bad}");
    for f in findings {
        assert!(f["kind"].is_string() && f["summary"].is_string(), "{f}");
        assert!(f.get("shaft").is_some(), "{f}");
        assert!(!f["evidence"].as_array().unwrap().is_empty(), "{f}");
    }
    // Parts first, then the changes of a whole band or stage, then what is left; each group
    // by the share of the change it explains.
    let group = |f: &Value| match f["kind"].as_str().unwrap() {
        "transfer-path" | "mesh-lines" => 1,
        "unexplained" => 2,
        _ => 0,
    };
    for w in findings.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        assert!(
            group(a) < group(b)
                || (group(a) == group(b)
                    && a["share"].as_f64().unwrap() >= b["share"].as_f64().unwrap()),
            "{findings:?}"
        );
    }

    let id = bad["id"].as_str().unwrap();
    let d = get(
        &app,
        &format!("/v1/diagnoses/{id}"),
        "/v1/diagnoses/{diagnosis_id}",
    )
    .await;
    assert_eq!(d["diagnosis"]["findings"], bad["findings"]);
    assert_eq!(d["diagnosis"]["operating_state"], bad["operating_state"]);
    let mv = get(&app, "/v1/machines/gb", machine).await;
    assert_eq!(mv["latest"]["findings"], bad["findings"]);
    assert_eq!(mv["latest"]["operating_state"], bad["operating_state"]);
    assert_eq!(mv["configuration"]["tacho_channel"], "tacho");

    let t0 = Instant::now();
    while rx.got.lock().unwrap().is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no webhook delivery"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let payload: Value = serde_json::from_slice(&rx.got.lock().unwrap()[0].1).unwrap();
    assert_eq!(payload["event"], "wear.threshold_crossed", "{payload}");
    assert_eq!(payload["diagnosis_id"], id, "{payload}");
    assert_eq!(payload["findings"], bad["findings"], "{payload}");
    assert_eq!(
        payload["operating_state"], bad["operating_state"],
        "{payload}"
    );

    // No fake wear: every diagnosis whose answer withheld the wear figure (the model does not
    // fit) has none in the list, the trend and the machine's latest either.
    let answers = [&ok, &far, &bad];
    assert!(
        answers.iter().all(|a| a["wear_degree"].is_null()),
        "these tones are not the model's: no wear figure expected"
    );
    assert!(
        bad["wear_note"]
            .as_str()
            .is_some_and(|n| n.contains("does not fit")),
        "{bad}"
    );
    assert!(mv["latest"]["wear_degree"].is_null(), "{}", mv["latest"]);
    assert!(mv["latest"]["wear_note"].is_string(), "{}", mv["latest"]);
    for p in mv["trend"].as_array().unwrap() {
        assert!(
            p["estimate"].is_null() && p["lower"].is_null(),
            "a wear of 0 plotted: {p}"
        );
    }
    let list = get(
        &app,
        "/v1/machines/gb/diagnoses",
        "/v1/machines/{machine_id}/diagnoses",
    )
    .await;
    for it in list["items"].as_array().unwrap() {
        assert!(it["wear_degree"].is_null(), "{it}");
    }
    assert!(payload["wear_degree"].is_null(), "{payload}");

    // The tachometer the machine names must be in the record; it is never diagnosed.
    let mut no_tacho = record(35.0, 103, false, Some("low"));
    no_tacho["channels"]
        .as_object_mut()
        .unwrap()
        .remove("tacho");
    let (s, p) = post(&app, "gb", "", &no_tacho).await;
    assert_eq!(s, 422, "{p}");
    assert_eq!(
        p["type"], "urn:gearwear:problem:missing-tacho-channel",
        "{p}"
    );
    let detail = p["detail"].as_str().unwrap();
    assert!(
        detail.contains("`tacho`") && detail.contains("`a1`, `a2`"),
        "{detail}"
    );
    let (s, p) = post(
        &app,
        "gb",
        "?channel=tacho",
        &record(35.0, 104, false, None),
    )
    .await;
    assert_eq!(s, 422, "{p}");
    assert_eq!(
        p["type"], "urn:gearwear:problem:no-vibration-channel",
        "{p}"
    );

    // A CSV body with the load in the query: the square wave passes as a pulse train.
    let (s, _, b) = checked(
        app.client
            .post(app.url("/v1/machines/gb/records?sample_rate_hz=20000&load=high"))
            .bearer_auth(&app.ingest_key)
            .header("content-type", "text/csv")
            .body(csv_record(40.0, 105)),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    let csv = json(&b);
    assert_eq!(s, 201, "{csv}");
    assert_state(&csv, 40.0, "high");
    assert_eq!(csv["alert"]["level"], "ok", "{}", csv["alert"]);

    // The same pulses in a channel that is not the tachometer: a clipped vibration channel.
    let mut renamed = record(40.0, 108, false, None);
    let pulses = renamed["channels"]["tacho"].take();
    let chans = renamed["channels"].as_object_mut().unwrap();
    chans.remove("tacho");
    chans.insert("speed".into(), pulses);
    let (s, p) = post(&app, "gb-2", "", &renamed).await;
    assert_eq!(s, 422, "{p}");
    assert_eq!(p["type"], "urn:gearwear:problem:clipped-record", "{p}");
    assert!(p["detail"].as_str().unwrap().contains("speed"), "{p}");

    // A machine that names no tachometer: a channel named `tacho` is one, its pulses per
    // revolution from the query (the machine's default is 1).
    let (s, _) = put(
        &app,
        "/v1/machines/plain",
        machine,
        json!({"gearbox": "helical"}),
    )
    .await;
    assert_eq!(s, 201);
    let (s, a) = post(
        &app,
        "plain",
        "?tacho_ppr=10&load=7.5",
        &record(40.0, 106, false, None),
    )
    .await;
    assert_eq!(s, 201, "{a}");
    assert_eq!(a["operating_state"]["load"], 7.5, "{a}");
    assert!(near(&a["operating_state"]["shaft_hz"], 40.0), "{a}");
    // (Sent as healthy: 400 Hz is far outside the table, which refuses any other record.)
    let (s, a) = post(
        &app,
        "plain",
        "?baseline=true",
        &record(40.0, 107, false, None),
    )
    .await;
    assert_eq!(s, 201, "{a}");
    assert!(
        near(&a["operating_state"]["shaft_hz"], 400.0),
        "1 pulse a revolution: {a}"
    );
}
