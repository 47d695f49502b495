//! Group commit (`Store::ingest_batch`, `IngestQueue`) on both stores: a batch is one
//! transaction, yet each record succeeds or fails on its own, and concurrent requests that
//! share a commit are each stored exactly once.

use gearwear::store::queue::IngestQueue;
use gearwear::store::{
    self, DiagnosisRow, GearboxRow, IdemRow, Ingest, MachineConfig, NewRecord, PutOutcome,
    StoreError, TableSpeed, TableText, new_id,
};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    a_failing_record_in_a_batch_fails_alone,
    concurrent_records_share_commits_and_are_each_stored_once,
    idempotency_answers_expire_records_stay,
    a_table_job_is_claimed_once_and_taken_over_after_its_lease,
    a_table_extension_is_claimed_once_and_the_table_stays_ready,
    a_gearbox_put_again_is_unchanged_and_a_new_description_requeues,
    baseline_marks_touch_only_the_machine_s_records,
    a_database_from_before_the_tachometer_keeps_working,
    stored_features_from_before_their_version_read_as_version_one,
);

fn gearbox(id: &str, hash: &str) -> GearboxRow {
    GearboxRow {
        id: id.into(),
        name: id.into(),
        source: "x".into(),
        source_format: "toml".into(),
        description: "{}".into(),
        hash: hash.into(),
        builtin: false,
        status: gearwear::signature::TableStatus::Queued,
        progress: 0.0,
        error: None,
        claimed_by: None,
        lease_until: 0,
        attempts: 0,
        created_at: 1,
        updated_at: 1,
        started_at: None,
        finished_at: None,
        table_columns: None,
        extension: None,
    }
}

fn table_text(json: &str) -> TableText {
    TableText {
        json: json.into(),
        columns: vec![0.5, 0.6],
    }
}

