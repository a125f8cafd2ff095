//! Queries on the `sweeps` table and the jobs that are its runs.
//!
//! A sweep and all its jobs are inserted in one transaction (a sweep is acknowledged whole or not
//! at all), and deleted in one.

use sqlx::Row;

use super::database::Database;
use super::error::StoreError;
use super::jobs::{JobRow, NewJob, insert_queued_row, job_columns, job_from_row};

/// A sweep as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRow {
    /// The sweep's id (never reused).
    pub id: i64,
    /// The sweep document, JSON.
    pub spec: String,
    /// When it was submitted (Unix milliseconds).
    pub created_at: i64,
}

/// The `sweeps` table and its runs: its queries (`Store::sweeps`).
pub struct SweepsTable<'a> {
    pub(super) db: &'a Database,
}

impl SweepsTable<'_> {
    /// Inserts a sweep and its runs (queued jobs, in run order); committed before it returns.
    pub async fn insert(&self, spec: &str, runs: &[NewJob], now: i64) -> Result<(i64, Vec<JobRow>), StoreError> {
        self.db
            .transaction(async |tx| {
                let id: i64 = sqlx::query_scalar("INSERT INTO sweeps (spec, created_at) VALUES (?, ?) RETURNING id")
                    .bind(spec)
                    .bind(now)
                    .fetch_one(&mut *tx)
                    .await?;
                let mut rows = Vec::with_capacity(runs.len());
                for (run, job) in runs.iter().enumerate() {
                    let job = NewJob { now, ..job.clone() };
                    rows.push(insert_queued_row(tx, &job, Some((id, run))).await?);
                }
                Ok((id, rows))
            })
            .await
    }

    /// One sweep.
    pub async fn get(&self, id: i64) -> Result<Option<SweepRow>, StoreError> {
        let row = sqlx::query("SELECT id, spec, created_at FROM sweeps WHERE id = ?")
            .bind(id)
            .fetch_optional(self.db.pool())
            .await?;
        row.map(|r| {
            Ok(SweepRow { id: r.try_get("id")?, spec: r.try_get("spec")?, created_at: r.try_get("created_at")? })
        })
        .transpose()
        .map_err(|e: sqlx::Error| e.into())
    }

    /// Sweeps newest first, with ids below `before`.
    pub async fn list(&self, before: Option<i64>, limit: u32) -> Result<Vec<SweepRow>, StoreError> {
        let rows = sqlx::query("SELECT id, spec, created_at FROM sweeps WHERE id < ? ORDER BY id DESC LIMIT ?")
            .bind(before.unwrap_or(i64::MAX))
            .bind(i64::from(limit))
            .fetch_all(self.db.pool())
            .await?;
        rows.iter()
            .map(|r| {
                Ok(SweepRow { id: r.try_get("id")?, spec: r.try_get("spec")?, created_at: r.try_get("created_at")? })
            })
            .collect::<Result<_, sqlx::Error>>()
            .map_err(Into::into)
    }

    /// The jobs of a sweep with their run index, in run order (a job deleted alone is missing).
    pub async fn runs(&self, id: i64) -> Result<Vec<(usize, JobRow)>, StoreError> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            ", sweep_run FROM jobs WHERE sweep_id = ? ORDER BY sweep_run"
        ))
        .bind(id)
        .fetch_all(self.db.pool())
        .await?;
        rows.iter()
            .map(|r| Ok((r.try_get::<i64, _>("sweep_run")? as usize, job_from_row(r)?)))
            .collect::<Result<_, sqlx::Error>>()
            .map_err(Into::into)
    }

    /// Deletes a sweep and its jobs (with their checkpoints), returning whether it existed.
    pub async fn delete(&self, id: i64) -> Result<bool, StoreError> {
        self.db
            .transaction(async |tx| {
                sqlx::query("DELETE FROM jobs WHERE sweep_id = ?").bind(id).execute(&mut *tx).await?;
                let done = sqlx::query("DELETE FROM sweeps WHERE id = ?").bind(id).execute(&mut *tx).await?;
                Ok(done.rows_affected() == 1)
            })
            .await
    }
}
