//! The machine's own model in the service, on both stores: a simulated machine — the
//! two-stage parallel reducer built with stiffer, less damped meshes than its description
//! says, seen through a housing mode — posts six healthy records at three speeds; its own
//! model (physics fitted to the records' line ratios, then its own table) is computed in the
//! background and shown under the baseline's `physics`; once it is ready the machine's records
//! are read against it (their warnings say so). A refusal by the core is an outcome too: then
//! it says why and the records are read as before.

use std::time::{Duration, Instant};

use serde_json::{Value, json};

use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
use gearwear::gearbox::{Gearbox, PhysicsFactors, StageFactors};

use crate::both_stores;
use crate::helpers::*;

both_stores!(a_machine_s_own_model_is_fitted_in_the_background_and_reads_its_records);

const TWO_STAGE: &str = include_str!("../../configs/gearboxes/two-stage-parallel.toml");
/// The warning a reading against the machine's own model carries.
const OWN_MODEL: &str = "wear read against the machine's own model";

/// The machine: the description with its own physics, per stage.
fn machine(gb: &Gearbox) -> Gearbox {
    let stage = StageFactors {
        stiffness: 1.35,
        damping: 0.6,
        ..Default::default()
    };
    gb.with_factors(&PhysicsFactors {
        stages: vec![stage; gb.topology.stages.len()],
        ..Default::default()
    })
    .unwrap()
}

/// A 1 s record of the machine at input rate `hz` and wear `ea`, through a peaking path mode
/// at 1.3 × the description's reference frequency, as a JSON body.
fn record(gb: &Gearbox, m: &Gearbox, hz: f64, ea: f64, seed: u64) -> Value {
    let f1 = gb.f1_hz(hz);
    let r = generate(
        m,
        &RigSpec {
            ea,
            omega1: f1 / m.reference_frequency_hz(),
            sample_rate: 25_600.0,
            duration: 1.0,
            gain: 37.0,
            snr_db: 25.0,
            seed,
            effects: RigEffects {
                path_peak: Some((1.3 * gb.reference_frequency_hz() / f1, 0.05, 5.0)),
                ..Default::default()
            },
        },
    )
    .unwrap();
    json!({"sample_rate_hz": r.sample_rate, "samples": r.samples})
}

async fn post(app: &TestApp, query: &str, body: &Value) -> Value {
    let (s, _, b) = checked(
        app.client
            .post(app.url(&format!("/v1/machines/m/records{query}")))
            .bearer_auth(&app.ingest_key)
            .json(body),
        "POST",
        "/v1/machines/{machine_id}/records",
    )
    .await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&b));
    json(&b)
}

async fn baseline(app: &TestApp) -> Value {
    let (s, _, b) = checked(
        app.client
            .get(app.url("/v1/machines/m/baseline"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}/baseline",
    )
    .await;
    assert_eq!(s, 200);
    json(&b)
}

fn warned(d: &Value) -> bool {
    d["warnings"].as_array().is_some_and(|w| {
        w.iter()
            .any(|w| w.as_str().is_some_and(|w| w.starts_with(OWN_MODEL)))
    })
}

async fn a_machine_s_own_model_is_fitted_in_the_background_and_reads_its_records(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    assert_eq!(put_gearbox(&app, "two", TWO_STAGE).await, 201);
    let (s, _) = put_machine(&app, "m", json!({"gearbox": "two", "input_shaft_hz": 30.0})).await;
    assert_eq!(s, 201);
    crate::tables::wait_gearbox(&app, "two", "its table", Duration::from_secs(120), |g| {
        crate::tables::covers(g, 25.5, 34.5)
    })
    .await;
    let gb = Gearbox::parse(TWO_STAGE, "test").unwrap();
    let m = machine(&gb);
    // Nothing to fit yet.
    assert_eq!(baseline(&app).await["physics"], Value::Null);

    // Six healthy records at three speeds.
    let mut seed = 700;
    for hz in [26.4, 30.0, 33.6] {
        for _ in 0..2 {
            seed += 1;
            let a = post(
                &app,
                &format!("?baseline=true&shaft_hz={hz}"),
                &record(&gb, &m, hz, 0.1, seed),
            )
            .await;
            assert!(!warned(&a), "no own model yet: {a}");
        }
    }
    // Its own model: fitted and tabled in the background, its progress shown.
    let t0 = Instant::now();
    let mut seen = Vec::new();
    let physics = loop {
        let p = baseline(&app).await["physics"].clone();
        let status = p["status"].as_str().unwrap_or("none").to_string();
        if !seen.contains(&status) {
            eprintln!(
                "{b:?}: physics {status} after {:.1} s",
                t0.elapsed().as_secs_f64()
            );
            seen.push(status.clone());
        }
        match status.as_str() {
            "ready" | "refused" if p["current"] == true => break p,
            "failed" => panic!("{p}"),
            _ => {}
        }
        assert!(t0.elapsed() < Duration::from_secs(300), "not done: {p}");
        tokio::time::sleep(Duration::from_millis(500)).await;
    };
    let a = post(&app, "?shaft_hz=30", &record(&gb, &m, 30.0, 0.5, 900)).await;
    match physics["status"].as_str() {
        Some("ready") => {
            let r = &physics["report"];
            assert_eq!(r["parameters"][0]["name"], "stage 1 stiffness", "{r}");
            assert!(
                r["left_out_db"].as_f64().unwrap() < r["yardstick_db"].as_f64().unwrap(),
                "{r}"
            );
            assert_eq!(r["records"], 6, "{r}");
            assert_eq!(physics["progress"], 1.0, "{physics}");
            eprintln!(
                "{b:?}: stage-1 stiffness {:.2} (90 % {:.2}–{:.2}), left out {:.1} dB against {:.1} dB; \
                 a record at ea 0.5 read {}",
                r["parameters"][0]["value"].as_f64().unwrap(),
                r["parameters"][0]["lower"].as_f64().unwrap(),
                r["parameters"][0]["upper"].as_f64().unwrap(),
                r["left_out_db"].as_f64().unwrap(),
                r["yardstick_db"].as_f64().unwrap(),
                a["wear_degree"]
            );
            assert!(warned(&a), "read against its own model: {a}");
        }
        Some("refused") => {
            let why = physics["error"].as_str().unwrap();
            assert!(!why.is_empty(), "{physics}");
            eprintln!("{b:?}: refused: {why}");
            assert!(!warned(&a), "{a}");
        }
        other => panic!("{other:?}"),
    }
}
