//! The cluster executor: a job's iterations as one array of a batch system per round (the job's
//! first iterations; each extension's), followed from the server until every task's document is
//! complete. What is asked of the batch system is [`BatchSystem`]'s few calls; the rounds, the
//! retries, the adoption and the merges here are the same for every system.
//!
//! One look at a job (every `--slurm-poll-seconds`, on the job's driver thread — a blocking
//! thread, never a tokio worker): plan a round for iterations no round covers yet and submit it
//! (its intent recorded first, so a restart finds the array by its name instead of submitting it
//! again); ask the system's queue once for all of the job's tasks; read the documents that
//! changed; judge each task, resubmitting one that ended without its iterations (same shard, so
//! the same iterations, up to `--task-retries` times, then the job fails naming the task, its id
//! in the batch system and its log); merge the tasks' latest documents and hand them to the
//! driver, which checkpoints them as it does a local run's. Because each document holds only its
//! task's iterations and merges are exact, the merged statistics never count an iteration twice,
//! whatever ran twice.
//!
//! A shutdown leaves the tasks running (the next start adopts them); a cancel cancels them.

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::files::{ClusterDir, JobDir, Record, Round};
use super::options::ClusterOptions;
use super::private::FileError;
use super::system::{BatchError, BatchSystem, QueueEntry, Submission, Tasks};
use super::tracking::{Tracking, round_spec};
use crate::jobs::core::executor::{Executor, OnBatch, Segment, SegmentError};
use crate::metrics::Metrics;
use crate::sim::runner::RunError;
use crate::sim::spec::{JobSpec, SpecError};
use crate::sim::stats::moments::Moments;

/// Runs jobs as arrays of a batch system.
pub struct ClusterExecutor {
    options: ClusterOptions,
    dir: ClusterDir,
    system: Box<dyn BatchSystem>,
    metrics: Arc<Metrics>,
    /// What is known of each followed job between two segments; std Mutex, map operations only.
    tracking: Mutex<HashMap<i64, Tracking>>,
    /// Tasks by state of each followed job (for the metrics).
    counts: Mutex<HashMap<i64, BTreeMap<String, i64>>>,
}

impl ClusterExecutor {
    /// Checks the options, the cluster directory and that the batch system answers: a clear error
    /// at start-up rather than failed jobs later.
    pub fn start(options: ClusterOptions, metrics: Arc<Metrics>) -> Result<Self, String> {
        options.validate()?;
        let dir = ClusterDir::open(&options.cluster_dir)?;
        let system = options.system.start();
        let name = system.name();
        let version = system
            .check()
            .map_err(|e| format!("--executor {}: {name} does not answer: {e}", name.to_ascii_lowercase()))?;
        if !options.binary.exists() {
            tracing::warn!(binary = %options.binary.display(),
                "--slurm-binary does not exist on this machine; it must on the nodes");
        }
        tracing::info!(system = name, %version, cluster_dir = %options.cluster_dir.display(),
            binary = %options.binary.display(),
            "running jobs on a batch system (its queue and the task documents are followed)");
        Ok(Self { options, dir, system, metrics, tracking: Mutex::default(), counts: Mutex::default() })
    }

    /// The tasks of round `r`, as one array.
    fn submit_round(&self, dir: &JobDir, r: usize, round: &Round) -> Result<String, BatchError> {
        self.system.submit(&Submission {
            name: &dir.round_name(r),
            tasks: Tasks::Array(round.tasks),
            command: &self.task_command(dir, r, round, None),
            cpus: self.options.cpus_per_task,
            log: &|k| dir.log(r, k),
        })
    }

    /// Task `k` of round `r` again, on its own (same shard: the same iterations).
    fn resubmit_task(&self, dir: &JobDir, r: usize, round: &Round, k: u64) -> Result<String, BatchError> {
        self.system.submit(&Submission {
            name: &dir.task_name(r, k),
            tasks: Tasks::One(k),
            command: &self.task_command(dir, r, round, Some(k)),
            cpus: self.options.cpus_per_task,
            log: &|k| dir.log(r, k),
        })
    }

