//! optimis: optimal multiple-importance-sampling weights for bidirectional photon mapping, by direct
//! minimisation of the pixel variance (Ershov, Voloboy, Zhdanov et al. 2020).
//!
//! # Layout
//!
//! Imports point down this list (`tests/architecture.rs` checks it, and that no file passes 500
//! lines):
//!
//! * [`cli`] — the command line, a thin shell around all of the below.
//! * [`server`] — wiring (store → pools → job manager → router → listener), the accept loop with
//!   its connection limits, TLS, graceful shutdown (feature `server`).
//! * [`api`] — the HTTP routes, their limits and bearer token, the error mapping, the OpenAPI
//!   description and the dashboard (feature `server`).
//! * [`jobs`] — the job runner: its lifecycle core (manager, scheduler, drivers, job state,
//!   checkpoints, policy, the executor seam) and the features built on it — statistics, merges and
//!   peers, solves, predictions, sweeps, the cluster executor (feature `server`).
//! * [`trust`] — signing keys and trusted keys, TLS pins and this server's certificate, secret
//!   files (feature `server`).
//! * [`metrics`] — Prometheus metrics of requests, checkpoints and jobs (feature `server`).
//! * [`store`] — SQLite persistence of jobs, their typed states and checkpoints (feature `server`).
//! * [`sim`] — the pure simulation core in folders by concept: math → model → engines → stats →
//!   solve → spec/document/runner → checks.
//!
//! `main.rs` only parses the command line and calls into this library. Without the default
//! `server` feature only the core and the local CLI build: the core depends on no server crate.
//!
//! Unit tests live at the end of the file they test, in `#[cfg(test)] mod tests { … }`; a file
//! that would pass 500 lines with them declares `#[cfg(test)] mod tests;` and keeps them in
//! `<file>/tests.rs` (where Rust looks for it: no `#[path]`). Tests through the public interfaces
//! — the HTTP API, the command line, whole runs — are the integration tests in `tests/`.
//!
//! Every folder's module file (its `mod.rs`) ends its description with the crate modules the
//! folder may import besides its own files, in one line that `tests/architecture.rs` checks:
//! `Imports: crate::sim, crate::store` or `Imports: nothing from the crate`. Here it is that of the
//! files at the top of `src/` (this one, `main.rs`, `metrics.rs` and `process_metrics.rs`):
//!
//! Imports: crate::store

#[cfg(feature = "server")]
pub mod api;
pub mod cli;
#[cfg(feature = "server")]
pub mod jobs;
#[cfg(feature = "server")]
pub mod metrics;
#[cfg(feature = "server")]
mod process_metrics;
#[cfg(feature = "server")]
pub mod server;
pub mod sim;
#[cfg(feature = "server")]
pub mod store;
#[cfg(feature = "server")]
pub mod trust;
