//! What the server knows of one job's tasks between two looks at the cluster: each task's
//! iterations, its latest verified document, its state in the batch system and how long it has
//! been missing — and the steps of one look: plan the rounds, read the documents, judge each task.
//! Nothing here is a particular batch system's: states arrive as [`Phase`]s, ids through
//! [`BatchSystem::array_task_id`].

use std::collections::HashMap;
use std::ops::Range;
use std::time::{Instant, SystemTime};

use super::files::{JobDir, MAX_TASK_DOCUMENT, Record, Round, document_name};
use super::private::PrivateDir;
use super::system::{BatchSystem, Phase, QueueEntry};
use crate::jobs::core::executor::{ExecutionView, TaskView};
use crate::sim::document::MomentsDocument;
use crate::sim::spec::{JobSpec, Shard, ValidJob};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::{MergeError, Moments};

/// One task: shard `k` of round `round`.
pub(super) struct Task {
    pub round: usize,
    pub k: u64,
    pub range: Range<u64>,
    /// Iterations of its latest verified document (the one with the most seen).
    pub done: u64,
    /// That document's moments while the task is incomplete; a complete task's are added to
    /// `Tracking::completed` and dropped, so memory holds the incomplete tasks' only.
    moments: Option<Moments>,
    /// Modification time and length of the document last read.
    stamp: Option<(SystemTime, u64)>,
    /// Its state as last judged (lower case).
    pub state: String,
    /// Since when it has been gone from the queue (or completed) without a complete document.
    pub missing_since: Option<Instant>,
}

impl Task {
    /// Whether its document holds all its iterations.
    pub fn complete(&self) -> bool {
        self.done == self.range.end - self.range.start
    }
}

/// A job's tasks as the follower tracks them.
pub(super) struct Tracking {
    pub record: Record,
    pub tasks: Vec<Task>,
    /// The sum of the complete tasks' moments (None before the first).
    completed: Option<Moments>,
}

/// The specification of a round: the job's, for iterations [first, first + iterations), cut into
/// shards by the tasks (`--shard-count`, or `--shard` for a resubmission).
pub(super) fn round_spec(job: &JobSpec, first: u64, iterations: u64) -> JobSpec {
    let mut spec = job.clone();
    spec.first_iteration = Some(first);
    spec.iterations = iterations;
    spec.shard = None;
    spec.execution = None;
    spec
}

/// Iterations of shard `k` of `round` (the same cut `optimis run --shard` makes).
fn shard_range(job: &JobSpec, round: &Round, k: u64) -> Range<u64> {
    let mut spec = round_spec(job, round.first, round.iterations);
    spec.shard = Some(Shard { index: k, count: round.tasks });
    spec.iteration_range()
}

impl Tracking {
    /// The tasks of `record`'s rounds, nothing read yet.
    pub fn new(job: &JobSpec, record: Record) -> Self {
        let mut tracking = Self { record, tasks: Vec::new(), completed: None };
        tracking.add_tasks(job);
        tracking
    }

    /// Tracks the tasks of rounds added to the record since.
    pub fn add_tasks(&mut self, job: &JobSpec) {
        let known = self.tasks.last().map_or(0, |t| t.round + 1);
        for (r, round) in self.record.rounds.iter().enumerate().skip(known) {
            for k in 0..round.tasks {
                self.tasks.push(Task {
                    round: r,
                    k,
                    range: shard_range(job, round, k),
                    done: 0,
                    moments: None,
                    stamp: None,
                    state: "submitting".into(),
                    missing_since: None,
                });
            }
        }
    }

    /// The iteration the rounds reach (`first` with none).
    pub fn covered_end(&self, first: u64) -> u64 {
        self.record.rounds.last().map_or(first, |r| r.first + r.iterations)
    }

    /// Task `t`'s current id in the batch system (its array's task, or a resubmission's id); None
    /// while its latest submission awaits the system's answer.
    pub fn key(&self, t: &Task, system: &dyn BatchSystem) -> Option<String> {
        let round = &self.record.rounds[t.round];
        match round.resubmits.get(&t.k).and_then(|r| r.last()) {
            Some(last) => last.clone(),
            None => round.array.as_ref().map(|a| system.array_task_id(a, t.k)),
        }
    }

    /// Submissions of task `t` so far.
    pub fn attempts(&self, t: &Task) -> u32 {
        1 + self.record.rounds[t.round].resubmits.get(&t.k).map_or(0, |r| r.len() as u32)
    }

