//! A bounded load generator for `gearwear serve`: POSTs a 1 s record at 25.6 kHz (JSON or f32)
//! over loopback and prints throughput, latency percentiles, errors and — with `--pid` — the
//! server's RSS and CPU time per record.
//!
//! Two modes:
//! * closed loop (default): `--concurrency` clients each send the next record as soon as the
//!   previous one is answered — measures capacity;
//! * open loop (`--rate R`): records are due at a fixed rate of R per second whatever the
//!   answers do (at most `--concurrency` in flight; a record that finds every slot busy is
//!   counted as `late` and sent when one frees) — the soak test at a chosen fraction of
//!   capacity.
//!
//! `--record FILE` sends that record (any file `gearwear diagnose` reads, e.g. one written by
//! `gearwear synth`) instead of the built-in four-sine record, which fits the model poorly and
//! so takes the diagnosis's slowest path.
//!
//! `--requests N` stops after N requests (a fixed amount of work, e.g. for an instruction count
//! of the server under callgrind: `scripts/record_path_profile.sh`).
//!
//! `--report-every S` prints one line per S-second window (records, errors, p50/p99, server
//! RSS) so a soak shows start and end; the last line is a JSON summary for scripts.
//!
//! ```sh
//! cargo run --release --example loadgen -- --url http://127.0.0.1:8080 --key gw_… \
//!     --concurrency 4 --seconds 20 --format json --pid $(pgrep -n gearwear)
//! cargo run --release --example loadgen -- --key gw_… --rate 120 --seconds 600 \
//!     --report-every 60 --pid $(pgrep -n gearwear)
//! ```

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[path = "../benches/common/four_sines.rs"]
mod four_sines;

fn arg(args: &[String], name: &str, default: &str) -> String {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
        .unwrap_or_else(|| default.to_string())
}

/// `(VmRSS kB, VmHWM kB)` of a process.
fn rss_kb(pid: &str) -> Option<(u64, u64)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| {
        s.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// User + system CPU seconds of a process (`/proc/PID/stat`, fields 14 and 15, in clock ticks
/// of 1/100 s — the kernel's USER_HZ on Linux).
/// CPU seconds of a process: (user, kernel), from `/proc/PID/stat` (clock ticks of 10 ms).
fn cpu_seconds(pid: &str) -> Option<(f64, f64)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may contain spaces.
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut / 100.0, st / 100.0))
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() as f64 - 1.0) * p).round() as usize] * 1e3
}

#[derive(Default)]
struct Window {
    lat: Vec<f64>,
    errors: usize,
}

/// The command line (see the module documentation).
struct Options {
    url: String,
    key: String,
    conc: usize,
    secs: f64,
    rate: f64,
    every: f64,
    machines: usize,
    format: String,
    pid: String,
    record: String,
    /// `--requests N`: stop after N requests (0: no limit; `--seconds` still bounds the run).
    requests: usize,
}

impl Options {
    fn parse(args: &[String]) -> Self {
        Options {
            url: arg(args, "--url", "http://127.0.0.1:8080"),
            key: arg(args, "--key", ""),
            conc: arg(args, "--concurrency", "4").parse().unwrap(),
            secs: arg(args, "--seconds", "10").parse().unwrap(),
            rate: arg(args, "--rate", "0").parse().unwrap(),
            every: arg(args, "--report-every", "0").parse().unwrap(),
            machines: arg(args, "--machines", "4").parse().unwrap(),
            format: arg(args, "--format", "json"),
            pid: arg(args, "--pid", ""),
            record: arg(args, "--record", ""),
            requests: arg(args, "--requests", "0").parse().unwrap(),
        }
    }
}

/// The request body, its content type and the query string.
///
/// The default record: four sines and a little noise (a poor fit to the model, so the
/// diagnosis tries every f1 candidate — the slow path); `--record FILE` sends any record
/// file `gearwear diagnose` reads (e.g. one written by `gearwear synth`), resampled to
/// nothing: its own samples and rate.
fn request_body(o: &Options) -> (Vec<u8>, &'static str, String) {
    let record = &o.record;
    let (x, fs) = if record.is_empty() {
        (four_sines::samples(), four_sines::SAMPLE_RATE_HZ)
    } else {
        let r = gearwear::record::read_record(
            std::path::Path::new(record),
            &gearwear::record::ReadOptions::default(),
        )
        .unwrap_or_else(|e| panic!("--record {record}: {e}"));
        (r.samples, r.sample_rate)
    };
    if o.format == "f32" {
        let b: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
        (
            b,
            "application/octet-stream",
            format!("?sample_rate_hz={fs}"),
        )
    } else {
        let b =
            serde_json::to_vec(&serde_json::json!({"sample_rate_hz": fs, "samples": x})).unwrap();
        (b, "application/json", String::new())
    }
}

