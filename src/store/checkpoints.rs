//! Queries on the `checkpoints` table: every write that stores a job's statistics (a checkpoint,
//! merged statistics, a study born with them), each in one transaction with the job row's
//! bookkeeping (`iterations_done`, best strategy, warnings) and the history row (`history`), so
//! the three never disagree; and the reads of the latest checkpoint.
//!
//! Every write runs in a transaction whose commit is awaited, and goes through [`Store::track`]
//! (see `jobs`).

use sqlx::Row;

use super::database::Database;
use super::error::StoreError;
use super::history::thin_history;
use super::jobs::{JobRow, NewJob, job_columns, job_from_row};
use super::state::JobState;

/// A job's latest checkpoint: its statistics and what was computed from them. As read back by
/// [`CheckpointsTable::load`], only the first four fields are filled (`best`, `warnings` and
/// `history` live in the job row and the history table).
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// The iterations the moments cover; written to the job's `iterations_done` with them.
    pub iterations_done: u64,
    /// The moments, JSON.
    pub moments: Vec<u8>,
    /// SHA-256 (hex) of `moments` when written.
    pub checksum: String,
    /// The result document (JSON) computed from them.
    pub result: String,
    /// SHA-256 (hex) of `result` when written (none for a row written before it was kept, until
    /// the start that fills it in).
    pub result_checksum: Option<String>,
    /// The best strategy (JSON) at this checkpoint, copied to the job row.
    pub best: Option<String>,
    /// The result's warnings (JSON list), copied to the job row.
    pub warnings: Option<String>,
    /// Each strategy's luminance and RMS (JSON), appended to the job's history.
    pub history: String,
    /// Points of the history since the previous checkpoint (iterations, JSON), appended before
    /// this one's: the per-path rows at every --checkpoint-iterations between two checkpoints.
    pub between: Vec<(u64, String)>,
}

/// A job's latest result as stored, with the two checksums that guard it.
#[derive(Debug, Clone)]
pub struct StoredResult {
    /// The iterations of the checkpoint.
    pub iterations_done: u64,
    /// The result document (JSON).
    pub result: String,
    /// SHA-256 (hex) of the checkpoint's moments.
    pub checksum: String,
    /// SHA-256 (hex) of `result` (none for a row written before it was kept).
    pub result_checksum: Option<String>,
}

/// Replaces job `id`'s checkpoint row and appends (or replaces) its history row at the same
/// iterations, then thins the history, in `tx`; the caller updates the job row in the same
/// transaction.
async fn upsert_checkpoint(
    tx: &mut sqlx::SqliteConnection,
    id: i64,
    checkpoint: &Checkpoint,
    now: i64,
) -> Result<(), StoreError> {
    sqlx::query(
        "INSERT INTO checkpoints (job_id, iterations_done, moments, checksum, result, result_checksum, written_at) \
         VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT (job_id) DO UPDATE SET iterations_done = excluded.iterations_done, \
         moments = excluded.moments, checksum = excluded.checksum, result = excluded.result, \
         result_checksum = excluded.result_checksum, written_at = excluded.written_at",
    )
    .bind(id)
    .bind(checkpoint.iterations_done as i64)
    .bind(&checkpoint.moments)
    .bind(&checkpoint.checksum)
    .bind(&checkpoint.result)
    .bind(&checkpoint.result_checksum)
    .bind(now)
    .execute(&mut *tx)
    .await?;
    let between = checkpoint.between.iter().filter(|(i, _)| *i < checkpoint.iterations_done);
    let own = std::iter::once((checkpoint.iterations_done, checkpoint.history.as_str()));
    for (iterations, strategies) in between.map(|(i, s)| (*i, s.as_str())).chain(own) {
        sqlx::query(
            "INSERT INTO checkpoint_history (job_id, iterations, strategies, written_at) VALUES (?, ?, ?, ?) \
             ON CONFLICT (job_id, iterations) DO UPDATE SET strategies = excluded.strategies, written_at = excluded.written_at",
        )
        .bind(id)
        .bind(iterations as i64)
        .bind(strategies)
        .bind(now)
        .execute(&mut *tx)
        .await?;
    }
    thin_history(tx, id).await
}

/// The `checkpoints` table (with the merged and study rows it writes): its queries (`Store::checkpoints`).
pub struct CheckpointsTable<'a> {
    pub(super) db: &'a Database,
}

