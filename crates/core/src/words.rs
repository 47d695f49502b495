//! Enums whose variants are words of the API and the database: each is written and read as its
//! word, and compared as a value, never as text. The error of a word that names none,
//! [`UnknownWord`], lists those that do.
//!
//! New enums derive `strum`'s `Display`, `EnumString` (with `parse_err_ty = UnknownWord`),
//! `IntoStaticStr`, `VariantArray` and `VariantNames`, as
//! [`TableStatus`](crate::signature::TableStatus) does. The [`words!`] macro stays only for
//! the alert's [`Level`](crate::assessment::Level) and [`Basis`](crate::assessment::Basis)
//! until they move to `strum` too (their module, `assessment/`, is being changed elsewhere;
//! the move is the same as `TableStatus`'s, and their words the same as their `serde` names).

/// A word that names no variant of the type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{word}` is not {what} ({})", .words.join(", "))]
pub struct UnknownWord {
    pub word: String,
    /// What was expected (`an alert level`).
    pub what: &'static str,
    /// The words that are.
    pub words: &'static [&'static str],
}

/// For `enum $ty { $variant, … }`: `ALL` (in declaration order), `as_str` (the word),
/// `Display` and `FromStr` (refusing any other word with an [`UnknownWord`] that lists them).
macro_rules! words {
    ($ty:ident, $what:literal, { $($variant:ident => $word:literal),+ $(,)? }) => {
        impl $ty {
            /// Every value, in declaration order.
            pub const ALL: &'static [$ty] = &[$($ty::$variant),+];

            /// The word the API and the database use.
            pub const fn as_str(self) -> &'static str {
                match self {
                    $($ty::$variant => $word),+
                }
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl std::str::FromStr for $ty {
            type Err = $crate::words::UnknownWord;

            fn from_str(s: &str) -> Result<$ty, $crate::words::UnknownWord> {
                $ty::ALL
                    .iter()
                    .copied()
                    .find(|v| v.as_str() == s)
                    .ok_or_else(|| $crate::words::UnknownWord {
                        word: s.to_string(),
                        what: $what,
                        words: &[$($word),+],
                    })
            }
        }
    };
}
pub(crate) use words;
