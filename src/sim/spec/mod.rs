//! The job specification: the JSON document users submit (CLI `--spec` and `POST /v1/jobs` alike),
//! its presets, and its validation.
//!
//! A document names a `preset` (default `paper-table1`) and overrides any of its fields. Overrides
//! follow JSON Merge Patch (RFC 7386): objects merge field by field, arrays and numbers replace, and
//! `null` removes a field (so `{"solver": {"fixed": {"w0": null}}}` frees w₀). One exception keeps
//! tagged objects sane: an object whose `kind` differs from the preset's replaces it whole, so
//! `{"scene": {"illumination": {"kind": "uniform", "r_ls": 20}}}` does not inherit the spot's `a`.
//!
//! Unknown fields are errors, never ignored. Parsing gives a [`JobSpec`]; [`JobSpec::validate`] is
//! the one place where values are checked, and yields the [`ValidJob`] everything else consumes.
//!
//! # Files
//!
//! Every name is used through this module (`crate::sim::spec::JobSpec`); the files are private:
//!
//! * `document` — [`JobSpec`] field by field, the iterations it runs, its validation (which calls
//!   the checks of the files below and of the model's and solver's parameters) and the
//!   [`ValidJob`] it yields;
//! * `execution` — which iterations run and how: [`Shard`], [`Execution`] (a cluster's tasks),
//!   [`EngineName`], and their checks against the job's iterations;
//! * `presets` — the presets and [`parse_job_spec`]: preset + merge patch → [`JobSpec`];
//! * `annotations` — the fields for people (`name`, `labels`, `notes`): their bounds;
//! * `labels` — [`Label`]: the one definition of a label's key and value, their limits and
//!   messages, for the document's `labels` and the job list's `label=KEY=VALUE` filter alike.
//!
//! Imports: crate::sim::engines, crate::sim::model, crate::sim::solve, crate::sim::stats

mod annotations;
mod document;
mod execution;
mod labels;
mod presets;
#[cfg(test)]
mod tests;

pub use crate::sim::model::params::SpecError;
pub use annotations::{MAX_NAME, MAX_NOTES};
pub use document::{JobSpec, MAX_ITERATIONS, ValidJob};
pub use execution::{EngineName, Execution, MAX_TASKS, Shard};
pub use labels::{Label, MAX_LABEL_KEY, MAX_LABEL_VALUE, MAX_LABELS};
pub use presets::{DEFAULT_PRESET, PRESETS, parse_job_spec, preset};
