//! Bad records, table-driven: each request, the exact problem+json it gets (status, `type`,
//! `title`, a phrase of the `detail` a person can act on, and the numbers it carries), and
//! nothing stored for any of them. The list follows the reliability issue: empty, one sample,
//! NaN, ±Inf, all zeros, clipped, sample rate 0 / negative / absurd, below Nyquist for the
//! needed lines, shaft rate outside the signature table's band, truncated WAV, wrong content
//! type, 10× the size limit — in every body format where the format can carry the fault.

use serde_json::{Value, json};

use crate::both_stores;
use crate::helpers::*;

both_stores!(bad_records_get_exact_problems_and_store_nothing, bad_reads);

/// Body-size limit for this test: 1 MiB (so 10× is 10 MiB).
const LIMIT: usize = 1 << 20;
/// Sample-count limit for this test.
const MAX_SAMPLES: usize = 100_000;

/// One bad request and the problem it must get.
struct Case {
    what: &'static str,
    content_type: &'static str,
    query: String,
    body: Vec<u8>,
    status: u16,
    slug: &'static str,
    title: &'static str,
    /// A phrase the `detail` must contain.
    detail: &'static str,
    /// Extension members the problem must carry, with their values (`Value::Null`: present,
    /// any value).
    extra: Vec<(&'static str, Value)>,
}

fn case(
    what: &'static str,
    content_type: &'static str,
    query: &str,
    body: Vec<u8>,
    (status, slug, title): (u16, &'static str, &'static str),
    detail: &'static str,
) -> Case {
    Case {
        what,
        content_type,
        query: query.to_string(),
        body,
        status,
        slug,
        title,
        detail,
        extra: vec![],
    }
}

impl Case {
    fn with(mut self, key: &'static str, v: Value) -> Case {
        self.extra.push((key, v));
        self
    }
}

fn json_body(v: Value) -> Vec<u8> {
    serde_json::to_vec(&v).unwrap()
}

fn f32_body(x: &[f64]) -> Vec<u8> {
    x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect()
}

fn csv_body(x: &[f64]) -> Vec<u8> {
    x.iter()
        .map(|v| format!("{v}\n"))
        .collect::<String>()
        .into_bytes()
}

const EMPTY: (u16, &str, &str) = (422, "empty-record", "Empty record");
const NON_FINITE: (u16, &str, &str) = (422, "non-finite-sample", "Non-finite sample");
const FLAT: (u16, &str, &str) = (422, "flat-record", "Flat record");
const CLIPPED: (u16, &str, &str) = (422, "clipped-record", "Clipped record");
const SHORT: (u16, &str, &str) = (422, "record-too-short", "Record too short");
const PARAM: (u16, &str, &str) = (422, "invalid-parameter", "Invalid parameter");
const MALFORMED: (u16, &str, &str) = (400, "malformed-record", "Malformed record");
const BAD_JSON: (u16, &str, &str) = (400, "invalid-json", "Malformed JSON record");
const BAD_QUERY: (u16, &str, &str) = (400, "invalid-query", "Invalid query parameter");
const MEDIA: (u16, &str, &str) = (415, "unsupported-media-type", "Unsupported content type");
const NO_RATE: (u16, &str, &str) = (422, "missing-sample-rate", "Sample rate missing");
const SLOW_RATE: (u16, &str, &str) = (422, "sample-rate-too-low", "Sample rate too low");
const BAND: (u16, &str, &str) = (
    422,
    "speed-out-of-band",
    "Operating speed outside the signature table",
);

fn cases() -> Vec<Case> {
    let (x, fs) = record_samples(1.07, 1.0, 3);
    let x = &x[..20_000];
    let rate = format!("?sample_rate_hz={fs}");
    let mut with_nan = x.to_vec();
    with_nan[1234] = f64::NAN;
    let mut with_inf = x.to_vec();
    with_inf[77] = f64::INFINITY;
    let mut with_ninf = x.to_vec();
    with_ninf[5] = f64::NEG_INFINITY;
    // The record peaks near 1.6; an ADC whose range ends at ±1.0 writes ±1.0 for every sample
    // beyond it.
    let clipped: Vec<f64> = x.iter().map(|v| v.clamp(-1.0, 1.0)).collect();
    // Only the positive half saturates (an offset sensor).
    let top_clipped: Vec<f64> = x.iter().map(|v| v.min(0.9)).collect();
    let zeros = vec![0.0; 20_000];
    let wav16 = |v: &[f64]| gearwear::record::encode_wav(v, 25_600, false);
    let wavf = |v: &[f64]| gearwear::record::encode_wav(v, 25_600, true);
    let half: Vec<f64> = x.iter().map(|v| 0.5 * v).collect();
    let good_wav = wav16(&half);
    let mut nan_csv = String::from_utf8(csv_body(x)).unwrap();
    nan_csv = nan_csv.replacen(&format!("{}\n", x[1234]), "nan\n", 1);
    let inf_csv =
        String::from_utf8(csv_body(x))
            .unwrap()
            .replacen(&format!("{}\n", x[10]), "-inf\n", 1);
    let big = |v: f64| json!({"sample_rate_hz": fs, "samples": x, "shaft_hz": v});
    vec![
        // ---- empty
        case(
            "empty JSON samples",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": []})),
            EMPTY,
            "holds no samples",
        ),
        case(
            "empty CSV body",
            "text/csv",
            &rate,
            vec![],
            EMPTY,
            "holds no samples",
        ),
        case(
            "CSV of only a header and comments",
            "text/csv",
            &rate,
            b"# sensor a1\nvalue\n".to_vec(),
            EMPTY,
            "holds no samples",
        ),
        case(
            "empty f32 body",
            "application/octet-stream",
            &rate,
            vec![],
            EMPTY,
            "holds no samples",
        ),
        case(
            "WAV with an empty data chunk",
            "audio/wav",
            "",
            wav16(&[]),
            EMPTY,
            "holds no samples",
        ),
        // ---- one sample
        case(
            "one JSON sample",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": [0.5]})),
            SHORT,
            "too short",
        )
        .with("samples", json!(1))
        .with("needed_samples", Value::Null),
        case(
            "one CSV sample",
            "text/csv",
            &rate,
            b"0.5\n".to_vec(),
            SHORT,
            "too short",
        )
        .with("samples", json!(1)),
        case(
            "one f32 sample",
            "application/octet-stream",
            &rate,
            f32_body(&[0.5]),
            SHORT,
            "too short",
        )
        .with("samples", json!(1)),
        case(
            "100 samples (4 periods of f1)",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": &x[..100]})),
            SHORT,
            "the estimator needs at least",
        )
        .with("samples", json!(100)),
        // ---- NaN and ±Inf
        case(
            "NaN in CSV",
            "text/csv",
            &rate,
            nan_csv.into_bytes(),
            NON_FINITE,
            "sample 1234 is NaN",
        )
        .with("index", json!(1234)),
        case(
            "-inf in CSV",
            "text/csv",
            &rate,
            inf_csv.into_bytes(),
            NON_FINITE,
            "sample 10 is -inf",
        )
        .with("index", json!(10)),
        case(
            "NaN in f32",
            "application/octet-stream",
            &rate,
            f32_body(&with_nan),
            NON_FINITE,
            "sample 1234 is NaN",
        )
        .with("index", json!(1234)),
        case(
            "+Inf in f32",
            "application/octet-stream",
            &rate,
            f32_body(&with_inf),
            NON_FINITE,
            "sample 77 is inf",
        )
        .with("index", json!(77)),
        case(
            "-Inf in float WAV",
            "audio/wav",
            "",
            wavf(&with_ninf),
            NON_FINITE,
            "sample 5 is -inf",
        )
        .with("index", json!(5)),
        case(
            "NaN literal in JSON",
            "application/json",
            "",
            br#"{"sample_rate_hz": 25600, "samples": [1, NaN]}"#.to_vec(),
            BAD_JSON,
            "JSON has no NaN or Infinity",
        ),
        case(
            "Infinity literal in JSON",
            "application/json",
            "",
            br#"{"sample_rate_hz": 25600, "samples": [1, -Infinity]}"#.to_vec(),
            BAD_JSON,
            "JSON has no NaN or Infinity",
        ),
        case(
            "1e999 in JSON (overflows to infinity)",
            "application/json",
            "",
            br#"{"sample_rate_hz": 25600, "samples": [1, 1e999, 2]}"#.to_vec(),
            BAD_JSON,
            "number out of range",
        ),
        // ---- all zeros / flat
        case(
            "all zeros in JSON",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": zeros})),
            FLAT,
            "all 20000 samples of the record are 0",
        )
        .with("samples", json!(20_000)),
        case(
            "all zeros in f32",
            "application/octet-stream",
            &rate,
            f32_body(&zeros),
            FLAT,
            "disconnected sensor",
        ),
        case(
            "all zeros in 16-bit WAV",
            "audio/wav",
            "",
            wav16(&zeros),
            FLAT,
            "carries no vibration",
        ),
        case(
            "a constant offset in CSV",
            "text/csv",
            &rate,
            "3.25\n".repeat(20_000).into_bytes(),
            FLAT,
            "are 3.25",
        ),
        // ---- clipped / saturated
        case(
            "clipped at ±1 in JSON",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": clipped})),
            CLIPPED,
            "lower the gain or widen the input range",
        )
        .with("clipped_samples", Value::Null)
        .with("longest_run", Value::Null),
        case(
            "clipped by a 16-bit WAV's full scale",
            "audio/wav",
            "",
            wav16(x),
            CLIPPED,
            "sit exactly at its maximum 0.999969",
        ),
        case(
            "only the top clipped, in f32",
            "application/octet-stream",
            &rate,
            f32_body(&top_clipped),
            CLIPPED,
            "sit exactly at its maximum 0.89999997",
        ),
        // ---- sample rate
        case(
            "sample rate 0 in JSON",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": 0, "samples": x})),
            PARAM,
            "must be a positive number of samples per second",
        )
        .with("parameter", json!("sample rate")),
        case(
            "negative sample rate in JSON",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": -25600, "samples": x})),
            PARAM,
            "must be a positive number",
        ),
        case(
            "negative sample rate in the query",
            "text/csv",
            "?sample_rate_hz=-1",
            csv_body(x),
            PARAM,
            "must be a positive number",
        ),
        case(
            "absurd sample rate (1e12 Hz) in JSON",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": 1e12, "samples": x})),
            PARAM,
            "beyond any vibration ADC",
        ),
        case(
            "absurd sample rate in the query",
            "application/octet-stream",
            "?sample_rate_hz=1e15",
            f32_body(x),
            PARAM,
            "beyond any vibration ADC",
        ),
        case(
            "NaN sample rate in the query",
            "application/octet-stream",
            "?sample_rate_hz=NaN",
            f32_body(x),
            BAD_QUERY,
            "must be a finite number",
        ),
        case(
            "sample rate that is not a number",
            "text/csv",
            "?sample_rate_hz=fast",
            csv_body(x),
            BAD_QUERY,
            "sample_rate_hz",
        ),
        case(
            "f32 without a sample rate",
            "application/octet-stream",
            "",
            f32_body(x),
            NO_RATE,
            "raw f32 (no header) carries no sample rate: give it (`?sample_rate_hz=…`)",
        ),
        case(
            "CSV without a sample rate or time column",
            "text/csv",
            "",
            csv_body(x),
            NO_RATE,
            "a CSV without a time column carries no sample rate: give it (`?sample_rate_hz=…`)",
        ),
        case(
            "sample rate below Nyquist for the needed lines",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": 2000, "samples": x, "shaft_hz": 32.1})),
            SLOW_RATE,
            "under twice the highest needed line",
        )
        .with("needed_hz", Value::Null),
        // ---- shaft rate
        case(
            "shaft rate far below the table's band",
            "application/json",
            "",
            json_body(big(5.0)),
            BAND,
            "outside the signature table",
        ),
        case(
            "shaft rate far above the table's band",
            "application/json",
            "",
            json_body(big(60.0)),
            BAND,
            "the table covers",
        ),
        case(
            "shaft rate 0",
            "application/json",
            "",
            json_body(big(0.0)),
            PARAM,
            "the input-shaft rate must be a positive number",
        )
        .with("parameter", json!("shaft_hz")),
        case(
            "negative shaft rate in the query",
            "text/csv",
            &format!("{rate}&shaft_hz=-3"),
            csv_body(x),
            PARAM,
            "the input-shaft rate must be a positive number",
        ),
        // ---- malformed bodies
        case(
            "WAV truncated inside its header",
            "audio/wav",
            "",
            good_wav[..30].to_vec(),
            MALFORMED,
            "could not be read as the stated format",
        ),
        case(
            "WAV truncated inside its data",
            "audio/wav",
            "",
            good_wav[..good_wav.len() / 2].to_vec(),
            MALFORMED,
            "truncated",
        ),
        case(
            "WAV that is a text file",
            "audio/wav",
            "",
            b"0.1\n0.2\n".to_vec(),
            MALFORMED,
            "could not be read as the stated format",
        ),
        case(
            "CSV with a word among the numbers",
            "text/csv",
            &rate,
            b"0.1\n0.2\nbanana\n".to_vec(),
            MALFORMED,
            "could not be read as the stated format",
        ),
        case(
            "f32 body whose length is not a multiple of 4",
            "application/octet-stream",
            &rate,
            vec![0u8; 4001],
            MALFORMED,
            "is not a whole number of 4-byte f32 samples",
        ),
        case(
            "JSON without samples",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs})),
            BAD_JSON,
            "missing field `samples`",
        ),
        case(
            "JSON with a string sample",
            "application/json",
            "",
            br#"{"sample_rate_hz": 25600, "samples": [1, "2"]}"#.to_vec(),
            BAD_JSON,
            "expected {\"sample_rate_hz\": number",
        ),
        case(
            "JSON array instead of a record",
            "application/json",
            "",
            b"[1, 2, 3]".to_vec(),
            BAD_JSON,
            "not a valid record",
        ),
        case(
            "JSON with an unknown field",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": [1, 2], "rate": 3})),
            BAD_JSON,
            "unknown field `rate`",
        ),
        case(
            "recorded_at that is not RFC 3339",
            "application/json",
            "",
            json_body(json!({"sample_rate_hz": fs, "samples": x, "recorded_at": "yesterday"})),
            (400, "invalid-recorded-at", "Invalid recorded_at"),
            "RFC 3339",
        ),
        // ---- content type
        case(
            "text/plain",
            "text/plain",
            &rate,
            csv_body(x),
            MEDIA,
            "send application/json, text/csv",
        )
        .with("accepted", Value::Null),
        case(
            "no content type",
            "",
            &rate,
            csv_body(x),
            MEDIA,
            "is not a record format",
        ),
        case(
            "application/xml",
            "application/xml",
            "",
            b"<samples/>".to_vec(),
            MEDIA,
            "is not a record format",
        ),
        // ---- size
        case(
            "10× the body-size limit",
            "text/csv",
            &rate,
            "0.125\n".repeat(10 * LIMIT / 6 + 1).into_bytes(),
            (413, "body-too-large", "Request body too large"),
            "send a shorter record or a binary format",
        ),
        case(
            "more samples than the limit",
            "application/octet-stream",
            &rate,
            vec![0u8; 4 * (MAX_SAMPLES + 1)],
            (413, "too-many-samples", "Record too long"),
            "split it into shorter records",
        )
        .with("limit_samples", json!(MAX_SAMPLES)),
    ]
}

