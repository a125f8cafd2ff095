//! Start-up recovery: what a previous server left unfinished is re-queued (running jobs resume
//! from their last checkpoint), cancelled or failed, before the scheduler starts.

use super::resource::{JobState, now_ms, parse_stored_spec, resource_from_row};
use super::state::Inner;
use crate::sim::math::digest::sha256_hex;
use crate::store::StoreError;

/// Fills in the result checksums of checkpoints written before they were kept (once: later
/// starts find none), in bounded batches hashed on the request pool.
async fn checksum_old_results(inner: &Inner) -> Result<(), StoreError> {
    loop {
        let rows = inner.store.checkpoints().results_without_checksum(64).await?;
        if rows.is_empty() {
            return Ok(());
        }
        let hashed = inner
            .pools
            .light(move || rows.into_iter().map(|(id, result)| (id, sha256_hex(result.as_bytes()))).collect())
            .await
            .map_err(|e| StoreError::Corrupt { job: 0, detail: e.to_string() })?;
        let hashed: Vec<(i64, String)> = hashed;
        for (id, checksum) in hashed {
            inner.store.checkpoints().fill_result_checksum(id, &checksum).await?;
        }
    }
}

/// Re-queues, cancels or fails each job a previous server left queued or running.
pub(in crate::jobs) async fn recover(inner: &Inner) -> Result<(), StoreError> {
    checksum_old_results(inner).await?;
    for row in inner.store.jobs().unfinished().await? {
        if row.cancel_requested {
            // The cancel was acknowledged before the server stopped: honour it.
            inner.store.jobs().set_state(row.id, JobState::Cancelled, None, now_ms()).await?;
            tracing::info!(job = row.id, iterations_done = row.iterations_done, "cancelled job stays cancelled");
            continue;
        }
        let valid =
            parse_stored_spec(&row).map_err(|e| e.to_string()).and_then(|s| s.validate().map_err(|e| e.to_string()));
        match valid {
            Ok(job) => {
                if row.state != JobState::Queued {
                    inner.store.jobs().set_state(row.id, JobState::Queued, None, now_ms()).await?;
                }
                let mut resource =
                    resource_from_row(&row).map_err(|e| StoreError::Corrupt { job: row.id, detail: e.to_string() })?;
                resource.state = JobState::Queued;
                inner.enqueue(row.id, job, resource);
                tracing::info!(job = row.id, iterations_done = row.iterations_done, "re-queued unfinished job");
            }
            Err(e) => {
                let reason = format!("the stored specification is no longer valid: {e}");
                inner.store.jobs().set_state(row.id, JobState::Failed, Some(&reason), now_ms()).await?;
            }
        }
    }
    Ok(())
}