    /// `optimis cluster-task` for task `k` of round `r` (none: each task of the array, its index
    /// given by the batch system): it reads the round's spec, writes its document every few
    /// seconds and resumes from one a retry finds. Given to the system as argv, so that no script
    /// in the shared directory is ever run.
    fn task_command(&self, dir: &JobDir, r: usize, round: &Round, k: Option<u64>) -> Vec<String> {
        let mut argv = vec![
            path(&self.options.binary),
            "cluster-task".into(),
            "--cluster-dir".into(),
            path(self.dir.path()),
            "--job".into(),
            dir.id().to_string(),
            "--round".into(),
            r.to_string(),
            "--tasks".into(),
            round.tasks.to_string(),
            "--threads".into(),
            self.options.cpus_per_task.to_string(),
            "--checkpoint-seconds".into(),
            self.options.task_checkpoint_seconds.to_string(),
        ];
        if let Some(k) = k {
            argv.extend(["--task".into(), k.to_string()]);
        }
        argv
    }

    /// Every id in the batch system the job's record holds (arrays whole, resubmissions).
    fn submitted_ids(record: &Record) -> Vec<String> {
        let mut ids = Vec::new();
        for round in &record.rounds {
            ids.extend(round.array.iter().cloned());
            ids.extend(round.resubmits.values().flatten().flatten().cloned());
        }
        ids
    }

    /// Cancels every task of a job, those whose id is not recorded yet included (by name).
    fn cancel_all(&self, dir: &JobDir, record: &Record) {
        let mut ids = Self::submitted_ids(record);
        if let Ok(queue) = self.system.queue(&dir.prefix) {
            ids.extend(queue.into_iter().map(|e| e.id));
        }
        if let Err(e) = self.system.cancel(&ids) {
            tracing::error!(prefix = %dir.prefix, error = %e, "the cancel failed; the tasks may still run");
        }
    }

    /// Updates the metrics' counts of tasks by state.
    fn count(&self, id: i64, tracking: Option<&Tracking>) {
        let mut counts = self.counts.lock().expect("counts");
        match tracking {
            Some(t) => {
                let mut by_state = BTreeMap::new();
                for task in &t.tasks {
                    *by_state.entry(task.state.clone()).or_insert(0) += 1;
                }
                counts.insert(id, by_state);
            }
            None => {
                counts.remove(&id);
            }
        }
        let mut totals: BTreeMap<String, i64> = BTreeMap::new();
        for by_state in counts.values() {
            for (state, n) in by_state {
                *totals.entry(state.clone()).or_insert(0) += n;
            }
        }
        self.metrics.set_cluster_tasks(&totals);
    }

    /// The number of tasks for a job's round of `iterations`.
    fn tasks_for(&self, spec: &JobSpec, iterations: u64) -> u64 {
        let asked = spec.execution.map_or(self.options.default_tasks, |e| e.tasks);
        asked.min(self.options.max_tasks).min(iterations).max(1)
    }

