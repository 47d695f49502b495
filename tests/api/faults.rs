//! Faults: the real binary killed with SIGKILL in the middle of concurrent ingests,
//! and PostgreSQL going away while the service runs (through a [`CutProxy`], so the shared
//! database is never stopped). Webhook receivers that are down: `webhooks.rs`.
//!
//! `kill9_long` (ignored) is the longer run `scripts/fault_kill9.sh` drives; it prints the
//! figures recorded in `docs/reliability/faults.md`.

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;
use sha2::{Digest, Sha256};

use crate::helpers::*;

// ---------------------------------------------------------------------------------------------
// kill -9 in the middle of concurrent ingests
// ---------------------------------------------------------------------------------------------

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn kill9_mid_ingest_sqlite() {
    kill9_test(Backend::Sqlite).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn kill9_mid_ingest_postgres() {
    kill9_test(Backend::Postgres).await
}

/// 48 records from 4 concurrent clients, one SIGKILL once 12 of them got their 201.
async fn kill9_test(b: Backend) {
    let Some(db) = TestDb::new(b).await else {
        return;
    };
    let f = kill9_run(
        &db.url,
        b,
        &Kill9Plan {
            records: 48,
            clients: 4,
            kills: 1,
        },
    )
    .await;
    f.print(&format!("kill9_mid_ingest_{b:?}"));
    f.assert_sound();
}

/// The long run of `scripts/fault_kill9.sh`: sizes from the environment
/// (`GEARWEAR_FAULT_RECORDS`, `_CLIENTS`, `_KILLS`, `_BACKEND` = sqlite | postgres).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
#[ignore = "long; run by scripts/fault_kill9.sh"]
async fn kill9_long() {
    let env = |k: &str, d: usize| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let b = match std::env::var("GEARWEAR_FAULT_BACKEND").as_deref() {
        Ok("postgres") => Backend::Postgres,
        _ => Backend::Sqlite,
    };
    let plan = Kill9Plan {
        records: env("GEARWEAR_FAULT_RECORDS", 2000),
        clients: env("GEARWEAR_FAULT_CLIENTS", 8),
        kills: env("GEARWEAR_FAULT_KILLS", 5),
    };
    let Some(db) = TestDb::new(b).await else {
        panic!("no database for {b:?}");
    };
    let f = kill9_run(&db.url, b, &plan).await;
    f.print(&format!("kill9_long_{b:?}"));
    f.assert_sound();
}

/// How big a kill -9 run is.
struct Kill9Plan {
    records: usize,
    clients: usize,
    /// SIGKILLs in the middle of ingests (a last one follows, with the service idle, before
    /// the file is checked).
    kills: usize,
}

/// What a kill -9 run measured.
#[derive(Debug, Default)]
struct Kill9Figures {
    records: usize,
    clients: usize,
    kills: usize,
    /// POSTs sent, all phases.
    requests: usize,
    /// 201 answers that created the record.
    created: usize,
    /// 201 answers replayed from an `Idempotency-Key`.
    replayed: usize,
    /// Requests without an HTTP answer (in flight at a kill, or refused while down).
    no_answer: usize,
    /// Client requests in flight at the moments of the kills (sum).
    in_flight_at_kills: usize,
    /// Records committed before a kill whose client never saw the answer: the re-send was
    /// a replay.
    committed_unanswered: usize,
    /// Re-sends of records that already had a 201 (all must replay the same diagnosis).
    resent_answered: usize,
    /// ... of which answered with the original diagnosis id and `idempotent-replayed`.
    resent_same_answer: usize,
    /// Answers other than 201 (none expected), and their statuses.
    other_status: usize,
    other_statuses: Vec<u16>,
    /// Records with a 201 (by the id in that answer) found after the last restart.
    present_after_restart: usize,
    /// Records with a 201 read back over the API (`GET /v1/diagnoses/{id}`) after restart.
    readable_after_restart: usize,
    /// Rows in the store after the run.
    stored_records: usize,
    stored_diagnoses: usize,
    stored_idempotency_keys: usize,
    /// Rows beyond one per request body (SHA-256) or per idempotency key.
    duplicates: usize,
    /// `PRAGMA integrity_check` + `foreign_key_check` (SQLite) or amcheck (PostgreSQL).
    integrity: String,
    seconds: f64,
}

impl Kill9Figures {
    fn print(&self, name: &str) {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(
            out,
            "FIGURES {name}: {} records from {} clients, {} kills mid-ingest",
            self.records, self.clients, self.kills
        );
        let _ = writeln!(out, "{self:#?}");
    }

    fn assert_sound(&self) {
        assert_eq!(self.other_status, 0, "answers other than 201: {self:#?}");
        assert!(
            self.in_flight_at_kills >= self.kills,
            "every kill should land with requests in flight: {self:#?}"
        );
        assert!(self.no_answer >= 1, "no request lost its answer: {self:#?}");
        assert!(
            self.resent_answered >= 1,
            "answered records were re-sent: {self:#?}"
        );
        assert_eq!(
            self.resent_same_answer, self.resent_answered,
            "a re-sent record got a different answer: {self:#?}"
        );
        assert_eq!(
            self.present_after_restart, self.records,
            "a record that got a 201 is missing: {self:#?}"
        );
        assert_eq!(self.readable_after_restart, self.records, "{self:#?}");
        assert_eq!(self.duplicates, 0, "a record stored twice: {self:#?}");
        assert_eq!(self.stored_records, self.records, "{self:#?}");
        assert_eq!(self.stored_diagnoses, self.records, "{self:#?}");
        assert_eq!(self.stored_idempotency_keys, self.records, "{self:#?}");
        assert_eq!(self.integrity, "ok", "{self:#?}");
    }
}

/// The body of record `i` (raw f32, 1 s at 25.6 kHz, a different noise seed per record).
fn f32_body(i: usize) -> Vec<u8> {
    let (x, _) = record_samples(1.07, 1.0, 10_000 + i as u64);
    x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect()
}

/// A `gearwear serve` process.
struct Server {
    child: Child,
    base: String,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Start the binary on a free loopback port and wait for `/readyz`.
async fn start_server(db_url: &str, log: &Path, client: &reqwest::Client) -> Server {
    for _ in 0..5 {
        let port = free_port();
        let out = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .unwrap();
        let child = gearwear_bin()
            .args([
                "serve",
                "--address",
                &format!("127.0.0.1:{port}"),
                "--database-url",
                db_url,
                "--allow-stale-table",
                "--rate-per-second",
                "100000",
                "--rate-burst",
                "100000",
            ])
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(out.try_clone().unwrap())
            .stderr(out)
            .spawn()
            .expect("start gearwear serve");
        let mut s = Server {
            child,
            base: format!("http://127.0.0.1:{port}"),
        };
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(60) {
            if let Ok(Some(_)) = s.child.try_wait() {
                break; // port taken meanwhile, or a start-up failure: see the log
            }
            if let Ok(r) = client.get(format!("{}/readyz", s.base)).send().await
                && r.status() == 200
            {
                return s;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let _ = s.child.kill();
        let _ = s.child.wait();
    }
    panic!(
        "gearwear serve did not become ready; log:\n{}",
        std::fs::read_to_string(log).unwrap_or_default()
    );
}

/// SIGKILL (`Child::kill` is SIGKILL on Unix) and reap.
fn kill9(s: &mut Server) {
    s.child.kill().expect("SIGKILL");
    let _ = s.child.wait();
}

/// A 201's ids, or why there was none.
#[derive(Debug, Clone)]
enum Outcome {
    Created {
        diagnosis_id: String,
        record_id: String,
        replayed: bool,
    },
    Status(u16),
    NoAnswer,
}

async fn post_record(
    client: &reqwest::Client,
    base: &str,
    key: &str,
    run: &str,
    i: usize,
) -> Outcome {
    let r = client
        .post(format!(
            "{base}/v1/machines/kill9-{}/records?sample_rate_hz=25600",
            i % 3
        ))
        .bearer_auth(key)
        .header("content-type", "application/octet-stream")
        .header("idempotency-key", format!("{run}-{i}"))
        .body(f32_body(i))
        .send()
        .await;
    let Ok(r) = r else {
        return Outcome::NoAnswer;
    };
    let status = r.status().as_u16();
    let replayed = r
        .headers()
        .get("idempotent-replayed")
        .is_some_and(|v| v == "true");
    let Ok(body) = r.bytes().await else {
        return Outcome::NoAnswer;
    };
    if status != 201 {
        eprintln!("record {i}: {status} {}", String::from_utf8_lossy(&body));
        return Outcome::Status(status);
    }
    let v: Value = serde_json::from_slice(&body).expect("a 201 is JSON");
    Outcome::Created {
        diagnosis_id: v["id"].as_str().unwrap().to_string(),
        record_id: v["record_id"].as_str().unwrap().to_string(),
        replayed,
    }
}

/// Start, stream records from `clients` tasks, SIGKILL after a share of 201s while requests
/// are in flight, restart on the same database, re-send what got no answer (and some that
/// did), `kills` times; then a last phase without a kill, a last idle SIGKILL, and the checks.
async fn kill9_run(db_url: &str, b: Backend, plan: &Kill9Plan) -> Kill9Figures {
    let started = Instant::now();
    let dir =
        std::env::temp_dir().join(format!("gearwear-kill9-{}", uuid::Uuid::new_v4().simple()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("serve.log");
    let run = uuid::Uuid::new_v4().simple().to_string();
    let n = plan.records;
    let shas: Vec<String> = (0..n)
        .map(|i| hex::encode(Sha256::digest(f32_body(i))))
        .collect();

    // The key: the binary, as an operator would.
    let key = cli_key(db_url, "ingest,read");

    // No pooled connections and a timeout: a hung request fails the run instead of hanging it.
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap();
    let mut f = Kill9Figures {
        records: n,
        clients: plan.clients,
        kills: plan.kills,
        ..Default::default()
    };
    let mut first: HashMap<usize, (String, String)> = HashMap::new();
    for phase in 0..=plan.kills {
        let mut server = start_server(db_url, &log, &client).await;
        // This phase: everything without an answer, and every fifth answered record again.
        let work: Vec<usize> = (0..n)
            .filter(|i| !first.contains_key(i) || (phase > 0 && i % 5 == phase % 5))
            .collect();
        let kill_after = if phase < plan.kills {
            (n / (plan.kills + 1)).max(1)
        } else {
            usize::MAX
        };
        let work = Arc::new(work);
        let next = Arc::new(AtomicUsize::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let in_flight = Arc::new(AtomicUsize::new(0));
        let created = Arc::new(AtomicUsize::new(0));
        let results = Arc::new(Mutex::new(Vec::<(usize, Outcome)>::new()));
        let mut tasks = Vec::new();
        for _ in 0..plan.clients {
            let (work, next, stop, in_flight, created, results) = (
                work.clone(),
                next.clone(),
                stop.clone(),
                in_flight.clone(),
                created.clone(),
                results.clone(),
            );
            let (client, base, key, run) = (
                client.clone(),
                server.base.clone(),
                key.clone(),
                run.clone(),
            );
            tasks.push(tokio::spawn(async move {
                loop {
                    if stop.load(Ordering::SeqCst) {
                        break;
                    }
                    let j = next.fetch_add(1, Ordering::SeqCst);
                    let Some(&i) = work.get(j) else { break };
                    in_flight.fetch_add(1, Ordering::SeqCst);
                    let o = post_record(&client, &base, &key, &run, i).await;
                    in_flight.fetch_sub(1, Ordering::SeqCst);
                    if matches!(o, Outcome::Created { .. }) {
                        created.fetch_add(1, Ordering::SeqCst);
                    }
                    results.lock().unwrap().push((i, o));
                }
            }));
        }
        if kill_after != usize::MAX {
            // Kill once enough 201s came back, at a moment with requests in flight.
            loop {
                let done = next.load(Ordering::SeqCst) >= work.len();
                if (created.load(Ordering::SeqCst) >= kill_after || done)
                    && in_flight.load(Ordering::SeqCst) > 0
                {
                    break;
                }
                if done && in_flight.load(Ordering::SeqCst) == 0 {
                    break;
                }
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
            f.in_flight_at_kills += in_flight.load(Ordering::SeqCst);
            kill9(&mut server);
            stop.store(true, Ordering::SeqCst);
        }
        for t in tasks {
            t.await.unwrap();
        }
        if kill_after == usize::MAX {
            kill9(&mut server); // idle: the state a crash leaves is what gets checked
        }
        for (i, o) in results.lock().unwrap().drain(..) {
            f.requests += 1;
            match o {
                Outcome::NoAnswer => f.no_answer += 1,
                Outcome::Status(s) => {
                    f.other_status += 1;
                    f.other_statuses.push(s);
                }
                Outcome::Created {
                    diagnosis_id,
                    record_id,
                    replayed,
                } => {
                    if replayed {
                        f.replayed += 1;
                    } else {
                        f.created += 1;
                    }
                    match first.get(&i) {
                        Some((d, _)) => {
                            f.resent_answered += 1;
                            if replayed && *d == diagnosis_id {
                                f.resent_same_answer += 1;
                            }
                        }
                        None => {
                            if replayed {
                                f.committed_unanswered += 1;
                            }
                            first.insert(i, (diagnosis_id, record_id));
                        }
                    }
                }
            }
        }
    }

    // Every answered record over the API after one more restart.
    {
        let mut server = start_server(db_url, &log, &client).await;
        for (d, r) in first.values() {
            let resp = client
                .get(format!("{}/v1/diagnoses/{d}", server.base))
                .bearer_auth(&key)
                .send()
                .await
                .unwrap();
            if resp.status() == 200 {
                let v: Value = resp.json().await.unwrap();
                if v["record_id"].as_str() == Some(r.as_str()) {
                    f.readable_after_restart += 1;
                }
            }
        }
        kill9(&mut server);
    }

    // The store itself.
    let facts = store_facts(db_url, b).await;
    let records: HashMap<&str, &str> = facts
        .records
        .iter()
        .map(|(id, sha)| (id.as_str(), sha.as_str()))
        .collect();
    let diagnoses: HashMap<&str, &str> = facts
        .diagnoses
        .iter()
        .map(|(id, r)| (id.as_str(), r.as_str()))
        .collect();
    for (i, (d, r)) in &first {
        if diagnoses.get(d.as_str()) == Some(&r.as_str())
            && records.get(r.as_str()) == Some(&shas[*i].as_str())
        {
            f.present_after_restart += 1;
        }
    }
    let mut per_sha: HashMap<&str, usize> = HashMap::new();
    for (_, sha) in &facts.records {
        *per_sha.entry(sha).or_default() += 1;
    }
    let mut per_key: HashMap<&str, usize> = HashMap::new();
    for k in &facts.idempotency_keys {
        *per_key.entry(k).or_default() += 1;
    }
    f.duplicates = per_sha.values().map(|c| c - 1).sum::<usize>()
        + per_key.values().map(|c| c - 1).sum::<usize>();
    f.stored_records = facts.records.len();
    f.stored_diagnoses = facts.diagnoses.len();
    f.stored_idempotency_keys = facts.idempotency_keys.len();
    f.integrity = facts.integrity;
    f.seconds = started.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&dir);
    f
}

/// Rows read straight from the store, and its integrity check.
struct StoreFacts {
    /// (record id, sha256)
    records: Vec<(String, String)>,
    /// (diagnosis id, record id)
    diagnoses: Vec<(String, String)>,
    idempotency_keys: Vec<String>,
    integrity: String,
}

async fn store_facts(url: &str, b: Backend) -> StoreFacts {
    const RECORDS: &str = "SELECT id, sha256 FROM records";
    const DIAGNOSES: &str = "SELECT id, record_id FROM diagnoses";
    const IDEM: &str = "SELECT idem_key FROM idempotency_keys";
    match b {
        Backend::Sqlite => {
            let opts = sqlx::sqlite::SqliteConnectOptions::new().filename(url);
            let pool = sqlx::sqlite::SqlitePoolOptions::new()
                .max_connections(1)
                .connect_with(opts)
                .await
                .unwrap();
            let check: Vec<(String,)> = sqlx::query_as("PRAGMA integrity_check")
                .fetch_all(&pool)
                .await
                .unwrap();
            let fk: Vec<(String,)> =
                sqlx::query_as("SELECT \"table\" FROM pragma_foreign_key_check")
                    .fetch_all(&pool)
                    .await
                    .unwrap();
            let mut integrity = check
                .iter()
                .map(|r| r.0.clone())
                .collect::<Vec<_>>()
                .join("; ");
            if !fk.is_empty() {
                integrity = format!("{integrity}; foreign key violations in {fk:?}");
            }
            let facts = StoreFacts {
                records: sqlx::query_as(RECORDS).fetch_all(&pool).await.unwrap(),
                diagnoses: sqlx::query_as(DIAGNOSES).fetch_all(&pool).await.unwrap(),
                idempotency_keys: sqlx::query_as::<_, (String,)>(IDEM)
                    .fetch_all(&pool)
                    .await
                    .unwrap()
                    .into_iter()
                    .map(|r| r.0)
                    .collect(),
                integrity,
            };
            pool.close().await;
            facts
        }
        Backend::Postgres => {
            let pool = sqlx::postgres::PgPoolOptions::new()
                .max_connections(1)
                .connect(url)
                .await
                .unwrap();
            // B-tree indexes against their tables (amcheck ships with PostgreSQL); an
            // inconsistency is an error.
            let integrity = match sqlx::query("CREATE EXTENSION IF NOT EXISTS amcheck")
                .execute(&pool)
                .await
            {
                Err(e) => format!("amcheck unavailable: {e}"),
                Ok(_) => match sqlx::query(
                    "SELECT bt_index_check(c.oid, true) FROM pg_index i \
                     JOIN pg_class c ON c.oid = i.indexrelid \
                     JOIN pg_namespace n ON n.oid = c.relnamespace \
                     WHERE n.nspname = 'public' AND c.relam = 403",
                )
                .fetch_all(&pool)
                .await
                {
                    Ok(rows) if !rows.is_empty() => "ok".to_string(),
                    Ok(_) => "no indexes checked".to_string(),
                    Err(e) => format!("amcheck: {e}"),
                },
            };
            let facts = StoreFacts {
                records: sqlx::query_as(RECORDS).fetch_all(&pool).await.unwrap(),
                diagnoses: sqlx::query_as(DIAGNOSES).fetch_all(&pool).await.unwrap(),
                idempotency_keys: sqlx::query_as::<_, (String,)>(IDEM)
                    .fetch_all(&pool)
                    .await
                    .unwrap()
                    .into_iter()
                    .map(|r| r.0)
                    .collect(),
                integrity,
            };
            pool.close().await;
            facts
        }
    }
}

// ---------------------------------------------------------------------------------------------
// PostgreSQL going away while the service runs
// ---------------------------------------------------------------------------------------------

/// A problem answer: status, `Retry-After` seconds, the problem type, the time it took.
#[derive(Debug)]
struct Answer {
    status: u16,
    retry_after: Option<u64>,
    body: Value,
    seconds: f64,
}

async fn answer(req: reqwest::RequestBuilder, method: &str, template: &str) -> Answer {
    let t = Instant::now();
    let (status, headers, body) = checked(req, method, template).await;
    Answer {
        status,
        retry_after: headers
            .get("retry-after")
            .and_then(|v| v.to_str().ok())
            .and_then(|s| s.parse().ok()),
        body: serde_json::from_slice(&body).unwrap_or(Value::Null),
        seconds: t.elapsed().as_secs_f64(),
    }
}

/// The longest a request may take to get its 503 while the database is gone: the pool's
/// acquire timeout (5 s) plus slack, well under the request timeout (15 s).
const OUTAGE_ANSWER_S: f64 = 8.0;

fn assert_store_unavailable(what: &str, a: &Answer) {
    assert_eq!(a.status, 503, "{what} during the outage: {a:?}");
    assert_eq!(
        a.body["type"], "urn:gearwear:problem:store-unavailable",
        "{what}: {a:?}"
    );
    assert!(
        a.retry_after.is_some_and(|s| s >= 1),
        "{what}: Retry-After missing: {a:?}"
    );
    assert!(
        a.seconds < OUTAGE_ANSWER_S,
        "{what} took {:.1} s to fail; it should fail fast",
        a.seconds
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn postgres_outage_gives_503_then_recovers() {
    let admin = pg_admin_url();
    let upstream = split_pg_url(&admin).1.to_string();
    let proxy = Arc::new(CutProxy::start(&upstream).await);
    let p = proxy.clone();
    let Some(app) = spawn_app(Backend::Postgres, move |s| {
        s.database_url = p.proxied_url(&s.database_url);
        // Thresholds out of reach: one `diagnosis.created` event per record, nothing else.
        s.thresholds.warning = 10.0;
        s.thresholds.alarm = 20.0;
    })
    .await
    else {
        return;
    };
    let real_url = app.db.as_ref().unwrap().url.clone();
    let (rx, hook_url, _rt) = crate::webhooks::start_receiver(0, 0).await;
    crate::webhooks::create_hook(&app, &hook_url).await;

    let post = |seed: u64, key: &str| {
        app.client
            .post(app.url("/v1/machines/m-outage/records"))
            .bearer_auth(&app.ingest_key)
            .header("idempotency-key", key)
            .json(&json_record(seed))
    };
    const POST: (&str, &str) = ("POST", "/v1/machines/{machine_id}/records");
    // Every 201: idempotency key → diagnosis id.
    let mut created: HashMap<String, String> = HashMap::new();

    let a = answer(post(1, "before"), POST.0, POST.1).await;
    assert_eq!(a.status, 201, "{a:?}");
    created.insert("before".into(), a.body["id"].as_str().unwrap().into());
    let d0 = created["before"].clone();
    let ready = || app.client.get(app.url("/readyz"));
    assert_eq!(answer(ready(), "GET", "/readyz").await.status, 200);

    // --- The database goes away.
    proxy.cut().await;
    let (ingest, machine, diagnosis, readyz, healthz) = tokio::join!(
        answer(post(2, "during"), POST.0, POST.1),
        answer(
            app.client
                .get(app.url("/v1/machines/m-outage"))
                .bearer_auth(&app.read_key),
            "GET",
            "/v1/machines/{machine_id}"
        ),
        answer(
            app.client
                .get(app.url(&format!("/v1/diagnoses/{d0}")))
                .bearer_auth(&app.read_key),
            "GET",
            "/v1/diagnoses/{diagnosis_id}"
        ),
        answer(ready(), "GET", "/readyz"),
        answer(app.client.get(app.url("/healthz")), "GET", "/healthz"),
    );
    eprintln!(
        "outage: ingest {} in {:.2} s, machine {} in {:.2} s, diagnosis {} in {:.2} s, \
         readyz {} in {:.2} s, healthz {}",
        ingest.status,
        ingest.seconds,
        machine.status,
        machine.seconds,
        diagnosis.status,
        diagnosis.seconds,
        readyz.status,
        readyz.seconds,
        healthz.status
    );
    assert_store_unavailable("ingest", &ingest);
    assert_store_unavailable("GET machine", &machine);
    assert_store_unavailable("GET diagnosis", &diagnosis);
    assert_eq!(readyz.status, 503, "{readyz:?}");
    assert_eq!(readyz.body["checks"]["store"]["ok"], false, "{readyz:?}");
    assert!(readyz.retry_after.is_some(), "{readyz:?}");
    // Bounded below the pool's acquire timeout: a probe gets its answer in time.
    assert!(
        readyz.seconds < gearwear::service::health::READY_STORE_TIMEOUT.as_secs_f64() + 0.5,
        "{readyz:?}"
    );
    assert_eq!(healthz.status, 200, "the process itself is alive");

    // --- The database returns: no restart, the service finds it again by itself.
    proxy.restore().await;
    let back = Instant::now();
    let first_201 = loop {
        let a = answer(post(3, "after"), POST.0, POST.1).await;
        if a.status == 201 {
            created.insert("after".into(), a.body["id"].as_str().unwrap().into());
            break back.elapsed().as_secs_f64();
        }
        assert_eq!(a.status, 503, "{a:?}");
        assert!(
            back.elapsed() < Duration::from_secs(10),
            "no 201 within 10 s of the return"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    eprintln!("first 201 {first_201:.3} s after the database returned");
    assert_eq!(answer(ready(), "GET", "/readyz").await.status, 200);
    // The ingest that got a 503 left nothing: its re-send creates the record (no replay).
    let a = answer(post(2, "during"), POST.0, POST.1).await;
    assert_eq!(a.status, 201, "{a:?}");
    let r = app
        .client
        .post(app.url("/v1/machines/m-outage/records"))
        .bearer_auth(&app.ingest_key)
        .header("idempotency-key", "during")
        .json(&json_record(2))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(
        r.headers()["idempotent-replayed"],
        "true",
        "the second re-send replays"
    );
    created.insert("during".into(), a.body["id"].as_str().unwrap().into());

    // --- A cut in the middle of concurrent ingests: each answer is a 201 or a 503, and after
    // the return the 503s' re-sends create their record exactly once.
    let storm = Storm::start(&app, "mid", 4);
    storm.wait_answers(6).await;
    proxy.cut().await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let outcomes = storm.finish().await;
    proxy.restore().await;
    let (failed, replays) = settle(&app, &real_url, outcomes, &mut created, |a| {
        assert_store_unavailable("ingest cut mid-flight", a)
    })
    .await;
    eprintln!(
        "cut mid-flight: {failed} answers 503, {replays} re-sends replayed an unacknowledged commit"
    );
    assert!(failed > 0, "the cut hit no request");
    check_stored_and_delivered(&real_url, &created, &rx, "both outages").await;
}

/// A network partition instead of a refusal: the database's packets stop (no RST, nothing
/// closed) in the middle of concurrent ingests, then flow again. Requests that were waiting
/// for a connection get `store-unavailable` at the pool's acquire timeout (5 s); requests
/// that were inside a query get `request-timeout` at the request timeout (6 s here, 15 s by
/// default) — both 503 with Retry-After, none hangs longer. When the packets flow again the
/// service recovers by itself; a timed-out request whose COMMIT was held in the network can
/// still commit then, so its re-send with the same key replays it (counted).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn postgres_partition_gives_503_within_the_request_timeout() {
    const REQUEST_TIMEOUT_S: f64 = 6.0;
    let admin = pg_admin_url();
    let upstream = split_pg_url(&admin).1.to_string();
    let proxy = Arc::new(CutProxy::start(&upstream).await);
    let p = proxy.clone();
    let Some(app) = spawn_app(Backend::Postgres, move |s| {
        s.database_url = p.proxied_url(&s.database_url);
        s.thresholds.warning = 10.0;
        s.thresholds.alarm = 20.0;
        s.limits.request_timeout = Duration::from_secs_f64(REQUEST_TIMEOUT_S);
    })
    .await
    else {
        return;
    };
    let real_url = app.db.as_ref().unwrap().url.clone();
    let (rx, hook_url, _rt) = crate::webhooks::start_receiver(0, 0).await;
    crate::webhooks::create_hook(&app, &hook_url).await;
    let mut created: HashMap<String, String> = HashMap::new();

    let storm = Storm::start(&app, "part", 4);
    storm.wait_answers(6).await;
    proxy.stall();
    let readyz = answer(app.client.get(app.url("/readyz")), "GET", "/readyz").await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let outcomes = storm.finish().await;
    proxy.resume();
    let back = Instant::now();
    eprintln!(
        "partition: readyz {} in {:.2} s",
        readyz.status, readyz.seconds
    );
    assert_eq!(readyz.status, 503, "{readyz:?}");
    assert!(
        readyz.seconds < gearwear::service::health::READY_STORE_TIMEOUT.as_secs_f64() + 0.5,
        "{readyz:?}"
    );
    let mut slugs: HashMap<String, (usize, f64)> = HashMap::new();
    for (_, _, a) in outcomes.iter().filter(|(_, _, a)| a.status == 503) {
        let e = slugs
            .entry(a.body["type"].as_str().unwrap_or("").to_string())
            .or_default();
        e.0 += 1;
        e.1 = e.1.max(a.seconds);
    }
    eprintln!("partition: 503s by type (count, slowest s): {slugs:?}");
    let (failed, replays) = settle(&app, &real_url, outcomes, &mut created, |a| {
        assert!(a.retry_after.is_some_and(|s| s >= 1), "{a:?}");
        assert!(
            a.body["type"] == "urn:gearwear:problem:store-unavailable"
                || a.body["type"] == "urn:gearwear:problem:request-timeout",
            "{a:?}"
        );
        assert!(
            a.seconds < REQUEST_TIMEOUT_S + 1.0,
            "a request hung past the request timeout: {a:?}"
        );
    })
    .await;
    eprintln!(
        "partition: {failed} answers 503, {replays} re-sends replayed a commit made after the \
         503; first re-send answered {:.2} s after the packets flowed again",
        back.elapsed().as_secs_f64()
    );
    assert!(failed > 0, "the partition hit no request");
    check_stored_and_delivered(&real_url, &created, &rx, "the partition").await;
}

/// Every 201 (idempotency key → diagnosis id) is in the store, no record body is stored
/// twice, and the webhook worker delivered every diagnosis — it lived through the fault.
async fn check_stored_and_delivered(
    real_url: &str,
    created: &HashMap<String, String>,
    rx: &crate::webhooks::Receiver,
    fault: &str,
) {
    assert_eq!(
        count(
            real_url,
            "SELECT COUNT(*) FROM (SELECT sha256 FROM records GROUP BY sha256 \
             HAVING COUNT(*) > 1) AS d"
        )
        .await,
        0,
        "a record body stored twice"
    );
    let ids: Vec<(String,)> = {
        let pool = sqlx::PgPool::connect(real_url).await.unwrap();
        let v = sqlx::query_as("SELECT id FROM diagnoses")
            .fetch_all(&pool)
            .await
            .unwrap();
        pool.close().await;
        v
    };
    let ids: HashSet<String> = ids.into_iter().map(|r| r.0).collect();
    for (k, d) in created {
        assert!(ids.contains(d), "the 201 of {k} ({d}) is not stored");
    }

    // The webhook worker lived through the fault: every diagnosis is delivered.
    let want: HashSet<String> = created.values().cloned().collect();
    let t = Instant::now();
    let delivered = loop {
        let got: Vec<Value> = rx
            .got
            .lock()
            .unwrap()
            .iter()
            .map(|(_, b)| serde_json::from_slice(b).unwrap())
            .collect();
        let seen: HashSet<String> = got
            .iter()
            .filter_map(|p| p["diagnosis_id"].as_str().map(String::from))
            .collect();
        if want.is_subset(&seen) {
            break got;
        }
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "deliveries missing after {fault}: {:?}",
            want.difference(&seen).collect::<Vec<_>>()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    eprintln!(
        "webhooks after {fault}: {} diagnoses, {} deliveries received ({} duplicates)",
        want.len(),
        delivered.len(),
        delivered.len() - want.len()
    );
}

/// Concurrent ingest clients, each posting new records (own key, own seed) until stopped.
struct Storm {
    stop: Arc<AtomicBool>,
    answered: Arc<AtomicUsize>,
    outcomes: Arc<Mutex<Vec<(String, u64, Answer)>>>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl Storm {
    fn start(app: &TestApp, prefix: &str, clients: u64) -> Storm {
        let stop = Arc::new(AtomicBool::new(false));
        let answered = Arc::new(AtomicUsize::new(0));
        let outcomes = Arc::new(Mutex::new(Vec::new()));
        let mut tasks = Vec::new();
        for c in 0..clients {
            let (stop, answered, outcomes) = (stop.clone(), answered.clone(), outcomes.clone());
            let (client, url, key, prefix) = (
                app.client.clone(),
                app.url("/v1/machines/m-outage/records"),
                app.ingest_key.clone(),
                prefix.to_string(),
            );
            tasks.push(tokio::spawn(async move {
                for j in 0u64.. {
                    if stop.load(Ordering::SeqCst) {
                        break;
                    }
                    let (k, seed) = (format!("{prefix}-{c}-{j}"), 100 + c * 1000 + j);
                    let req = client
                        .post(&url)
                        .bearer_auth(&key)
                        .header("idempotency-key", &k)
                        .json(&json_record(seed));
                    let a = answer(req, "POST", "/v1/machines/{machine_id}/records").await;
                    answered.fetch_add(1, Ordering::SeqCst);
                    outcomes.lock().unwrap().push((k, seed, a));
                }
            }));
        }
        Storm {
            stop,
            answered,
            outcomes,
            tasks,
        }
    }

    async fn wait_answers(&self, n: usize) {
        while self.answered.load(Ordering::SeqCst) < n {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }

    /// Stop the clients; every answer, once each client's last request returned.
    async fn finish(self) -> Vec<(String, u64, Answer)> {
        self.stop.store(true, Ordering::SeqCst);
        for t in self.tasks {
            t.await.unwrap();
        }
        std::mem::take(&mut *self.outcomes.lock().unwrap())
    }
}

/// After the database is back: take the storm's 201s into `created`, check each 503 with
/// `check`, and show that the 503s left nothing half-written — the store holds exactly the
/// 201s, up to commits whose acknowledgement the fault swallowed, which the re-send (same
/// key) then replays. Returns (503s, such replays).
async fn settle(
    app: &TestApp,
    real_url: &str,
    outcomes: Vec<(String, u64, Answer)>,
    created: &mut HashMap<String, String>,
    check: impl Fn(&Answer),
) -> (usize, usize) {
    let mut failed = Vec::new();
    for (k, seed, a) in outcomes {
        match a.status {
            201 => {
                created.insert(k, a.body["id"].as_str().unwrap().into());
            }
            503 => {
                check(&a);
                failed.push((k, seed));
            }
            s => panic!("ingest answered {s} during the fault: {a:?}"),
        }
    }
    // A request answered 503 by its timeout may still sit in the group-commit queue and be
    // committed once the database answers again: wait until the count stops moving.
    let stored_before_resend = stable_count(real_url, "SELECT COUNT(*) FROM records").await;
    let before = created.len();
    let mut replays = 0;
    for (k, seed) in &failed {
        let r = app
            .client
            .post(app.url("/v1/machines/m-outage/records"))
            .bearer_auth(&app.ingest_key)
            .header("idempotency-key", k)
            .json(&json_record(*seed))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
        if r.headers().get("idempotent-replayed").is_some() {
            replays += 1;
        }
        let v: Value = r.json().await.unwrap();
        created.insert(k.clone(), v["id"].as_str().unwrap().into());
    }
    assert_eq!(
        stored_before_resend as usize,
        before + replays,
        "records stored by requests that got a 503"
    );
    assert_eq!(
        count(real_url, "SELECT COUNT(*) FROM records").await as usize,
        created.len(),
        "one record per idempotency key that got a 201"
    );
    (failed.len(), replays)
}

/// [`count`] once it reads the same twice, 500 ms apart (at most 30 s).
async fn stable_count(url: &str, sql: &'static str) -> i64 {
    let mut last = count(url, sql).await;
    for _ in 0..60 {
        tokio::time::sleep(Duration::from_millis(500)).await;
        let n = count(url, sql).await;
        if n == last {
            return n;
        }
        last = n;
    }
    last
}

async fn count(url: &str, sql: &'static str) -> i64 {
    let pool = sqlx::PgPool::connect(url).await.unwrap();
    let n: (i64,) = sqlx::query_as(sql).fetch_one(&pool).await.unwrap();
    pool.close().await;
    n.0
}

// ---------------------------------------------------------------------------------------------
// SIGTERM with a request in flight: graceful shutdown finishes it
// ---------------------------------------------------------------------------------------------

/// SIGTERM to the real binary while a record upload is half sent: the service stops taking new
/// connections, still reads the rest of the upload, diagnoses it, commits it, answers 201, and
/// only then exits 0; after a restart the record is there.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sigterm_finishes_the_request_in_flight() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let dir = std::env::temp_dir().join(format!("gearwear-term-{}", uuid::Uuid::new_v4().simple()));
    std::fs::create_dir_all(&dir).unwrap();
    let db = dir.join("term.db").display().to_string();
    let log = dir.join("serve.log");
    let key = cli_key(&db, "ingest,read");
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .timeout(Duration::from_secs(30))
        .build()
        .unwrap();
    let mut server = start_server(&db, &log, &client).await;
    let addr = server.base.trim_start_matches("http://").to_string();

    // Half of the upload.
    let body = f32_body(1);
    let (first, rest) = body.split_at(body.len() / 2);
    let mut conn = tokio::net::TcpStream::connect(&addr).await.unwrap();
    let head = format!(
        "POST /v1/machines/term/records?sample_rate_hz=25600 HTTP/1.1\r\nHost: {addr}\r\n\
         Authorization: Bearer {key}\r\nContent-Type: application/octet-stream\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    conn.write_all(head.as_bytes()).await.unwrap();
    conn.write_all(first).await.unwrap();
    conn.flush().await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;

    // SIGTERM, then the rest of the upload after the service has begun shutting down.
    let pid = server.child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(
        server.child.try_wait().unwrap().is_none(),
        "the service exited with a request in flight; log:\n{}",
        std::fs::read_to_string(&log).unwrap_or_default()
    );
    // New requests are no longer taken.
    let late = client
        .get(format!("{}/healthz", server.base))
        .timeout(Duration::from_secs(2))
        .send()
        .await;
    assert!(
        late.is_err(),
        "a new request was served during shutdown: {late:?}"
    );
    conn.write_all(rest).await.unwrap();
    conn.flush().await.unwrap();
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(30), conn.read_to_end(&mut answer))
        .await
        .expect("the in-flight request was answered")
        .unwrap();
    let answer = String::from_utf8_lossy(&answer);
    assert!(
        answer.starts_with("HTTP/1.1 201"),
        "in-flight request: {}",
        answer.lines().next().unwrap_or("")
    );

    // Then the process exits, cleanly.
    let started = Instant::now();
    let status = loop {
        if let Some(s) = server.child.try_wait().unwrap() {
            break s;
        }
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "the service did not exit after its last request"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert!(status.success(), "exit status {status}");

    // The acknowledged record is stored.
    let mut again = start_server(&db, &log, &client).await;
    let m: Value = client
        .get(format!("{}/v1/machines/term", again.base))
        .bearer_auth(&key)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(m["record_count"], 1, "{m}");
    kill9(&mut again);
    let _ = std::fs::remove_dir_all(&dir);
}
