//! A stand-in batch system for the tests (`tests/cluster/fake.rs`), never chosen from the command
//! line: each task runs as a child process of this process, and its state is what the process
//! did. It is also the proof that a second batch system is this one file and one arm of
//! [`super::options::BatchSystemKind`]: the rounds, retries, adoption and merges it goes through
//! are the executor's, shared with Slurm.
//!
//! Like a cluster it outlives the server: its queue ([`FakeCluster`]) is shared by every executor
//! started with clones of the same options, so a test can stop a server while its tasks run and
//! let a new one adopt them. It can be told to hold tasks before they start (they show
//! `PENDING`), and to fail the first attempt of chosen tasks of each array (as on a lost node), so
//! that the executor's retries run.

use std::collections::BTreeSet;
use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::system::{BatchError, BatchSystem, Phase, QueueEntry, Submission, Tasks};

/// How often a task's thread looks at its hold, its cancel and its process.
const TICK: Duration = Duration::from_millis(20);

/// The first id the stand-in hands out (any digits would do; these are not Slurm's).
const FIRST_ID: u64 = 1000;

/// The stand-in's settings.
#[derive(Debug, Clone, Default)]
pub struct FakeOptions {
    /// Indexes of array tasks whose attempt within the array fails at once, without running
    /// (exit status 1): the executor then resubmits them alone, and those attempts run.
    pub fail_first: BTreeSet<u64>,
    /// The queue, shared by every clone of these options.
    pub cluster: FakeCluster,
}

/// The stand-in's queue: what a restarted server finds.
#[derive(Debug, Clone, Default)]
pub struct FakeCluster(Arc<Shared>);

#[derive(Debug, Default)]
struct Shared {
    /// While set, tasks wait (`PENDING`) before they start.
    held: AtomicBool,
    queue: Mutex<Queue>,
}

#[derive(Debug, Default)]
struct Queue {
    /// Submissions so far (ids from [`FIRST_ID`]).
    submissions: u64,
    /// The names submitted, in order.
    names: Vec<String>,
    tasks: Vec<FakeTask>,
}

#[derive(Debug)]
struct FakeTask {
    id: String,
    submission: String,
    name: String,
    /// `PENDING`, `RUNNING`, `COMPLETED`, `FAILED` or `CANCELLED`.
    state: &'static str,
    /// Asked to stop: its thread kills its process, or never starts it.
    cancel: bool,
}

impl FakeCluster {
    /// Holds the tasks before they start (true), or lets them start (false).
    pub fn hold(&self, held: bool) {
        self.0.held.store(held, Ordering::SeqCst);
    }

    /// The names submitted so far, in order (a round's array, a resubmission's `…-tK`).
    pub fn submitted(&self) -> Vec<String> {
        self.queue().names.clone()
    }

    fn queue(&self) -> std::sync::MutexGuard<'_, Queue> {
        self.0.queue.lock().expect("the fake queue")
    }

    /// Task `at`'s state.
    fn set(&self, at: usize, state: &'static str) {
        self.queue().tasks[at].state = state;
    }

    fn cancelled(&self, at: usize) -> bool {
        self.queue().tasks[at].cancel
    }

    /// Runs task `at` on a thread of its own: waits while held, then runs `argv` with its output
    /// appended to `log`, and records how it ended.
    fn launch(&self, at: usize, argv: Vec<String>, log: PathBuf) {
        let cluster = self.clone();
        std::thread::spawn(move || {
            while cluster.0.held.load(Ordering::SeqCst) && !cluster.cancelled(at) {
                std::thread::sleep(TICK);
            }
            if cluster.cancelled(at) {
                return cluster.set(at, "CANCELLED");
            }
            // A clean environment, as the server asks of Slurm (`--export=NONE`).
            let (out, err) = outputs(&log);
            let spawned = Command::new(&argv[0])
                .args(&argv[1..])
                .env_clear()
                .stdin(Stdio::null())
                .stdout(out)
                .stderr(err)
                .spawn();
            let mut child = match spawned {
                Ok(child) => child,
                Err(e) => {
                    say(&log, &format!("fake batch system: cannot run {}: {e}", argv[0]));
                    return cluster.set(at, "FAILED");
                }
            };
            cluster.set(at, "RUNNING");
            loop {
                if cluster.cancelled(at) {
                    let _ = child.kill();
                    let _ = child.wait();
                    return cluster.set(at, "CANCELLED");
                }
                match child.try_wait() {
                    Ok(Some(status)) => return cluster.set(at, if status.success() { "COMPLETED" } else { "FAILED" }),
                    Ok(None) => std::thread::sleep(TICK),
                    Err(_) => return cluster.set(at, "FAILED"),
                }
            }
        });
    }
}

/// The task's stdout and stderr: its log, appended (nowhere if the log cannot be opened, as a
/// batch system whose output path is wrong loses the output, not the task).
fn outputs(log: &Path) -> (Stdio, Stdio) {
    let open = || OpenOptions::new().create(true).append(true).open(log);
    match (open(), open()) {
        (Ok(out), Ok(err)) => (out.into(), err.into()),
        _ => (Stdio::null(), Stdio::null()),
    }
}

/// Appends a line of the stand-in's own to a task's log.
fn say(log: &Path, line: &str) {
    use std::io::Write;
    if let Ok(mut file) = OpenOptions::new().create(true).append(true).open(log) {
        let _ = writeln!(file, "{line}");
    }
}

/// The stand-in batch system.
pub struct FakeBatch {
    options: FakeOptions,
}

impl FakeBatch {
    /// The stand-in with these settings.
    pub fn new(options: FakeOptions) -> Self {
        Self { options }
    }
}

