//! Queries on the `jobs` and `checkpoints` tables (a checkpoint's history row is appended with it:
//! `history`).
//!
//! Every write runs in a transaction whose commit is awaited, and goes through [`Store::track`]:
//! an insert with `RETURNING` in autocommit mode once handed back a row whose commit had failed on
//! a full disk (and so an id that was never stored).

use sqlx::Row;
use sqlx::sqlite::SqliteRow;

use super::history::thin_history;
use super::{JobState, Store, StoreError};

/// Unix milliseconds now.
pub(crate) fn now_ms() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRow {
    pub id: i64,
    pub state: JobState,
    /// The resolved spec, JSON.
    pub spec: String,
    pub fingerprint: String,
    pub iterations_total: u64,
    pub iterations_done: u64,
    /// The quadrature reference; None when it did not converge.
    pub reference_luminance: Option<f64>,
    /// JSON of the best strategy at the latest checkpoint.
    pub best: Option<String>,
    /// JSON list of the latest checkpoint's warnings.
    pub warnings: Option<String>,
    pub error: Option<String>,
    /// Holds statistics merged from other runs.
    pub merged: bool,
    /// A cancel was acknowledged; the job must not run again.
    pub cancel_requested: bool,
    /// The sweep the job is a run of, if any.
    pub sweep_id: Option<i64>,
    pub created_at: i64,
    pub updated_at: i64,
}

/// A job to insert.
#[derive(Debug, Clone)]
pub struct NewJob {
    pub spec: String,
    pub fingerprint: String,
    pub iterations_total: u64,
    pub reference_luminance: Option<f64>,
    pub idempotency_key: Option<String>,
    pub request_hash: Option<String>,
    pub now: i64,
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

/// A job's latest checkpoint.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    pub iterations_done: u64,
    /// The moments, JSON.
    pub moments: Vec<u8>,
    /// SHA-256 (hex) of `moments` when written.
    pub checksum: String,
    /// The result document (JSON) computed from them.
    pub result: String,
    /// The best strategy (JSON) at this checkpoint, copied to the job row.
    pub best: Option<String>,
    /// The result's warnings (JSON list), copied to the job row.
    pub warnings: Option<String>,
    /// Each strategy's luminance and RMS (JSON), appended to the job's history.
    pub history: String,
}

/// The columns of a [`JobRow`], as a literal for `concat!` (queries stay static strings).
macro_rules! job_columns {
    () => {
        "id, state, spec, fingerprint, iterations_total, iterations_done, reference_luminance, best, warnings, \
         error, merged, cancel_requested, sweep_id, created_at, updated_at"
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
    })
}

