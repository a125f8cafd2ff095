//! Queries on the `checkpoint_history` table: each strategy's figures at every checkpoint, kept
//! bounded as they are written and read back thinned.

use sqlx::Row;

use super::database::Database;
use super::error::StoreError;

/// The indices of at most `max` of `n` items, evenly spaced, the first and the last included (all
/// of them when `n ≤ max`).
pub fn evenly_kept(n: usize, max: usize) -> Vec<usize> {
    if n <= max || max < 2 {
        return (0..n).collect();
    }
    (0..max).map(|k| k * (n - 1) / (max - 1)).collect()
}

/// Rows a job's history may reach before it is thinned (to ~1,000, evenly spaced in iterations).
pub const MAX_HISTORY_ROWS: i64 = 2000;

/// Keeps a job's history bounded: past [`MAX_HISTORY_ROWS`] rows, only the first row of each of
/// ~1,000 equal buckets of iterations (and the latest row) stay. A job checkpointed every
/// iteration for 10⁶ iterations once kept 10⁶ rows that every history request loaded.
pub(super) async fn thin_history(tx: &mut sqlx::SqliteConnection, id: i64) -> Result<(), StoreError> {
    let rows: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM checkpoint_history WHERE job_id = ?")
        .bind(id)
        .fetch_one(&mut *tx)
        .await?;
    if rows <= MAX_HISTORY_ROWS {
        return Ok(());
    }
    sqlx::query(
        "DELETE FROM checkpoint_history WHERE job_id = ?1 AND iterations IN ( \
             SELECT iterations FROM ( \
                 SELECT iterations, last, \
                        ROW_NUMBER() OVER (PARTITION BY iterations / ((last + 999) / 1000) ORDER BY iterations) AS r \
                 FROM (SELECT iterations, MAX(iterations) OVER () AS last FROM checkpoint_history WHERE job_id = ?1)) \
             WHERE r > 1 AND iterations < last)",
    )
    .bind(id)
    .execute(&mut *tx)
    .await?;
    Ok(())
}

/// The checkpoints' history: its queries (`Store::history`).
pub struct HistoryTable<'a> {
    pub(super) db: &'a Database,
}

impl HistoryTable<'_> {
    /// A job's checkpoint history: (iterations, strategies JSON), oldest first.
    ///
    /// At most `max` rows, evenly spaced and with the first and the last ([`evenly_kept`]),
    /// streamed and thinned as they are read: memory holds `max` rows whatever the table holds
    /// (the writer keeps ~2,000 per job, but the table is only a file).
    pub async fn load(&self, id: i64, max: usize) -> Result<Vec<(u64, String)>, StoreError> {
        use futures_util::TryStreamExt;
        let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM checkpoint_history WHERE job_id = ?")
            .bind(id)
            .fetch_one(self.db.pool())
            .await?;
        let keep = evenly_kept(n.max(0) as usize, max);
        let mut rows =
            sqlx::query("SELECT iterations, strategies FROM checkpoint_history WHERE job_id = ? ORDER BY iterations")
                .bind(id)
                .fetch(self.db.pool());
        let (mut out, mut i) = (Vec::with_capacity(keep.len()), 0usize);
        while let Some(row) = rows.try_next().await? {
            // Rows appended since the count are past the last kept index: stop there.
            if i > *keep.last().unwrap_or(&0) {
                break;
            }
            if keep.binary_search(&i).is_ok() {
                out.push((row.try_get::<i64, _>("iterations")? as u64, row.try_get("strategies")?));
            }
            i += 1;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::evenly_kept;

    #[test]
    fn thinning_keeps_the_ends_and_spaces_evenly() {
        assert_eq!(evenly_kept(5, 10), vec![0, 1, 2, 3, 4]);
        let t = evenly_kept(10_001, 1000);
        assert_eq!(t.len(), 1000);
        assert_eq!((t[0], *t.last().unwrap()), (0, 10_000));
        assert!(t.windows(2).all(|w| (10..=11).contains(&(w[1] - w[0]))));
    }
}