/// An extension of a ready table: queued only when the table is ready and none is pending (a
/// record's speed queues it), claimed by one replica, taken over after its lease; the table
/// stays ready with its old columns until the extension's table replaces it.
async fn a_table_extension_is_claimed_once_and_the_table_stays_ready(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    // A first job that waits for its machines (`lease_until` of a queued job: not before) is
    // not claimed early, unless made due.
    let mut waits = gearbox("gw", "h1");
    waits.lease_until = 5_000;
    st.put_gearbox(&waits).await.unwrap();
    assert!(
        st.claim_gearbox_job(100, 1_000, "A")
            .await
            .unwrap()
            .is_none()
    );
    assert!(st.expedite_gearbox_job("gw").await.unwrap());
    let got = st
        .claim_gearbox_job(100, 1_000, "A")
        .await
        .unwrap()
        .unwrap();
    assert_eq!(got.id, "gw");
    assert!(
        !st.expedite_gearbox_job("gw").await.unwrap(),
        "running: nothing to expedite"
    );
    st.put_gearbox(&gearbox("gx", "h1")).await.unwrap();
    // Not ready yet: nothing to extend.
    assert!(!st.request_extension("gx", "h1", 10).await.unwrap());
    st.claim_gearbox_job(10, 1_000, "A").await.unwrap().unwrap();
    st.finish_gearbox_job("gx", "h1", "A", Ok(table_text("{\"v\":1}")), 20)
        .await
        .unwrap();
    // A record's speed, twice: stored once, the extension queued once.
    let speed = TableSpeed {
        gearbox_id: "gx".into(),
        hash: "h1".into(),
        input_hz: 40.004,
        machine_id: "m".into(),
    };
    st.add_table_speed(&speed, 30).await.unwrap();
    st.add_table_speed(&speed, 31).await.unwrap();
    assert_eq!(st.table_speeds("gx", "h1").await.unwrap(), vec![40.0]);
    assert!(st.table_speeds("gx", "h2").await.unwrap().is_empty());
    let g = st.get_gearbox("gx").await.unwrap().unwrap();
    assert_eq!(g.status.as_str(), "ready");
    assert_eq!(g.table_columns.as_deref(), Some(&[0.5, 0.6][..]));
    assert_eq!(
        g.extension.as_ref().map(|x| x.status.as_str()),
        Some("queued")
    );
    assert!(!st.request_extension("gx", "h1", 32).await.unwrap());
    let (a, bb) = tokio::join!(
        st.claim_extension(100, 1_000, "A"),
        st.claim_extension(100, 1_000, "B")
    );
    let (a, bb) = (a.unwrap(), bb.unwrap());
    assert!(a.is_some() != bb.is_some(), "exactly one claims it");
    let holder = if a.is_some() { "A" } else { "B" };
    let other = if holder == "A" { "B" } else { "A" };
    assert!(
        st.extension_progress("gx", "h1", holder, 0.5, Some(&[0.4, 0.5, 0.6]), 1_100, 200)
            .await
            .unwrap()
    );
    assert!(
        st.claim_extension(900, 1_000, other)
            .await
            .unwrap()
            .is_none()
    );
    let took = st
        .claim_extension(1_200, 1_000, other)
        .await
        .unwrap()
        .unwrap();
    let x = took.extension.unwrap();
    assert_eq!((x.claimed_by.as_deref(), x.attempts), (Some(other), 2));
    assert_eq!(x.columns.as_deref(), Some(&[0.4, 0.5, 0.6][..]));
    // The table is still the first one, ready.
    assert_eq!(
        st.gearbox_table("gx", "h1").await.unwrap().as_deref(),
        Some("{\"v\":1}")
    );
    let wider = TableText {
        json: "{\"v\":2}".into(),
        columns: vec![0.4, 0.5, 0.6],
    };
    assert!(
        !st.finish_extension("gx", "h1", holder, Ok(Some(wider.clone())), 1_300)
            .await
            .unwrap()
    );
    assert!(
        st.finish_extension("gx", "h1", other, Ok(Some(wider)), 1_400)
            .await
            .unwrap()
    );
    let g = st.get_gearbox("gx").await.unwrap().unwrap();
    assert!(g.extension.is_none(), "{:?}", g.extension);
    assert_eq!(g.table_columns.as_deref(), Some(&[0.4, 0.5, 0.6][..]));
    assert_eq!(
        st.gearbox_table("gx", "h1").await.unwrap().as_deref(),
        Some("{\"v\":2}")
    );
    // A failed extension leaves the table, and is queued again by the next request.
    assert!(st.request_extension("gx", "h1", 1_500).await.unwrap());
    st.claim_extension(1_600, 1_000, "A")
        .await
        .unwrap()
        .unwrap();
    assert!(
        st.finish_extension("gx", "h1", "A", Err("too large".into()), 1_700)
            .await
            .unwrap()
    );
    let g = st.get_gearbox("gx").await.unwrap().unwrap();
    let x = g.extension.unwrap();
    assert_eq!(
        (x.status.as_str(), x.error.as_deref()),
        ("failed", Some("too large"))
    );
    assert_eq!(g.status.as_str(), "ready");
    assert!(st.request_extension("gx", "h1", 1_800).await.unwrap());
    // A new description drops its speeds, columns and extension.
    st.put_gearbox(&gearbox("gx", "h2")).await.unwrap();
    let g = st.get_gearbox("gx").await.unwrap().unwrap();
    assert!(g.extension.is_none() && g.table_columns.is_none());
    assert!(st.table_speeds("gx", "h1").await.unwrap().is_empty());
    st.close().await;
}