    /// One look at the job: rounds planned and submitted, the queue, the documents, the tasks
    /// judged. Ok(true) if the merged statistics changed.
    fn look(&self, segment: &Segment<'_>, dir: &JobDir, t: &mut Tracking) -> Result<bool, SegmentError> {
        let spec = segment.job.spec();
        let end = t.covered_end(segment.first);
        if end < segment.total {
            let r = t.record.rounds.len();
            let iterations = segment.total - end;
            let round = Round {
                first: end,
                iterations,
                tasks: self.tasks_for(spec, iterations),
                array: None,
                resubmits: BTreeMap::new(),
            };
            let text =
                serde_json::to_vec_pretty(&round_spec(spec, round.first, round.iterations)).expect("a spec serialises");
            t.record.rounds.push(round);
            let written = dir.write_spec(r, &text).and_then(|()| dir.save_record(&t.record));
            if let Err(e) = written {
                // Not planned until both are stored: the next look tries again.
                t.record.rounds.pop();
                return wait_or_fail(segment.id, e, "the tasks' specification").map(|()| false);
            }
            t.add_tasks(spec);
        }
        let queue = match self.system.queue(&dir.prefix) {
            Ok(entries) => {
                Some(entries.into_iter().map(|e| (e.id.clone(), e)).collect::<HashMap<String, QueueEntry>>())
            }
            Err(e) => {
                tracing::warn!(job = segment.id, error = %e,
                    "the queue did not answer; the tasks are judged at the next look");
                None
            }
        };
        let changed = t.read_documents(dir, segment.job).map_err(RunError::from)?;
        for (i, why) in t.judge(queue.as_ref(), self.options.missing_grace, &*self.system) {
            let task = &t.tasks[i];
            let (r, k, attempts) = (task.round, task.k, t.attempts(task));
            let key = t.key(task, &*self.system).unwrap_or_default();
            let log = dir.log(r, &k.to_string());
            if attempts > self.options.retries {
                self.cancel_all(dir, &t.record);
                return Err(SegmentError::Failed(format!(
                    "task {i} (iterations [{}, {})) failed: {} job {key} {why}, after {attempts} attempts; its log: {}",
                    task.range.start,
                    task.range.end,
                    self.system.name(),
                    log.display()
                )));
            }
            tracing::warn!(job = segment.id, task = i, batch_job = %key, %why, log = %log.display(),
                "resubmitting a task");
            // The intent first (a restart adopts or repeats it); `submit_pending` submits it, with
            // the same retry of transient submission errors as a round's.
            t.record.rounds[r].resubmits.entry(k).or_default().push(None);
            if let Err(e) = dir.save_record(&t.record) {
                // Not recorded, not submitted: judged again at the next look.
                if let Some(ids) = t.record.rounds[r].resubmits.get_mut(&k) {
                    ids.pop();
                    if ids.is_empty() {
                        t.record.rounds[r].resubmits.remove(&k);
                    }
                }
                return wait_or_fail(segment.id, e, "the job's record").map(|()| changed);
            }
            t.tasks[i].missing_since = None;
        }
        self.submit_pending(segment.id, dir, t, queue.as_ref())?;
        Ok(changed)
    }

    /// Submits what the record says is to be submitted: a round or a resubmission whose intent
    /// was recorded without the system's answer (a restart, or a timeout) — unless the queue shows
    /// it under its name, then it is adopted.
    fn submit_pending(
        &self,
        job: i64,
        dir: &JobDir,
        t: &mut Tracking,
        queue: Option<&HashMap<String, QueueEntry>>,
    ) -> Result<(), SegmentError> {
        let Some(queue) = queue else { return Ok(()) };
        let named = |name: &str| queue.values().find(|e| e.name == name).map(|e| e.submission.clone());
        for r in 0..t.record.rounds.len() {
            if t.record.rounds[r].array.is_none() {
                let array = match named(&dir.round_name(r)) {
                    Some(array) => array,
                    None => match self.submit_round(dir, r, &t.record.rounds[r]) {
                        Ok(array) => array,
                        Err(e) if e.is_transient() => {
                            tracing::warn!(job, round = r, error = %e, "submission: retrying at the next look");
                            continue;
                        }
                        Err(e) => return Err(self.refused(e)),
                    },
                };
                tracing::info!(job, round = r, array = %array, tasks = t.record.rounds[r].tasks, "array submitted");
                t.record.rounds[r].array = Some(array);
                // Unsaved, the id is still known here; a restart would adopt the array by its name.
                if let Err(e) = dir.save_record(&t.record) {
                    return wait_or_fail(job, e, "the job's record");
                }
            }
            let waiting: Vec<u64> = t.record.rounds[r]
                .resubmits
                .iter()
                .filter(|(_, ids)| ids.last().is_some_and(Option::is_none))
                .map(|(k, _)| *k)
                .collect();
            for k in waiting {
                let id = match named(&dir.task_name(r, k)) {
                    Some(id) => id,
                    None => match self.resubmit_task(dir, r, &t.record.rounds[r], k) {
                        Ok(id) => id,
                        Err(e) if e.is_transient() => continue,
                        Err(e) => return Err(self.refused(e)),
                    },
                };
                if let Some(last) = t.record.rounds[r].resubmits.get_mut(&k).and_then(|v| v.last_mut()) {
                    *last = Some(id);
                }
                if let Err(e) = dir.save_record(&t.record) {
                    return wait_or_fail(job, e, "the job's record");
                }
            }
        }
        Ok(())
    }