impl CheckpointsTable<'_> {
    /// Replaces a job's checkpoint and advances its `iterations_done`, in one transaction.
    pub async fn write(&self, id: i64, checkpoint: &Checkpoint, now: i64) -> Result<(), StoreError> {
        self.write_checkpoint_tx(id, checkpoint, now).await
    }

    async fn write_checkpoint_tx(&self, id: i64, checkpoint: &Checkpoint, now: i64) -> Result<(), StoreError> {
        self.db
            .transaction(async |tx| {
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
    pub async fn write_merged(
        &self,
        id: i64,
        checkpoint: &Checkpoint,
        spec: &str,
        provenance: &str,
        now: i64,
    ) -> Result<(), StoreError> {
        self.db
            .transaction(async |tx| {
                upsert_checkpoint(tx, id, checkpoint, now).await?;
                sqlx::query(
                    "UPDATE jobs SET iterations_done = ?1, iterations_total = ?1, best = ?2, merged = 1, spec = ?3, \
                 updated_at = ?4, warnings = ?6, provenance = ?7 WHERE id = ?5",
                )
                .bind(checkpoint.iterations_done as i64)
                .bind(&checkpoint.best)
                .bind(spec)
                .bind(now)
                .bind(id)
                .bind(&checkpoint.warnings)
                .bind(provenance)
                .execute(&mut *tx)
                .await?;
                Ok(())
            })
            .await
    }

    /// Inserts a finished job holding merged statistics (a study), with its checkpoint, in one
    /// transaction.
    pub async fn insert_study(
        &self,
        job: &NewJob,
        checkpoint: &Checkpoint,
        provenance: &str,
    ) -> Result<JobRow, StoreError> {
        self.db.transaction(async |tx| {
            let row = sqlx::query(concat!(
            "INSERT INTO jobs (state, spec, fingerprint, iterations_total, iterations_done, reference_luminance, best, \
             warnings, merged, created_at, updated_at, provenance) VALUES (?, ?, ?, ?, ?, ?, ?, ?, 1, ?, ?, ?) RETURNING ",
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
        .bind(provenance)
        .fetch_one(&mut *tx)
        .await?;
            let id: i64 = row.try_get("id")?;
            upsert_checkpoint(tx, id, checkpoint, job.now).await?;
            Ok(job_from_row(&row)?)
        })
        .await
    }

    /// A job's latest checkpoint, if any.
    pub async fn load(&self, id: i64) -> Result<Option<Checkpoint>, StoreError> {
        let row = sqlx::query(
            "SELECT iterations_done, moments, checksum, result, result_checksum FROM checkpoints WHERE job_id = ?",
        )
        .bind(id)
        .fetch_optional(self.db.pool())
        .await?;
        row.map(|row| {
            Ok::<_, sqlx::Error>(Checkpoint {
                iterations_done: row.try_get::<i64, _>("iterations_done")? as u64,
                moments: row.try_get("moments")?,
                checksum: row.try_get("checksum")?,
                result: row.try_get("result")?,
                result_checksum: row.try_get("result_checksum")?,
                best: None,
                warnings: None,
                history: String::new(),
                between: Vec::new(),
            })
        })
        .transpose()
        .map_err(StoreError::from)
    }

    /// A job's latest result document without the moments, if it has a checkpoint.
    pub async fn load_result(&self, id: i64) -> Result<Option<StoredResult>, StoreError> {
        let row =
            sqlx::query("SELECT iterations_done, result, checksum, result_checksum FROM checkpoints WHERE job_id = ?")
                .bind(id)
                .fetch_optional(self.db.pool())
                .await?;
        row.map(|row| {
            Ok(StoredResult {
                iterations_done: row.try_get::<i64, _>("iterations_done")? as u64,
                result: row.try_get("result")?,
                checksum: row.try_get("checksum")?,
                result_checksum: row.try_get("result_checksum")?,
            })
        })
        .transpose()
        .map_err(|e: sqlx::Error| e.into())
    }

    /// The checkpoints whose result has no checksum yet (written before it was kept): (job id,
    /// result JSON), at most `limit` of them.
    pub async fn results_without_checksum(&self, limit: u32) -> Result<Vec<(i64, String)>, StoreError> {
        let rows = sqlx::query("SELECT job_id, result FROM checkpoints WHERE result_checksum IS NULL LIMIT ?")
            .bind(limit)
            .fetch_all(self.db.pool())
            .await?;
        Ok(rows.iter().map(|r| Ok((r.try_get("job_id")?, r.try_get("result")?))).collect::<Result<_, sqlx::Error>>()?)
    }

    /// Records the checksum of job `id`'s stored result, if it still has none.
    pub async fn fill_result_checksum(&self, id: i64, checksum: &str) -> Result<(), StoreError> {
        sqlx::query("UPDATE checkpoints SET result_checksum = ? WHERE job_id = ? AND result_checksum IS NULL")
            .bind(checksum)
            .bind(id)
            .execute(self.db.pool())
            .await?;
        Ok(())
    }
}