/// Two replicas racing for one job: exactly one claims it; the other gets it only once the
/// holder's lease ran out, and then the first can no longer report progress or finish it.
async fn a_table_job_is_claimed_once_and_taken_over_after_its_lease(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    assert_eq!(
        st.put_gearbox(&gearbox("gb1", "h1")).await.unwrap(),
        PutOutcome::Created
    );
    let (a, bb) = tokio::join!(
        st.claim_gearbox_job(100, 1_000, "A"),
        st.claim_gearbox_job(100, 1_000, "B")
    );
    let (a, bb) = (a.unwrap(), bb.unwrap());
    assert!(
        a.is_some() != bb.is_some(),
        "exactly one replica claims the job"
    );
    let (holder, other) = if a.is_some() { ("A", "B") } else { ("B", "A") };
    // Within the lease nobody else gets it; progress renews it.
    assert!(
        st.claim_gearbox_job(900, 1_000, other)
            .await
            .unwrap()
            .is_none()
    );
    assert!(
        st.gearbox_progress("gb1", "h1", holder, 0.5, 2_000, 900)
            .await
            .unwrap()
    );
    assert!(
        st.claim_gearbox_job(1_500, 1_000, other)
            .await
            .unwrap()
            .is_none()
    );
    let g = st.get_gearbox("gb1").await.unwrap().unwrap();
    assert_eq!((g.status.as_str(), g.progress), ("running", 0.5));
    // The holder dies: after the lease the other takes the job over.
    let took = st
        .claim_gearbox_job(2_001, 1_000, other)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (took.claimed_by.as_deref(), took.attempts),
        (Some(other), 2)
    );
    assert!(
        !st.gearbox_progress("gb1", "h1", holder, 0.9, 5_000, 2_100)
            .await
            .unwrap()
    );
    assert!(
        !st.finish_gearbox_job("gb1", "h1", holder, Ok(table_text("late")), 2_200)
            .await
            .unwrap()
    );
    assert!(
        st.finish_gearbox_job("gb1", "h1", other, Ok(table_text("{\"t\":1}")), 2_300)
            .await
            .unwrap()
    );
    let g = st.get_gearbox("gb1").await.unwrap().unwrap();
    assert_eq!((g.status.as_str(), g.progress), ("ready", 1.0));
    assert_eq!(
        st.gearbox_table("gb1", "h1").await.unwrap().as_deref(),
        Some("{\"t\":1}")
    );
    assert!(st.gearbox_table("gb1", "other").await.unwrap().is_none());
    // A ready job is not claimed again.
    assert!(
        st.claim_gearbox_job(99_999, 1_000, "C")
            .await
            .unwrap()
            .is_none()
    );
    st.close().await;
}

async fn a_gearbox_put_again_is_unchanged_and_a_new_description_requeues(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    st.put_gearbox(&gearbox("gb2", "h1")).await.unwrap();
    st.claim_gearbox_job(10, 1_000, "A").await.unwrap().unwrap();
    st.finish_gearbox_job("gb2", "h1", "A", Err("boom".into()), 20)
        .await
        .unwrap();
    assert_eq!(
        st.get_gearbox("gb2").await.unwrap().unwrap().status,
        gearwear::signature::TableStatus::Failed
    );
    assert_eq!(
        st.put_gearbox(&gearbox("gb2", "h1")).await.unwrap(),
        PutOutcome::Unchanged
    );
    assert_eq!(
        st.put_gearbox(&gearbox("gb2", "h2")).await.unwrap(),
        PutOutcome::Replaced
    );
    let g = st.get_gearbox("gb2").await.unwrap().unwrap();
    assert_eq!(
        (g.status.as_str(), g.hash.as_str(), g.error),
        ("queued", "h2", None)
    );
    // The built-in one cannot be replaced, and its job is never claimed.
    let mut bi = gearbox("builtin", "hb");
    bi.builtin = true;
    st.ensure_builtin_gearbox(&bi).await.unwrap();
    st.ensure_builtin_gearbox(&bi).await.unwrap();
    assert!(st.put_gearbox(&gearbox("builtin", "other")).await.is_err());
    let g = st.get_gearbox("builtin").await.unwrap().unwrap();
    assert_eq!((g.status.as_str(), g.builtin), ("ready", true));
    let claimed = st.claim_gearbox_job(30, 1_000, "A").await.unwrap().unwrap();
    assert_eq!(claimed.id, "gb2");
    assert_eq!(st.list_gearboxes().await.unwrap().len(), 2);
    st.close().await;
}