/// Every `every` seconds (none when `every ≤ 0`): the last window's throughput, latencies and
/// the server's RSS.
fn spawn_reporter(
    window: Arc<Mutex<Window>>,
    pid: String,
    every: f64,
    start: Instant,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        if every <= 0.0 {
            return;
        }
        let mut t = tokio::time::interval_at(
            tokio::time::Instant::now() + Duration::from_secs_f64(every),
            Duration::from_secs_f64(every),
        );
        loop {
            t.tick().await;
            let w = std::mem::take(&mut *window.lock().unwrap());
            let mut l = w.lat;
            l.sort_by(|a, b| a.partial_cmp(b).unwrap());
            let (rss, _) = rss_kb(&pid).unwrap_or((0, 0));
            println!(
                "t={:>6.0}s  {:>6} ok  {:>3} errors  {:>7.1} rec/s  p50 {:>6.2} ms  p99 {:>6.2} ms  server RSS {:.1} MB",
                start.elapsed().as_secs_f64(),
                l.len(),
                w.errors,
                l.len() as f64 / every,
                percentile(&l, 0.5),
                percentile(&l, 0.99),
                rss as f64 / 1024.0
            );
        }
    })
}

/// One request: what it posts, where, and the windows its latency (or error) goes to.
struct Request {
    client: reqwest::Client,
    url: String,
    key: String,
    q: String,
    ct: &'static str,
    body: axum::body::Bytes,
    /// Machine index and request number.
    m: usize,
    i: usize,
    windows: [Arc<Mutex<Window>>; 2],
}

impl Request {
    /// Post the record; add the latency of a `201` (body read) to both windows, else an error.
    async fn send(self) {
        let Request {
            client,
            url,
            key,
            q,
            ct,
            body,
            m,
            i,
            windows,
        } = self;
        let t = Instant::now();
        let r = client
            .post(format!("{url}/v1/machines/load-{m}/records{q}"))
            .bearer_auth(&key)
            .header("content-type", ct)
            .header(
                "idempotency-key",
                format!("load-{i}-{}", std::process::id()),
            )
            .body(body)
            .send()
            .await;
        let ok = match r {
            Ok(r) if r.status() == 201 => r.bytes().await.is_ok(),
            Ok(r) => {
                eprintln!("{}: {}", r.status(), r.text().await.unwrap_or_default());
                false
            }
            Err(e) => {
                eprintln!("{e}");
                false
            }
        };
        let dt = t.elapsed().as_secs_f64();
        for w in &windows {
            let mut w = w.lock().unwrap();
            if ok {
                w.lat.push(dt);
            } else {
                w.errors += 1;
            }
        }
    }
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let o = Options::parse(&args);
    let (conc, rate) = (o.conc, o.rate);
    let (body, ct, q) = request_body(&o);
    println!(
        "body: {} bytes ({ct}); {}",
        body.len(),
        if rate > 0.0 {
            format!("open loop at {rate} records/s, at most {conc} in flight")
        } else {
            format!("closed loop, concurrency {conc}")
        }
    );
    // Shared, reference-counted: sending does not copy the body.
    let body_bytes = axum::body::Bytes::from(body);
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(conc)
        .build()
        .unwrap();
    let window = Arc::new(Mutex::new(Window::default()));
    let all = Arc::new(Mutex::new(Window::default()));
    let slots = Arc::new(tokio::sync::Semaphore::new(conc));
    let start = Instant::now();
    let end = start + Duration::from_secs_f64(o.secs);
    let before = Usage::now(&o.pid);

    let reporter = spawn_reporter(window.clone(), o.pid.clone(), o.every, start);

