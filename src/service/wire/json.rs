//! The JSON record body and its one-pass reader: bytes to channels, no HTTP. Errors are
//! serde_json's (the caller turns them into a problem).

use serde::Deserialize;

use crate::condition::Load;

/// The JSON body: one channel, `{"sample_rate_hz": n, "samples": [..], …}`, or several,
/// `{"sample_rate_hz": n, "channels": {"a1": [..], "a2": [..]}, …}` (exactly one of
/// `samples` and `channels`; channel names non-empty and distinct, kept in the body's order).
/// [`JsonRecord::into_channels`] gives either form as channels.
#[derive(Debug, Deserialize)]
#[serde(try_from = "JsonRecordBody")]
pub struct JsonRecord {
    pub sample_rate_hz: f64,
    /// The `samples` form's samples; empty in the `channels` form.
    pub samples: Vec<f64>,
    /// The `channels` form's channels, in the body's order; `None` in the `samples` form.
    pub channels: Option<Vec<crate::record::Channel>>,
    pub shaft_hz: Option<f64>,
    pub recorded_at: Option<String>,
    pub sensor: Option<String>,
    /// `load`: a number, or a label (text that reads as a number is one: `"40"` is 40).
    pub load: Option<Load>,
    /// `record_id`: the publisher's id of the record, which MQTT ingest de-duplicates by
    /// (`docs/service.md#mqtt-ingest`); the HTTP endpoint refuses it (it has `Idempotency-Key`).
    pub record_id: Option<String>,
}

/// The members as written, before the one-of rule on `samples` / `channels`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonRecordBody {
    sample_rate_hz: f64,
    // Absent is `None`; present must be the form's value (`null` is refused, as before
    // `channels` existed).
    #[serde(default, deserialize_with = "present")]
    samples: Option<Vec<f64>>,
    #[serde(default, deserialize_with = "present")]
    channels: Option<JsonChannels>,
    #[serde(default)]
    shaft_hz: Option<f64>,
    #[serde(default)]
    recorded_at: Option<String>,
    #[serde(default)]
    sensor: Option<String>,
    #[serde(default, deserialize_with = "load_member")]
    load: Option<Load>,
    #[serde(default)]
    record_id: Option<String>,
}

/// The `load` member: a number, a label ([`Load::parse`]: trimmed, a number when it reads as
/// one; empty is no load) or `null`.
fn load_member<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Load>, D::Error> {
    struct Visitor;
    impl serde::de::Visitor<'_> for Visitor {
        type Value = Option<Load>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a load: a number or a label such as \"high\"")
        }
        fn visit_unit<E: serde::de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Self::Value, E> {
            Ok(Some(Load::Value(v)))
        }
        fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
            Ok(Some(Load::Value(v as f64)))
        }
        fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
            Ok(Some(Load::Value(v as f64)))
        }
        fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
            Ok(Load::parse(v))
        }
    }
    d.deserialize_any(Visitor)
}

/// A member that, when present, must hold a `T` (not `null`).
fn present<'de, D: serde::Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

impl TryFrom<JsonRecordBody> for JsonRecord {
    type Error = String;

    fn try_from(b: JsonRecordBody) -> Result<JsonRecord, String> {
        let (samples, channels) = match (b.samples, b.channels) {
            (Some(s), None) => (s, None),
            (None, Some(c)) => (Vec::new(), Some(c.0)),
            (Some(_), Some(_)) => {
                return Err(
                    "the record has both `samples` and `channels`; give `samples` \
                     for one channel or `channels` for several, not both"
                        .into(),
                );
            }
            (None, None) => {
                return Err(
                    "missing field `samples` (an array of numbers, one channel) or \
                     `channels` (an object of channel name: array of numbers)"
                        .into(),
                );
            }
        };
        Ok(JsonRecord {
            sample_rate_hz: b.sample_rate_hz,
            samples,
            channels,
            shaft_hz: b.shaft_hz,
            recorded_at: b.recorded_at,
            sensor: b.sensor,
            load: b.load,
            record_id: b.record_id,
        })
    }
}

/// `{"a1": [..], "a2": [..]}`, in the body's order, refusing an empty object, an empty
/// name and a name given twice.
struct JsonChannels(Vec<crate::record::Channel>);

