//! Where a gearbox's signature table stands: [`TableStatus`].

use serde::{Deserialize, Serialize};

/// Where a gearbox's signature table stands. The service's tables go `queued` → `running` →
/// `ready` or `failed`; `missing` is a diagnosis without a table at all (`gearwear diagnose`
/// with none given).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TableStatus {
    Queued,
    Running,
    Ready,
    Failed,
    Missing,
}

crate::words::words!(TableStatus, "a table status", {
    Queued => "queued",
    Running => "running",
    Ready => "ready",
    Failed => "failed",
    Missing => "missing",
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statuses_read_and_write_their_words() {
        for &t in TableStatus::ALL {
            assert_eq!(t.as_str().parse::<TableStatus>(), Ok(t));
            assert_eq!(serde_json::to_value(t).unwrap(), t.as_str());
        }
        assert!("Ready".parse::<TableStatus>().is_err());
    }
}
