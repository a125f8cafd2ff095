//! A job's labels, key → value, to find jobs by: the one definition of what a label is — the rule
//! of its key and of its value, their limits and their messages — read by the job document's
//! `labels` (`annotations`) and by the job list's `label=KEY=VALUE` filter alike.

use std::fmt;
use std::str::FromStr;

use crate::sim::model::params::SpecError;

/// Most labels on one job.
pub const MAX_LABELS: usize = 32;

/// Longest label key, in characters (its characters are ASCII: one byte each).
pub const MAX_LABEL_KEY: usize = 64;

/// Longest label value, in characters.
pub const MAX_LABEL_VALUE: usize = 200;

/// Whether `text` shows as it is in a table or a page: no control characters.
pub(super) fn printable(text: &str) -> bool {
    !text.chars().any(char::is_control)
}

/// One label: a key of 1 to [`MAX_LABEL_KEY`] letters, digits, `_`, `-` or `.`, and a value of at
/// most [`MAX_LABEL_VALUE`] printable characters. Only [`Label::new`] and [`Label::parse`] make
/// one, so holding a `Label` means holding a key and a value that passed; in particular a job list
/// may build the JSON path `$.labels."KEY"` from the key without escaping it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Label {
    key: String,
    value: String,
}

impl Label {
    /// The label `key` → `value`, or an error naming its field in a job document (`labels.KEY`)
    /// and the rule it breaks.
    pub fn new(key: impl Into<String>, value: impl Into<String>) -> Result<Label, SpecError> {
        let (key, value) = (key.into(), value.into());
        let key_ok = (1..=MAX_LABEL_KEY).contains(&key.len())
            && key.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.'));
        if !key_ok {
            let message = format!("a label's key is 1 to {MAX_LABEL_KEY} letters, digits, '_', '-' or '.'");
            return Err(SpecError::new(format!("labels.{key}"), message));
        }
        if value.chars().count() > MAX_LABEL_VALUE || !printable(&value) {
            let message = format!("a label's value is at most {MAX_LABEL_VALUE} printable characters");
            return Err(SpecError::new(format!("labels.{key}"), message));
        }
        Ok(Label { key, value })
    }

    /// A label written `KEY=VALUE` (the job list's `label=` filter): the key up to the first `=`,
    /// the value after it. Errors name the field `label` and say the rule [`Label::new`] states.
    pub fn parse(text: &str) -> Result<Label, SpecError> {
        let (key, value) = text.split_once('=').ok_or_else(|| SpecError::new("label", "must be KEY=VALUE"))?;
        Label::new(key, value).map_err(|e| SpecError::new("label", e.message))
    }

    /// The key.
    pub fn key(&self) -> &str {
        &self.key
    }

    /// The value.
    pub fn value(&self) -> &str {
        &self.value
    }
}

impl FromStr for Label {
    type Err = SpecError;

    /// [`Label::parse`].
    fn from_str(text: &str) -> Result<Label, SpecError> {
        Label::parse(text)
    }
}

impl fmt::Display for Label {
    /// `KEY=VALUE`, as [`Label::parse`] reads it.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.key, self.value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_values_follow_the_one_rule() {
        let label = Label::new("study.v2_a-b", "radius, seed 1").unwrap();
        assert_eq!((label.key(), label.value()), ("study.v2_a-b", "radius, seed 1"));
        Label::new("k".repeat(MAX_LABEL_KEY), "v".repeat(MAX_LABEL_VALUE)).unwrap();
        Label::new("k", "").unwrap();
        for (key, value) in [
            ("", "x"),
            ("bad key", "x"),
            ("k\"", "x"),
            ("ключ", "x"),
            (&*"k".repeat(MAX_LABEL_KEY + 1), "x"),
            ("k", &*"v".repeat(MAX_LABEL_VALUE + 1)),
            ("k", "a\nb"),
            ("k", "\u{7}"),
        ] {
            let e = Label::new(key, value).unwrap_err();
            assert_eq!(e.field, format!("labels.{key}"), "{key:?} = {value:?}");
            assert!(e.message.starts_with("a label's"), "{e}");
        }
        assert!(Label::new("bad key", "x").unwrap_err().message.contains("key is 1 to 64"));
        assert!(Label::new("k", "\n").unwrap_err().message.contains("value is at most 200 printable"));
    }

    #[test]
    fn the_list_filter_reads_key_equals_value() {
        let label: Label = "study=radius=2".parse().unwrap();
        assert_eq!((label.key(), label.value()), ("study", "radius=2"), "the key ends at the first '='");
        assert_eq!(label.to_string(), "study=radius=2");
        assert_eq!(Label::parse("k=").unwrap().value(), "");
        for (text, says) in [("study", "KEY=VALUE"), ("bad key=1", "key is"), ("=1", "key is"), ("k=\t", "value is")] {
            let e = Label::parse(text).unwrap_err();
            assert_eq!(e.field, "label", "{text}");
            assert!(e.message.contains(says), "{text}: {e}");
        }
    }
}