    /// Reads every incomplete task's document if it changed; true if any brought iterations.
    /// A document is checked as any document from outside is (its checksum and consistency, its
    /// sums bounded), and must be this user's own regular file in the job's checked folders
    /// (never a link) holding only its task's iterations; one that is not is logged and ignored
    /// (the task then counts as missing once it leaves the queue, and runs again).
    pub fn read_documents(&mut self, dir: &JobDir, job: &ValidJob) -> Result<bool, MergeError> {
        let mut changed = false;
        let mut rounds: HashMap<usize, Option<PrivateDir>> = HashMap::new();
        for task in self.tasks.iter_mut().filter(|t| !t.complete()) {
            let folder = rounds.entry(task.round).or_insert_with(|| match dir.round(task.round, false) {
                Ok(folder) => Some(folder),
                Err(e) if e.is_missing() => None,
                Err(e) => {
                    tracing::warn!(error = %e, "a round's folder is not used");
                    None
                }
            });
            let Some(folder) = folder else { continue };
            let name = document_name(task.k);
            let Ok(stamp) = folder.stamp(&name) else { continue };
            if task.stamp == Some(stamp) {
                continue;
            }
            task.stamp = Some(stamp);
            let checked = folder
                .read(&name, MAX_TASK_DOCUMENT)
                .map_err(|e| e.to_string())
                .and_then(|bytes| MomentsDocument::from_json(&bytes).map_err(|e| e.to_string()))
                .and_then(|doc| {
                    let own = Coverage::range(job.spec().seed, task.range.start, task.range.end);
                    if doc.fingerprint != job.config().fingerprint() || !doc.coverage.is_within(&own) {
                        return Err("its configuration or iterations are not the task's".to_string());
                    }
                    doc.moments.check_bounded().map_err(|e| e.to_string())?;
                    Ok(doc.moments)
                });
            match checked {
                Ok(moments) if moments.iterations() > task.done => {
                    task.done = moments.iterations();
                    changed = true;
                    if task.complete() {
                        self.completed.get_or_insert_with(|| Moments::new(job.config())).merge(&moments)?;
                        task.moments = None;
                    } else {
                        task.moments = Some(moments);
                    }
                }
                Ok(_) => {}
                Err(e) => tracing::warn!(document = %folder.path().join(&name).display(), error = %e,
                    "a task's document is ignored"),
            }
        }
        Ok(changed)
    }

    /// The merge of every task's latest document: exact sums over disjoint coverage, so the same
    /// bits in any order and however the iterations were divided.
    pub fn merged(&self, job: &ValidJob) -> Result<Moments, MergeError> {
        let mut merged = self.completed.clone().unwrap_or_else(|| Moments::new(job.config()));
        for moments in self.tasks.iter().filter_map(|t| t.moments.as_ref()) {
            merged.merge(moments)?;
        }
        Ok(merged)
    }

    /// The tasks that need a (re)submission: judged from the queue by id (None when it did not
    /// answer). A task on its way keeps its state; one that ended without a complete document —
    /// failed, cancelled, timed out, or gone from the queue (or completed) for longer than
    /// `grace` — is returned with why.
    pub fn judge(
        &mut self,
        queue: Option<&HashMap<String, QueueEntry>>,
        grace: std::time::Duration,
        system: &dyn BatchSystem,
    ) -> Vec<(usize, String)> {
        let keys: Vec<Option<String>> = self.tasks.iter().map(|t| self.key(t, system)).collect();
        let mut failed = Vec::new();
        for (i, (task, key)) in self.tasks.iter_mut().zip(keys).enumerate() {
            if task.complete() {
                task.state = "completed".into();
                task.missing_since = None;
                continue;
            }
            let Some(key) = key else {
                task.state = "submitting".into();
                continue;
            };
            let Some(queue) = queue else { continue };
            let mut missing = |task: &mut Task, why: String| {
                let since = *task.missing_since.get_or_insert_with(Instant::now);
                if since.elapsed() >= grace {
                    failed.push((i, why));
                }
            };
            match queue.get(&key).map(|e| (e.phase, e.state.as_str())) {
                Some((Phase::Active, state)) => {
                    task.state = state.to_ascii_lowercase();
                    task.missing_since = None;
                }
                Some((Phase::Completed, state)) => {
                    task.state = "completed".into();
                    missing(task, format!("ended {state} without a complete document"));
                }
                Some((Phase::Ended, state)) => {
                    task.state = state.to_ascii_lowercase();
                    failed.push((i, format!("ended {state}")));
                }
                None => {
                    if task.state == "submitting" {
                        task.state = "submitted".into();
                    }
                    missing(task, "left the queue without a complete document".into());
                }
            }
        }
        failed
    }

