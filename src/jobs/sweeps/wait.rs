//! The long-poll of a sweep (`GET /v1/sweeps/{id}?wait=S`): until every run has ended.

use std::time::{Duration, Instant};

use super::{Sweeps, no_sweep, overall_state};
use crate::jobs::core::error::JobError;
use crate::jobs::core::resource::JobState;

impl Sweeps {
    /// Returns once every run of the sweep has ended, `wait` has passed or the server stops; one
    /// indexed read of the runs' states every half second (`?wait=` of `GET /v1/sweeps/{id}`).
    pub async fn wait_for_end(&self, id: i64, wait: Duration) -> Result<(), JobError> {
        let deadline = Instant::now() + wait;
        let mut shutdown = self.jobs.shutdown_signal();
        loop {
            let runs = self.jobs.store().sweep_jobs(id).await?;
            if runs.is_empty() && self.jobs.store().get_sweep(id).await?.is_none() {
                return Err(no_sweep(id));
            }
            let states: Vec<JobState> = runs
                .iter()
                .map(|(_, job)| self.jobs.active(job.id).map_or(job.state, |active| active.view.borrow().state))
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
}