impl BatchSystem for FakeBatch {
    fn name(&self) -> &'static str {
        "Fake"
    }

    fn check(&self) -> Result<String, BatchError> {
        Ok("fake batch system (tasks as child processes of the server)".into())
    }

    /// Every task of the submission at once (each waits on its own thread while held); an
    /// array's task gets its index as `--task K`.
    fn submit(&self, submission: &Submission<'_>) -> Result<String, BatchError> {
        let cluster = &self.options.cluster;
        let (id, starts) = {
            let mut queue = cluster.queue();
            let id = (FIRST_ID + queue.submissions).to_string();
            queue.submissions += 1;
            queue.names.push(submission.name.to_string());
            let tasks: Vec<(String, Vec<String>, u64)> = match submission.tasks {
                Tasks::Array(count) => (0..count)
                    .map(|k| {
                        let mut argv = submission.command.to_vec();
                        argv.extend(["--task".to_string(), k.to_string()]);
                        (self.array_task_id(&id, k), argv, k)
                    })
                    .collect(),
                Tasks::One(k) => vec![(id.clone(), submission.command.to_vec(), k)],
            };
            let mut starts = Vec::new();
            for (task_id, argv, k) in tasks {
                let log = (submission.log)(&k.to_string());
                let fails = matches!(submission.tasks, Tasks::Array(_)) && self.options.fail_first.contains(&k);
                queue.tasks.push(FakeTask {
                    id: task_id,
                    submission: id.clone(),
                    name: submission.name.to_string(),
                    state: if fails { "FAILED" } else { "PENDING" },
                    cancel: false,
                });
                if fails {
                    say(&log, &format!("fake batch system: task {k} of {id} fails on purpose (its first attempt)"));
                } else {
                    starts.push((queue.tasks.len() - 1, argv, log));
                }
            }
            (id, starts)
        };
        for (at, argv, log) in starts {
            cluster.launch(at, argv, log);
        }
        Ok(id)
    }

    fn queue(&self, prefix: &str) -> Result<Vec<QueueEntry>, BatchError> {
        let queue = self.options.cluster.queue();
        Ok(queue
            .tasks
            .iter()
            .filter(|t| t.name.starts_with(prefix))
            .map(|t| QueueEntry {
                id: t.id.clone(),
                submission: t.submission.clone(),
                state: t.state.to_string(),
                phase: match t.state {
                    "PENDING" | "RUNNING" => Phase::Active,
                    "COMPLETED" => Phase::Completed,
                    _ => Phase::Ended,
                },
                name: t.name.clone(),
            })
            .collect())
    }

    /// `ARRAY.K`: not Slurm's `ARRAY_K`, so that nothing outside the seam can rely on Slurm's.
    fn array_task_id(&self, array: &str, k: u64) -> String {
        format!("{array}.{k}")
    }

    fn cancel(&self, ids: &[String]) -> Result<(), BatchError> {
        let mut queue = self.options.cluster.queue();
        for task in queue.tasks.iter_mut().filter(|t| ids.contains(&t.id) || ids.contains(&t.submission)) {
            task.cancel = true;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Waits until the queue's states under `prefix` are `states`.
    fn until(system: &FakeBatch, prefix: &str, states: &[&str]) {
        for _ in 0..500 {
            let now: Vec<String> = system.queue(prefix).unwrap().into_iter().map(|e| e.state).collect();
            if now == states {
                return;
            }
            std::thread::sleep(TICK);
        }
        panic!("the tasks never were {states:?}: {:?}", system.queue(prefix).unwrap());
    }

    #[test]
    fn the_stand_in_holds_fails_runs_and_cancels_tasks() {
        let tmp = tempfile::tempdir().unwrap();
        let options = FakeOptions { fail_first: BTreeSet::from([1]), cluster: FakeCluster::default() };
        let system = FakeBatch::new(options.clone());
        options.cluster.hold(true);
        // Each task writes its index (the `--task K` the stand-in appends) to its log.
        let command = ["/bin/sh".to_string(), "-c".to_string(), "echo \"$2\"".to_string(), "sh".to_string()];
        let log = |k: &str| tmp.path().join(format!("task-{k}.log"));
        let array =
            Submission { name: "optimis-x-1-r0", tasks: Tasks::Array(3), command: &command, cpus: 1, log: &log };
        let id = system.submit(&array).unwrap();
        until(&system, "optimis-x-1-", &["PENDING", "FAILED", "PENDING"]);
        let entry = &system.queue("optimis-x-1-").unwrap()[2];
        assert_eq!((entry.id.as_str(), entry.submission.as_str(), entry.phase), ("1000.2", id.as_str(), Phase::Active));
        // A clone of the options (a restarted server) sees the same queue; released, the tasks run.
        let again = FakeBatch::new(options.clone());
        options.cluster.hold(false);
        until(&again, "optimis-x-1-", &["COMPLETED", "FAILED", "COMPLETED"]);
        assert_eq!(std::fs::read_to_string(log("2")).unwrap(), "2\n");
        assert!(std::fs::read_to_string(log("1")).unwrap().contains("on purpose"));
        // A task alone runs even if its index failed in the array; a cancel stops a running one.
        let sleep = ["/bin/sh".to_string(), "-c".to_string(), "sleep 30".to_string()];
        let one = Submission { name: "optimis-x-1-r0-t1", tasks: Tasks::One(1), command: &sleep, cpus: 1, log: &log };
        let alone = again.submit(&one).unwrap();
        until(&again, "optimis-x-1-r0-t1", &["RUNNING"]);
        again.cancel(&[alone]).unwrap();
        until(&again, "optimis-x-1-r0-t1", &["CANCELLED"]);
        assert_eq!(options.cluster.submitted(), ["optimis-x-1-r0", "optimis-x-1-r0-t1"]);
    }
}