impl<'de> Deserialize<'de> for JsonChannels {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = JsonChannels;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object of channel name: array of numbers")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<JsonChannels, A::Error> {
                use crate::record::Channel;
                use serde::de::Error as _;
                let mut out: Vec<Channel> = Vec::new();
                while let Some(name) = map.next_key::<String>()? {
                    if name.is_empty() {
                        return Err(A::Error::custom("a channel name in `channels` is empty"));
                    }
                    if out.iter().any(|c| c.name == name) {
                        return Err(A::Error::custom(format!(
                            "channel `{name}` appears twice in `channels`"
                        )));
                    }
                    let samples = map.next_value::<Vec<f64>>()?;
                    out.push(Channel { name, samples });
                }
                if out.is_empty() {
                    return Err(A::Error::custom(
                        "`channels` holds no channel; give at least one",
                    ));
                }
                Ok(JsonChannels(out))
            }
        }
        d.deserialize_map(Visitor)
    }
}

impl JsonRecord {
    /// Parse a JSON body: the same answer as `serde_json::from_slice::<JsonRecord>`, faster for
    /// the usual body. [`fast_json_record`] reads the plain one-channel form (the five known
    /// members once each, numbers, strings without escapes, `null` for the optional ones) in
    /// one pass, samples included; anything else — the `channels` form, an escape, an unknown
    /// or repeated member, a sample that is not a number or overflows, any syntax error — goes
    /// through `serde_json` whole, so every error message is serde_json's.
    ///
    /// Numbers are correctly rounded (`fast_float2`, like Rust's `str::parse::<f64>`);
    /// serde_json's default number path may differ from that by one unit in the last place
    /// (the fuzzer found a long integer rate where it does).
    pub fn from_json(bytes: &[u8]) -> serde_json::Result<JsonRecord> {
        match fast_json_record(bytes) {
            Some(r) => Ok(r),
            None => serde_json::from_slice(bytes),
        }
    }

    /// The record's channels: the `channels` form's, in the body's order, or the `samples`
    /// form's one channel, named `"0"` (as a one-column CSV's or a raw f32 body's).
    pub fn into_channels(self) -> Vec<crate::record::Channel> {
        match self.channels {
            Some(c) => c,
            None => vec![crate::record::Channel {
                name: "0".into(),
                samples: self.samples,
            }],
        }
    }
}

/// One-pass reader of the plain JSON record (see [`JsonRecord::from_json`]); `None` for
/// anything it does not take, valid or not.
pub fn fast_json_record(b: &[u8]) -> Option<JsonRecord> {
    let mut p = JsonCursor { b, i: 0 };
    let (mut rate, mut samples, mut shaft, mut recorded_at, mut sensor, mut load) =
        (None, None, None, None, None, None);
    let mut record_id = None;
    p.ws();
    p.eat(b'{')?;
    loop {
        p.ws();
        let key = p.plain_string()?;
        p.ws();
        p.eat(b':')?;
        p.ws();
        match key {
            "sample_rate_hz" if rate.is_none() => rate = Some(p.number()?),
            "samples" if samples.is_none() => samples = Some(p.numbers()?),
            "shaft_hz" if shaft.is_none() => {
                shaft = Some(if p.null() { None } else { Some(p.number()?) })
            }
            "recorded_at" if recorded_at.is_none() => {
                recorded_at = Some(if p.null() {
                    None
                } else {
                    Some(p.plain_string()?.to_owned())
                })
            }
            "sensor" if sensor.is_none() => {
                sensor = Some(if p.null() {
                    None
                } else {
                    Some(p.plain_string()?.to_owned())
                })
            }
            "record_id" if record_id.is_none() => {
                record_id = Some(if p.null() {
                    None
                } else {
                    Some(p.plain_string()?.to_owned())
                })
            }
            "load" if load.is_none() => {
                load = Some(if p.null() {
                    None
                } else if p.b.get(p.i) == Some(&b'"') {
                    Load::parse(p.plain_string()?)
                } else {
                    Some(Load::Value(p.number()?))
                })
            }
            _ => return None,
        }
        p.ws();
        match p.next()? {
            b',' => continue,
            b'}' => break,
            _ => return None,
        }
    }
    p.ws();
    if p.i != b.len() {
        return None;
    }
    Some(JsonRecord {
        sample_rate_hz: rate?,
        samples: samples?,
        channels: None,
        shaft_hz: shaft.flatten(),
        recorded_at: recorded_at.flatten(),
        sensor: sensor.flatten(),
        load: load.flatten(),
        record_id: record_id.flatten(),
    })
}

