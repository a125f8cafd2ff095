//! Queries on the `jobs` table: a job's row (its spec, state and bookkeeping) from insert to
//! delete, and the listings. Writes that carry statistics (a checkpoint, merged statistics, a
//! study) update the row together with the checkpoint, in `checkpoints`.
//!
//! Every write runs in a transaction whose commit is awaited, and goes through [`Store::track`]:
//! an insert with `RETURNING` in autocommit mode once handed back a row whose commit had failed on
//! a full disk (and so an id that was never stored).

use sqlx::Row;
use sqlx::sqlite::SqliteRow;

use super::database::Database;
use super::error::StoreError;
use super::state::JobState;
use crate::sim::spec::Label;

/// A job as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRow {
    /// The job's id (SQLite rowid, never reused: the table is `AUTOINCREMENT`).
    pub id: i64,
    /// Where the job is in its life cycle.
    pub state: JobState,
    /// The resolved spec, JSON.
    pub spec: String,
    /// The simulation configuration's fingerprint (hex SHA-256, `SimConfig::fingerprint`): only
    /// moments with the same one may be merged into this job.
    pub fingerprint: String,
    /// Iterations the job runs in all (the length of its iteration range).
    pub iterations_total: u64,
    /// Iterations its latest checkpoint covers (0 before the first).
    pub iterations_done: u64,
    /// The quadrature reference; None when it did not converge.
    pub reference_luminance: Option<f64>,
    /// JSON of the best strategy at the latest checkpoint.
    pub best: Option<String>,
    /// JSON list of the latest checkpoint's warnings.
    pub warnings: Option<String>,
    /// Why the job failed (a `failed` job), if it did.
    pub error: Option<String>,
    /// Holds statistics merged from other runs.
    pub merged: bool,
    /// A cancel was acknowledged; the job must not run again.
    pub cancel_requested: bool,
    /// The sweep the job is a run of, if any.
    pub sweep_id: Option<i64>,
    /// When the job was submitted (Unix milliseconds).
    pub created_at: i64,
    /// When the row last changed (Unix milliseconds).
    pub updated_at: i64,
    /// Where a merged job's statistics come from (JSON, `jobs::provenance`); None for a job that
    /// merged nothing.
    pub provenance: Option<String>,
}

/// A job to insert (queued, or a study with its checkpoint).
#[derive(Debug, Clone)]
pub struct NewJob {
    /// The resolved spec, JSON ([`JobRow::spec`]).
    pub spec: String,
    /// The configuration's fingerprint ([`JobRow::fingerprint`]).
    pub fingerprint: String,
    /// Iterations the job is to run (a study takes its checkpoint's instead).
    pub iterations_total: u64,
    /// The quadrature reference; None when it did not converge.
    pub reference_luminance: Option<f64>,
    /// The client's `Idempotency-Key`, unique among jobs: a second insert with it answers the
    /// first job instead of inserting one.
    pub idempotency_key: Option<String>,
    /// SHA-256 (hex) of the submitted body, stored with the key to tell a replay (same body) from
    /// a reuse of the key with another body.
    pub request_hash: Option<String>,
    /// The insert's time (Unix milliseconds): `created_at` and `updated_at`.
    pub now: i64,
}

/// Which jobs a list holds: every condition given must hold.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JobFilter {
    /// Only jobs in this state.
    pub state: Option<JobState>,
    /// Only the runs of this sweep.
    pub sweep: Option<i64>,
    /// Only jobs with this label.
    pub label: Option<Label>,
}

/// The outcome of an insert with an idempotency key.
#[derive(Debug, Clone, PartialEq)]
pub enum Inserted {
    /// A new job.
    Created(JobRow),
    /// The key was used before with the same body: the original job.
    Replayed(JobRow),
    /// The key was used before with another body.
    KeyReused,
}

/// The columns of a [`JobRow`], as a literal for `concat!` (queries stay static strings).
macro_rules! job_columns {
    () => {
        "id, state, spec, fingerprint, iterations_total, iterations_done, reference_luminance, best, warnings, \
         error, merged, cancel_requested, sweep_id, created_at, updated_at, provenance"
    };
}
pub(super) use job_columns;

/// The `state` column as a [`JobState`]; any other text is a decoding error (a corrupted row).
fn decode_state(row: &SqliteRow) -> Result<JobState, sqlx::Error> {
    let text: String = row.try_get("state")?;
    JobState::parse(&text).ok_or_else(|| sqlx::Error::ColumnDecode {
        index: "state".into(),
        source: format!("unknown job state {text:?}").into(),
    })
}