    fn refused(&self, e: BatchError) -> SegmentError {
        SegmentError::Failed(format!("{} refused the job's tasks: {e}", self.system.name()))
    }

    /// Sleeps for the poll interval in short steps; true if the job was asked to stop meanwhile.
    fn pause(&self, segment: &Segment<'_>) -> bool {
        let until = Instant::now() + self.options.poll_interval;
        while Instant::now() < until {
            if segment.stop.load(Ordering::SeqCst) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        segment.stop.load(Ordering::SeqCst)
    }
}

/// A file of the cluster directory that could not be written: on a full disk or quota the job
/// waits (the next look tries again), as a local job waits for its database; anything else fails
/// it, naming the file.
fn wait_or_fail(job: i64, e: FileError, what: &str) -> Result<(), SegmentError> {
    if e.is_full() {
        tracing::warn!(job, error = %e, "the cluster directory is full; {what} is written again at the next look");
        Ok(())
    } else {
        Err(SegmentError::Failed(format!("cannot write {what}: {e}")))
    }
}

/// A path as an argument (the options checked it is UTF-8).
fn path(p: &std::path::Path) -> String {
    p.to_string_lossy().into_owned()
}

impl Executor for ClusterExecutor {
    fn admit(&self, spec: &JobSpec) -> Result<(), SpecError> {
        match spec.execution {
            Some(e) if e.tasks > self.options.max_tasks => Err(SpecError::new(
                "execution.tasks",
                format!("must be at most {} on this server (--max-tasks), got {}", self.options.max_tasks, e.tasks),
            )),
            _ => Ok(()),
        }
    }

    fn run_segment(
        &self,
        segment: &Segment<'_>,
        _range: Range<u64>,
        moments: &mut Moments,
        on_batch: &mut OnBatch<'_>,
    ) -> Result<u64, SegmentError> {
        let dir = self.dir.job(segment.id);
        let taken = self.tracking.lock().expect("tracking").remove(&segment.id);
        let mut t = match taken {
            Some(t) => t,
            None => Tracking::new(segment.job.spec(), dir.load_record().map_err(SegmentError::Failed)?),
        };
        let outcome = self.follow(segment, &dir, &mut t, moments, on_batch);
        match &outcome {
            // Between two segments (a checkpoint) the tracking is kept.
            Ok(next) if *next < segment.total => {
                self.tracking.lock().expect("tracking").insert(segment.id, t);
            }
            _ => self.count(segment.id, None),
        }
        outcome
    }

    fn cancel(&self, id: i64) {
        let dir = self.dir.job(id);
        self.cancel_all(&dir, &dir.load_record().unwrap_or_default());
        self.tracking.lock().expect("tracking").remove(&id);
        self.count(id, None);
    }

    fn forget(&self, id: i64) {
        self.cancel(id);
        let dir = self.dir.job(id);
        if let Err(e) = dir.remove() {
            tracing::warn!(job = id, dir = %dir.path().display(), error = %e, "could not remove the job's cluster files");
        }
    }
}

impl ClusterExecutor {
    /// Looks at the job until it is complete, a checkpoint is due or it is asked to stop.
    fn follow(
        &self,
        segment: &Segment<'_>,
        dir: &JobDir,
        t: &mut Tracking,
        moments: &mut Moments,
        on_batch: &mut OnBatch<'_>,
    ) -> Result<u64, SegmentError> {
        let mut first_look = true;
        loop {
            if segment.stop.load(Ordering::SeqCst) {
                if (segment.cancelled)() {
                    self.cancel_all(dir, &t.record);
                }
                return Err(RunError::Cancelled.into());
            }
            let changed = self.look(segment, dir, t)?;
            (segment.report)(t.view(dir, &*self.system));
            self.count(segment.id, Some(t));
            if changed || first_look {
                first_look = false;
                let merged = t.merged(segment.job).map_err(RunError::from)?;
                // Never back: a checkpoint may hold more than the documents (a directory wiped).
                if merged.iterations() >= moments.iterations() {
                    *moments = merged;
                }
                let next = segment.first + moments.iterations();
                if next >= segment.total {
                    return Ok(next);
                }
                if changed && on_batch(&mut &*moments, next).is_break() {
                    return Ok(next);
                }
            }
            self.pause(segment);
        }
    }
}
