//! Group commit (`Store::ingest_batch`, `IngestQueue`) on both stores: a batch is one
//! transaction, yet each record succeeds or fails on its own, and concurrent requests that
//! share a commit are each stored exactly once.

use gearwear::store::queue::IngestQueue;
use gearwear::store::{self, DiagnosisRow, IdemRow, Ingest, NewRecord, StoreError, new_id};

use crate::both_stores;
use crate::helpers::*;

both_stores!(
    a_failing_record_in_a_batch_fails_alone,
    concurrent_records_share_commits_and_are_each_stored_once,
    idempotency_answers_expire_records_stay,
);

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

fn ingest(machine: &str, idem: Option<&str>, t: i64) -> Ingest {
    let (rid, did) = (new_id(), new_id());
    Ingest {
        record: NewRecord {
            id: rid.clone(),
            machine_id: machine.into(),
            received_at: t,
            recorded_at: None,
            sensor: None,
            content_type: "application/json".into(),
            sample_rate_hz: 25_600.0,
            shaft_hz: None,
            sample_count: 1,
            sha256: "00".into(),
            features: "{}".into(),
            samples: Some(vec![0, 0, 128, 63]),
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
            alert_level: "ok".into(),
            motion_state: "period-1".into(),
            body: "{}".into(),
            spectrum: "null".into(),
        },
        idempotency: idem.map(|k| IdemRow {
            key_id: "key".into(),
            idem_key: k.into(),
            request_hash: "h".into(),
            status: 201,
            response: "{}".into(),
        }),
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
            Ok(()) => ok += 1,
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