pub(super) fn job_from_row(row: &SqliteRow) -> Result<JobRow, sqlx::Error> {
    Ok(JobRow {
        id: row.try_get("id")?,
        state: decode_state(row)?,
        spec: row.try_get("spec")?,
        fingerprint: row.try_get("fingerprint")?,
        iterations_total: row.try_get::<i64, _>("iterations_total")? as u64,
        iterations_done: row.try_get::<i64, _>("iterations_done")? as u64,
        reference_luminance: row.try_get("reference_luminance")?,
        best: row.try_get("best")?,
        warnings: row.try_get("warnings")?,
        error: row.try_get("error")?,
        merged: row.try_get::<i64, _>("merged")? != 0,
        cancel_requested: row.try_get::<i64, _>("cancel_requested")? != 0,
        sweep_id: row.try_get("sweep_id")?,
        created_at: row.try_get("created_at")?,
        updated_at: row.try_get("updated_at")?,
        provenance: row.try_get("provenance")?,
    })
}

/// Inserts a queued job (a run of sweep `sweep.0`, number `sweep.1`, if given) in `tx`.
pub(super) async fn insert_queued_row(
    tx: &mut sqlx::SqliteConnection,
    job: &NewJob,
    sweep: Option<(i64, usize)>,
) -> Result<JobRow, StoreError> {
    let row = sqlx::query(concat!(
        "INSERT INTO jobs (state, spec, fingerprint, iterations_total, reference_luminance, idempotency_key, \
         request_hash, sweep_id, sweep_run, created_at, updated_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) RETURNING ",
        job_columns!()
    ))
    .bind(JobState::Queued.as_str())
    .bind(&job.spec)
    .bind(&job.fingerprint)
    .bind(job.iterations_total as i64)
    .bind(job.reference_luminance)
    .bind(&job.idempotency_key)
    .bind(&job.request_hash)
    .bind(sweep.map(|s| s.0))
    .bind(sweep.map(|s| s.1 as i64))
    .bind(job.now)
    .bind(job.now)
    .fetch_one(&mut *tx)
    .await?;
    Ok(job_from_row(&row)?)
}

/// The `jobs` table: its queries (`Store::jobs`).
pub struct JobsTable<'a> {
    pub(super) db: &'a Database,
}

