//! Where a gearbox's signature table stands: [`TableStatus`].

use serde::{Deserialize, Serialize};

use crate::words::UnknownWord;

/// Where a gearbox's signature table stands. The service's tables go `queued` → `running` →
/// `ready` or `failed`; `missing` is a diagnosis without a table at all (`gearwear diagnose`
/// with none given).
///
/// Its words, by `strum` (read, written, listed) and by `serde` (the API), are the same
/// lowercase names; the test below holds them together.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    Serialize,
    Deserialize,
    strum::Display,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "lowercase")]
#[strum(
    serialize_all = "lowercase",
    parse_err_ty = UnknownWord,
    parse_err_fn = unknown_status
)]
pub enum TableStatus {
    Queued,
    Running,
    Ready,
    Failed,
    Missing,
}

impl TableStatus {
    /// Every value, in declaration order.
    pub const ALL: &'static [TableStatus] = <TableStatus as strum::VariantArray>::VARIANTS;

    /// The word the API and the database use.
    pub fn as_str(self) -> &'static str {
        self.into()
    }
}

/// The error of a word that names no status, listing those that do.
fn unknown_status(word: &str) -> UnknownWord {
    UnknownWord {
        word: word.to_string(),
        what: "a table status",
        words: <TableStatus as strum::VariantNames>::VARIANTS,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statuses_read_and_write_their_words() {
        for &t in TableStatus::ALL {
            assert_eq!(t.as_str().parse::<TableStatus>(), Ok(t));
            assert_eq!(serde_json::to_value(t).unwrap(), t.as_str());
        }
        assert_eq!(
            "Ready".parse::<TableStatus>().unwrap_err().to_string(),
            "`Ready` is not a table status (queued, running, ready, failed, missing)"
        );
        assert_eq!(TableStatus::Running.to_string(), "running");
    }
}
