//! One task on a node (`optimis cluster-task`, the command the executor hands to the batch system):
//! its round's specification and shard read from the cluster directory, the iterations run, the
//! moments document written every few seconds and at the end.
//!
//! The task trusts the directory exactly as the server does ([`ClusterDir::open_existing`]: this
//! user's alone, nothing read or written through a link). Two things never fail it:
//!
//! * a document it finds from an earlier attempt that cannot be used (truncated, corrupted,
//!   another run's, not a file of this user) — the shard starts over, so that one bad file costs
//!   one task's iterations, not the job;
//! * a full disk or quota — the iterations stay in memory, a periodic document is skipped, and the
//!   final one is retried with a growing pause until it fits (as a local job waits for its
//!   database to have room), until the batch system's time limit or a cancel ends the task.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use super::files::{ClusterDir, MAX_TASK_DOCUMENT, document_name};
use super::private::{FileError, PrivateDir};
use crate::sim::document::MomentsDocument;
use crate::sim::runner::run_iterations;
use crate::sim::spec::{Shard, ValidJob, parse_job_spec};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::Moments;

/// Writes a line to the task's log (its stderr). A log that cannot be written (it may sit on the
/// same full disk as the documents) is not a reason to fail: the line is dropped.
fn say(line: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "optimis cluster-task: {line}");
}

/// Longest pause between two attempts to write the final document on a full disk.
const FULL_RETRY_CAP: Duration = Duration::from_secs(60);

/// What the executor tells a task.
#[derive(Debug, Clone)]
pub struct TaskOptions {
    /// The cluster directory (its path on the node).
    pub cluster_dir: PathBuf,
    /// The server's job id.
    pub job: i64,
    /// The round.
    pub round: usize,
    /// The task's index in its round (for an array's tasks the command line takes it from the
    /// batch system's environment, `SLURM_ARRAY_TASK_ID`, unless `--task` gives it).
    pub task: u64,
    /// Tasks in the round.
    pub tasks: u64,
    /// Worker threads.
    pub threads: usize,
    /// Seconds between two partial documents.
    pub checkpoint_seconds: f64,
}

