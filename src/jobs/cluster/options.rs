//! How the server runs jobs on a Slurm cluster: the flags of `optimis serve --executor slurm`,
//! validated once at start-up.

use std::path::PathBuf;
use std::time::Duration;

/// sbatch options this server sets itself; `--sbatch-option` may not set them.
const RESERVED: &[&str] =
    &["--array", "--output", "--error", "--job-name", "--parsable", "--open-mode", "--wrap", "-a", "-o", "-e", "-J"];

/// The Slurm executor's settings.
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    /// The directory shared by the server and the nodes: task specifications, documents, logs.
    pub cluster_dir: PathBuf,
    /// The `optimis` binary the tasks run (a path valid on the nodes).
    pub binary: PathBuf,
    /// Where `sbatch`, `squeue` and `scancel` are (None: on the PATH).
    pub slurm_bin_dir: Option<PathBuf>,
    /// `--partition`, if any.
    pub partition: Option<String>,
    /// `--account`, if any.
    pub account: Option<String>,
    /// `--cpus-per-task` (also the task's `--threads`).
    pub cpus_per_task: u32,
    /// `--time`, if any.
    pub time_limit: Option<String>,
    /// Further sbatch options, passed as they are (one argument each).
    pub sbatch_options: Vec<String>,
    /// Tasks of a job whose document gives no `execution.tasks`.
    pub default_tasks: u64,
    /// Most tasks of one job.
    pub max_tasks: u64,
    /// Resubmissions of one task before its job fails.
    pub retries: u32,
    /// Seconds between two looks at a running job's tasks.
    pub poll_interval: Duration,
    /// Deadline of each Slurm command.
    pub command_timeout: Duration,
    /// How long a task may be gone from the queue (or `COMPLETED`) without a complete document
    /// before it counts as failed: shared filesystems lag.
    pub missing_grace: Duration,
    /// How often a task writes its partial document.
    pub task_checkpoint_seconds: f64,
}

impl SlurmOptions {
    /// Checks the settings that need no cluster: paths, counts, the extra sbatch options.
    pub fn validate(&self) -> Result<(), String> {
        if !self.binary.is_absolute() {
            return Err(format!(
                "--slurm-binary must be an absolute path (on the nodes), got {}",
                self.binary.display()
            ));
        }
        for (flag, path) in [("--cluster-dir", &self.cluster_dir), ("--slurm-binary", &self.binary)] {
            if path.to_str().is_none_or(|p| p.chars().any(char::is_control)) {
                return Err(format!("{flag} must be a UTF-8 path without control characters"));
            }
        }
        if !(1..=self.max_tasks).contains(&self.default_tasks) {
            return Err(format!(
                "--default-tasks must be in [1, --max-tasks = {}], got {}",
                self.max_tasks, self.default_tasks
            ));
        }
        for option in &self.sbatch_options {
            if !option.starts_with('-') || option.chars().any(char::is_control) {
                return Err(format!("--sbatch-option {option:?}: expected one sbatch option such as --qos=normal"));
            }
            let name = option.split('=').next().unwrap_or(option);
            if RESERVED.contains(&name) {
                return Err(format!("--sbatch-option {option:?}: {name} is set by the server"));
            }
        }
        for (flag, value) in [
            ("--slurm-partition", &self.partition),
            ("--slurm-account", &self.account),
            ("--slurm-time", &self.time_limit),
        ] {
            if value.as_deref().is_some_and(|v| v.is_empty() || v.chars().any(|c| c.is_control() || c.is_whitespace()))
            {
                return Err(format!("{flag} must be one word"));
            }
        }
        Ok(())
    }

    /// The sbatch options every task of this server gets (before the per-submission ones).
    pub(super) fn common_sbatch_options(&self) -> Vec<String> {
        // A clean environment: the server's own (its tokens, its database URL) stays out of the
        // cluster's jobs; paths are absolute, so nothing needs the PATH.
        let mut options = vec!["--export=NONE".to_string(), "--open-mode=append".to_string()];
        options.push(format!("--cpus-per-task={}", self.cpus_per_task));
        if let Some(p) = &self.partition {
            options.push(format!("--partition={p}"));
        }
        if let Some(a) = &self.account {
            options.push(format!("--account={a}"));
        }
        if let Some(t) = &self.time_limit {
            options.push(format!("--time={t}"));
        }
        options.extend(self.sbatch_options.iter().cloned());
        options
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn options() -> SlurmOptions {
        SlurmOptions {
            cluster_dir: "/shared/optimis".into(),
            binary: "/opt/optimis/bin/optimis".into(),
            slurm_bin_dir: None,
            partition: Some("batch".into()),
            account: None,
            cpus_per_task: 2,
            time_limit: Some("01:00:00".into()),
            sbatch_options: vec!["--qos=normal".into()],
            default_tasks: 1,
            max_tasks: 64,
            retries: 2,
            poll_interval: Duration::from_secs(2),
            command_timeout: Duration::from_secs(20),
            missing_grace: Duration::from_secs(60),
            task_checkpoint_seconds: 10.0,
        }
    }

    #[test]
    fn options_are_checked_at_the_edge() {
        let ok = options();
        assert!(ok.validate().is_ok());
        assert_eq!(
            ok.common_sbatch_options(),
            [
                "--export=NONE",
                "--open-mode=append",
                "--cpus-per-task=2",
                "--partition=batch",
                "--time=01:00:00",
                "--qos=normal"
            ]
        );
        let broken = |f: fn(&mut SlurmOptions)| {
            let mut o = options();
            f(&mut o);
            o.validate().unwrap_err()
        };
        assert!(broken(|o| o.binary = "optimis".into()).contains("absolute"));
        assert!(broken(|o| o.sbatch_options = vec!["--array=0-9".into()]).contains("set by the server"));
        assert!(broken(|o| o.sbatch_options = vec!["qos".into()]).contains("expected one sbatch option"));
        assert!(broken(|o| o.partition = Some("a b".into())).contains("one word"));
        assert!(broken(|o| o.default_tasks = 65).contains("--default-tasks"));
    }
}
