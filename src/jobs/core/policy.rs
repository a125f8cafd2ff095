//! How jobs are run and what a server accepts: the run policy and the checks of a job against it
//! (its budget of pairs and cells, the expected work of one iteration, the targets of an extension).

use std::time::Duration;

use super::error::JobError;
use crate::sim::engines::cost::{MERGE_WEIGHT, iteration_work};
use crate::sim::spec::{EngineName, JobSpec, SpecError, ValidJob};

/// How jobs are run.
#[derive(Debug, Clone)]
pub struct RunPolicy {
    /// Jobs running at once; the others wait in submission order.
    pub workers: usize,
    /// Checkpoint at least every this many iterations…
    pub checkpoint_iterations: u64,
    /// …and at least this often.
    pub checkpoint_interval: Duration,
    /// Largest N_F · N_B · iterations of one job.
    pub job_budget: f64,
    /// Largest expected work of one iteration, in light-path equivalents (`sim::engines::cost`).
    pub max_iteration_work: f64,
    /// Most cells of a job's grid.
    pub max_cells: usize,
    /// Most jobs waiting in the queue; beyond it submissions get 429 with Retry-After.
    pub max_queued_jobs: usize,
    /// Most points of one sweep.
    pub max_sweep_points: usize,
    /// Longest a study may take to gather and merge its sources (its pulls included).
    pub study_deadline: Duration,
}

/// Default per-iteration work limit: 10¹⁰ light-path equivalents, about 45 s of the brute force
/// on 2 cores (the paper's brute-force iteration is 10⁷, its restricted one ~3·10³).
pub const DEFAULT_MAX_ITERATION_WORK: f64 = 1e10;

/// Default study deadline: enough for the merges' `CONCURRENT_PULLS` slow peers at a time to
/// deliver documents at the document limit twice over, short enough that no study holds a request
/// for hours.
pub const DEFAULT_STUDY_DEADLINE: Duration = Duration::from_secs(180);

/// Default limit on the points of a sweep.
pub const DEFAULT_MAX_SWEEP_POINTS: usize = 256;

impl Default for RunPolicy {
    /// `optimis serve`'s defaults: one job at a time, a checkpoint every 50 iterations or 15 s.
    fn default() -> Self {
        Self {
            workers: 1,
            checkpoint_iterations: 50,
            checkpoint_interval: Duration::from_secs(15),
            job_budget: 1e16,
            max_iteration_work: DEFAULT_MAX_ITERATION_WORK,
            max_cells: crate::sim::model::cells::MAX_CELLS,
            max_queued_jobs: 1000,
            max_sweep_points: DEFAULT_MAX_SWEEP_POINTS,
            study_deadline: DEFAULT_STUDY_DEADLINE,
        }
    }
}

/// Refuses jobs beyond this server's budget: N_F · N_B · `iterations` and the cell count.
pub(in crate::jobs) fn check_budget(policy: &RunPolicy, spec: &JobSpec, iterations: u64) -> Result<(), JobError> {
    let pairs = spec.light_paths as f64 * spec.camera_paths as f64 * iterations as f64;
    if pairs > policy.job_budget {
        return Err(SpecError::new(
            "iterations",
            format!(
                "light_paths × camera_paths × iterations = {pairs:.3e} exceeds this server's per-job budget of {:.3e} \
                 (--max-job-budget); run fewer iterations, or split the study into shards",
                policy.job_budget
            ),
        )
        .into());
    }
    let cells = spec.cells.r2_edges.len() * spec.cells.r3_edges.len() * spec.cells.phi_bins as usize;
    if cells > policy.max_cells {
        return Err(SpecError::new(
            "cells",
            format!("the grid has {cells} cells; this server accepts at most {} (--max-cells)", policy.max_cells),
        )
        .into());
    }
    Ok(())
}

/// Refuses a configuration whose single iteration is expected to cost more than the server
/// allows (the check behind "a job that cannot be cancelled": an iteration of 10¹⁷ light-path
/// equivalents once ran for ever). CPU work: call it on the request pool.
pub(in crate::jobs) fn check_iteration_work(policy: &RunPolicy, job: &ValidJob) -> Result<(), JobError> {
    let work = iteration_work(job.config());
    let total = work.total();
    if total.is_finite() && total <= policy.max_iteration_work {
        return Ok(());
    }
    // The brute force traces N_F paths; the restricted engine's candidates and every engine's merges
    // grow with the merge discs (R²).
    let traced_dominates = work.light_paths >= MERGE_WEIGHT * work.merges;
    let field = if job.spec().engine == EngineName::Brute && traced_dominates { "light_paths" } else { "merge_radius" };
    Err(SpecError::new(
        field,
        format!(
            "one iteration is expected to cost {total:.3e} light-path equivalents ({:.3e} light paths drawn, {:.3e} \
             merges{}) — beyond this server's per-iteration limit of {:.3e} (--max-iteration-work); reduce merge_radius, \
             light_paths or camera_paths{}",
            work.light_paths,
            work.merges,
            if work.components > 1.0 { format!(", ×{} for the noise components", work.components) } else { String::new() },
            policy.max_iteration_work,
            if work.components > 1.0 { ", or run without noise_components" } else { "" }
        ),
    )
    .into())
}

/// The new total of an extension: `more` beyond `base`, or `total` outright (which must exceed
/// `done`); at most 10⁹.
pub(in crate::jobs) fn target_total(
    base: u64,
    done: u64,
    more: Option<u64>,
    total: Option<u64>,
) -> Result<u64, JobError> {
    const MAX: u64 = crate::sim::spec::MAX_ITERATIONS;
    match (more, total) {
        (Some(add), None) => match base.checked_add(add) {
            Some(t) if add >= 1 && t <= MAX => Ok(t),
            _ => Err(SpecError::new(
                "iterations",
                format!("must be ≥ 1 and bring the total ({base}) to at most 10^9, got {add}"),
            )
            .into()),
        },
        (None, Some(t)) if t > done && t <= MAX => Ok(t),
        (None, Some(t)) => Err(SpecError::new(
            "total",
            format!("must exceed the iterations the job holds ({done}) and be at most 10^9, got {t}"),
        )
        .into()),
        _ => {
            Err(SpecError::new("", "give exactly one of `iterations` (how many more) and `total` (the new target)")
                .into())
        }
    }
}

/// Iterations a job runs (its range's length).
pub(in crate::jobs) fn range_len(spec: &JobSpec) -> u64 {
    let r = spec.iteration_range();
    r.end - r.start
}

/// A shard's range is fixed by its study: running past it would overlap the next shard.
pub(in crate::jobs) fn refuse_shard_extension(id: i64, spec: &JobSpec) -> Result<(), JobError> {
    match spec.shard {
        Some(_) => Err(JobError::Conflict(format!(
            "job {id} is a shard: its range is fixed by the study; add iterations with a new job using first_iteration"
        ))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extensions_add_to_what_the_job_would_reach_or_set_the_target() {
        // A cancelled job holding 100 of 1,000: 50 more → 150; resume to its target → 1,000.
        assert_eq!(target_total(100, 100, Some(50), None).unwrap(), 150);
        assert_eq!(target_total(100, 100, None, Some(1000)).unwrap(), 1000);
        assert!(target_total(100, 100, None, Some(100)).is_err(), "the target must exceed what it holds");
        assert!(target_total(100, 100, Some(0), None).is_err());
        assert!(target_total(100, 100, Some(1), Some(200)).is_err(), "one of the two");
        assert!(target_total(100, 100, None, None).is_err());
        assert!(target_total(999_999_999, 0, Some(2), None).is_err());
    }
}
