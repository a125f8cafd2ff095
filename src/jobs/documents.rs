//! Documents the job API returns besides the job resource: result envelopes, job lists and the
//! moments export.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::resource::{JobResource, JobState};
use crate::sim::report::RunReport;

/// A job's results: the noise table and weights of the core's report, from the latest checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobResult {
    pub job_id: i64,
    /// True until the job has succeeded with all its iterations: the figures come from a
    /// checkpoint of a job that is still running, was cancelled or failed.
    pub partial: bool,
    pub state: JobState,
    #[serde(flatten)]
    pub report: RunReport,
}

/// One page of the job list, newest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobList {
    pub jobs: Vec<JobResource>,
    /// Pass as `cursor` to get the next page; null on the last page.
    pub next_cursor: Option<String>,
}
