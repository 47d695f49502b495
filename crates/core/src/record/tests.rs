use super::*;

fn sine(n: usize, per_period: f64, amp: f64) -> Vec<f64> {
    (0..n)
        .map(|i| amp * (std::f64::consts::TAU * i as f64 / per_period + 0.3).sin())
        .collect()
}

#[test]
fn check_signal_refuses_empty_nan_flat_and_clipped() {
    assert!(matches!(check_signal(&[]), Err(Error::EmptyRecord)));
    assert!(matches!(
        check_signal(&[1.0, f64::NAN, 2.0]),
        Err(Error::NonFiniteSample { index: 1, .. })
    ));
    assert!(matches!(
        check_signal(&[0.0, 1.0, f64::NEG_INFINITY]),
        Err(Error::NonFiniteSample { index: 2, .. })
    ));
    assert!(matches!(
        check_signal(&[0.0; 1000]),
        Err(Error::FlatRecord { samples: 1000, .. })
    ));
    // One sample is not flat: the estimator says it is too short.
    assert!(check_signal(&[0.5]).is_ok());
    // A sine of amplitude 1.6 through an ADC whose range ends at ±1.
    let clipped: Vec<f64> = sine(25_600, 29.4, 1.6)
        .iter()
        .map(|v| v.clamp(-1.0, 1.0))
        .collect();
    match check_signal(&clipped) {
        Err(Error::ClippedRecord {
            side,
            level,
            longest_run,
            ..
        }) => {
            assert_eq!((side, level), ("maximum", 1.0));
            assert!(longest_run >= 5, "{longest_run}");
        }
        other => panic!("clipped sine passed: {other:?}"),
    }
    // Only the bottom saturates.
    let bottom: Vec<f64> = sine(25_600, 29.4, 1.0)
        .iter()
        .map(|v| v.max(-0.8))
        .collect();
    assert!(matches!(
        check_signal(&bottom),
        Err(Error::ClippedRecord {
            side: "minimum",
            ..
        })
    ));
}

/// A tachometer's pulses sit at the supply rail (an open collector pulled up to 5 V: exactly
/// 5.0 for many samples in a row) between noisy lows: refused as clipped by `check_signal`,
/// accepted as a pulse train by `check_pulses` (which still refuses a flat channel), and only
/// for the channel named as the tachometer.
#[test]
fn a_tachometer_square_wave_is_a_pulse_train_not_a_clipped_record() {
    let square: Vec<f64> = (0..20_000)
        .map(|i| {
            if (i % 50) < 15 {
                5.0
            } else {
                0.02 * (i as f64 * 0.37).sin()
            }
        })
        .collect();
    assert!(matches!(
        check_signal(&square),
        Err(Error::ClippedRecord { .. })
    ));
    assert!(check_pulses(&square).is_ok());
    assert!(matches!(
        check_pulses(&[5.0; 100]),
        Err(Error::FlatRecord { .. })
    ));
    let mut csv = String::from("tacho,a1\n");
    for (i, v) in square.iter().enumerate() {
        csv.push_str(&format!("{v},{}\n", (i as f64 * 0.37).sin()));
    }
    let opts = ReadOptions {
        sample_rate: Some(20_000.0),
        ..Default::default()
    };
    let e = parse_record_channels(csv.as_bytes(), Format::Csv, &opts, "body").unwrap_err();
    assert!(e.to_string().contains("tacho"), "{e}");
    let r = parse_record_channels_with_pulses(
        csv.as_bytes(),
        Format::Csv,
        &opts,
        "body",
        Some("tacho"),
    )
    .unwrap();
    assert_eq!(r.names(), ["tacho", "a1"]);
}