    let late = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let mut tasks = Vec::new();
    let mut i = 0usize;
    loop {
        let due = if rate > 0.0 {
            start + Duration::from_secs_f64(i as f64 / rate)
        } else {
            Instant::now()
        };
        if due >= end || (o.requests > 0 && i >= o.requests) {
            break;
        }
        if rate > 0.0 {
            tokio::time::sleep_until(due.into()).await;
        }
        let permit = match slots.clone().try_acquire_owned() {
            Ok(p) => p,
            Err(_) => {
                if rate > 0.0 {
                    late.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                slots.clone().acquire_owned().await.unwrap()
            }
        };
        if Instant::now() >= end {
            break;
        }
        let request = Request {
            client: client.clone(),
            url: o.url.clone(),
            key: o.key.clone(),
            q: q.clone(),
            ct,
            body: body_bytes.clone(),
            m: i % o.machines.max(1),
            i,
            windows: [window.clone(), all.clone()],
        };
        tasks.push(tokio::spawn(async move {
            let _permit = permit;
            request.send().await;
        }));
        i += 1;
        if tasks.len() > 4 * conc {
            tasks.retain(|t| !t.is_finished());
        }
    }
    for t in tasks {
        t.await.unwrap();
    }
    reporter.abort();
    let wall = start.elapsed().as_secs_f64();
    let all = std::mem::take(&mut *all.lock().unwrap());
    let late = late.load(std::sync::atomic::Ordering::Relaxed);
    report(&o, all, late, wall, &before);
}

/// CPU seconds of the server and of this process, and the server's memory, at one moment.
struct Usage {
    server_cpu: Option<(f64, f64)>,
    self_cpu: Option<(f64, f64)>,
    rss: Option<(u64, u64)>,
}

impl Usage {
    fn now(pid: &str) -> Self {
        Usage {
            server_cpu: cpu_seconds(pid),
            self_cpu: cpu_seconds("self"),
            rss: rss_kb(pid),
        }
    }
}

/// The run's totals: throughput, latency percentiles, CPU per record and memory, as text and
/// as one JSON line.
fn report(o: &Options, all: Window, late: usize, wall: f64, before: &Usage) {
    let (format, rate, conc, pid) = (&o.format, o.rate, o.conc, &o.pid);
    let mut lat = all.lat;
    lat.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = lat.len();
    println!(
        "{n} records in {wall:.1} s = {:.1} records/s, {} errors, {} late",
        n as f64 / wall,
        all.errors,
        late
    );
    let (p50, p90, p99, max) = (
        percentile(&lat, 0.5),
        percentile(&lat, 0.9),
        percentile(&lat, 0.99),
        percentile(&lat, 1.0),
    );
    println!("latency ms: p50 {p50:.2}, p90 {p90:.2}, p99 {p99:.2}, max {max:.2}");
    let per_record = |a: Option<(f64, f64)>, b: Option<(f64, f64)>| match (a, b) {
        (Some(a), Some(b)) if n > 0 => ((b.0 - a.0) / n as f64 * 1e3, (b.1 - a.1) / n as f64 * 1e3),
        _ => (f64::NAN, f64::NAN),
    };
    let (server_user, server_kernel) = per_record(before.server_cpu, cpu_seconds(pid));
    let server_cpu = server_user + server_kernel;
    let (client_user, client_kernel) = per_record(before.self_cpu, cpu_seconds("self"));
    let client_cpu = client_user + client_kernel;
    let (rss0, rss1) = (before.rss, rss_kb(pid));
    if !pid.is_empty() {
        println!(
            "server CPU per record {server_cpu:.2} ms (user {server_user:.2}, kernel {server_kernel:.2}), \
             load generator CPU per record {client_cpu:.2} ms; \
             server RSS start {:.1} MB, end {:.1} MB, peak {:.1} MB",
            rss0.map_or(f64::NAN, |r| r.0 as f64 / 1024.0),
            rss1.map_or(f64::NAN, |r| r.0 as f64 / 1024.0),
            rss1.map_or(f64::NAN, |r| r.1 as f64 / 1024.0),
        );
    }
    println!(
        "{}",
        serde_json::json!({
            "records": n, "errors": all.errors, "late": late,
            "seconds": wall, "records_per_second": n as f64 / wall,
            "p50_ms": p50, "p90_ms": p90, "p99_ms": p99, "max_ms": max,
            "server_cpu_ms_per_record": server_cpu, "client_cpu_ms_per_record": client_cpu,
            "server_user_ms_per_record": server_user, "server_kernel_ms_per_record": server_kernel,
            "rss_start_kb": rss0.map(|r| r.0), "rss_end_kb": rss1.map(|r| r.0), "rss_peak_kb": rss1.map(|r| r.1),
            "format": format, "rate": rate, "concurrency": conc,
        })
    );
}
