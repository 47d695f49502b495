//! Fuzz harnesses: one function per input format, each taking arbitrary bytes.
//!
//! The `cargo fuzz` targets under `fuzz/` call these, and so does `tests/fuzz_corpus.rs`, which
//! replays every committed corpus and regression file: one harness, two drivers. Each function
//! runs the bytes through the same functions the service handler and the CLI run (not a copy)
//! and then checks invariants. A violated invariant panics on purpose, which is what the fuzzer
//! reports as a crash; a parser that panics by itself is a crash too. See
//! `docs/reliability/fuzzing.md`.

use gearwear::condition::Load;
use gearwear::configuration::{Limits, Settings};
use gearwear::gearbox::Gearbox;
use gearwear::model::Wear;
use gearwear::model::rig_b::{ModelBConfig, ModelBOptions};
use gearwear::record::{
    Column, Format, MAX_DECOMPRESSED_BYTES, MultiRecord, ReadOptions, Record, gunzip, parse_record,
    parse_record_channels,
};
use gearwear::service::error::ApiError;
use gearwear::service::wire::{BodyFormat, Decoded, JsonRecord, decode, parse_query};

/// Sample rate the harnesses pass where a format needs one (Hz).
const FS: f64 = 25_600.0;

/// The service's default request limits (what `gearwear serve` runs with).
fn limits() -> Limits {
    Settings::default().limits
}

/// A decode error must be the client's fault (4xx), never a 500.
pub fn check_problem(e: &ApiError, what: &str) {
    assert!(
        e.status.is_client_error(),
        "{what}: decode answered {} ({}): {}",
        e.status,
        e.slug,
        e.detail
    );
}

fn check_channel(samples: &[f64], limits: &Limits, what: &str) {
    assert!(!samples.is_empty(), "{what}: empty record accepted");
    assert!(
        samples.len() <= limits.max_samples,
        "{what}: {} samples accepted, limit {}",
        samples.len(),
        limits.max_samples
    );
    assert!(
        samples.iter().all(|v| v.is_finite()),
        "{what}: non-finite sample accepted"
    );
}

/// What the service's `decode` returns must be a record the diagnosis may be handed.
pub fn check_decoded(d: &Decoded, limits: &Limits, body_len: usize, what: &str) {
    assert!(
        !d.channels.is_empty(),
        "{what}: a record without channels accepted"
    );
    for (name, samples) in &d.channels {
        check_channel(samples, limits, &format!("{what}, channel {name}"));
    }
    assert!(
        d.channels.iter().map(|c| c.1.len()).sum::<usize>() <= limits.max_samples,
        "{what}: more samples than the limit {} over all channels",
        limits.max_samples
    );
    assert!(
        body_len <= limits.max_body_bytes,
        "{what}: body of {body_len} bytes accepted, limit {}",
        limits.max_body_bytes
    );
    assert!(
        d.sample_rate_hz.is_finite() && d.sample_rate_hz > 0.0,
        "{what}: sample rate {} accepted",
        d.sample_rate_hz
    );
    if let Some(s) = d.shaft_hz {
        assert!(s.is_finite(), "{what}: shaft_hz {s} accepted");
    }
    match &d.load {
        Some(Load::Label(l)) => assert!(
            !l.is_empty() && l.chars().count() <= 100,
            "{what}: load label {l:?} accepted"
        ),
        Some(Load::Value(v)) => assert!(v.is_finite(), "{what}: load {v} accepted"),
        None => {}
    }
    if let Some(s) = &d.sensor {
        assert!(
            s.len() <= 200,
            "{what}: sensor of {} bytes accepted",
            s.len()
        );
    }
    if let Some(t) = &d.recorded_at {
        assert!(
            gearwear::time::parse_rfc3339(t).is_some(),
            "{what}: recorded_at `{t}` accepted"
        );
    }
}