#[test]
fn check_signal_accepts_unclipped_records_even_coarsely_quantised() {
    // Continuous values: every extreme occurs once.
    assert!(check_signal(&sine(25_600, 29.4, 1.6)).is_ok());
    // A slow sine on an 8-bit ADC using its whole range: the top code is held for several
    // samples at each peak, but no more often than the codes just below (no pile-up).
    for per_period in [29.4, 200.0, 1000.0] {
        let q: Vec<f64> = sine(25_600, per_period, 127.0)
            .iter()
            .map(|v| v.round())
            .collect();
        assert!(
            check_signal(&q).is_ok(),
            "8-bit sine, {per_period} samples/period"
        );
    }
    // Plus noise, 16-bit.
    let mut state = 7u64;
    let noisy: Vec<f64> = sine(25_600, 29.4, 20_000.0)
        .iter()
        .map(|v| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (v + ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2000.0).round()
        })
        .collect();
    assert!(check_signal(&noisy).is_ok());
}

#[test]
fn sample_rates_beyond_any_adc_are_refused() {
    assert!(check_sample_rate(25_600.0).is_ok());
    assert!(check_sample_rate(MAX_SAMPLE_RATE_HZ).is_ok());
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e12] {
        assert!(
            matches!(check_sample_rate(bad), Err(Error::InvalidParameter { .. })),
            "{bad}"
        );
    }
}

fn opts(fs: Option<f64>, col: Option<&str>) -> ReadOptions {
    ReadOptions {
        format: None,
        sample_rate: fs,
        column: col.map(Column::parse),
    }
}

#[test]
fn csv_variants() {
    let r = parse_record(b"1\n2\n3\n", Format::Csv, &opts(Some(10.0), None), "t").unwrap();
    assert_eq!(r.samples, vec![1.0, 2.0, 3.0]);
    let r = parse_record(
        b"time,acc\n0,1\n0.5,2\n1.0,3\n",
        Format::Csv,
        &opts(None, None),
        "t",
    )
    .unwrap();
    assert_eq!(r.samples, vec![1.0, 2.0, 3.0]);
    assert!((r.sample_rate - 2.0).abs() < 1e-12);
    let r = parse_record(
        b"a1,a2,a3\n1,2,3\n4,5,6\n",
        Format::Csv,
        &opts(Some(1.0), Some("a2")),
        "t",
    )
    .unwrap();
    assert_eq!(r.samples, vec![2.0, 5.0]);
    let r = parse_record(
        b"1;2;3\n4;5;6\n",
        Format::Csv,
        &opts(Some(1.0), Some("2")),
        "t",
    )
    .unwrap();
    assert_eq!(r.samples, vec![3.0, 6.0]);
    assert!(parse_record(b"1,2,3\n", Format::Csv, &opts(Some(1.0), None), "t").is_err());
    assert!(parse_record(b"1\n2\n", Format::Csv, &opts(None, None), "t").is_err());
    assert!(parse_record(b"", Format::Csv, &opts(Some(1.0), None), "t").is_err());
    assert!(matches!(
        parse_record(b"1\nnan\n", Format::Csv, &opts(Some(1.0), None), "t"),
        Err(Error::NonFiniteSample { index: 1, .. })
    ));
}

#[test]
fn f32_and_wav() {
    let x: Vec<f64> = (0..100).map(|i| (i as f64 * 0.1).sin() * 0.5).collect();
    let raw: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
    let r = parse_record(&raw, Format::F32, &opts(Some(100.0), None), "t").unwrap();
    assert!((r.samples[7] - x[7]).abs() < 1e-6);
    assert!(
        parse_record(
            &raw[..raw.len() - 1],
            Format::F32,
            &opts(Some(1.0), None),
            "t"
        )
        .is_err()
    );
    assert!(parse_record(&raw, Format::F32, &opts(None, None), "t").is_err());
    for float in [false, true] {
        let w = encode_wav(&x, 8000, float);
        let r = parse_record(&w, Format::Wav, &opts(None, None), "t").unwrap();
        assert_eq!(r.sample_rate, 8000.0);
        assert_eq!(r.samples.len(), x.len());
        assert!((r.samples[7] - x[7]).abs() < 1e-4);
        assert!(parse_record(&w[..w.len() - 3], Format::Wav, &opts(None, None), "t").is_err());
        assert!(parse_record(&w[..30], Format::Wav, &opts(None, None), "t").is_err());
    }
}

