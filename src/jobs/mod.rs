//! The job runner: queued jobs, run a bounded number at a time on a dedicated rayon pool, with
//! progress in memory and checkpoints in the store.
//!
//! Layout (each module imports only those below it):
//! * [`statistics`] — results, re-solves, the moments export, merges and studies (on the manager);
//! * [`solves`] — named re-solves kept with a job (on the manager);
//! * [`sweeps`] — sweeps: their runs queued as jobs, their figures and table (on the manager);
//! * [`prediction`] — a job's noise table predicted at another ray budget (on the manager);
//! * [`evaluation`] — given weights scored on a job's statistics (on the manager);
//! * [`manager`] — the public handle: submit, get, list, cancel, extend, delete, shutdown;
//! * [`scheduler`] — starts queued jobs in submission order while workers are free;
//! * [`driver`] — runs one job segment by segment and writes its checkpoints;
//! * [`state`] — the jobs in memory (`ActiveJob`, `StopReason`) and the transitions of their state;
//! * [`compute`] — the pools a request's CPU work runs on: light work, and bounded heavy work;
//! * [`references`] — each configuration's expected luminances, computed once;
//! * [`checkpoint`] — the stored forms: spec JSON, checkpoint encoding and verified decoding;
//! * [`policy`] — what this server accepts: budgets, the work of an iteration, extension targets;
//! * [`peer_tls`] — how https peers' certificates are verified (roots, and `--peer-ca` pins);
//! * [`signing`] — provenance: this server's signature on exports, the keys merges require;
//! * [`peers`] — moments documents pulled from allowed peer servers, for merges;
//! * [`resource`], [`documents`] — what the API shows of a job; [`error`] — what job operations fail with.

pub mod checkpoint;
pub mod compute;
pub mod documents;
pub mod driver;
pub mod error;
pub mod evaluation;
pub mod manager;
pub mod peer_tls;
pub mod peers;
pub mod policy;
pub mod prediction;
pub mod references;
pub mod resource;
pub mod scheduler;
pub mod signing;
pub mod solves;
pub mod state;
pub mod statistics;
pub mod sweeps;

pub use error::JobError;
pub use manager::JobManager;
pub use policy::RunPolicy;
