//! A machine's lifecycle, on both stores: `DELETE /v1/machines/{id}` takes the
//! machine and everything of it and nothing else, tells the webhooks, needs `admin`, and a
//! replayed `Idempotency-Key` after it is a new request; `--require-registered-machines`
//! refuses records of machines that were not PUT (before the diagnosis and inside the
//! record's transaction); `gearwear machine delete`; a database from before migration 0005.

use gearwear::store::{self, CalibrationRow, Ingest, MachineConfig, StoreError, new_id, now_ms};
use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;
use crate::webhooks::{start_receiver, wait_for};

both_stores!(
    deleting_a_machine_takes_everything_of_it_and_nothing_else,
    a_strict_service_takes_records_only_for_registered_machines,
    the_store_refuses_an_unregistered_machine_inside_the_transaction,
    machine_delete_on_the_command_line,
    a_database_from_before_0005_keeps_its_registrations_and_answers,
);

/// POST `body` for `machine` with the ingest key (and `Idempotency-Key` `idem`); the answer.
async fn post(app: &TestApp, machine: &str, query: &str, idem: Option<&str>) -> Value {
    let mut req = app
        .client
        .post(app.url(&format!("/v1/machines/{machine}/records{query}")))
        .bearer_auth(&app.ingest_key)
        .json(&json_record(2));
    if let Some(k) = idem {
        req = req.header("idempotency-key", k);
    }
    let (s, _, body) = checked(req, "POST", "/v1/machines/{machine_id}/records").await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&body));
    json(&body)
}

/// A calibration row written to the store directly (a real calibration simulates for a
/// minute).
async fn calibrate(app: &TestApp, machine: &str) {
    app.store
        .put_calibration(&CalibrationRow {
            machine_id: machine.into(),
            id: new_id(),
            created_at: now_ms(),
            effects: "[]".into(),
            report: json!({"effects": []}).to_string(),
        })
        .await
        .unwrap();
}

async fn delete(app: &TestApp, machine: &str, key: &str) -> (u16, Value) {
    let req = app
        .client
        .delete(app.url(&format!("/v1/machines/{machine}")))
        .bearer_auth(key);
    let (s, _, body) = checked(req, "DELETE", "/v1/machines/{machine_id}").await;
    (
        s,
        if body.is_empty() {
            Value::Null
        } else {
            json(&body)
        },
    )
}

/// `PUT /v1/machines/{machine}` with the admin key; the status.
async fn put_machine(app: &TestApp, machine: &str, config: Value) -> u16 {
    let req = app
        .client
        .put(app.url(&format!("/v1/machines/{machine}")))
        .bearer_auth(&app.admin_key)
        .json(&config);
    checked(req, "PUT", "/v1/machines/{machine_id}").await.0
}

/// The machine's `record_count` in the store; `None` when it has no row.
async fn record_count(app: &TestApp, machine: &str) -> Option<i64> {
    let m = app.store.get_machine(machine).await.unwrap();
    m.map(|m| m.record_count)
}

async fn status_of(app: &TestApp, path: &str) -> u16 {
    app.get(path).await.status().as_u16()
}