/// A gzip member of `n` zero bytes (compresses about 1000:1).
fn gz_zeros(n: usize) -> Vec<u8> {
    use flate2::{Compression, write::GzEncoder};
    use std::io::Write;
    let mut enc = GzEncoder::new(Vec::new(), Compression::best());
    enc.write_all(&vec![0u8; n]).unwrap();
    enc.finish().unwrap()
}

#[test]
fn gunzip_refuses_a_stream_beyond_its_limit() {
    let gz = gz_zeros(10_000);
    assert_eq!(gunzip(&gz, "t.gz", 10_000).unwrap().len(), 10_000);
    let e = gunzip(&gz, "t.gz", 9_999).unwrap_err().to_string();
    assert!(e.contains("expands beyond 9999 bytes"), "{e}");
    // Concatenated members count together.
    let two = [gz.clone(), gz].concat();
    assert_eq!(gunzip(&two, "t.gz", 20_000).unwrap().len(), 20_000);
    assert!(gunzip(&two, "t.gz", 19_999).is_err());
    assert!(gunzip(b"not gzip", "t.gz", 100).is_err());
}

/// A gzip bomb: 257 concatenated 1 MiB members of zeros (about 260 KB on disk) expand to
/// 257 MiB, past `MAX_DECOMPRESSED_BYTES`; `read_record` refuses it instead of
/// decompressing without bound (before the cap it read the whole stream into memory).
#[test]
fn read_record_refuses_a_gzip_bomb() {
    let member = gz_zeros(1 << 20);
    let n = MAX_DECOMPRESSED_BYTES / (1 << 20) + 1;
    let bomb: Vec<u8> = member
        .iter()
        .copied()
        .cycle()
        .take(member.len() * n)
        .collect();
    assert!(bomb.len() < 1 << 20, "the bomb is small on disk");
    let dir = std::env::temp_dir().join(format!("gearwear-bomb-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bomb.csv.gz");
    std::fs::write(&path, &bomb).unwrap();
    let r = read_record(&path, &opts(Some(1.0), None));
    std::fs::remove_dir_all(&dir).ok();
    match r {
        Err(Error::RecordFormat { reason, .. }) => {
            assert!(
                reason.contains("expands beyond 268435456 bytes"),
                "{reason}"
            )
        }
        other => panic!("a gzip bomb was not refused: {other:?}"),
    }
}

#[test]
fn csv_time_step_without_a_finite_rate_is_refused() {
    // Found by review for the fuzz harness's rate invariant: 1/5e-324 = inf.
    let e = parse_record(b"t,v\n0,1\n5e-324,2\n", Format::Csv, &opts(None, None), "t")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no finite sample rate"), "{e}");
}

#[test]
fn csv_line_of_only_quotes_is_skipped() {
    // fuzz/regressions/csv/quote-only-line-then-number.csv, found by `cargo fuzz run csv`:
    // the line `"` has no field; it became an empty row and `r[value_col]` panicked.
    let r = parse_record(b"\"\n000.03554\n", Format::Csv, &opts(Some(1.0), None), "t").unwrap();
    assert_eq!(r.samples, vec![0.03554]);
    let r = parse_record(b"\"  \"\n1\n2\n", Format::Csv, &opts(Some(1.0), None), "t").unwrap();
    assert_eq!(r.samples, vec![1.0, 2.0]);
}

// ---- multichannel ----

/// `rows` rows of `cols` distinct values: row k, column c holds `c + k/100` (sin-free and
/// never flat or clipped).
fn table_csv(header: Option<&str>, cols: usize, rows: usize) -> String {
    let mut s = header.map(|h| format!("{h}\n")).unwrap_or_default();
    for k in 0..rows {
        let row: Vec<String> = (0..cols)
            .map(|c| format!("{}", c as f64 + ((k * 7) % 11) as f64 / 100.0))
            .collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
}

fn channels(csv: &str, fs: Option<f64>, col: Option<&str>) -> Result<MultiRecord> {
    parse_record_channels(csv.as_bytes(), Format::Csv, &opts(fs, col), "t")
}

#[test]
fn csv_channels_named_by_the_header() {
    let csv = table_csv(Some("a1,a2,a3,a4"), 4, 20);
    let r = channels(&csv, Some(12_800.0), None).unwrap();
    assert_eq!(r.names(), ["a1", "a2", "a3", "a4"]);
    assert_eq!(r.sample_rate, 12_800.0);
    for (c, ch) in r.channels.iter().enumerate() {
        assert_eq!(ch.samples.len(), 20);
        // The same column as the single-channel reader picks.
        let one = parse_record(
            csv.as_bytes(),
            Format::Csv,
            &opts(Some(12_800.0), Some(&c.to_string())),
            "t",
        )
        .unwrap();
        assert_eq!(ch.samples, one.samples, "{}", ch.name);
    }
    // The single-channel reader still asks the CLI user for --column.
    let e = parse_record(csv.as_bytes(), Format::Csv, &opts(Some(1.0), None), "t")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("choose one with --column") && e.contains("(a1, a2, a3, a4)"),
        "{e}"
    );
}

#[test]
fn csv_channels_without_a_header_are_numbered() {
    let r = channels(&table_csv(None, 3, 10), Some(100.0), None).unwrap();
    assert_eq!(r.names(), ["0", "1", "2"]);
    assert_eq!(r.channels[2].samples[1], 2.07);
    let r = channels("1\n2\n3\n", Some(100.0), None).unwrap();
    assert_eq!(r.names(), ["0"]);
    assert_eq!(r.channels[0].samples, [1.0, 2.0, 3.0]);
    // Two columns without a header are `time,value`, as for the single-channel reader.
    let r = channels("0,1\n0.5,2\n1.0,3\n", None, None).unwrap();
    assert_eq!(r.names(), ["0"]);
    assert_eq!(r.channels[0].samples, [1.0, 2.0, 3.0]);
    assert!((r.sample_rate - 2.0).abs() < 1e-12);
}

#[test]
fn csv_time_column_gives_the_rate_and_is_no_channel() {
    let csv = "Time,a1,a2\n0,1,5\n0.001,2,4\n0.002,3,6\n0.003,1,4\n";
    let r = channels(csv, None, None).unwrap();
    assert_eq!(r.names(), ["a1", "a2"]);
    assert!((r.sample_rate - 1000.0).abs() < 1e-9, "{}", r.sample_rate);
    assert_eq!(r.channels[1].samples, [5.0, 4.0, 6.0, 4.0]);
    // A given rate wins; the time column is still not a channel.
    let r = channels(csv, Some(50.0), None).unwrap();
    assert_eq!(
        (r.sample_rate, r.names()),
        (50.0, vec!["a1".to_string(), "a2".to_string()])
    );
    // `time,acc`: one channel.
    let r = channels("t,acc\n0,1\n0.5,2\n1.0,3\n", None, None).unwrap();
    assert_eq!(r.names(), ["acc"]);
    // Two named columns that are not a time are two channels (the single-channel reader
    // takes the first of two columns as the time whatever its name).
    let r = channels("a1,a2\n1,2\n3,5\n", Some(10.0), None).unwrap();
    assert_eq!(r.names(), ["a1", "a2"]);
    // No time column, no rate: asked for without naming a CLI flag.
    let e = channels("a1,a2\n1,2\n3,5\n", None, None).unwrap_err();
    assert!(matches!(e, Error::MissingSampleRate { .. }), "{e:?}");
    assert!(e.to_string().ends_with("give the sample rate in Hz"), "{e}");
    let e = channels("time,a1,a2\n0,1,5\n0.001,2,4\n0.005,3,6\n", None, None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("non-uniform time column") && e.ends_with("resample or give the sample rate"),
        "{e}"
    );
}

#[test]
fn one_channel_chosen_by_name_or_index() {
    let csv = table_csv(Some("time,a1,a2,a3,a4"), 5, 16);
    let all = channels(&csv, Some(1000.0), None).unwrap();
    for key in ["a3", "2"] {
        assert_eq!(all.channel(key).unwrap().name, "a3", "{key}");
    }
    assert_eq!(all.record("a3").unwrap().samples, all.channels[2].samples);
    assert_eq!(all.record("a3").unwrap().sample_rate, 1000.0);
    // `opts.column` keeps just that channel, chosen the same way (the index counts
    // channels, not the time column).
    for key in ["a3", "2"] {
        let one = channels(&csv, Some(1000.0), Some(key)).unwrap();
        assert_eq!(one.channels, [all.channel("a3").unwrap().clone()], "{key}");
    }
    // WAV and f32: names are indices.
    let (x, y) = (sine(64, 16.0, 0.5), sine(64, 5.0, 0.25));
    let wav = encode_wav_channels(&[&x, &y], 8000, true);
    let one = parse_record_channels(&wav, Format::Wav, &opts(None, Some("1")), "t").unwrap();
    assert_eq!(one.names(), ["1"]);
    let raw: Vec<u8> = x.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
    let r = parse_record_channels(&raw, Format::F32, &opts(Some(100.0), Some("0")), "t").unwrap();
    assert_eq!(r.names(), ["0"]);
    assert!(parse_record_channels(&raw, Format::F32, &opts(Some(1.0), Some("1")), "t").is_err());
}

#[test]
fn an_unknown_channel_lists_the_channels() {
    let csv = table_csv(Some("a1,a2,a3,a4"), 4, 8);
    let all = channels(&csv, Some(1.0), None).unwrap();
    for key in ["a9", "4", "time"] {
        let e = all.channel(key).unwrap_err();
        assert!(matches!(&e, Error::UnknownChannel { requested, available }
            if requested == key && available.len() == 4));
        let e = e.to_string();
        assert!(
            e.contains(&format!("no channel `{key}`"))
                && e.contains("`a1`, `a2`, `a3`, `a4`")
                && !e.contains("--"),
            "{e}"
        );
    }
    let e = channels(&csv, Some(1.0), Some("a9")).unwrap_err();
    assert!(matches!(e, Error::UnknownChannel { .. }), "{e:?}");
    // Many channels: the first 16 and the count.
    let many = MultiRecord {
        sample_rate: 1.0,
        channels: (0..40)
            .map(|i| Channel {
                name: i.to_string(),
                samples: vec![0.0, 1.0],
            })
            .collect(),
    };
    let e = many.channel("x").unwrap_err().to_string();
    assert!(
        e.contains("`15`, … (40 in all)") && !e.contains("`16`"),
        "{e}"
    );
}

#[test]
fn a_bad_channel_is_named_in_the_error() {
    let csv = "a1,a2,a3\n1,2,3\n2,nan,4\n3,1,5\n";
    let e = channels(csv, Some(10.0), None).unwrap_err();
    match &e {
        Error::InChannel { channel, error } => {
            assert_eq!(channel, "a2");
            assert!(matches!(**error, Error::NonFiniteSample { index: 1, .. }));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        e.to_string(),
        "channel `a2`: sample 1 of the record is NaN; the record must contain only finite \
         numbers"
    );
    let (ch, inner) = e.split_channel();
    assert_eq!(ch, Some("a2"));
    assert!(matches!(inner, Error::NonFiniteSample { .. }));
    // Only the channel asked for is checked.
    assert!(channels(csv, Some(10.0), Some("a3")).is_ok());
    // A dead (flat) channel.
    let e = channels("x,y\n1,0\n2,0\n3,0\n", Some(10.0), None).unwrap_err();
    assert!(
        matches!(&e, Error::InChannel { channel, error }
            if channel == "y" && matches!(**error, Error::FlatRecord { samples: 3, .. })),
        "{e:?}"
    );
    // A WAV's second channel.
    let x = sine(64, 16.0, 0.5);
    let wav = encode_wav_channels(&[&x, &[0.0; 64]], 8000, false);
    let e = parse_record_channels(&wav, Format::Wav, &opts(None, None), "t").unwrap_err();
    assert!(
        e.to_string().starts_with("channel `1`: all 64 samples"),
        "{e}"
    );
    assert_eq!(
        check_channel(&Channel {
            name: "j".into(),
            samples: vec![]
        })
        .unwrap_err()
        .to_string(),
        "channel `j`: the record holds no samples; send at least one second of signal"
    );
}

#[test]
fn wav_two_channels() {
    let (x, y) = (sine(200, 16.0, 0.5), sine(200, 7.0, 0.8));
    for float in [false, true] {
        let w = encode_wav_channels(&[&x, &y], 8000, float);
        let r = parse_record_channels(&w, Format::Wav, &opts(None, None), "t").unwrap();
        assert_eq!(
            (r.sample_rate, r.names()),
            (8000.0, vec!["0".to_string(), "1".to_string()])
        );
        for (ch, want) in r.channels.iter().zip([&x, &y]) {
            assert_eq!(ch.samples.len(), 200);
            let err = ch.samples.iter().zip(want).map(|(a, b)| (a - b).abs());
            assert!(err.fold(0.0, f64::max) < 1e-4, "{}", ch.name);
        }
        // The single-channel reader's channel 1 is the same.
        let one = parse_record(&w, Format::Wav, &opts(None, Some("1")), "t").unwrap();
        assert_eq!(one.samples, r.channels[1].samples);
        let e = parse_record_channels(&w, Format::Wav, &opts(None, Some("a1")), "t")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no channel `a1`") && e.contains("`0`, `1`"),
            "{e}"
        );
    }
    // A mono file encodes as before.
    assert_eq!(
        encode_wav(&x, 8000, false),
        encode_wav_channels(&[&x], 8000, false)
    );
}

#[test]
fn csv_header_names_must_be_unique_and_non_empty() {
    let e = channels("a,b,a\n1,2,3\n2,3,4\n", Some(1.0), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("two columns `a` (0 and 2)"), "{e}");
    let e = channels("t,a,\"\"\n0,2,3\n1,3,4\n", None, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("column 2 has an empty name"), "{e}");
}

/// Over HTTP there is no command line: no multichannel error names a flag.
#[test]
fn multichannel_errors_name_no_cli_flag() {
    let wav = encode_wav(&sine(64, 16.0, 0.5), 0, true);
    let cases: Vec<(&[u8], Format, ReadOptions)> = vec![
        (&b"a1,a2,a3\n1,2,3\n"[..], Format::Csv, opts(None, None)),
        (&b"1,2,3\n4,5,6\n"[..], Format::Csv, opts(None, Some("7"))),
        (&b"time,a\n1,2\n0,3\n"[..], Format::Csv, opts(None, None)),
        (
            &b"time,a\n0,2\n5e-324,3\n"[..],
            Format::Csv,
            opts(None, None),
        ),
        (&b"\xff\xfe"[..], Format::Csv, opts(Some(1.0), None)),
        (&b"1,2\n3\n"[..], Format::Csv, opts(Some(1.0), None)),
        (&b"\x00\x00\x80\x3f"[..], Format::F32, opts(None, None)),
        (&wav[..], Format::Wav, opts(None, None)),
        (&wav[..], Format::Wav, opts(Some(8000.0), Some("x"))),
        (&b"1\n2\n"[..], Format::Csv, opts(Some(0.0), None)),
    ];
    for (bytes, format, o) in cases {
        let e = parse_record_channels(bytes, format, &o, "body")
            .unwrap_err()
            .to_string();
        assert!(!e.contains("--"), "{format:?} {o:?}: {e}");
    }
    // The same inputs through the single-channel reader keep the CLI's wording.
    let e = parse_record(&wav, Format::Wav, &opts(None, None), "f").unwrap_err();
    assert!(e.to_string().ends_with("give --sample-rate"), "{e}");
    let e = parse_record(b"1\n2\n", Format::Csv, &opts(None, None), "f").unwrap_err();
    assert_eq!(
        e.to_string(),
        "a CSV without a time column carries no sample rate: give it (--sample-rate HZ)"
    );
}

#[test]
fn gzip_csv_channels_from_a_file() {
    use flate2::{Compression, write::GzEncoder};
    use std::io::Write;
    let csv = table_csv(Some("time,a1,a2,a3,a4"), 5, 0)
        + &(0..100)
            .map(|k| {
                let t = k as f64 / 12_800.0;
                format!("{t},{},{},{},{}\n", k % 7, k % 5, k % 3, (k * k) % 11)
            })
            .collect::<String>();
    let mut enc = GzEncoder::new(Vec::new(), Compression::default());
    enc.write_all(csv.as_bytes()).unwrap();
    let dir = std::env::temp_dir().join(format!("gearwear-multich-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.csv.gz");
    std::fs::write(&path, enc.finish().unwrap()).unwrap();
    let r = read_record_channels(&path, &ReadOptions::default());
    let one = read_record_channels(
        &path,
        &ReadOptions {
            column: Some(Column::Name("a4".into())),
            ..ReadOptions::default()
        },
    );
    std::fs::remove_dir_all(&dir).ok();
    let r = r.unwrap();
    assert_eq!(r.names(), ["a1", "a2", "a3", "a4"]);
    assert!((r.sample_rate - 12_800.0).abs() < 1e-6, "{}", r.sample_rate);
    assert_eq!(r.channels[1].samples[..6], [0.0, 1.0, 2.0, 3.0, 4.0, 0.0]);
    assert_eq!(one.unwrap().channels, [r.channels[3].clone()]);
}

/// A 2 kHz sine with `n` one-sample impulses of `height` every 500 samples.
fn with_impulses(n: usize, height: f64) -> Vec<f64> {
    let mut x: Vec<f64> = (0..20_000)
        .map(|i| (2.0 * std::f64::consts::PI * 2000.0 * i as f64 / 25_600.0).sin())
        .collect();
    for k in 0..n {
        x[250 + 500 * k] = height;
    }
    x
}

#[test]
fn a_few_spikes_are_repaired_many_impulses_kept_and_absurd_ones_refused() {
    let few = inspect(&with_impulses(3, 60.0), 25_600.0, None).unwrap();
    assert_eq!(few.spans.len(), 3);
    assert!(few.findings.iter().all(|f| f.action == "repaired"));

    let many = inspect(&with_impulses(20, 60.0), 25_600.0, None).unwrap();
    assert!(many.spans.is_empty(), "impulses are kept as signal");
    assert_eq!(many.findings.len(), 1);
    let f = &many.findings[0];
    assert_eq!((f.defect, f.action), ("impulses", "warned"));
    assert_eq!((f.first_sample, f.last_sample), (250, 250 + 500 * 19));

    let corrupt = inspect(&with_impulses(20, 1e20), 25_600.0, None);
    assert!(
        matches!(corrupt, Err(Error::RecordQuality(ref f)) if f.defect == "spike"),
        "{corrupt:?}"
    );
}