async fn bad_records_get_exact_problems_and_store_nothing(b: Backend) {
    let Some(app) = spawn_app(b, |s| {
        s.limits.max_body_bytes = LIMIT;
        s.limits.max_samples = MAX_SAMPLES;
    })
    .await
    else {
        return;
    };
    let cases = cases();
    let n = cases.len();
    let mut failures = Vec::new();
    for c in cases {
        let mut req = app
            .client
            .post(app.url(&format!("/v1/machines/bad/records{}", c.query)))
            .bearer_auth(&app.ingest_key)
            .body(c.body);
        if !c.content_type.is_empty() {
            req = req.header("content-type", c.content_type);
        }
        let r = req.send().await.unwrap();
        let status = r.status().as_u16();
        let ct = r
            .headers()
            .get("content-type")
            .map(|v| v.to_str().unwrap().to_string());
        let body = r.bytes().await.unwrap();
        let p: Value = serde_json::from_slice(&body).unwrap_or(Value::Null);
        let mut wrong = vec![];
        if ct.as_deref() != Some("application/problem+json") {
            wrong.push(format!("content-type {ct:?}"));
        }
        if status != c.status || p["status"] != c.status {
            wrong.push(format!("status {status} (want {})", c.status));
        }
        if p["type"] != format!("urn:gearwear:problem:{}", c.slug) {
            wrong.push(format!("type {} (want {})", p["type"], c.slug));
        }
        if p["title"] != c.title {
            wrong.push(format!("title {} (want {:?})", p["title"], c.title));
        }
        let detail = p["detail"].as_str().unwrap_or("");
        if !detail.contains(c.detail) {
            wrong.push(format!("detail lacks {:?}", c.detail));
        }
        for (k, v) in &c.extra {
            if p.get(*k).is_none() || (!v.is_null() && &p[*k] != v) {
                wrong.push(format!("member {k} = {} (want {v})", p[*k]));
            }
        }
        if !wrong.is_empty() {
            failures.push(format!(
                "{}: {} — got {}",
                c.what,
                wrong.join("; "),
                String::from_utf8_lossy(&body)
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {n} bad records got the wrong answer:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // Nothing stored: no machine, no diagnosis, no idempotency answer.
    assert!(app.store.list_machines().await.unwrap().is_empty());
    let ms = json(&app.get("/v1/machines").await.bytes().await.unwrap());
    assert_eq!(
        ms["machines"],
        json!([]),
        "nothing stored for a rejected record"
    );
    assert_eq!(app.get("/v1/machines/bad").await.status(), 404);
    // The store still takes a good record afterwards (no half-written state left behind).
    let r = app
        .client
        .post(app.url("/v1/machines/bad/records"))
        .bearer_auth(&app.ingest_key)
        .json(&json_record(5))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let m = json(&app.get("/v1/machines/bad").await.bytes().await.unwrap());
    assert_eq!(m["record_count"], 1);
}

/// Reads of things that are not there, and requests the router refuses.
async fn bad_reads(b: Backend) {
    let Some(app) = spawn_app(b, |_| {}).await else {
        return;
    };
    let bad_id = app
        .client
        .post(app.url("/v1/machines/a%20b/records"))
        .bearer_auth(&app.ingest_key)
        .json(&json_record(1))
        .send()
        .await
        .unwrap();
    let put = app
        .client
        .put(app.url("/v1/machines"))
        .send()
        .await
        .unwrap();
    let cases: Vec<(&str, reqwest::Response, u16, &str)> = vec![
        ("bad machine id", bad_id, 400, "invalid-machine-id"),
        (
            "unknown machine",
            app.get("/v1/machines/nope").await,
            404,
            "unknown-machine",
        ),
        (
            "unknown machine diagnoses",
            app.get("/v1/machines/nope/diagnoses").await,
            404,
            "unknown-machine",
        ),
        (
            "unknown diagnosis",
            app.get("/v1/diagnoses/nope").await,
            404,
            "unknown-diagnosis",
        ),
        (
            "bad limit",
            app.get("/v1/machines/nope/diagnoses?limit=0").await,
            400,
            "invalid-query",
        ),
        (
            "unknown record",
            app.get("/v1/records/nope").await,
            404,
            "unknown-record",
        ),
        (
            "unknown route",
            app.get("/v2/nothing").await,
            404,
            "not-found",
        ),
        ("wrong method", put, 405, "method-not-allowed"),
    ];
    for (what, r, status, slug) in cases {
        assert_eq!(
            r.headers().get("content-type").map(|v| v.to_str().unwrap()),
            Some("application/problem+json"),
            "{what}"
        );
        let s = r.status().as_u16();
        let p = json(&r.bytes().await.unwrap());
        assert_eq!(
            (s, p["type"].as_str().unwrap()),
            (status, format!("urn:gearwear:problem:{slug}").as_str()),
            "{what}: {p}"
        );
        assert!(
            p["detail"].as_str().unwrap().len() > 20,
            "{what}: a detail a person can act on: {p}"
        );
    }
}
