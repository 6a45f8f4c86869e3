//! The refusal of a word that names none of a setting's choices, shared by every option of the
//! processes that is one word out of a few (`--wait`, `--trigger`).

/// `value` is not one of the words a setting takes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{value:?} is not {what} (expected {expected})")]
pub struct UnknownWord {
    pub value: String,
    /// What the word should have named, with its article: "a trigger".
    pub what: &'static str,
    /// The words it may be, for the user: "clock or state".
    pub expected: &'static str,
}
