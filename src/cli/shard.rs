//! Which shard a headless run is: from `--shard K/N`, or from the index a batch scheduler gives
//! each task of an array job.
//!
//! * Slurm job arrays set `SLURM_ARRAY_TASK_ID` (counted from `SLURM_ARRAY_TASK_MIN`, often 0 or
//!   1) and `SLURM_ARRAY_TASK_COUNT`;
//! * Kubernetes indexed Jobs set `JOB_COMPLETION_INDEX` (from 0); the count is the Job's
//!   `completions`, passed as `--shard-count` or in the spec's `shard.count`.

use std::collections::HashMap;

use crate::sim::spec::{Shard, SpecError};

/// Parses `K/N`.
pub fn parse_shard(text: &str) -> Result<Shard, String> {
    let (k, n) = text.split_once('/').ok_or_else(|| format!("expected K/N (shard K of N, from 0), got {text:?}"))?;
    let index = k.trim().parse::<u64>().map_err(|_| format!("shard index {k:?} is not a number"))?;
    let count = n.trim().parse::<u64>().map_err(|_| format!("shard count {n:?} is not a number"))?;
    Ok(Shard { index, count })
}

/// The index a batch scheduler gives this task, where it came from, and the array's size when the
/// scheduler says it.
pub struct TaskIndex {
    pub index: u64,
    pub source: &'static str,
    pub count: Option<u64>,
}

/// The task index of `SLURM_ARRAY_TASK_ID` (minus `SLURM_ARRAY_TASK_MIN`, with
/// `SLURM_ARRAY_TASK_COUNT`) or `JOB_COMPLETION_INDEX`, if either is set.
pub fn task_index(env: &HashMap<String, String>) -> Result<Option<TaskIndex>, SpecError> {
    let number = |name: &str| -> Result<Option<u64>, SpecError> {
        match env.get(name) {
            None => Ok(None),
            Some(v) => v.trim().parse().map(Some).map_err(|_| SpecError::new(name, format!("is not a number: {v:?}"))),
        }
    };
    if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
        let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
        let index = id
            .checked_sub(min)
            .ok_or_else(|| SpecError::new("SLURM_ARRAY_TASK_ID", "is below SLURM_ARRAY_TASK_MIN"))?;
        let count = number("SLURM_ARRAY_TASK_COUNT")?;
        return Ok(Some(TaskIndex { index, source: "SLURM_ARRAY_TASK_ID", count }));
    }
    Ok(number("JOB_COMPLETION_INDEX")?.map(|index| TaskIndex { index, source: "JOB_COMPLETION_INDEX", count: None }))
}

/// The shard of this run: the flag if given, else the scheduler's index (with the count from the
/// flag, the scheduler or the spec), else none. `env` is the process environment.
pub fn resolve_shard(
    flag: Option<Shard>,
    count_flag: Option<u64>,
    spec_shard: Option<Shard>,
    env: &HashMap<String, String>,
) -> Result<Option<Shard>, SpecError> {
    if flag.is_some() {
        return Ok(flag);
    }
    let spec_count = spec_shard.map(|s| s.count);
    let Some(task) = task_index(env)? else { return Ok(spec_shard) };
    let count = count_flag.or(task.count).or(spec_count);
    let (index, source) = (task.index, task.source);
    let count = count.ok_or_else(|| {
        SpecError::new(
            "shard.count",
            format!("{source} gives the shard index; give the number of shards with --shard-count"),
        )
    })?;
    Ok(Some(Shard { index, count }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(pairs: &[(&str, &str)]) -> HashMap<String, String> {
        pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
    }

    #[test]
    fn shards_come_from_the_flag_or_the_scheduler() {
        let s = |index, count| Some(Shard { index, count });
        assert_eq!(parse_shard("2/8"), Ok(Shard { index: 2, count: 8 }));
        assert!(parse_shard("2").is_err() && parse_shard("a/3").is_err());
        assert_eq!(resolve_shard(s(1, 4), None, None, &env(&[("SLURM_ARRAY_TASK_ID", "3")])).unwrap(), s(1, 4));
        let slurm =
            env(&[("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "4")]);
        assert_eq!(resolve_shard(None, None, None, &slurm).unwrap(), s(2, 4));
        let k8s = env(&[("JOB_COMPLETION_INDEX", "5")]);
        assert_eq!(resolve_shard(None, Some(8), None, &k8s).unwrap(), s(5, 8));
        assert_eq!(resolve_shard(None, None, s(0, 6), &k8s).unwrap(), s(5, 6));
        assert_eq!(resolve_shard(None, None, None, &k8s).unwrap_err().field, "shard.count");
        assert_eq!(resolve_shard(None, None, None, &env(&[])).unwrap(), None);
        assert!(resolve_shard(None, None, None, &env(&[("JOB_COMPLETION_INDEX", "x")])).is_err());
    }
}
