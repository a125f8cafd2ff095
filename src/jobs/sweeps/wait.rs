//! The long-poll of a sweep (`GET /v1/sweeps/{id}?wait=S`): until every run has ended.

use std::time::{Duration, Instant};

use super::{no_sweep, overall_state};
use crate::jobs::core::error::JobError;
use crate::jobs::core::manager::JobManager;
use crate::jobs::core::resource::JobState;

/// Returns once every run of sweep `id` has ended, `wait` has passed or the server stops; one
/// indexed read of the runs' states every half second (`?wait=` of `GET /v1/sweeps/{id}`).
pub(super) async fn until_ended(jobs: &JobManager, id: i64, wait: Duration) -> Result<(), JobError> {
    let deadline = Instant::now() + wait;
    let mut shutdown = jobs.shutdown_signal();
    loop {
        let runs = jobs.store().sweeps().runs(id).await?;
        if runs.is_empty() && jobs.store().sweeps().get(id).await?.is_none() {
            return Err(no_sweep(id));
        }
        let states: Vec<JobState> = runs
            .iter()
            .map(|(_, job)| jobs.active(job.id).map_or(job.state, |active| active.view.borrow().state))
            .collect();
        let now = Instant::now();
        if overall_state(&states).is_terminal() || now >= deadline || *shutdown.borrow() {
            return Ok(());
        }
        tokio::select! {
            _ = tokio::time::sleep((deadline - now).min(Duration::from_millis(500))) => {}
            _ = shutdown.changed() => return Ok(()),
        }
    }
}
