//! What the server knows of one job's tasks between two looks at the cluster: each task's
//! iterations, its latest verified document, its Slurm state and how long it has been missing —
//! and the steps of one look: plan the rounds, read the documents, judge each task.

use std::collections::HashMap;
use std::ops::Range;
use std::time::{Instant, SystemTime};

use super::files::{JobDir, MAX_TASK_DOCUMENT, Record, Round, read_bounded};
use super::slurm::{QueueEntry, is_active};
use crate::jobs::executor::{ExecutionView, TaskView};
use crate::sim::document::MomentsDocument;
use crate::sim::spec::{JobSpec, Shard, ValidJob};
use crate::sim::stats::coverage::Coverage;
use crate::sim::stats::moments::{MergeError, Moments};

/// One task: shard `k` of round `round`.
pub(super) struct Task {
    pub round: usize,
    pub k: u64,
    pub range: Range<u64>,
    /// Its latest verified document's moments (the one with the most iterations seen).
    pub moments: Option<Moments>,
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
        self.moments.as_ref().is_some_and(|m| m.iterations() == self.range.end - self.range.start)
    }
}

/// A job's tasks as the follower tracks them.
pub(super) struct Tracking {
    pub record: Record,
    pub tasks: Vec<Task>,
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
        let mut tracking = Self { record, tasks: Vec::new() };
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

    /// Task `t`'s current Slurm key (`ARRAY_TASK` or a resubmission's id); None while its latest
    /// submission awaits sbatch's answer.
    pub fn key(&self, t: &Task) -> Option<String> {
        let round = &self.record.rounds[t.round];
        match round.resubmits.get(&t.k).and_then(|r| r.last()) {
            Some(last) => last.clone(),
            None => round.array.as_ref().map(|a| format!("{a}_{}", t.k)),
        }
    }

    /// Submissions of task `t` so far.
    pub fn attempts(&self, t: &Task) -> u32 {
        1 + self.record.rounds[t.round].resubmits.get(&t.k).map_or(0, |r| r.len() as u32)
    }

    /// Reads every incomplete task's document if it changed; true if any brought iterations.
    /// A document that does not verify, or holds iterations outside its task, is logged and
    /// ignored (the task then counts as missing once it leaves the queue).
    pub fn read_documents(&mut self, dir: &JobDir, job: &ValidJob) -> bool {
        let mut changed = false;
        for task in self.tasks.iter_mut().filter(|t| !t.complete()) {
            let path = dir.document(task.round, &task.k.to_string());
            let Ok(meta) = std::fs::metadata(&path) else { continue };
            let stamp = (meta.modified().unwrap_or(SystemTime::UNIX_EPOCH), meta.len());
            if task.stamp == Some(stamp) {
                continue;
            }
            task.stamp = Some(stamp);
            let checked = read_bounded(&path, MAX_TASK_DOCUMENT)
                .map_err(|e| e.to_string())
                .and_then(|bytes| MomentsDocument::from_json(&bytes).map_err(|e| e.to_string()))
                .and_then(|doc| {
                    let own = Coverage::range(job.spec().seed, task.range.start, task.range.end);
                    if doc.fingerprint != job.config().fingerprint() || !doc.coverage.is_within(&own) {
                        return Err("its configuration or iterations are not the task's".to_string());
                    }
                    Ok(doc.moments)
                });
            match checked {
                Ok(moments) if moments.iterations() > task.moments.as_ref().map_or(0, Moments::iterations) => {
                    task.moments = Some(moments);
                    changed = true;
                }
                Ok(_) => {}
                Err(e) => tracing::warn!(document = %path.display(), error = %e, "a task's document is ignored"),
            }
        }
        changed
    }

    /// The merge of every task's latest document: exact sums over disjoint coverage, so the same
    /// bits in any order and however the iterations were divided.
    pub fn merged(&self, job: &ValidJob) -> Result<Moments, MergeError> {
        let mut merged = Moments::new(job.config());
        for moments in self.tasks.iter().filter_map(|t| t.moments.as_ref()) {
            merged.merge(moments)?;
        }
        Ok(merged)
    }

    /// The tasks that need a (re)submission: judged from the queue (None when it did not
    /// answer). A task on its way keeps its state; one that ended without a complete document —
    /// failed, cancelled, timed out, or gone from the queue (or `COMPLETED`) for longer than
    /// `grace` — is returned with why.
    pub fn judge(
        &mut self,
        queue: Option<&HashMap<String, QueueEntry>>,
        grace: std::time::Duration,
    ) -> Vec<(usize, String)> {
        let keys: Vec<Option<String>> = self.tasks.iter().map(|t| self.key(t)).collect();
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
            match queue.get(&key).map(|e| e.state.as_str()) {
                Some(state) if is_active(state) => {
                    task.state = state.to_ascii_lowercase();
                    task.missing_since = None;
                }
                Some("COMPLETED") => {
                    task.state = "completed".into();
                    missing(task, "ended COMPLETED without a complete document".into());
                }
                Some(state) => {
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
    pub fn view(&self, dir: &JobDir) -> ExecutionView {
        let tasks = self
            .tasks
            .iter()
            .enumerate()
            .map(|(index, t)| TaskView {
                index: index as u64,
                first_iteration: t.range.start,
                iterations: t.range.end - t.range.start,
                iterations_done: t.moments.as_ref().map_or(0, Moments::iterations),
                state: t.state.clone(),
                slurm_job_id: self.key(t),
                attempts: self.attempts(t),
                log: dir.log(t.round, &t.k.to_string()).display().to_string(),
            })
            .collect();
        ExecutionView { executor: "slurm".into(), tasks }
    }
}
