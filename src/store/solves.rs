//! Queries on the `solves` table: named solver options kept with a job.

use sqlx::Row;

use super::database::Database;
use super::error::StoreError;

/// A named solve as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveRow {
    /// The solve's name, unique per job.
    pub name: String,
    /// The patch on the job's solver options, JSON.
    pub patch: String,
    /// When it was stored or last replaced (Unix milliseconds).
    pub created_at: i64,
}

fn solve_from_row(r: &sqlx::sqlite::SqliteRow) -> Result<SolveRow, sqlx::Error> {
    Ok(SolveRow { name: r.try_get("name")?, patch: r.try_get("patch")?, created_at: r.try_get("created_at")? })
}

/// The `solves` table: its queries (`Store::solves`).
pub struct SolvesTable<'a> {
    pub(super) db: &'a Database,
}

impl SolvesTable<'_> {
    /// Stores (or replaces) a named solve of a job, if the job has fewer than `max` other ones;
    /// false when it has `max` already. One transaction: the count and the write agree.
    pub async fn put(&self, job: i64, name: &str, patch: &str, now: i64, max: i64) -> Result<bool, StoreError> {
        self.db
            .transaction(async |tx| {
                let others: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM solves WHERE job_id = ? AND name <> ?")
                    .bind(job)
                    .bind(name)
                    .fetch_one(&mut *tx)
                    .await?;
                if others >= max {
                    return Ok(false);
                }
                sqlx::query(
                    "INSERT INTO solves (job_id, name, patch, created_at) VALUES (?, ?, ?, ?) \
                     ON CONFLICT (job_id, name) DO UPDATE SET patch = excluded.patch, created_at = excluded.created_at",
                )
                .bind(job)
                .bind(name)
                .bind(patch)
                .bind(now)
                .execute(&mut *tx)
                .await?;
                Ok(true)
            })
            .await
    }

    /// A job's named solves, oldest first.
    pub async fn list(&self, job: i64) -> Result<Vec<SolveRow>, StoreError> {
        let rows = sqlx::query("SELECT name, patch, created_at FROM solves WHERE job_id = ? ORDER BY created_at, name")
            .bind(job)
            .fetch_all(self.db.pool())
            .await?;
        rows.iter().map(solve_from_row).collect::<Result<_, sqlx::Error>>().map_err(Into::into)
    }

    /// One named solve.
    pub async fn get(&self, job: i64, name: &str) -> Result<Option<SolveRow>, StoreError> {
        let row = sqlx::query("SELECT name, patch, created_at FROM solves WHERE job_id = ? AND name = ?")
            .bind(job)
            .bind(name)
            .fetch_optional(self.db.pool())
            .await?;
        Ok(row.as_ref().map(solve_from_row).transpose()?)
    }

    /// Deletes a named solve, returning whether it existed.
    pub async fn delete(&self, job: i64, name: &str) -> Result<bool, StoreError> {
        let done = sqlx::query("DELETE FROM solves WHERE job_id = ? AND name = ?")
            .bind(job)
            .bind(name)
            .execute(self.db.pool())
            .await;
        Ok(done?.rows_affected() == 1)
    }
}
