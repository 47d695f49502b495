//! A bounded load generator for `gearwear serve`: `concurrency` clients each POST a 1 s record
//! at 25.6 kHz (JSON or f32) in a closed loop for `seconds`, then print p50/p99 latency,
//! records/s and errors; with `--pid` also the server's RSS (VmRSS, VmHWM) at the end.
//!
//! ```sh
//! cargo run --release --example loadgen -- --url http://127.0.0.1:8080 --key gw_… \
//!     --concurrency 4 --seconds 20 --format json --pid $(pgrep -n gearwear)
//! ```

use std::f64::consts::TAU;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn arg(args: &[String], name: &str, default: &str) -> String {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
        .unwrap_or_else(|| default.to_string())
}

fn rss(pid: &str) -> String {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .map(|s| {
            s.lines()
                .filter(|l| l.starts_with("VmRSS") || l.starts_with("VmHWM"))
                .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
                .collect::<Vec<_>>()
                .join(", ")
        })
        .unwrap_or_else(|_| "n/a".into())
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let url = arg(&args, "--url", "http://127.0.0.1:8080");
    let key = arg(&args, "--key", "");
    let conc: usize = arg(&args, "--concurrency", "4").parse().unwrap();
    let secs: f64 = arg(&args, "--seconds", "10").parse().unwrap();
    let format = arg(&args, "--format", "json");
    let pid = arg(&args, "--pid", "");
    let fs = 25_600.0;
    let f1 = 1.07 * 870.0;
    let x: Vec<f64> = (0..25_600)
        .map(|i| {
            let t = i as f64 / fs;
            (TAU * f1 * t).sin()
                + 0.2 * (TAU * 0.36 * f1 * t).sin()
                + 0.05 * (TAU * 0.0875 * f1 * t).sin()
                + 0.3 * (TAU * 2.0 * f1 * t).sin()
                + 0.01 * ((i * 7919 % 1000) as f64 / 1000.0 - 0.5)
        })
        .collect();
    let (body, ct, q) = if format == "f32" {
        let b: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
        (b, "application/octet-stream", "?sample_rate_hz=25600")
    } else {
        let b =
            serde_json::to_vec(&serde_json::json!({"sample_rate_hz": fs, "samples": x})).unwrap();
        (b, "application/json", "")
    };
    println!("body: {} bytes ({ct})", body.len());
    let body = Arc::new(body);
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(conc)
        .build()
        .unwrap();
    let end = Instant::now() + Duration::from_secs_f64(secs);
    let start = Instant::now();
    let mut tasks = Vec::new();
    for w in 0..conc {
        let (client, body, url, key) = (client.clone(), body.clone(), url.clone(), key.clone());
        tasks.push(tokio::spawn(async move {
            let mut lat = Vec::new();
            let mut errors = 0usize;
            let mut i = 0usize;
            while Instant::now() < end {
                let t = Instant::now();
                let r = client
                    .post(format!("{url}/v1/machines/load-{w}/records{q}"))
                    .bearer_auth(&key)
                    .header("content-type", ct)
                    .header(
                        "idempotency-key",
                        format!("load-{w}-{i}-{}", std::process::id()),
                    )
                    .body(body.as_ref().clone())
                    .send()
                    .await;
                match r {
                    Ok(r) if r.status() == 201 => {
                        let _ = r.bytes().await;
                        lat.push(t.elapsed().as_secs_f64());
                    }
                    Ok(r) => {
                        errors += 1;
                        if errors < 3 {
                            eprintln!("{}: {}", r.status(), r.text().await.unwrap_or_default());
                        }
                    }
                    Err(e) => {
                        errors += 1;
                        eprintln!("{e}");
                    }
                }
                i += 1;
            }
            (lat, errors)
        }));
    }
    let mut lat = Vec::new();
    let mut errors = 0;
    for t in tasks {
        let (l, e) = t.await.unwrap();
        lat.extend(l);
        errors += e;
    }
    let wall = start.elapsed().as_secs_f64();
    lat.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let q = |p: f64| lat[((lat.len() as f64 - 1.0) * p).round() as usize] * 1e3;
    println!(
        "{} records in {wall:.1} s = {:.1} records/s, {errors} errors, concurrency {conc}",
        lat.len(),
        lat.len() as f64 / wall
    );
    if !lat.is_empty() {
        println!(
            "latency ms: p50 {:.2}, p90 {:.2}, p99 {:.2}, max {:.2}",
            q(0.5),
            q(0.9),
            q(0.99),
            q(1.0)
        );
    }
    if !pid.is_empty() {
        println!("server {}", rss(&pid));
    }
}
