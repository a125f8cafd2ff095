//! How the server runs jobs on a cluster: the settings every batch system shares (the cluster
//! directory, the tasks' binary, counts, retries, the pace of the looks) and the batch system
//! named once, with its own settings ([`BatchSystemKind`]); validated once at start-up.

use std::path::PathBuf;
use std::time::Duration;

use super::fake::{FakeBatch, FakeOptions};
use super::slurm::{Slurm, SlurmOptions};
use super::system::BatchSystem;

/// The cluster executor's settings. The command line fills them from `--executor slurm`, the
/// `--slurm-*` flags and the generic ones (`--cluster-dir`, `--default-tasks`, `--task-retries`…),
/// whose names stay Slurm's where the README and the scripts use them.
#[derive(Debug, Clone)]
pub struct ClusterOptions {
    /// The batch system the tasks run on, with its own settings.
    pub system: BatchSystemKind,
    /// The directory shared by the server and the nodes: task specifications, documents, logs.
    pub cluster_dir: PathBuf,
    /// The `optimis` binary the tasks run (a path valid on the nodes).
    pub binary: PathBuf,
    /// CPUs each task gets (also the task's `--threads`).
    pub cpus_per_task: u32,
    /// Tasks of a job whose document gives no `execution.tasks`.
    pub default_tasks: u64,
    /// Most tasks of one job.
    pub max_tasks: u64,
    /// Resubmissions of one task before its job fails.
    pub retries: u32,
    /// Seconds between two looks at a running job's tasks.
    pub poll_interval: Duration,
    /// How long a task may be gone from the queue (or completed) without a complete document
    /// before it counts as failed: shared filesystems lag.
    pub missing_grace: Duration,
    /// How often a task writes its partial document.
    pub task_checkpoint_seconds: f64,
}

/// The batch system, named once: a second one is a file of this folder implementing
/// [`BatchSystem`] and one arm here (with its lines in the two matches below).
#[derive(Debug, Clone)]
pub enum BatchSystemKind {
    /// Slurm (`--executor slurm`).
    Slurm(SlurmOptions),
    /// The tests' stand-in: tasks as child processes of this process (never chosen from the
    /// command line).
    #[doc(hidden)]
    Fake(FakeOptions),
}

impl BatchSystemKind {
    /// Checks the system's own settings.
    fn validate(&self) -> Result<(), String> {
        match self {
            Self::Slurm(options) => options.validate(),
            Self::Fake(_) => Ok(()),
        }
    }

    /// The system, not yet asked anything (the executor checks that it answers).
    pub(super) fn start(&self) -> Box<dyn BatchSystem> {
        match self {
            Self::Slurm(options) => Box::new(Slurm::new(options.clone())),
            Self::Fake(options) => Box::new(FakeBatch::new(options.clone())),
        }
    }
}

impl ClusterOptions {
    /// Checks the settings that need no cluster: paths, counts, the system's own.
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
        self.system.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options() -> ClusterOptions {
        ClusterOptions {
            system: BatchSystemKind::Slurm(crate::jobs::cluster::slurm::tests::options()),
            cluster_dir: "/shared/optimis".into(),
            binary: "/opt/optimis/bin/optimis".into(),
            cpus_per_task: 2,
            default_tasks: 1,
            max_tasks: 64,
            retries: 2,
            poll_interval: Duration::from_secs(2),
            missing_grace: Duration::from_secs(60),
            task_checkpoint_seconds: 10.0,
        }
    }

    #[test]
    fn options_are_checked_at_the_edge() {
        assert!(options().validate().is_ok());
        let broken = |f: fn(&mut ClusterOptions)| {
            let mut o = options();
            f(&mut o);
            o.validate().unwrap_err()
        };
        assert!(broken(|o| o.binary = "optimis".into()).contains("absolute"));
        assert!(broken(|o| o.default_tasks = 65).contains("--default-tasks"));
        // The system's own settings are checked with the rest.
        let mut o = options();
        if let BatchSystemKind::Slurm(slurm) = &mut o.system {
            slurm.sbatch_options = vec!["--array=0-9".into()];
        }
        assert!(o.validate().unwrap_err().contains("set by the server"));
        let mut fake = options();
        fake.system = BatchSystemKind::Fake(FakeOptions::default());
        assert!(fake.validate().is_ok());
    }
}