async fn baseline_marks_touch_only_the_machine_s_records(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    let mut r1 = ingest("m1", None, 1);
    r1.record.baseline = true;
    let r2 = ingest("m1", None, 2);
    let r3 = ingest("m2", None, 3);
    for r in [&r1, &r2, &r3] {
        st.ingest(r).await.unwrap();
    }
    assert_eq!(st.baseline_records("m1").await.unwrap().len(), 1);
    let ids = vec![r2.record.id.clone(), r3.record.id.clone()];
    assert_eq!(
        st.machine_record_ids("m1", &ids).await.unwrap(),
        vec![r2.record.id.clone()]
    );
    assert_eq!(st.set_baseline("m1", &ids, true, 10).await.unwrap(), 1);
    let b1 = st.baseline_records("m1").await.unwrap();
    assert_eq!(b1.len(), 2);
    assert_eq!(b1[1].baseline_at, Some(10));
    assert!(st.baseline_records("m2").await.unwrap().is_empty());
    assert_eq!(st.clear_baseline("m1").await.unwrap(), 2);
    assert!(st.baseline_records("m1").await.unwrap().is_empty());
    // A machine configured before any record.
    let cfg = MachineConfig {
        id: "m3".into(),
        gearbox_id: Some("gb".into()),
        input_shaft_hz: Some(29.5),
        channels: Some(vec!["a1".into(), "a2".into()]),
        tacho_channel: Some("speed".into()),
        tacho_ppr: 60,
        channel_units: Some(r#"{"a1":{"unit":"V","sensitivity_mv_per_g":100.0}}"#.into()),
        iso_group: Some(2),
        iso_support: Some("rigid".into()),
        speed_range_hz: Some((25.0, 35.0)),
    };
    assert!(st.put_machine(&cfg, 5).await.unwrap());
    assert!(!st.put_machine(&cfg, 6).await.unwrap());
    let m = st.get_machine("m3").await.unwrap().unwrap();
    assert_eq!(m.gearbox_id.as_deref(), Some("gb"));
    assert_eq!(m.channels, Some(vec!["a1".to_string(), "a2".to_string()]));
    assert_eq!(
        (m.tacho_channel.as_deref(), m.tacho_ppr),
        (Some("speed"), 60)
    );
    assert_eq!((m.record_count, m.alert_level.as_str()), (0, "unknown"));
    assert_eq!(m.channel_units, cfg.channel_units);
    assert_eq!(
        (m.iso_group, m.iso_support.as_deref()),
        (Some(2), Some("rigid"))
    );
    assert_eq!(m.speed_range_hz, Some((25.0, 35.0)));
    // A later PUT without units clears them (a configuration is replaced whole).
    let unitless = MachineConfig {
        channel_units: None,
        iso_group: None,
        iso_support: None,
        ..cfg.clone()
    };
    assert!(!st.put_machine(&unitless, 7).await.unwrap());
    let m = st.get_machine("m3").await.unwrap().unwrap();
    assert_eq!(
        (m.channel_units, m.iso_group, m.iso_support),
        (None, None, None)
    );
    st.close().await;
}

async fn idempotency_answers_expire_records_stay(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    let (old, new) = (
        ingest("e1", Some("old"), 1_000),
        ingest("e1", Some("new"), 5_000),
    );
    st.ingest(&old).await.unwrap();
    st.ingest(&new).await.unwrap();
    assert_eq!(st.purge_idempotency(2_000).await.unwrap(), 1);
    assert!(st.get_idempotent("key", "old").await.unwrap().is_none());
    assert!(st.get_idempotent("key", "new").await.unwrap().is_some());
    // Only the answer is forgotten: the record and its diagnosis stay.
    assert!(st.get_diagnosis(&old.diagnosis.id).await.unwrap().is_some());
    assert_eq!(st.get_machine("e1").await.unwrap().unwrap().record_count, 2);
    st.close().await;
}

/// One accepted record of `machine` at time `t` (with `Idempotency-Key` `idem` of key `key`), as
/// the record path writes it; a new machine is made for it.
pub fn ingest(machine: &str, idem: Option<&str>, t: i64) -> Ingest {
    let (rid, did) = (new_id(), new_id());
    Ingest {
        record: NewRecord {
            id: rid.clone(),
            machine_id: machine.into(),
            received_at: t,
            recorded_at: None,
            measured_at: t,
            sensor: None,
            content_type: "application/json".into(),
            sample_rate_hz: 25_600.0,
            shaft_hz: None,
            sample_count: 1,
            sha256: "00".into(),
            features: "{}".into(),
            samples: Some(vec![0, 0, 128, 63]),
            baseline: false,
            channels: None,
        },
        diagnosis: DiagnosisRow {
            seq: 0,
            id: did,
            record_id: rid,
            machine_id: machine.into(),
            created_at: t,
            ea_estimate: 0.5,
            ea_lower: 0.4,
            ea_upper: 0.6,
            alert_level: gearwear::assessment::Level::Ok,
            motion_state: "period-1".into(),
            body: "{}".into(),
            spectrum: "null".into(),
            evidence: "null".into(),
            has_wear: true,
            novelty_score: None,
            novelty_threshold: None,
            channel: None,
            measured_at: t,
            wear_withheld: None,
            reread_status: None,
            reread_request: None,
            replaces: None,
        },
        idempotency: idem.map(|k| IdemRow {
            key_id: "key".into(),
            idem_key: k.into(),
            request_hash: "h".into(),
            status: 201,
            response: "{}".into(),
        }),
        event_extras: Default::default(),
        registered_only: false,
        alert: None,
        table_speed: None,
    }
}

async fn a_failing_record_in_a_batch_fails_alone(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    let batch = vec![
        ingest("g1", Some("k1"), 1),
        ingest("g1", Some("k1"), 2), // the same idempotency key: must fail alone
        ingest("g2", None, 3),
    ];
    let r = st.ingest_batch(&batch).await;
    assert_eq!(r.len(), 3);
    assert!(r[0].is_ok(), "{:?}", r[0]);
    assert!(matches!(r[1], Err(StoreError::Conflict(_))), "{:?}", r[1]);
    assert!(r[2].is_ok(), "{:?}", r[2]);
    // The first and third are stored, the second left nothing behind.
    assert!(
        st.get_diagnosis(&batch[0].diagnosis.id)
            .await
            .unwrap()
            .is_some()
    );
    assert!(
        st.get_diagnosis(&batch[1].diagnosis.id)
            .await
            .unwrap()
            .is_none()
    );
    assert!(
        st.get_diagnosis(&batch[2].diagnosis.id)
            .await
            .unwrap()
            .is_some()
    );
    let g1 = st.get_machine("g1").await.unwrap().unwrap();
    assert_eq!(g1.record_count, 1);
    assert_eq!(
        g1.last_diagnosis_id.as_deref(),
        Some(batch[0].diagnosis.id.as_str())
    );
    st.close().await;
}

async fn concurrent_records_share_commits_and_are_each_stored_once(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let st = store::connect(&db.url).await.unwrap();
    let q = IngestQueue::start(st.clone(), 8);
    let n = 48;
    let all: Vec<Ingest> = (0..n)
        .map(|i| ingest(&format!("c{}", i % 3), Some(&format!("k{i}")), i as i64))
        .collect();
    // Every record twice, concurrently: the second of each pair must be refused as a
    // conflict whichever batch it lands in.
    let mut tasks = Vec::new();
    for ing in all.iter().chain(all.iter()).cloned() {
        let q = q.clone();
        tasks.push(tokio::spawn(async move { q.ingest(ing).await }));
    }
    let mut ok = 0;
    let mut conflicts = 0;
    for t in tasks {
        match t.await.unwrap() {
            Ok(_) => ok += 1,
            Err(StoreError::Conflict(_)) => conflicts += 1,
            Err(e) => panic!("unexpected store error: {e}"),
        }
    }
    assert_eq!((ok, conflicts), (n, n));
    let counts: i64 = st
        .list_machines()
        .await
        .unwrap()
        .iter()
        .map(|m| m.record_count)
        .sum();
    assert_eq!(counts, n as i64);
    for i in 0..n {
        let k = format!("k{i}");
        let stored = st.get_idempotent("key", &k).await.unwrap();
        assert!(stored.is_some(), "{k} missing");
    }
    st.close().await;
}

/// A database migrated before 0004 opens with the new columns' defaults, and its
/// diagnoses stored with a withheld wear figure (`ea_*` written as exactly 0, `has_wear` 1)
/// stop reading as a wear of 0; a real wear figure is left as it was.
async fn a_database_from_before_the_tachometer_keeps_working(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let rows = [
        "INSERT INTO machines (id, created_at, updated_at, gearbox_id, input_shaft_hz) \
         VALUES ('old', 1, 1, NULL, 40.0)",
        "INSERT INTO records (id, machine_id, received_at, content_type, sample_rate_hz, \
         sample_count, sha256, features) VALUES ('r1', 'old', 1, 'text/csv', 20000, 1, '00', '{}')",
        "INSERT INTO diagnoses (id, record_id, machine_id, created_at, ea_estimate, ea_lower, \
         ea_upper, alert_level, motion_state, body, spectrum, has_wear) \
         VALUES ('withheld', 'r1', 'old', 1, 0, 0, 0, 'ok', 'period-1', '{}', 'null', 1)",
        "INSERT INTO diagnoses (id, record_id, machine_id, created_at, ea_estimate, ea_lower, \
         ea_upper, alert_level, motion_state, body, spectrum, has_wear) \
         VALUES ('worn', 'r1', 'old', 2, 0.5, 0.4, 0.6, 'ok', 'period-1', '{}', 'null', 1)",
    ];
    db.migrated_to(3, &rows).await;
    let st = store::connect(&db.url).await.unwrap();
    let m = st.get_machine("old").await.unwrap().unwrap();
    assert_eq!((m.tacho_channel, m.tacho_ppr), (None, 1));
    assert_eq!(m.input_shaft_hz, Some(40.0));
    let ds = st.list_diagnoses("old", 0, i64::MIN, 10).await.unwrap();
    let wear: Vec<(&str, bool)> = ds.iter().map(|d| (d.id.as_str(), d.has_wear)).collect();
    assert_eq!(wear, [("withheld", false), ("worn", true)]);
    assert!(gearwear::views::wear_json(&ds[0]).is_null());
    st.close().await;
}

/// Baseline records stored before the features' layout carried its version (migration 0010)
/// read as the core's `StoredFeatures`, version 1, with their novelty features whole.
async fn stored_features_from_before_their_version_read_as_version_one(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let features = r#"{"gearbox_id":"wang2019","gearbox_hash":"h1","f1_hz":500.0,"omega1":1.0,"lines":[],"channels":{"a1":{"novelty_features":{"values":{"rms":1.5},"indicators":null},"alert_level":"ok"}}}"#;
    let insert = format!(
        "INSERT INTO records (id, machine_id, received_at, content_type, sample_rate_hz, \
         sample_count, sha256, features, baseline) \
         VALUES ('r1', 'old', 1, 'text/csv', 20000, 1, '00', '{features}', 1)"
    );
    let rows = [
        "INSERT INTO machines (id, created_at, updated_at) VALUES ('old', 1, 1)",
        insert.as_str(),
    ];
    db.migrated_to(9, &rows).await;
    let st = store::connect(&db.url).await.unwrap();
    let recs = st.baseline_records("old").await.unwrap();
    assert_eq!(recs.len(), 1);
    let f: gearwear::assessment::StoredFeatures = serde_json::from_str(&recs[0].features).unwrap();
    assert_eq!(f.version, 1);
    assert_eq!(f.gearbox_hash, "h1");
    assert_eq!(f.channels["a1"].novelty_features.values["rms"], 1.5);
    let raw: serde_json::Value = serde_json::from_str(&recs[0].features).unwrap();
    assert_eq!(raw["version"], 1, "the version is written into the row");
    st.close().await;
}
