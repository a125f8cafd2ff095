//! The fields of a job for people — `name`, `labels`, `notes` — and their bounds. None is part of
//! the computation nor of the fingerprint, but they are shown in tables and pages and a job list
//! filters by the labels, so they are bounded, and the name and labels printable.

use std::collections::BTreeMap;

use super::labels::{Label, MAX_LABELS, printable};
use crate::sim::model::params::{SpecError, check};

/// Longest name of a job, in characters.
pub const MAX_NAME: usize = 200;

/// Longest notes of a job, in characters.
pub const MAX_NOTES: usize = 4000;

/// Checks a job's `name` (1 to [`MAX_NAME`] printable characters, not blank), its `labels` (at
/// most [`MAX_LABELS`], each a [`Label`]) and its `notes` (at most [`MAX_NOTES`] characters).
pub(super) fn validate_annotations(
    name: Option<&str>,
    labels: &BTreeMap<String, String>,
    notes: Option<&str>,
) -> Result<(), SpecError> {
    if let Some(name) = name {
        check(!name.trim().is_empty() && name.chars().count() <= MAX_NAME && printable(name), "name", || {
            format!("must be 1 to {MAX_NAME} printable characters")
        })?;
    }
    check(labels.len() <= MAX_LABELS, "labels", || format!("at most {MAX_LABELS} labels, got {}", labels.len()))?;
    for (key, value) in labels {
        Label::new(key.as_str(), value.as_str())?;
    }
    if let Some(notes) = notes {
        check(notes.chars().count() <= MAX_NOTES, "notes", || format!("at most {MAX_NOTES} characters"))?;
    }
    Ok(())
}
