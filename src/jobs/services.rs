//! The job layer's handles, built once at start-up: the lifecycle core and the feature services
//! on it. The HTTP state holds each of them; a route file uses one.

use std::sync::Arc;

use super::artifacts::Artifacts;
use super::core::manager::JobManager;
use super::evaluation::Evaluations;
use super::merges::Merges;
use super::merges::peers::Peers;
use super::prediction::Predictions;
use super::solves::Solves;
use super::statistics::Statistics;
use super::sweeps::Sweeps;
use crate::trust::signing::Provenance;

/// Every handle of the job layer; cheap to clone.
#[derive(Clone)]
pub struct Services {
    /// The lifecycle: submit, get, list, cancel, extend, delete, events, shutdown.
    pub jobs: JobManager,
    /// Results, histories, re-solves, the moments export.
    pub statistics: Statistics,
    /// Merges and studies.
    pub merges: Merges,
    /// Weights artifacts and effective weights.
    pub artifacts: Artifacts,
    /// Given weights scored on a job.
    pub evaluations: Evaluations,
    /// Named re-solves kept with a job.
    pub solves: Solves,
    /// Noise tables predicted at other ray budgets.
    pub predictions: Predictions,
    /// Sweeps and their tables.
    pub sweeps: Sweeps,
}

impl Services {
    /// The feature services on the lifecycle `jobs`: merges pull from `peers`, exports are signed
    /// and merged documents checked with `provenance`, at most `documents` merges or studies
    /// process documents at once.
    pub fn new(jobs: JobManager, peers: Peers, provenance: Provenance, documents: usize) -> Self {
        let statistics = Statistics::new(jobs.clone(), Arc::new(provenance));
        Self {
            merges: Merges::new(statistics.clone(), peers, documents),
            artifacts: Artifacts::new(statistics.clone()),
            evaluations: Evaluations::new(statistics.clone()),
            solves: Solves::new(statistics.clone()),
            predictions: Predictions::new(statistics.clone()),
            sweeps: Sweeps::new(statistics.clone()),
            statistics,
            jobs,
        }
    }
}