/// What `parse_record` returns: non-empty, finite samples, a positive finite rate (the one
/// given if one was given), and never more samples than `max_samples` (a bound from the input
/// size: the parser must not invent samples).
pub fn check_record(r: &Record, opts: &ReadOptions, max_samples: usize, what: &str) {
    assert!(!r.samples.is_empty(), "{what}: empty record accepted");
    assert!(
        r.samples.iter().all(|v| v.is_finite()),
        "{what}: non-finite sample accepted"
    );
    assert!(
        r.sample_rate.is_finite() && r.sample_rate > 0.0,
        "{what}: sample rate {} returned",
        r.sample_rate
    );
    if let Some(fs) = opts.sample_rate {
        assert_eq!(
            r.sample_rate, fs,
            "{what}: the given sample rate was not used"
        );
    }
    assert!(
        r.samples.len() <= max_samples,
        "{what}: {} samples from an input that can hold at most {max_samples}",
        r.samples.len()
    );
}

/// What `parse_record_channels` returns: at least one channel, names non-empty and distinct,
/// every channel of one non-zero length with finite samples, a positive finite rate (the one
/// given if one was given), never more samples in all than `max_samples`; only the channel
/// asked for when `opts.column` is given. An error names no CLI flag (`--…`) unless the input
/// itself holds `--` (a header name, a bad number): the service sends these to HTTP clients.
pub fn check_channels(
    r: &gearwear::Result<MultiRecord>,
    opts: &ReadOptions,
    data: &[u8],
    max_samples: usize,
    what: &str,
) {
    let r = match r {
        Ok(r) => r,
        Err(e) => {
            if !data.windows(2).any(|w| w == b"--") {
                let m = e.to_string();
                assert!(
                    !m.contains("--"),
                    "{what}: a multichannel error names a flag: {m}"
                );
            }
            return;
        }
    };
    assert!(!r.channels.is_empty(), "{what}: a record of no channel");
    if opts.column.is_some() {
        assert_eq!(r.channels.len(), 1, "{what}: one channel asked for");
    }
    let n = r.channels[0].samples.len();
    let mut total = 0usize;
    for (k, c) in r.channels.iter().enumerate() {
        assert!(!c.name.is_empty(), "{what}: channel {k} has no name");
        assert!(
            r.channels[..k].iter().all(|d| d.name != c.name),
            "{what}: two channels `{}`",
            c.name
        );
        assert!(
            n > 0 && c.samples.len() == n,
            "{what}: channel `{}` has {} samples, channel 0 {n}",
            c.name,
            c.samples.len()
        );
        assert!(
            c.samples.iter().all(|v| v.is_finite()),
            "{what}: non-finite sample accepted in `{}`",
            c.name
        );
        total += n;
    }
    assert!(
        total <= max_samples,
        "{what}: {total} samples from an input that can hold at most {max_samples}"
    );
    assert!(
        r.sample_rate.is_finite() && r.sample_rate > 0.0,
        "{what}: sample rate {} returned",
        r.sample_rate
    );
    if let Some(fs) = opts.sample_rate {
        assert_eq!(
            r.sample_rate, fs,
            "{what}: the given sample rate was not used"
        );
    }
}

/// The multichannel reader on `data` as `format` with `cases`; when reading every channel
/// succeeds, choosing each of its first four channels (by name, and by index) gives that
/// channel alone.
fn channels_cli(data: &[u8], format: Format, cases: &[(Option<f64>, Option<Column>)], what: &str) {
    for (fs, col) in cases {
        let o = opts(format, *fs, col.clone());
        let r = parse_record_channels(data, format, &o, "fuzz");
        let what = format!("{what} channels {o:?}");
        check_channels(&r, &o, data, data.len(), &what);
        let (Ok(all), None) = (&r, col) else {
            continue;
        };
        for (k, c) in all.channels.iter().enumerate().take(4) {
            // An index is first looked up as a name (a header `1,0` is legal).
            let by_index = all
                .channel(&k.to_string())
                .expect("an index below the count");
            for (key, want) in [
                (Column::Name(c.name.clone()), c),
                (Column::Index(k), by_index),
            ] {
                let o = opts(format, *fs, Some(key));
                match parse_record_channels(data, format, &o, "fuzz") {
                    Ok(one) => assert_eq!(
                        one.channels.as_slice(),
                        std::slice::from_ref(want),
                        "{what}: {o:?} is not that channel"
                    ),
                    Err(e) => panic!("{what}: {o:?} refused: {e}"),
                }
            }
        }
    }
}