async fn upsert_checkpoint(
    tx: &mut sqlx::SqliteConnection,
    id: i64,
    checkpoint: &Checkpoint,
    now: i64,
) -> Result<(), StoreError> {
    sqlx::query(
        "INSERT INTO checkpoints (job_id, iterations_done, moments, checksum, result, written_at) \
         VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (job_id) DO UPDATE SET iterations_done = excluded.iterations_done, \
         moments = excluded.moments, checksum = excluded.checksum, result = excluded.result, \
         written_at = excluded.written_at",
    )
    .bind(id)
    .bind(checkpoint.iterations_done as i64)
    .bind(&checkpoint.moments)
    .bind(&checkpoint.checksum)
    .bind(&checkpoint.result)
    .bind(now)
    .execute(&mut *tx)
    .await?;
    sqlx::query(
        "INSERT INTO checkpoint_history (job_id, iterations, strategies, written_at) VALUES (?, ?, ?, ?) \
         ON CONFLICT (job_id, iterations) DO UPDATE SET strategies = excluded.strategies, written_at = excluded.written_at",
    )
    .bind(id)
    .bind(checkpoint.iterations_done as i64)
    .bind(&checkpoint.history)
    .bind(now)
    .execute(&mut *tx)
    .await?;
    thin_history(tx, id).await
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

impl Store {
    /// Inserts a queued job, honouring an idempotency key. The row is committed before its id is
    /// returned.
    pub async fn insert_job(&self, job: &NewJob) -> Result<Inserted, StoreError> {
        if let Some(key) = &job.idempotency_key
            && let Some(found) = self.find_by_key(key, job.request_hash.as_deref()).await?
        {
            return Ok(found);
        }
        let result = self.track(self.insert_queued(job).await);
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
        self.transaction(async |tx| insert_queued_row(tx, job, None).await).await
    }

    async fn find_by_key(&self, key: &str, hash: Option<&str>) -> Result<Option<Inserted>, StoreError> {
        let row = sqlx::query(concat!("SELECT ", job_columns!(), ", request_hash FROM jobs WHERE idempotency_key = ?"))
            .bind(key)
            .fetch_optional(self.pool())
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
    pub async fn get_job(&self, id: i64) -> Result<Option<JobRow>, StoreError> {
        let row = sqlx::query(concat!("SELECT ", job_columns!(), " FROM jobs WHERE id = ?"))
            .bind(id)
            .fetch_optional(self.pool())
            .await?;
        Ok(row.as_ref().map(job_from_row).transpose()?)
    }

    /// Jobs newest first, optionally in one state, with ids below `before` (keyset pagination).
    pub async fn list_jobs(
        &self,
        state: Option<JobState>,
        before: Option<i64>,
        limit: u32,
    ) -> Result<Vec<JobRow>, StoreError> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE (?1 IS NULL OR state = ?1) AND (?2 IS NULL OR id < ?2) ORDER BY id DESC LIMIT ?3"
        ))
        .bind(state.map(JobState::as_str))
        .bind(before)
        .bind(i64::from(limit))
        .fetch_all(self.pool())
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    /// Jobs to pick up at start: those left running (in id order), then the queued ones.
    pub async fn unfinished_jobs(&self) -> Result<Vec<JobRow>, StoreError> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE state IN (?1, ?2) ORDER BY CASE state WHEN ?1 THEN 0 ELSE 1 END, id"
        ))
        .bind(JobState::Running.as_str())
        .bind(JobState::Queued.as_str())
        .fetch_all(self.pool())
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
            .execute(self.pool())
            .await;
        Ok(self.track(done.map_err(StoreError::from))?.rows_affected() == 1)
    }

    /// Records that a cancel of the job was acknowledged (before the running job stops), so that
    /// no restart runs it again.
    pub async fn request_cancel(&self, id: i64, now: i64) -> Result<bool, StoreError> {
        let done = sqlx::query("UPDATE jobs SET cancel_requested = 1, updated_at = ? WHERE id = ?")
            .bind(now)
            .bind(id)
            .execute(self.pool())
            .await;
        Ok(self.track(done.map_err(StoreError::from))?.rows_affected() == 1)
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
        .execute(self.pool())
        .await;
        Ok(self.track(done.map_err(StoreError::from))?.rows_affected() == 1)
    }

    /// Deletes a job and its checkpoint, returning whether it existed.
    pub async fn delete_job(&self, id: i64) -> Result<bool, StoreError> {
        let done = sqlx::query("DELETE FROM jobs WHERE id = ?").bind(id).execute(self.pool()).await;
        Ok(self.track(done.map_err(StoreError::from))?.rows_affected() == 1)
    }

    /// Replaces a job's checkpoint and advances its `iterations_done`, in one transaction.
    pub async fn write_checkpoint(&self, id: i64, checkpoint: &Checkpoint, now: i64) -> Result<(), StoreError> {
        let result = self.write_checkpoint_tx(id, checkpoint, now).await;
        self.track(result)
    }

    async fn write_checkpoint_tx(&self, id: i64, checkpoint: &Checkpoint, now: i64) -> Result<(), StoreError> {
        self.transaction(async |tx| {
            upsert_checkpoint(tx, id, checkpoint, now).await?;
            sqlx::query("UPDATE jobs SET iterations_done = ?, best = ?, warnings = ?, updated_at = ? WHERE id = ?")
                .bind(checkpoint.iterations_done as i64)
                .bind(&checkpoint.best)
                .bind(&checkpoint.warnings)
                .bind(now)
                .bind(id)
                .execute(&mut *tx)
                .await?;
            Ok(())
        })
        .await
    }

    /// Replaces the checkpoint of a finished job with merged statistics: the job becomes `merged`
    /// with `iterations_total = iterations_done` = the iterations now covered, and its spec
    /// (`spec`: iterations set to that total) says so. One transaction.
    pub async fn write_merged(&self, id: i64, checkpoint: &Checkpoint, spec: &str, now: i64) -> Result<(), StoreError> {
        let result = async {
            self.transaction(async |tx| {
                upsert_checkpoint(tx, id, checkpoint, now).await?;
                sqlx::query(
                    "UPDATE jobs SET iterations_done = ?1, iterations_total = ?1, best = ?2, merged = 1, spec = ?3, \
                     updated_at = ?4, warnings = ?6 WHERE id = ?5",
                )
                .bind(checkpoint.iterations_done as i64)
                .bind(&checkpoint.best)
                .bind(spec)
                .bind(now)
                .bind(id)
                .bind(&checkpoint.warnings)
                .execute(&mut *tx)
                .await?;
                Ok(())
            })
            .await
        }
        .await;
        self.track(result)
    }

    /// Inserts a finished job holding merged statistics (a study), with its checkpoint, in one
    /// transaction.
    pub async fn insert_study(&self, job: &NewJob, checkpoint: &Checkpoint) -> Result<JobRow, StoreError> {
        let result = self.insert_study_tx(job, checkpoint).await;
        self.track(result)
    }

    async fn insert_study_tx(&self, job: &NewJob, checkpoint: &Checkpoint) -> Result<JobRow, StoreError> {
        self.transaction(async |tx| {
            let row = sqlx::query(concat!(
            "INSERT INTO jobs (state, spec, fingerprint, iterations_total, iterations_done, reference_luminance, best, \
             warnings, merged, created_at, updated_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, 1, ?, ?) RETURNING ",
            job_columns!()
        ))
        .bind(JobState::Succeeded.as_str())
        .bind(&job.spec)
        .bind(&job.fingerprint)
        .bind(checkpoint.iterations_done as i64)
        .bind(checkpoint.iterations_done as i64)
        .bind(job.reference_luminance)
        .bind(&checkpoint.best)
        .bind(&checkpoint.warnings)
        .bind(job.now)
        .bind(job.now)
        .fetch_one(&mut *tx)
        .await?;
            let id: i64 = row.try_get("id")?;
            upsert_checkpoint(tx, id, checkpoint, job.now).await?;
            Ok(job_from_row(&row)?)
        })
        .await
    }

    /// A job's latest checkpoint, if any.
    pub async fn load_checkpoint(&self, id: i64) -> Result<Option<Checkpoint>, StoreError> {
        let row = sqlx::query("SELECT iterations_done, moments, checksum, result FROM checkpoints WHERE job_id = ?")
            .bind(id)
            .fetch_optional(self.pool())
            .await?;
        row.map(|row| {
            Ok::<_, sqlx::Error>(Checkpoint {
                iterations_done: row.try_get::<i64, _>("iterations_done")? as u64,
                moments: row.try_get("moments")?,
                checksum: row.try_get("checksum")?,
                result: row.try_get("result")?,
                best: None,
                warnings: None,
                history: String::new(),
            })
        })
        .transpose()
        .map_err(StoreError::from)
    }

    /// Number of jobs in each state (every state listed, zero included).
    pub async fn count_by_state(&self) -> Result<Vec<(JobState, i64)>, StoreError> {
        let rows = sqlx::query("SELECT state, COUNT(*) AS n FROM jobs GROUP BY state").fetch_all(self.pool()).await?;
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

    /// A job's latest result document, without the moments.
    /// (iterations done, result JSON, the moments' checksum) of a job's latest checkpoint.
    pub async fn load_result(&self, id: i64) -> Result<Option<(u64, String, String)>, StoreError> {
        let row = sqlx::query("SELECT iterations_done, result, checksum FROM checkpoints WHERE job_id = ?")
            .bind(id)
            .fetch_optional(self.pool())
            .await?;
        row.map(|row| {
            Ok((row.try_get::<i64, _>("iterations_done")? as u64, row.try_get("result")?, row.try_get("checksum")?))
        })
        .transpose()
        .map_err(|e: sqlx::Error| e.into())
    }
}
