//! RFC 3339 formatting and parsing of unix-millisecond timestamps.

use time::format_description::well_known::Rfc3339;
use time::{OffsetDateTime, UtcOffset};

/// `1700000000123` → `"2023-11-14T22:13:20.123Z"`.
pub fn rfc3339(ms: i64) -> String {
    let t = OffsetDateTime::from_unix_timestamp_nanos(ms as i128 * 1_000_000)
        .unwrap_or(OffsetDateTime::UNIX_EPOCH)
        .to_offset(UtcOffset::UTC);
    // Millisecond precision, `Z` suffix.
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second(),
        t.millisecond()
    )
}

/// Parse an RFC 3339 timestamp into unix milliseconds.
pub fn parse_rfc3339(s: &str) -> Option<i64> {
    let t = OffsetDateTime::parse(s, &Rfc3339).ok()?;
    Some((t.unix_timestamp_nanos() / 1_000_000) as i64)
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip() {
        let ms = 1_700_000_000_123;
        assert_eq!(super::rfc3339(ms), "2023-11-14T22:13:20.123Z");
        assert_eq!(super::parse_rfc3339(&super::rfc3339(ms)), Some(ms));
        assert_eq!(
            super::parse_rfc3339("2023-11-14T23:13:20.123+01:00"),
            Some(ms)
        );
        assert_eq!(super::parse_rfc3339("yesterday"), None);
    }
}