fn opts(format: Format, sample_rate: Option<f64>, column: Option<Column>) -> ReadOptions {
    ReadOptions {
        format: Some(format),
        sample_rate,
        column,
    }
}

/// The service's decode of a non-JSON body, with and without `?sample_rate_hz=`.
fn service_binary(format: BodyFormat, data: &[u8]) {
    let limits = limits();
    if data.len() > limits.max_body_bytes {
        return; // `read_body` answers 413 before decoding.
    }
    for query in [None, Some("sample_rate_hz=25600")] {
        let q = parse_query(query).expect("a fixed valid query");
        let what = format!("service {format:?} {query:?}");
        // A channel named `tacho` is checked as a pulse train, as the service does for a
        // machine that names no tachometer.
        match decode(format, &q, data, &limits, Some("tacho")) {
            Ok(d) => {
                check_decoded(&d, &limits, data.len(), &what);
                if query.is_some() {
                    assert_eq!(d.sample_rate_hz, FS, "{what}: query rate not used");
                }
            }
            Err(e) => check_problem(&e, &what),
        }
    }
}

/// `POST /v1/machines/{id}/records` with `Content-Type: application/json`: the handler's
/// `decode` with the service's default limits. Checks: a 4xx problem or a record within the
/// limits with finite samples and a positive finite rate; a JSON sample takes at least two
/// bytes (`0,`), so never more than `len/2` samples.
pub fn json_body(data: &[u8]) {
    let limits = limits();
    if data.len() > limits.max_body_bytes {
        return;
    }
    json_fast_path_agrees(data);
    for query in [None, Some("shaft_hz=30&sensor=fuzz")] {
        let q = parse_query(query).expect("a fixed valid query");
        let what = format!("json {query:?}");
        match decode(BodyFormat::Json, &q, data, &limits, Some("tacho")) {
            Ok(d) => {
                check_decoded(&d, &limits, data.len(), &what);
                let n: usize = d.channels.iter().map(|c| c.1.len()).sum();
                assert!(
                    n <= data.len() / 2,
                    "{what}: {n} samples from {} bytes",
                    data.len()
                );
            }
            Err(e) => check_problem(&e, &what),
        }
    }
}

/// [`JsonRecord::from_json`] (the one-pass reader, serde_json for the rest) against
/// `serde_json::from_slice` alone: the same record, every number within one ulp (serde_json's
/// default float parser is not always correctly rounded), or the same error message. Panics
/// otherwise, naming the body.
pub fn json_fast_path_agrees(data: &[u8]) {
    let ulps = |x: f64, y: f64| (x.to_bits() as i64).wrapping_sub(y.to_bits() as i64).abs();
    let body = || String::from_utf8_lossy(data);
    match (
        JsonRecord::from_json(data),
        serde_json::from_slice::<JsonRecord>(data),
    ) {
        (Ok(a), Ok(b)) => {
            assert_eq!(
                a.samples.len(),
                b.samples.len(),
                "json: sample counts: {}",
                body()
            );
            for (&x, &y) in a.samples.iter().zip(&b.samples) {
                assert!(
                    ulps(x, y) <= 1,
                    "json: sample {x} vs serde_json {y}: {}",
                    body()
                );
            }
            let (x, y) = (a.sample_rate_hz, b.sample_rate_hz);
            assert!(
                ulps(x, y) <= 1,
                "json: sample_rate_hz {x} vs serde_json {y}: {}",
                body()
            );
            match (a.shaft_hz, b.shaft_hz) {
                (Some(x), Some(y)) => {
                    assert!(ulps(x, y) <= 1, "json: shaft_hz {x} vs {y}: {}", body())
                }
                (x, y) => assert_eq!(x, y, "json: shaft_hz: {}", body()),
            }
            match (&a.load, &b.load) {
                (Some(Load::Value(x)), Some(Load::Value(y))) => {
                    assert!(ulps(*x, *y) <= 1, "json: load {x} vs {y}: {}", body())
                }
                (x, y) => assert_eq!(x, y, "json: load: {}", body()),
            }
            // The `channels` form always goes through serde_json: equal, not within an ulp.
            assert_eq!(a.channels, b.channels, "json: channels: {}", body());
            assert_eq!(
                (a.recorded_at, a.sensor),
                (b.recorded_at, b.sensor),
                "json: strings: {}",
                body()
            );
        }
        (Err(a), Err(b)) => assert_eq!(
            a.to_string(),
            b.to_string(),
            "json: error messages: {}",
            body()
        ),
        (a, b) => panic!("json: fast path {a:?}, serde_json {b:?}: {}", body()),
    }
}

