//! Which iterations of a job run and how: the document's [`Shard`] (a part of a study's
//! iterations), [`Execution`] (how many tasks a cluster cuts the job into) and [`EngineName`] (how
//! light paths are drawn), and their checks against the job's iterations.

use serde::{Deserialize, Serialize};

use crate::sim::model::config::{Engine, Proposals};
use crate::sim::model::params::{SpecError, check, count};
use crate::sim::stats::coverage::MAX_ITERATION_INDEX;

/// Most tasks one job may be cut into (a server's `--max-tasks` may lower it).
pub const MAX_TASKS: u64 = 10_000;

/// How a server divides a job among a cluster's tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Execution {
    /// The number of tasks (shards of the job's iterations, one Slurm array task each): at least
    /// 1, at most the job's iterations and 10,000.
    #[cfg_attr(feature = "server", schema(minimum = 1, maximum = 10_000))]
    #[serde(deserialize_with = "count")]
    pub tasks: u64,
}

/// The engine of a job: `restricted` draws only the light paths that can merge (an exact Poisson
/// process, thousands of times faster); `brute` streams all N_F of them (the reference).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum EngineName {
    /// Every light path, streamed (the reference).
    #[default]
    Brute,
    /// Only the light paths that can merge, as an exact Poisson process.
    Restricted,
}

impl EngineName {
    /// The engine of the simulation configuration.
    pub(super) fn engine(self) -> Engine {
        match self {
            EngineName::Brute => Engine::Brute,
            EngineName::Restricted => Engine::Restricted(Proposals::Auto),
        }
    }
}

/// Shard `index` of `count` equal parts of a study's iterations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// 0-based, below `count`.
    #[serde(deserialize_with = "count")]
    pub index: u64,
    /// At least 1, at most the study's `iterations`.
    #[cfg_attr(feature = "server", schema(minimum = 1))]
    #[serde(deserialize_with = "count")]
    pub count: u64,
}

/// Checks a job's `shard` and `first_iteration` against its `iterations`: every shard has
/// iterations, and the last iteration has an index.
pub(super) fn validate_range(
    iterations: u64,
    shard: Option<Shard>,
    first_iteration: Option<u64>,
) -> Result<(), SpecError> {
    if let Some(Shard { index, count }) = shard {
        check((1..=iterations).contains(&count), "shard.count", || {
            format!("must be in [1, iterations = {iterations}] so that every shard has iterations, got {count}")
        })?;
        check(index < count, "shard.index", || {
            format!("must be in [0, shard.count - 1 = {}], got {index}", count - 1)
        })?;
    }
    if let Some(first) = first_iteration {
        check(first <= MAX_ITERATION_INDEX - iterations, "first_iteration", || {
            format!("must be at most 2^62 - iterations, got {first}")
        })?;
    }
    Ok(())
}

/// Checks a job's `execution` against its `iterations`: every task has iterations.
pub(super) fn validate_execution(iterations: u64, execution: Option<Execution>) -> Result<(), SpecError> {
    let Some(Execution { tasks }) = execution else { return Ok(()) };
    check((1..=iterations.min(MAX_TASKS)).contains(&tasks), "execution.tasks", || {
        format!("must be in [1, min(iterations, {MAX_TASKS})] so that every task has iterations, got {tasks}")
    })
}