    /// The tasks as the job resource shows them.
    pub fn view(&self, dir: &JobDir, system: &dyn BatchSystem) -> ExecutionView {
        let tasks = self
            .tasks
            .iter()
            .enumerate()
            .map(|(index, t)| TaskView {
                index: index as u64,
                first_iteration: t.range.start,
                iterations: t.range.end - t.range.start,
                iterations_done: t.done,
                state: t.state.clone(),
                batch_job_id: self.key(t, system),
                attempts: self.attempts(t),
                log: dir.log(t.round, &t.k.to_string()).display().to_string(),
            })
            .collect();
        ExecutionView { executor: system.name().to_ascii_lowercase(), tasks }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::time::Duration;

    use serde_json::json;

    use super::*;
    use crate::jobs::cluster::files::ClusterDir;
    use crate::jobs::cluster::slurm::{Slurm, tests::options};
    use crate::sim::runner::run;
    use crate::sim::spec::parse_job_spec;

    fn job(seed: u64) -> ValidJob {
        let doc =
            json!({ "light_paths": 20_000, "camera_paths": 100, "merge_radius": 0.02, "iterations": 8, "seed": seed });
        parse_job_spec(&doc).unwrap().validate().unwrap()
    }

    fn record() -> Record {
        let round = Round {
            first: 0,
            iterations: 8,
            tasks: 4,
            array: Some("7".into()),
            resubmits: BTreeMap::from([(2, vec![Some("9".into())])]),
        };
        Record { rounds: vec![round] }
    }

    fn entry(id: &str, state: &str, phase: Phase) -> (String, QueueEntry) {
        let submission = id.split('_').next().unwrap().into();
        (
            id.to_string(),
            QueueEntry { id: id.into(), submission, state: state.into(), phase, name: "optimis-x-1-r0".into() },
        )
    }

    #[test]
    fn tasks_are_judged_from_the_queue_with_a_grace_for_missing_documents() {
        let job = job(3);
        let mut t = Tracking::new(job.spec(), record());
        let ranges: Vec<_> = t.tasks.iter().map(|t| t.range.clone()).collect();
        assert_eq!(ranges, [0..2, 2..4, 4..6, 6..8]);
        let slurm = Slurm::new(options());
        let keys: Vec<_> = t.tasks.iter().map(|task| t.key(task, &slurm)).collect();
        assert_eq!(keys, [Some("7_0".into()), Some("7_1".into()), Some("9".into()), Some("7_3".into())]);
        assert_eq!(t.attempts(&t.tasks[2]), 2);
        let queue: HashMap<_, _> = [
            entry("7_0", "RUNNING", Phase::Active),
            entry("7_1", "FAILED", Phase::Ended),
            entry("9", "COMPLETED", Phase::Completed),
        ]
        .into();
        // The system did not answer: nothing is judged.
        assert!(t.judge(None, Duration::ZERO, &slurm).is_empty());
        // A long grace: only what the system says failed fails.
        let failed = t.judge(Some(&queue), Duration::from_secs(3600), &slurm);
        assert_eq!(failed, [(1, "ended FAILED".to_string())]);
        let states: Vec<_> = t.tasks.iter().map(|t| t.state.as_str()).collect();
        assert_eq!(states, ["running", "failed", "completed", "submitted"]);
        // Past the grace, a task completed or gone without its document fails too.
        let failed: Vec<usize> = t.judge(Some(&queue), Duration::ZERO, &slurm).into_iter().map(|(i, _)| i).collect();
        assert_eq!(failed, [1, 2, 3]);
    }

    #[test]
    fn documents_are_verified_merged_exactly_and_foreign_ones_ignored() {
        let job = job(3);
        let tmp = tempfile::tempdir().unwrap();
        let dir = ClusterDir::open(&tmp.path().join("cluster")).unwrap().job(1);
        let mut t = Tracking::new(job.spec(), record());
        let round = dir.round(0, true).unwrap();
        let write = |k: u64, seed: u64, range: Range<u64>| {
            let other = tests::job(seed);
            let moments = run(other.config(), seed, range);
            round.write(&document_name(k), &MomentsDocument::new(other.spec().clone(), moments).to_json()).unwrap();
        };
        write(0, 3, 0..2);
        write(1, 3, 2..3); // partial
        write(2, 4, 4..6); // another seed: not the task's iterations
        write(3, 3, 0..2); // another task's iterations
        assert!(t.read_documents(&dir, &job).unwrap());
        let done: Vec<u64> = t.tasks.iter().map(|t| t.done).collect();
        assert_eq!(done, [2, 1, 0, 0]);
        assert!(t.tasks[0].complete() && !t.tasks[1].complete());
        assert!(!t.read_documents(&dir, &job).unwrap(), "unchanged files are not read again");
        write(1, 3, 2..4);
        write(2, 3, 4..6);
        write(3, 3, 6..8);
        assert!(t.read_documents(&dir, &job).unwrap());
        assert!(t.tasks.iter().all(Task::complete));
        let whole = run(job.config(), 3, 0..8);
        assert_eq!(serde_json::to_vec(&t.merged(&job).unwrap()).unwrap(), serde_json::to_vec(&whole).unwrap());
        let view = t.view(&dir, &Slurm::new(options()));
        assert_eq!(view.executor, "slurm");
        assert_eq!(view.tasks.iter().map(|t| t.iterations_done).sum::<u64>(), 8);
        assert!(view.tasks[3].log.ends_with("round-0/task-3.log"));
    }
}