async fn deleting_a_machine_takes_everything_of_it_and_nothing_else(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let (rx, url, _t) = start_receiver(0, 0).await;
    let req = app
        .client
        .post(app.url("/v1/webhooks"))
        .bearer_auth(&app.admin_key)
        .json(&json!({"url": url, "events": ["machine.deleted"]}));
    let (s, _, hook) = checked(req, "POST", "/v1/webhooks").await;
    assert_eq!(s, 201, "{}", String::from_utf8_lossy(&hook));
    let hook_id = json(&hook)["id"].as_str().unwrap().to_string();

    // "doomed": configured, three records (one a baseline record, one with an
    // Idempotency-Key), a calibration. "kept": one record with a key, a calibration.
    let config = json!({"gearbox": "wang2019", "input_shaft_hz": 32.1});
    assert_eq!(put_machine(&app, "doomed", config).await, 201);
    let first = post(&app, "doomed", "?baseline=true", None).await;
    let keyed = post(&app, "doomed", "", Some("k-doomed")).await;
    let last = post(&app, "doomed", "", None).await;
    let kept = post(&app, "kept", "", Some("k-kept")).await;
    calibrate(&app, "doomed").await;
    calibrate(&app, "kept").await;
    let doomed_records: Vec<String> = [&first, &keyed, &last]
        .iter()
        .map(|d| d["record_id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(app.store.baseline_records("doomed").await.unwrap().len(), 1);
    let ingest_key_id = gearwear::keys::split_token(&app.ingest_key).unwrap().0;
    assert!(
        app.store
            .get_idempotent(ingest_key_id, "k-doomed")
            .await
            .unwrap()
            .is_some()
    );

    // Read and ingest keys may not delete; nothing changes.
    for key in [&app.read_key, &app.ingest_key] {
        let (s, p) = delete(&app, "doomed", key).await;
        assert_eq!(
            (s, p["required_scope"].as_str()),
            (403, Some("admin")),
            "{p}"
        );
    }
    assert_eq!(record_count(&app, "doomed").await, Some(3));

    let (s, _) = delete(&app, "doomed", &app.admin_key).await;
    assert_eq!(s, 204);

    // Everything of it is gone, through the API and in the store.
    for path in [
        "/v1/machines/doomed".to_string(),
        "/v1/machines/doomed/diagnoses".into(),
        "/v1/machines/doomed/baseline".into(),
        "/v1/machines/doomed/calibration".into(),
        format!("/v1/diagnoses/{}", first["id"].as_str().unwrap()),
        format!("/v1/diagnoses/{}", last["id"].as_str().unwrap()),
    ] {
        assert_eq!(status_of(&app, &path).await, 404, "{path}");
    }
    let fleet = json(&app.get("/v1/machines").await.bytes().await.unwrap());
    let ids: Vec<&str> = fleet["machines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["id"].as_str().unwrap())
        .collect();
    assert_eq!(ids, ["kept"]);
    let st = &app.store;
    assert!(st.get_machine("doomed").await.unwrap().is_none());
    assert!(
        st.machine_record_ids("doomed", &doomed_records)
            .await
            .unwrap()
            .is_empty()
    );
    assert!(st.baseline_records("doomed").await.unwrap().is_empty());
    assert!(st.get_calibration("doomed").await.unwrap().is_none());
    assert!(
        st.get_idempotent(ingest_key_id, "k-doomed")
            .await
            .unwrap()
            .is_none()
    );

    // The other machine is untouched.
    let k = st.get_machine("kept").await.unwrap().unwrap();
    assert_eq!(k.record_count, 1);
    assert_eq!(k.last_diagnosis_id.as_deref(), kept["id"].as_str());
    assert!(st.get_calibration("kept").await.unwrap().is_some());
    assert!(
        st.get_idempotent(ingest_key_id, "k-kept")
            .await
            .unwrap()
            .is_some()
    );
    let path = format!("/v1/diagnoses/{}", kept["id"].as_str().unwrap());
    assert_eq!(status_of(&app, &path).await, 200);

    // The webhook got `machine.deleted` with what went; the delivery log matches the spec.
    wait_for("the machine.deleted delivery", || {
        !rx.got.lock().unwrap().is_empty()
    })
    .await;
    let (headers, body) = rx.got.lock().unwrap()[0].clone();
    assert_eq!(headers["gearwear-event"], "machine.deleted");
    let ev: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(ev["event"], "machine.deleted");
    assert_eq!(ev["machine_id"], "doomed");
    assert_eq!(
        (ev["records"].as_u64(), ev["diagnoses"].as_u64()),
        (Some(3), Some(3))
    );
    assert_eq!(ev["calibration"], true);
    assert_eq!(ev["alert_level"], last["alert_level"]);
    let req = app
        .client
        .get(app.url(&format!("/v1/webhooks/{hook_id}/deliveries")))
        .bearer_auth(&app.admin_key);
    let (s, _, log) = checked(req, "GET", "/v1/webhooks/{webhook_id}/deliveries").await;
    assert_eq!(s, 200);
    assert_eq!(json(&log)["deliveries"][0]["event"], "machine.deleted");

    // A second DELETE finds nothing: 404, and nothing is announced again.
    let (s, p) = delete(&app, "doomed", &app.admin_key).await;
    assert_eq!(
        (s, p["type"].as_str()),
        (404, Some("urn:gearwear:problem:unknown-machine"))
    );
    let deliveries = st.list_deliveries(&hook_id, 10).await.unwrap();
    assert_eq!(deliveries.len(), 1);

    // The deleted record's Idempotency-Key is a new request now: stored and diagnosed anew for
    // a new, empty machine, not answered with the deleted diagnosis.
    let again = app
        .client
        .post(app.url("/v1/machines/doomed/records"))
        .bearer_auth(&app.ingest_key)
        .header("idempotency-key", "k-doomed")
        .json(&json_record(2))
        .send()
        .await
        .unwrap();
    assert_eq!(again.status(), 201);
    assert!(again.headers().get("idempotent-replayed").is_none());
    let again = json(&again.bytes().await.unwrap());
    assert_ne!(again["id"], keyed["id"]);
    let m = st.get_machine("doomed").await.unwrap().unwrap();
    assert_eq!((m.record_count, m.registered_at), (1, None));
}

async fn a_strict_service_takes_records_only_for_registered_machines(b: Backend) {
    let Some(app) = spawn_app(b, |s| s.require_registered_machines = true).await else {
        return;
    };
    // A machine that exists only through records (posted before the service turned strict).
    app.store
        .ingest(&crate::store::ingest("legacy", None, 1))
        .await
        .unwrap();

    for machine in ["typo-7", "legacy"] {
        let req = app
            .client
            .post(app.url(&format!("/v1/machines/{machine}/records")))
            .bearer_auth(&app.ingest_key)
            .header("idempotency-key", format!("strict-{machine}"))
            .json(&json_record(2));
        let (s, _, body) = checked(req, "POST", "/v1/machines/{machine_id}/records").await;
        let p = json(&body);
        assert_eq!(s, 404, "{p}");
        assert_eq!(p["type"], "urn:gearwear:problem:unknown-machine");
        assert_eq!(p["machine_id"], machine);
        let detail = p["detail"].as_str().unwrap();
        assert!(
            detail.contains(&format!("PUT /v1/machines/{machine}"))
                && detail.contains("nothing was stored"),
            "{detail}"
        );
    }
    // A calibration for a machine nobody registered is refused the same way.
    let req = app
        .client
        .post(app.url("/v1/machines/typo-7/calibration"))
        .bearer_auth(&app.admin_key)
        .json(&json_record(2));
    let (s, _, body) = checked(req, "POST", "/v1/machines/{machine_id}/calibration").await;
    assert_eq!(s, 404, "{}", json(&body));
    assert_eq!(json(&body)["type"], "urn:gearwear:problem:unknown-machine");
    assert!(app.store.get_calibration("typo-7").await.unwrap().is_none());
    // Nothing stored: no machine made, the old one as it was, no idempotent answer kept.
    assert!(app.store.get_machine("typo-7").await.unwrap().is_none());
    assert_eq!(record_count(&app, "legacy").await, Some(1));
    let key_id = gearwear::keys::split_token(&app.ingest_key).unwrap().0;
    assert!(
        app.store
            .get_idempotent(key_id, "strict-typo-7")
            .await
            .unwrap()
            .is_none()
    );
    let fleet = json(&app.get("/v1/machines").await.bytes().await.unwrap());
    assert_eq!(fleet["machines"].as_array().unwrap().len(), 1, "{fleet}");
    assert!(fleet["machines"][0]["registered_at"].is_null(), "{fleet}");

    // Registered with a PUT: its records are taken; a machine registered this way keeps its
    // registration time across PUTs.
    for machine in ["press-1", "legacy"] {
        let s = put_machine(&app, machine, json!({"gearbox": "wang2019"})).await;
        assert!(s == 200 || s == 201, "{s}");
        let d = post(&app, machine, "", None).await;
        assert_eq!(d["machine_id"], machine);
    }
    let registered = app.store.get_machine("press-1").await.unwrap().unwrap();
    let when = registered.registered_at.expect("registered");
    assert_eq!(registered.record_count, 1);
    let (s, _, body) = checked(
        app.client
            .get(app.url("/v1/machines/press-1"))
            .bearer_auth(&app.read_key),
        "GET",
        "/v1/machines/{machine_id}",
    )
    .await;
    assert_eq!(s, 200);
    assert_eq!(json(&body)["registered_at"], gearwear::time::rfc3339(when));
    let config = json!({"gearbox": "wang2019", "input_shaft_hz": 31.0});
    assert_eq!(put_machine(&app, "press-1", config).await, 200);
    let again = app.store.get_machine("press-1").await.unwrap().unwrap();
    assert_eq!(again.registered_at, Some(when));
    assert_eq!(record_count(&app, "legacy").await, Some(2));

    // Deleted, it is not registered any more: its records are refused again.
    let (s, _) = delete(&app, "press-1", &app.admin_key).await;
    assert_eq!(s, 204);
    let r = app
        .client
        .post(app.url("/v1/machines/press-1/records"))
        .bearer_auth(&app.ingest_key)
        .json(&json_record(2))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    assert!(app.store.get_machine("press-1").await.unwrap().is_none());
}

/// The store's own check, which holds when the machine is deleted between the service's check
/// and the commit: a record written with `registered_only` for a machine that is not
/// registered stores nothing (alone in a batch, the others stored).
async fn the_store_refuses_an_unregistered_machine_inside_the_transaction(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    st.put_machine(
        &MachineConfig {
            id: "reg".into(),
            gearbox_id: None,
            input_shaft_hz: None,
            channels: None,
            tacho_channel: None,
            tacho_ppr: 1,
            channel_units: None,
            iso_group: None,
            iso_support: None,
            speed_range_hz: None,
        },
        5,
    )
    .await
    .unwrap();
    let strict = |m: &str, idem: Option<&str>, t| -> Ingest {
        let mut i = crate::store::ingest(m, idem, t);
        i.registered_only = true;
        i
    };
    let batch = vec![
        strict("reg", Some("a"), 10),
        strict("stray", Some("b"), 11),
        strict("reg", None, 12),
    ];
    let r = st.ingest_batch(&batch).await;
    assert!(r[0].is_ok() && r[2].is_ok(), "{r:?}");
    assert!(
        matches!(&r[1], Err(StoreError::UnregisteredMachine(m)) if m == "stray"),
        "{:?}",
        r[1]
    );
    assert!(st.get_machine("stray").await.unwrap().is_none());
    assert!(st.get_idempotent("key", "b").await.unwrap().is_none());
    assert!(
        st.get_diagnosis(&batch[1].diagnosis.id)
            .await
            .unwrap()
            .is_none()
    );
    let reg = st.get_machine("reg").await.unwrap().unwrap();
    assert_eq!((reg.record_count, reg.registered_at), (2, Some(5)));
    // Deleted between a check and the commit: the record does not bring it back.
    assert!(st.delete_machine("reg", 20).await.unwrap().is_some());
    assert!(matches!(
        st.ingest(&strict("reg", None, 21)).await,
        Err(StoreError::UnregisteredMachine(_))
    ));
    assert!(st.get_machine("reg").await.unwrap().is_none());
    st.close().await;
}

async fn machine_delete_on_the_command_line(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    for t in [1, 2] {
        let ing = crate::store::ingest("line-3", Some(&format!("cli-{t}")), t);
        st.ingest(&ing).await.unwrap();
    }
    st.ingest(&crate::store::ingest("line-4", None, 3))
        .await
        .unwrap();
    st.close().await;
    let out = gearwear_bin()
        .args(["machine", "delete", "line-3", "--database-url", &db.url])
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stderr}");
    let v: Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(
        v,
        json!({"id": "line-3", "deleted": true, "records": 2, "diagnoses": 2, "calibration": false})
    );
    assert!(stderr.contains("deleted machine `line-3`"), "{stderr}");
    // Again: nothing there, an error naming the database.
    let out = gearwear_bin()
        .args(["machine", "delete", "line-3", "--database-url", &db.url])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no machine `line-3`"), "{err}");
    let shown = gearwear::database::describe(&db.url);
    assert!(err.contains(&shown), "{err}");
    // A bad id is refused before the database is opened.
    let out = gearwear_bin()
        .args(["machine", "delete", "no/such", "--database-url", &db.url])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let st = store::connect(&db.url).await.unwrap();
    assert!(st.get_machine("line-3").await.unwrap().is_none());
    assert!(st.get_idempotent("key", "cli-1").await.unwrap().is_none());
    assert_eq!(
        st.get_machine("line-4")
            .await
            .unwrap()
            .unwrap()
            .record_count,
        1
    );
    st.close().await;
}

/// A database migrated up to 0004: a machine configured away from the defaults counts as
/// registered, one made by records does not, and the answers stored for idempotency keys
/// learn their machine (so deleting it deletes them).
async fn a_database_from_before_0005_keeps_its_registrations_and_answers(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let answer = |m: &str| {
        json!({"id": "d", "machine_id": m, "record_id": "r", "alert_level": "ok",
               "channels": [{"name": "x"}]})
        .to_string()
        .replace('\'', "''")
    };
    let rows = [
        "INSERT INTO machines (id, created_at, updated_at, input_shaft_hz) \
         VALUES ('configured', 7, 9, 40.0)"
            .to_string(),
        "INSERT INTO machines (id, created_at, updated_at, tacho_ppr) VALUES ('tacho', 8, 9, 10)"
            .into(),
        "INSERT INTO machines (id, created_at, updated_at) VALUES ('by-records', 1, 9)".into(),
        format!(
            "INSERT INTO idempotency_keys (key_id, idem_key, request_hash, status, response, \
             created_at) VALUES ('key', 'old', 'h', 201, '{}', 1)",
            answer("by-records")
        ),
        "INSERT INTO idempotency_keys (key_id, idem_key, request_hash, status, response, \
         created_at) VALUES ('key', 'junk', 'h', 201, 'not json', 1)"
            .into(),
    ];
    let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
    db.migrated_to(4, &rows).await;
    let st = store::connect(&db.url).await.unwrap();
    let reg = |id: &'static str| {
        let st = st.clone();
        async move { st.get_machine(id).await.unwrap().unwrap().registered_at }
    };
    assert_eq!(reg("configured").await, Some(7));
    assert_eq!(reg("tacho").await, Some(8));
    assert_eq!(reg("by-records").await, None);
    let gone = st.delete_machine("by-records", 10).await.unwrap().unwrap();
    assert_eq!(gone.idempotency_answers, 1);
    assert!(st.get_idempotent("key", "old").await.unwrap().is_none());
    assert!(st.get_idempotent("key", "junk").await.unwrap().is_some());
    st.close().await;
}