/// `t`, a number `fast_float2` read whole, is also one in JSON's grammar. `fast_float2` takes
/// `[+-]? digits* (. digits*)? ([eE][+-]?digits+)?` with at least one mantissa digit, and
/// `inf`/`nan`; JSON differs in wanting a digit first (after an optional `-`; the caller has
/// excluded `+`), no leading zero before another digit, and a digit after the point.
fn is_json_number(t: &[u8]) -> bool {
    let t = t.strip_prefix(b"-").unwrap_or(t);
    match t {
        [b'0', b'0'..=b'9', ..] => false,
        [b'0'..=b'9', ..] => match t.iter().position(|&c| c == b'.') {
            Some(p) => t.get(p + 1).is_some_and(u8::is_ascii_digit),
            None => true,
        },
        _ => false,
    }
}

struct JsonCursor<'a> {
    b: &'a [u8],
    i: usize,
}

impl<'a> JsonCursor<'a> {
    fn ws(&mut self) {
        while let Some(b' ' | b'\t' | b'\n' | b'\r') = self.b.get(self.i) {
            self.i += 1;
        }
    }
    fn next(&mut self) -> Option<u8> {
        let c = *self.b.get(self.i)?;
        self.i += 1;
        Some(c)
    }
    fn eat(&mut self, c: u8) -> Option<()> {
        (self.next()? == c).then_some(())
    }
    fn null(&mut self) -> bool {
        let hit = self.b[self.i..].starts_with(b"null");
        if hit {
            self.i += 4;
        }
        hit
    }
    /// A string without escapes or control characters, valid UTF-8.
    fn plain_string(&mut self) -> Option<&'a str> {
        self.eat(b'"')?;
        let start = self.i;
        loop {
            match self.next()? {
                b'"' => break,
                b'\\' | 0..=0x1f => return None,
                _ => {}
            }
        }
        std::str::from_utf8(&self.b[start..self.i - 1]).ok()
    }
    /// A number in JSON's grammar, `-?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?`, finite
    /// as an `f64`. `fast_float2` reads a superset of that grammar (`1.`, `.5`, `01`, `inf`);
    /// the text it took is then checked against JSON's.
    fn number(&mut self) -> Option<f64> {
        let rest = &self.b[self.i..];
        if !matches!(rest.first(), Some(b'-' | b'0'..=b'9')) {
            return None;
        }
        let (v, used): (f64, usize) = fast_float2::parse_partial(rest).ok()?;
        if !(v.is_finite() && is_json_number(&rest[..used])) {
            return None;
        }
        self.i += used;
        Some(v)
    }
    /// `[number, …]`.
    fn numbers(&mut self) -> Option<Vec<f64>> {
        self.eat(b'[')?;
        let mut out = Vec::new();
        self.ws();
        if self.b.get(self.i) == Some(&b']') {
            self.i += 1;
            return Some(out);
        }
        loop {
            out.push(self.number()?);
            self.ws();
            match self.next()? {
                b',' => self.ws(),
                b']' => return Some(out),
                _ => return None,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serde_record(body: &str) -> serde_json::Result<JsonRecord> {
        serde_json::from_slice(body.as_bytes())
    }

    /// Same samples as serde_json (to its one-ulp rounding) and exactly Rust's correctly
    /// rounded parse, for numbers written in every form JSON allows.
    #[test]
    fn fast_samples_match_serde_json() {
        let mut rng = crate::signature::SplitMix64::new(7);
        let mut texts: Vec<String> = vec![
            "0".into(),
            "-0".into(),
            "-0.0".into(),
            "1E+2".into(),
            "1e-2".into(),
            "123456789012345678901234567890".into(),
            "0.1000000000000000055511151231257827021181583404541015625".into(),
            "2.2250738585072014e-308".into(),
            "4.9e-324".into(),
            "1.7976931348623157e308".into(),
        ];
        for _ in 0..3000 {
            let u = rng.uniform();
            let v = (u - 0.5) * 10f64.powi((rng.uniform() * 40.0) as i32 - 20);
            texts.push(format!("{v}"));
            texts.push(format!("{v:e}"));
            texts.push(format!("{v:.3}"));
            texts.push(format!("{}", (v * 1e4).round() as i64));
        }
        for sep in [",", ", ", " ,\n\t", "\r\n,  "] {
            let body = format!(
                "{{ \"samples\" : [ {} ] , \"sample_rate_hz\": 25600, \"sensor\": \"é b\", \"shaft_hz\":null}}",
                texts.join(sep)
            );
            let fast = fast_json_record(body.as_bytes()).expect("the fast path takes this body");
            let slow = serde_record(&body).unwrap();
            assert_eq!(fast.samples.len(), texts.len());
            assert_eq!((fast.sensor.as_deref(), fast.shaft_hz), (Some("é b"), None));
            for ((a, b), t) in fast.samples.iter().zip(&slow.samples).zip(&texts) {
                assert_eq!(*a, t.parse::<f64>().unwrap(), "{t}");
                assert_eq!(a.is_sign_negative(), b.is_sign_negative(), "{t}");
                let ulps = (a.to_bits() as i64 - b.to_bits() as i64).abs();
                assert!(ulps <= 1, "{t}: {a} vs serde_json {b}");
            }
        }
        let empty = fast_json_record(br#"{"sample_rate_hz": 1, "samples": [ ]}"#).unwrap();
        assert!(empty.samples.is_empty());
        let full = fast_json_record(
            br#" {"recorded_at":"2026-11-22T08:30:00Z","shaft_hz":30.5,"sample_rate_hz":2.56e4,"samples":[-1,0.5],"sensor":null} "#,
        )
        .unwrap();
        assert_eq!(
            (
                full.sample_rate_hz,
                full.shaft_hz,
                full.recorded_at.as_deref(),
                full.sensor
            ),
            (25600.0, Some(30.5), Some("2026-11-22T08:30:00Z"), None)
        );
        assert_eq!(full.samples, [-1.0, 0.5]);
    }

    /// Whatever the fast path does not take gets serde_json's own answer, message included.
    #[test]
    fn everything_else_is_serde_json_s_answer() {
        for body in [
            r#"{"sample_rate_hz": 25600, "samples": [1, "2", 3]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, null]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, [2]]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, {"a": 2}]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [true]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, 1e999, 2]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [-1e400]}"#,
            r#"{"sample_rate_hz": 25600, "samples": null}"#,
            r#"{"sample_rate_hz": 25600, "samples": 3}"#,
            r#"{"sample_rate_hz": 25600, "samples": "1,2"}"#,
            r#"{"sample_rate_hz": 25600}"#,
            r#"{"samples": [1, 2]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "extra": 1}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "samples": [2]}"#,
            r#"{"sample_rate_hz": "x", "samples": ["a"]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1, 2,]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [NaN]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [01]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1 2]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1]} x"#,
            r#"[1, 2]"#,
            "",
            "{}",
            r#"{"sample_rate_hz": 25600, "samples": [1.]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [.5]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [+1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1e]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1e+]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [-]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1.e5]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [-01.5]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [0x10]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1,]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [,1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1]"#,
            r#"{"sample_rate_hz": 25600, "samples": [1],}"#,
            r#"{"sample_rate_hz": 25600 "samples": [1]}"#,
            r#"{"sample_rate_hz": null, "samples": [1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": null, "sensor": null}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": nul}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": "30"}"#,
            r#"{"\u0073amples": [1, 2], "sample_rate_hz": 25600}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "sensor": "a\"b"}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "sensor": "\u00e9"}"#,
            "{\"sample_rate_hz\": 25600, \"samples\": [1], \"sensor\": \"a\tb\"}",
            r#"{"sample_rate_hz": 25600, "samples": [1], "recorded_at": 5}"#,
            r#"{"sample_rate_hz": 1e999, "samples": [1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "shaft_hz": 30, "shaft_hz": 31}"#,
            "\u{feff}{\"sample_rate_hz\": 25600, \"samples\": [1]}",
            "{\"sample_rate_hz\": 25600,\u{a0}\"samples\": [1]}",
            r#"{"sample_rate_hz": 25600, "channels": {"a1": [1, 2], "a2": [3, 4]}}"#,
            r#"{"channels": {"a1": [1]}, "sample_rate_hz": 25600, "sensor": "s"}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "channels": {"a1": [1]}}"#,
            r#"{"sample_rate_hz": 25600, "channels": {"a1": [1]}, "samples": [1]}"#,
            r#"{"sample_rate_hz": 25600, "channels": {}}"#,
            r#"{"sample_rate_hz": 25600, "channels": null}"#,
            r#"{"sample_rate_hz": 25600, "channels": [[1]]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": "High"}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": " 40 "}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": 40.5}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": -3}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": null}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": ""}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": "h\u00e9"}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": true}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": [1]}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": 1e999}"#,
            r#"{"sample_rate_hz": 25600, "samples": [1], "load": 1, "load": 2}"#,
            r#"{"sample_rate_hz": 25600, "channels": {"a": [1]}, "load": "low"}"#,
        ] {
            let fast = JsonRecord::from_json(body.as_bytes()).map_err(|e| e.to_string());
            let slow = serde_record(body).map_err(|e| e.to_string());
            match (&fast, &slow) {
                (Err(a), Err(b)) => assert_eq!(a, b, "{body}"),
                (Ok(a), Ok(b)) => assert_eq!(
                    (
                        &a.samples,
                        &a.channels,
                        a.sample_rate_hz,
                        a.shaft_hz,
                        &a.recorded_at,
                        &a.sensor,
                        &a.load
                    ),
                    (
                        &b.samples,
                        &b.channels,
                        b.sample_rate_hz,
                        b.shaft_hz,
                        &b.recorded_at,
                        &b.sensor,
                        &b.load
                    ),
                    "{body}"
                ),
                _ => panic!("{body}: fast {fast:?}, serde_json {slow:?}"),
            }
        }
    }

    /// The several-channel form: channels in the body's order, the other members as in the
    /// one-channel form, and `into_channels` for both forms.
    #[test]
    fn channels_form_and_into_channels() {
        use crate::record::Channel;
        let body = br#"{"sample_rate_hz": 12800, "channels": {"a2": [1, 2.5], "a1": [-1, 0]},
            "shaft_hz": 30, "sensor": "s1"}"#;
        let r = JsonRecord::from_json(body).unwrap();
        assert_eq!(
            (r.sample_rate_hz, r.shaft_hz, r.sensor.as_deref()),
            (12800.0, Some(30.0), Some("s1"))
        );
        assert!(r.samples.is_empty());
        assert_eq!(
            r.into_channels(),
            [
                Channel {
                    name: "a2".into(),
                    samples: vec![1.0, 2.5]
                },
                Channel {
                    name: "a1".into(),
                    samples: vec![-1.0, 0.0]
                }
            ]
        );
        let r = JsonRecord::from_json(br#"{"sample_rate_hz": 1, "samples": [1, 2]}"#).unwrap();
        assert_eq!(r.channels, None);
        assert_eq!(
            r.into_channels(),
            [Channel {
                name: "0".into(),
                samples: vec![1.0, 2.0]
            }]
        );
    }

    /// `load` is a number or a label (text that reads as a number is one), read by the fast
    /// path too; anything else is refused with a message that says what a load is.
    #[test]
    fn load_is_a_number_or_a_label() {
        for (body, want) in [
            (r#""High""#, Some(Load::Label("High".into()))),
            (r#"" 40 ""#, Some(Load::Value(40.0))),
            ("12", Some(Load::Value(12.0))),
            ("-0.5", Some(Load::Value(-0.5))),
            ("null", None),
            ("\"\"", None),
        ] {
            let text = format!(r#"{{"sample_rate_hz": 1, "samples": [1, 2], "load": {body}}}"#);
            let fast = fast_json_record(text.as_bytes()).expect("the fast path takes a load");
            assert_eq!(fast.load, want, "{body}");
        }
        let e = JsonRecord::from_json(br#"{"sample_rate_hz": 1, "samples": [1], "load": true}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a load: a number or a label"), "{e}");
    }

    /// Each mistake in the choice of form gets its own serde_json error, the same through
    /// `from_json` as through serde_json.
    #[test]
    fn channels_form_errors() {
        for (body, want) in [
            (
                r#"{"sample_rate_hz": 1, "samples": [1], "channels": {"a": [1]}}"#,
                "the record has both `samples` and `channels`",
            ),
            (
                r#"{"sample_rate_hz": 1}"#,
                "missing field `samples` (an array of numbers, one channel) or `channels`",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {}}"#,
                "`channels` holds no channel; give at least one at line 1 column",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {"a1": [1], "a1": [2]}}"#,
                "channel `a1` appears twice in `channels` at line 1 column",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {"": [1]}}"#,
                "a channel name in `channels` is empty",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": [[1, 2]]}"#,
                "invalid type: sequence, expected an object of channel name: array of numbers",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": {"a": [1, "x"]}}"#,
                "invalid type: string \"x\", expected f64",
            ),
            (
                r#"{"sample_rate_hz": 1, "channels": null}"#,
                "invalid type: null, expected an object of channel name",
            ),
            (
                r#"{"sample_rate_hz": 1, "samples": null}"#,
                "invalid type: null, expected a sequence",
            ),
            (
                r#"{"sample_rate_hz": 1, "channel": {"a": [1]}}"#,
                "unknown field `channel`, expected one of `sample_rate_hz`, `samples`, \
                 `channels`",
            ),
        ] {
            let e = JsonRecord::from_json(body.as_bytes())
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{body}: {e}");
            assert_eq!(e, serde_record(body).unwrap_err().to_string(), "{body}");
        }
    }
}