/// Why a task cannot run.
#[derive(Debug, thiserror::Error)]
pub enum TaskError {
    /// A file or folder of the cluster directory.
    #[error(transparent)]
    File(#[from] FileError),
    /// The round's specification, or the task's index.
    #[error("{0}")]
    Spec(String),
    /// The thread pool.
    #[error("cannot start the worker threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
}

/// Runs the task and writes its document; the iterations it ran.
pub fn run_task(options: &TaskOptions) -> Result<u64, TaskError> {
    let dir = ClusterDir::open_existing(&options.cluster_dir)?;
    let round = dir.job(options.job).round(options.round, false)?;
    let k = options.task;
    if k >= options.tasks {
        return Err(TaskError::Spec(format!("task {k} of a round of {} tasks", options.tasks)));
    }
    let bytes = round.read("spec.json", MAX_TASK_DOCUMENT)?;
    let job = serde_json::from_slice(&bytes)
        .map_err(|e| e.to_string())
        .and_then(|value| parse_job_spec(&value).map_err(|e| e.to_string()))
        .and_then(|mut spec| {
            spec.shard = Some(Shard { index: k, count: options.tasks });
            spec.validate().map_err(|e| e.to_string())
        })
        .map_err(|e| TaskError::Spec(format!("{}: {e}", round.path().join("spec.json").display())))?;
    let name = document_name(k);
    let moments = resume(&round, &name, &job);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(options.threads.max(1)).build()?;
    let mut saver =
        Saver::new(Duration::from_secs_f64(options.checkpoint_seconds), |bytes: &[u8]| round.write(&name, bytes));
    let moments = pool.install(|| run_saving(&job, moments, &mut saver))?;
    saver.finish(&document(&job, &moments), std::thread::sleep)?;
    Ok(moments.iterations())
}

/// The moments of an earlier attempt's document, if it holds this shard's first iterations;
/// anything else (none, unreadable, another run's) starts the shard over, and says why.
fn resume(round: &PrivateDir, name: &str, job: &ValidJob) -> Moments {
    let fresh = Moments::new(job.config());
    let bytes = match round.read(name, MAX_TASK_DOCUMENT) {
        Ok(bytes) => bytes,
        Err(e) if e.is_missing() => return fresh,
        Err(e) => {
            say(format_args!("starting the shard over: {e}"));
            return fresh;
        }
    };
    let range = job.spec().iteration_range();
    match MomentsDocument::from_json(&bytes) {
        Ok(doc) => {
            let held = doc.moments.iterations();
            let prefix = Coverage::range(job.spec().seed, range.start, range.start + held);
            if doc.fingerprint == job.config().fingerprint()
                && doc.coverage == prefix
                && held <= range.end - range.start
                && doc.moments.check_bounded().is_ok()
            {
                say(format_args!("resuming after {held} iterations"));
                return doc.moments;
            }
            say(format_args!(
                "starting the shard over: {} holds other iterations than this task's first ones",
                round.path().join(name).display()
            ));
        }
        Err(e) => say(format_args!("starting the shard over: {}: {e}", round.path().join(name).display())),
    }
    fresh
}

fn document(job: &ValidJob, moments: &Moments) -> Vec<u8> {
    MomentsDocument::new(job.spec().clone(), moments.clone()).to_json()
}

/// Runs the shard's iterations that `moments` does not hold, saving a partial document as due.
fn run_saving<W>(job: &ValidJob, mut moments: Moments, saver: &mut Saver<W>) -> Result<Moments, FileError>
where
    W: FnMut(&[u8]) -> Result<(), FileError>,
{
    let range = job.spec().iteration_range();
    let resumed = moments.iterations();
    let never = AtomicBool::new(false);
    let mut failed = None;
    run_iterations(job.config(), job.spec().seed, range.start + resumed..range.end, &mut moments, &never, |m, _| {
        if saver.due()
            && let Err(e) = saver.save(&document(job, m.moments()))
        {
            failed = Some(e);
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    })
    .expect("the run is neither cancelled nor overlapping (a resumed document holds only its first iterations)");
    match failed {
        Some(e) => Err(e),
        None => Ok(moments),
    }
}

/// Writes the task's document: every `every` while the run goes on (skipped, not failed, while
/// the disk is full), and once at the end (retried while the disk is full).
struct Saver<W> {
    write: W,
    every: Duration,
    last: Instant,
    /// Since when the disk has been full (for the log).
    full_since: Option<Instant>,
}

impl<W: FnMut(&[u8]) -> Result<(), FileError>> Saver<W> {
    fn new(every: Duration, write: W) -> Self {
        Self { write, every, last: Instant::now(), full_since: None }
    }

    fn due(&self) -> bool {
        self.last.elapsed() >= self.every
    }

    /// A partial document: a full disk skips it (the iterations stay in memory); any other error
    /// fails the task.
    fn save(&mut self, bytes: &[u8]) -> Result<(), FileError> {
        self.last = Instant::now();
        match (self.write)(bytes) {
            Ok(()) => {
                self.full_since = None;
                Ok(())
            }
            Err(e) if e.is_full() => {
                let since = *self.full_since.get_or_insert_with(Instant::now);
                say(format_args!(
                    "{e}; the iterations are kept in memory and written once there is room \
                     (full for {:.0} s)",
                    since.elapsed().as_secs_f64()
                ));
                Ok(())
            }
            Err(e) => Err(e),
        }
    }

    /// The final document, retried with a growing pause (up to [`FULL_RETRY_CAP`]) while the disk
    /// is full.
    fn finish(&mut self, bytes: &[u8], mut sleep: impl FnMut(Duration)) -> Result<(), FileError> {
        let mut pause = Duration::from_secs(1);
        loop {
            match (self.write)(bytes) {
                Ok(()) => return Ok(()),
                Err(e) if e.is_full() => {
                    say(format_args!("{e}; the final document is written again in {} s", pause.as_secs()));
                    sleep(pause);
                    pause = (pause * 2).min(FULL_RETRY_CAP);
                }
                Err(e) => return Err(e),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::runner::run;

    fn full() -> FileError {
        FileError::Io { path: "task-0.json".into(), source: std::io::Error::from_raw_os_error(28) }
    }

    #[test]
    fn a_full_disk_makes_the_task_wait_and_other_errors_fail_it() {
        let mut attempts = 0;
        let mut pauses = Vec::new();
        let mut saver = Saver::new(Duration::ZERO, |_: &[u8]| {
            attempts += 1;
            if attempts <= 4 { Err(full()) } else { Ok(()) }
        });
        assert!(saver.save(b"partial").is_ok(), "a partial document on a full disk is skipped");
        saver.finish(b"final", |d| pauses.push(d)).unwrap();
        assert_eq!(pauses, [1, 2, 4].map(Duration::from_secs), "retried with a growing pause until it fit");
        let mut denied = Saver::new(Duration::ZERO, |_: &[u8]| {
            Err(FileError::Io { path: "x".into(), source: std::io::Error::from_raw_os_error(13) })
        });
        assert!(denied.save(b"x").is_err() && denied.finish(b"x", |_| unreachable!()).is_err());
    }

    #[test]
    fn a_task_resumes_its_own_document_and_starts_over_from_a_bad_one() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("cluster");
        let dir = ClusterDir::open(&root).unwrap();
        let job_dir = dir.job(4);
        let spec = serde_json::json!({ "engine": "brute", "light_paths": 20_000, "camera_paths": 100,
            "merge_radius": 0.02, "iterations": 6, "seed": 9 });
        job_dir.write_spec(0, spec.to_string().as_bytes()).unwrap();
        let options = TaskOptions {
            cluster_dir: root.clone(),
            job: 4,
            round: 0,
            task: 1,
            tasks: 2,
            threads: 1,
            checkpoint_seconds: 0.1,
        };
        let mut whole = parse_job_spec(&spec).unwrap();
        whole.shard = Some(Shard { index: 1, count: 2 });
        let shard = whole.validate().unwrap();
        let expected = run(shard.config(), 9, 3..6);
        let path = job_dir.round(0, false).unwrap().path().join("task-1.json");
        let written = || MomentsDocument::from_json(&std::fs::read(&path).unwrap()).unwrap().moments;
        // A truncated document (a disk that failed, an editor): the shard starts over.
        std::fs::write(&path, b"{\"kind\": \"optimis-mom").unwrap();
        assert_eq!(run_task(&options).unwrap(), 3);
        assert_eq!(serde_json::to_value(written()).unwrap(), serde_json::to_value(&expected).unwrap());
        // Its own complete document: nothing to redo, the same bits.
        assert_eq!(run_task(&options).unwrap(), 3);
        assert_eq!(serde_json::to_value(written()).unwrap(), serde_json::to_value(&expected).unwrap());
        // A link planted where the document goes: replaced, the file it names untouched.
        let decoy = tmp.path().join("decoy");
        std::fs::write(&decoy, "root's").unwrap();
        std::fs::remove_file(&path).unwrap();
        std::os::unix::fs::symlink(&decoy, &path).unwrap();
        assert_eq!(run_task(&options).unwrap(), 3);
        assert_eq!(std::fs::read_to_string(&decoy).unwrap(), "root's");
        assert_eq!(serde_json::to_value(written()).unwrap(), serde_json::to_value(&expected).unwrap());
        // An index outside the round.
        let outside = TaskOptions { task: 2, ..options };
        assert!(run_task(&outside).unwrap_err().to_string().contains("task 2 of a round of 2"));
    }
}