/// CSV as the service (`text/csv`) and the CLI (`--format csv`, several `--column` /
/// `--sample-rate` choices) read it. Checks [`check_record`]; a CSV row is at least one
/// byte and a line end, so never more samples than lines.
pub fn csv(data: &[u8]) {
    service_binary(BodyFormat::Csv, data);
    csv_cli(data, "csv");
}

fn csv_cli(data: &[u8], what: &str) {
    let lines = data.split(|&b| b == b'\n' || b == b'\r').count();
    for (fs, col) in [
        (None, None),
        (Some(FS), None),
        (None, Some(Column::Index(0))),
        (Some(FS), Some(Column::Index(2))),
        (None, Some(Column::Name("value".into()))),
    ] {
        let o = opts(Format::Csv, fs, col);
        if let Ok(r) = parse_record(data, Format::Csv, &o, "fuzz") {
            check_record(&r, &o, lines, &format!("{what} {o:?}"));
        }
    }
    channels_cli(
        data,
        Format::Csv,
        &[
            (None, None),
            (Some(FS), None),
            (Some(FS), Some(Column::Index(1))),
            (None, Some(Column::Name("a1".into()))),
        ],
        what,
    );
}

/// A `.gz` record as `read_record` reads it: [`gunzip`] with the CLI's limit, then the CSV
/// parser. Checks: the output never exceeds the limit; a small limit refuses exactly the
/// streams that expand beyond it and otherwise yields the same bytes.
pub fn csv_gz(data: &[u8]) {
    const SMALL: usize = 4096;
    let full = gunzip(data, "fuzz.csv.gz", MAX_DECOMPRESSED_BYTES);
    let small = gunzip(data, "fuzz.csv.gz", SMALL);
    match (&full, &small) {
        (Ok(f), Ok(s)) => {
            assert!(
                s.len() <= SMALL,
                "gunzip returned {} > {SMALL} bytes",
                s.len()
            );
            assert_eq!(f, s, "the limit changed the decompressed bytes");
        }
        (Ok(f), Err(_)) => assert!(
            f.len() > SMALL,
            "a {}-byte stream was refused by the {SMALL}-byte limit",
            f.len()
        ),
        (Err(_), Ok(s)) => panic!("a {}-byte stream passed only the smaller limit", s.len()),
        (Err(_), Err(_)) => {}
    }
    if let Ok(text) = full {
        assert!(text.len() <= MAX_DECOMPRESSED_BYTES);
        csv_cli(&text, "csv.gz");
    }
}