impl JobsTable<'_> {
    /// Inserts a queued job, honouring an idempotency key. The row is committed before its id is
    /// returned.
    pub async fn insert(&self, job: &NewJob) -> Result<Inserted, StoreError> {
        if let Some(key) = &job.idempotency_key
            && let Some(found) = self.find_by_key(key, job.request_hash.as_deref()).await?
        {
            return Ok(found);
        }
        let result = self.insert_queued(job).await;
        match result {
            Ok(row) => Ok(Inserted::Created(row)),
            // A concurrent request with the same key won the race: answer as a replay.
            Err(StoreError::Database(sqlx::Error::Database(e)))
                if e.is_unique_violation() && job.idempotency_key.is_some() =>
            {
                let key = job.idempotency_key.as_deref().unwrap_or_default();
                Ok(self.find_by_key(key, job.request_hash.as_deref()).await?.unwrap_or(Inserted::KeyReused))
            }
            Err(e) => Err(e),
        }
    }

    async fn insert_queued(&self, job: &NewJob) -> Result<JobRow, StoreError> {
        self.db.transaction(async |tx| insert_queued_row(tx, job, None).await).await
    }

    async fn find_by_key(&self, key: &str, hash: Option<&str>) -> Result<Option<Inserted>, StoreError> {
        let row = sqlx::query(concat!("SELECT ", job_columns!(), ", request_hash FROM jobs WHERE idempotency_key = ?"))
            .bind(key)
            .fetch_optional(self.db.pool())
            .await?;
        Ok(match row {
            None => None,
            Some(row) => {
                let stored: Option<String> = row.try_get("request_hash")?;
                Some(if stored.as_deref() == hash {
                    Inserted::Replayed(job_from_row(&row)?)
                } else {
                    Inserted::KeyReused
                })
            }
        })
    }

    /// One job.
    pub async fn get(&self, id: i64) -> Result<Option<JobRow>, StoreError> {
        let row = sqlx::query(concat!("SELECT ", job_columns!(), " FROM jobs WHERE id = ?"))
            .bind(id)
            .fetch_optional(self.db.pool())
            .await?;
        Ok(row.as_ref().map(job_from_row).transpose()?)
    }

    /// Jobs newest first, optionally in one state, with ids below `before` (keyset pagination).
    pub async fn list(&self, filter: &JobFilter, before: Option<i64>, limit: u32) -> Result<Vec<JobRow>, StoreError> {
        // The label's JSON path is bound, never spliced: `$.labels."KEY"` (a `Label`'s key is
        // letters, digits, `_`, `-`, `.`, so the quoted member name needs no escaping).
        let label_path = filter.label.as_ref().map(|label| format!("$.labels.\"{}\"", label.key()));
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE (?1 IS NULL OR state = ?1) AND (?2 IS NULL OR id < ?2) \
             AND (?4 IS NULL OR sweep_id = ?4) AND (?5 IS NULL OR json_extract(spec, ?5) = ?6) \
             ORDER BY id DESC LIMIT ?3"
        ))
        .bind(filter.state.map(JobState::as_str))
        .bind(before)
        .bind(i64::from(limit))
        .bind(filter.sweep)
        .bind(label_path)
        .bind(filter.label.as_ref().map(Label::value))
        .fetch_all(self.db.pool())
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    /// Jobs to pick up at start: those left running (in id order), then the queued ones.
    pub async fn unfinished(&self) -> Result<Vec<JobRow>, StoreError> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE state IN (?1, ?2) ORDER BY CASE state WHEN ?1 THEN 0 ELSE 1 END, id"
        ))
        .bind(JobState::Running.as_str())
        .bind(JobState::Queued.as_str())
        .fetch_all(self.db.pool())
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    /// Sets a job's state (and error), returning whether the job exists.
    pub async fn set_state(&self, id: i64, state: JobState, error: Option<&str>, now: i64) -> Result<bool, StoreError> {
        let done = sqlx::query("UPDATE jobs SET state = ?, error = ?, updated_at = ? WHERE id = ?")
            .bind(state.as_str())
            .bind(error)
            .bind(now)
            .bind(id)
            .execute(self.db.pool())
            .await;
        Ok(done?.rows_affected() == 1)
    }

    /// Sets a job's R → 0 reference luminance (computed by its run, not at its submission).
    pub async fn set_reference(&self, id: i64, reference: Option<f64>, now: i64) -> Result<bool, StoreError> {
        let done = sqlx::query("UPDATE jobs SET reference_luminance = ?, updated_at = ? WHERE id = ?")
            .bind(reference)
            .bind(now)
            .bind(id)
            .execute(self.db.pool())
            .await;
        Ok(done?.rows_affected() == 1)
    }

    /// Records that a cancel of the job was acknowledged (before the running job stops), so that
    /// no restart runs it again.
    pub async fn request_cancel(&self, id: i64, now: i64) -> Result<bool, StoreError> {
        let done = sqlx::query("UPDATE jobs SET cancel_requested = 1, updated_at = ? WHERE id = ?")
            .bind(now)
            .bind(id)
            .execute(self.db.pool())
            .await;
        Ok(done?.rows_affected() == 1)
    }

    /// Sets a job's total iterations with its updated spec (and state), clearing any error and
    /// cancel request, returning whether the job exists.
    pub async fn set_total(
        &self,
        id: i64,
        total: u64,
        spec: &str,
        state: JobState,
        now: i64,
    ) -> Result<bool, StoreError> {
        let done = sqlx::query(
            "UPDATE jobs SET iterations_total = ?, spec = ?, state = ?, error = NULL, cancel_requested = 0, \
             updated_at = ? WHERE id = ?",
        )
        .bind(total as i64)
        .bind(spec)
        .bind(state.as_str())
        .bind(now)
        .bind(id)
        .execute(self.db.pool())
        .await;
        Ok(done?.rows_affected() == 1)
    }

    /// Deletes a job and its checkpoint, returning whether it existed.
    pub async fn delete(&self, id: i64) -> Result<bool, StoreError> {
        let done = sqlx::query("DELETE FROM jobs WHERE id = ?").bind(id).execute(self.db.pool()).await;
        Ok(done?.rows_affected() == 1)
    }

    /// Number of jobs in each state (every state listed, zero included).
    pub async fn count_by_state(&self) -> Result<Vec<(JobState, i64)>, StoreError> {
        let rows =
            sqlx::query("SELECT state, COUNT(*) AS n FROM jobs GROUP BY state").fetch_all(self.db.pool()).await?;
        let mut counts: Vec<(JobState, i64)> = JobState::ALL.iter().map(|&s| (s, 0)).collect();
        for row in rows {
            let state = decode_state(&row)?;
            let n: i64 = row.try_get("n")?;
            if let Some(slot) = counts.iter_mut().find(|(s, _)| *s == state) {
                slot.1 = n;
            }
        }
        Ok(counts)
    }
}
