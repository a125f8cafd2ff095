//! Named re-solves kept with a job (`/v1/jobs/{id}/solves`): solver options a user wants to come
//! back to (a λ, freed weights), stored as a patch on the job's `solver` and re-solved from the
//! latest checkpoint when read, beside the job's own options (`default`).
//!
//! Bounds: at most [`MAX_SOLVES`] per job, names of at most 64 characters from `[a-z0-9_.-]`; a
//! patch is validated like `POST /v1/jobs/{id}/solve`'s (bounded λ grid), and reading a solve is a
//! re-solve on the request pool.

use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::core::documents::JobResult;
use super::core::error::JobError;
use super::core::resource::{now_ms, rfc3339};
use super::statistics::Statistics;
use crate::sim::model::params::check;
use crate::sim::solve::options::SolverOptions;

/// Most named solves of one job.
pub const MAX_SOLVES: i64 = 32;

/// The name of the job's own options.
pub const DEFAULT_SOLVE: &str = "default";

/// A named solve of a job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SavedSolve {
    /// The solve's name in `/v1/jobs/{id}/solves/{name}`: `default` for the job's own options,
    /// else 1 to 64 characters of `a-z`, `0-9`, `_`, `-`, `.`.
    pub name: String,
    /// True for `default`, the job's own solver options (what `/result` shows).
    pub default: bool,
    /// The options, resolved (the job's with the patch applied).
    pub solver: SolverOptions,
    /// The patch on the job's options (`{}` for `default`).
    #[schema(value_type = Object)]
    pub patch: Value,
    /// RFC 3339, UTC; the job's creation for `default`.
    pub created_at: String,
}

/// A job's solves: `default` first, then the named ones, oldest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SolveList {
    /// Id of the job the solves belong to.
    pub job_id: i64,
    /// `default` first, then the named solves, oldest first (at most 32 named).
    pub solves: Vec<SavedSolve>,
}

fn check_name(name: &str) -> Result<(), JobError> {
    let ok = (1..=64).contains(&name.len())
        && name.bytes().all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || matches!(b, b'_' | b'-' | b'.'));
    check(ok, "name", || format!("must be 1 to 64 characters of a-z, 0-9, '_', '-', '.', got {name:?}"))?;
    check(name != DEFAULT_SOLVE, "name", || "`default` is the job's own options; choose another name".to_string())?;
    // Browsers and curl resolve `.` and `..` path segments before sending: such a solve could be
    // stored but never read back.
    check(name != "." && name != "..", "name", || {
        format!("{name:?} is a path segment that browsers and curl resolve away; choose another name")
    })?;
    Ok(())
}

/// Named re-solves of jobs; cheap to clone.
#[derive(Clone)]
pub struct Solves {
    statistics: Statistics,
}

impl Solves {
    /// Named solves re-solved from the statistics of `statistics`' jobs.
    pub fn new(statistics: Statistics) -> Self {
        Self { statistics }
    }

    /// Stores `patch` as the job's solve `name` (replacing one of that name) and answers its result.
    pub async fn save_solve(&self, id: i64, name: &str, patch: &Value) -> Result<JobResult, JobError> {
        check_name(name)?;
        self.statistics.jobs.get(id).await?.spec.solver.patched(patch)?;
        // Solved before it is stored: a job without a checkpoint keeps no solve it cannot answer.
        let result = self.statistics.solve(id, patch, None).await?;
        if !self.statistics.jobs.store().solves().put(id, name, &patch.to_string(), now_ms(), MAX_SOLVES).await? {
            return Err(JobError::Conflict(format!(
                "job {id} keeps at most {MAX_SOLVES} named solves; delete one (DELETE /v1/jobs/{id}/solves/NAME)"
            )));
        }
        Ok(result)
    }

    /// The job's solves, `default` first.
    pub async fn list_solves(&self, id: i64) -> Result<SolveList, JobError> {
        let job = self.statistics.jobs.get(id).await?;
        let mut solves = vec![SavedSolve {
            name: DEFAULT_SOLVE.into(),
            default: true,
            solver: job.spec.solver.clone(),
            patch: Value::Object(Default::default()),
            created_at: job.created_at.clone(),
        }];
        for row in self.statistics.jobs.store().solves().list(id).await? {
            let patch: Value = serde_json::from_str(&row.patch).map_err(|e| {
                JobError::Internal(format!("stored solve {:?} of job {id} is unreadable: {e}", row.name))
            })?;
            let solver = job.spec.solver.patched(&patch)?;
            solves.push(SavedSolve {
                name: row.name,
                default: false,
                solver,
                patch,
                created_at: rfc3339(row.created_at),
            });
        }
        Ok(SolveList { job_id: id, solves })
    }

    /// The result of solve `name` from the latest checkpoint (`default`: the job's result).
    pub async fn solve_result(&self, id: i64, name: &str) -> Result<JobResult, JobError> {
        if name == DEFAULT_SOLVE {
            return self.statistics.result(id).await;
        }
        self.statistics.jobs.get(id).await?;
        let row = self.statistics.jobs.store().solves().get(id, name).await?.ok_or_else(|| no_solve(id, name))?;
        let patch: Value = serde_json::from_str(&row.patch)
            .map_err(|e| JobError::Internal(format!("stored solve {name:?} of job {id} is unreadable: {e}")))?;
        self.statistics.solve(id, &patch, None).await
    }

    /// Deletes solve `name` (`default` cannot be).
    pub async fn delete_solve(&self, id: i64, name: &str) -> Result<(), JobError> {
        check_name(name)?;
        self.statistics.jobs.get(id).await?;
        if self.statistics.jobs.store().solves().delete(id, name).await? { Ok(()) } else { Err(no_solve(id, name)) }
    }
}

fn no_solve(id: i64, name: &str) -> JobError {
    JobError::NotFound(format!("{id} with a solve named {name:?}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_bounded_and_reachable() {
        for good in ["s1", "lambda-0.1", "a.b", "...", &"x".repeat(64)] {
            assert!(check_name(good).is_ok(), "{good}");
        }
        for bad in ["", ".", "..", "default", "A", "a/b", "a b", &"x".repeat(65)] {
            let Err(JobError::Invalid(e)) = check_name(bad) else { panic!("{bad:?} accepted") };
            assert_eq!(e.field, "name");
        }
    }
}