/// Raw little-endian `f32` as the service (`application/octet-stream`) and the CLI read it.
/// Checks: accepted exactly when the length is a positive multiple of 4, every value is finite,
/// the samples pass [`gearwear::record::check_signal`] (not flat, not clipped) and a rate is
/// given; then `len/4` samples equal to the input's values.
pub fn f32_raw(data: &[u8]) {
    service_binary(BodyFormat::F32, data);
    let values: Vec<f32> = data
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let valid = !data.is_empty()
        && data.len().is_multiple_of(4)
        && values.iter().all(|v| v.is_finite())
        && gearwear::record::check_signal(
            &values.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(),
        )
        .is_ok();
    let o = opts(Format::F32, Some(FS), None);
    match parse_record(data, Format::F32, &o, "fuzz") {
        Ok(r) => {
            assert!(valid, "invalid f32 input accepted");
            check_record(&r, &o, data.len() / 4, "f32");
            assert_eq!(r.samples.len(), data.len() / 4, "f32: wrong sample count");
            for (a, b) in r.samples.iter().zip(&values) {
                assert_eq!(a.to_bits(), (*b as f64).to_bits(), "f32: value changed");
            }
        }
        Err(e) => assert!(!valid, "valid f32 input refused: {e}"),
    }
    let o = opts(Format::F32, None, None);
    assert!(
        parse_record(data, Format::F32, &o, "fuzz").is_err(),
        "raw f32 without a sample rate accepted"
    );
    // The multichannel reader: one channel `"0"`, the same samples, the same verdict.
    let o = opts(Format::F32, Some(FS), None);
    let r = parse_record_channels(data, Format::F32, &o, "fuzz");
    check_channels(&r, &o, data, data.len() / 4, "f32 channels");
    match r {
        Ok(r) => {
            assert!(valid, "invalid f32 input accepted as channels");
            assert_eq!(r.names(), ["0"], "f32: channel names");
            for (a, b) in r.channels[0].samples.iter().zip(&values) {
                assert_eq!(
                    a.to_bits(),
                    (*b as f64).to_bits(),
                    "f32 channels: value changed"
                );
            }
        }
        Err(e) => assert!(!valid, "valid f32 input refused as channels: {e}"),
    }
}

/// RIFF/WAVE as the service (`audio/wav`) and the CLI read it (channel 0 by default, channel
/// 1, a given sample rate). Checks [`check_record`]; every sample takes at least one byte of
/// the input, so never more samples than bytes (a header that claims a huge data size must not
/// create them); channel 0 given explicitly equals the default.
pub fn wav(data: &[u8]) {
    service_binary(BodyFormat::Wav, data);
    let mut default = None;
    for (fs, col) in [
        (None, None),
        (None, Some(Column::Index(0))),
        (None, Some(Column::Index(1))),
        (Some(8000.0), None),
    ] {
        let o = opts(Format::Wav, fs, col.clone());
        let r = parse_record(data, Format::Wav, &o, "fuzz");
        if let Ok(r) = &r {
            check_record(r, &o, data.len(), &format!("wav {o:?}"));
        }
        match (fs, &col) {
            (None, None) => default = Some(r.ok()),
            (None, Some(Column::Index(0))) => assert_eq!(
                default.take().flatten(),
                r.ok(),
                "wav: channel 0 differs from the default channel"
            ),
            _ => {}
        }
    }
    let cases = [
        (None, None),
        (Some(8000.0), None),
        (None, Some(Column::Index(1))),
    ];
    channels_cli(data, Format::Wav, &cases, "wav");
    // Every channel read together is the channel the single-channel reader picks.
    if let Ok(all) = parse_record_channels(data, Format::Wav, &opts(Format::Wav, None, None), "f") {
        for (k, c) in all.channels.iter().enumerate().take(4) {
            let o = opts(Format::Wav, None, Some(Column::Index(k)));
            match parse_record(data, Format::Wav, &o, "fuzz") {
                Ok(r) => assert_eq!(
                    (r.samples.as_slice(), r.sample_rate),
                    (c.samples.as_slice(), all.sample_rate),
                    "wav: channel {k} differs between the readers"
                ),
                Err(e) => panic!("wav: channel {k} read together, refused alone: {e}"),
            }
        }
    }
}

/// The model configuration files (gearbox descriptions `configs/gearboxes/*.toml` for
/// `--gearbox FILE`, and `configs/model_b.toml`): parse as both and, when that succeeds, build
/// and resolve the assembly, as `simulate`/`sweep`/`model-b` do before integrating. Checks: no
/// panic, and a description that loads has finite positive mesh frequencies and a finite
/// positive reference frequency.
pub fn model_config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return; // `from_file` reads with `read_to_string`, which refuses non-UTF-8.
    };
    if let Ok(gb) = Gearbox::parse(text, "fuzz.toml") {
        assert!(
            gb.mesh_ratios.iter().all(|r| r.is_finite() && *r > 0.0),
            "gearbox: mesh frequency ratios {:?}",
            gb.mesh_ratios
        );
        let f = gb.reference_frequency_hz();
        assert!(f.is_finite() && f > 0.0, "gearbox: reference frequency {f}");
        if let Ok(asm) = gb.assembly(Wear::fixed_axis(0.5))
            && let Ok(m) = asm.resolve()
        {
            assert!(
                m.omega_h.is_finite() && m.omega_h > 0.0,
                "gearbox: omega_h {}",
                m.omega_h
            );
        }
    }
    if let Ok(cfg) = ModelBConfig::from_toml(text, "fuzz.toml") {
        let (p1, p2) = cfg.mesh_periods_s();
        assert!(
            p1 > 0.0 && p2 > 0.0,
            "model B: mesh periods {p1}, {p2} from a loaded config"
        );
        if let Ok(asm) = cfg.assembly(&ModelBOptions::default())
            && let Ok(m) = asm.resolve()
        {
            assert!(
                m.omega_h.is_finite() && m.omega_h > 0.0,
                "model B: omega_h {}",
                m.omega_h
            );
        }
    }
}

/// A harness: arbitrary bytes in, a panic on a crash or a broken invariant.
pub type Harness = fn(&[u8]);

/// The harnesses by target name (the names of `fuzz/fuzz_targets/*.rs` and of the
/// `fuzz/seeds/<target>/`, `fuzz/corpus/<target>/` and `fuzz/regressions/<target>/` folders).
pub const TARGETS: [(&str, Harness); 7] = [
    ("json_body", json_body),
    ("csv", csv),
    ("csv_gz", csv_gz),
    ("f32_raw", f32_raw),
    ("wav", wav),
    ("model_config", model_config),
    ("quality", quality),
];

/// The record-quality checks ([`gearwear::record::quality`]) on the input read as raw
/// little-endian `f32` samples at 12.8 kHz. Checks: no panic; on a record that passes
/// [`gearwear::record::check_signal`], [`gearwear::record::inspect`] either refuses with a
/// finding whose sample range lies inside the record, or returns spans inside the record whose
/// repair leaves every sample finite and changes no sample outside them.
pub fn quality(data: &[u8]) {
    let x: Vec<f64> = data
        .chunks_exact(4)
        .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        .collect();
    if gearwear::record::check_signal(&x).is_err() {
        return;
    }
    match gearwear::record::inspect(&x, 12_800.0, None) {
        Ok(ins) => {
            let mut y = x.clone();
            ins.repair(&mut y);
            let mut inside = vec![false; x.len()];
            for &(a, b) in &ins.spans {
                assert!(a <= b && b < x.len(), "span {a}..={b} outside the record");
                inside[a..=b].iter_mut().for_each(|v| *v = true);
            }
            for (i, (a, b)) in x.iter().zip(&y).enumerate() {
                assert!(b.is_finite(), "repair left sample {i} non-finite");
                if !inside[i] {
                    assert_eq!(a.to_bits(), b.to_bits(), "repair changed sample {i}");
                }
            }
        }
        Err(gearwear::Error::RecordQuality(f)) => {
            assert!(
                f.first_sample <= f.last_sample && f.last_sample < x.len(),
                "{f:?}"
            );
        }
        Err(e) => panic!("inspect failed with a non-quality error: {e}"),
    }
}
