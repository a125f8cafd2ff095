//! optimis: optimal multiple-importance-sampling weights for bidirectional photon mapping, by direct
//! minimisation of the pixel variance (Ershov, Voloboy, Zhdanov et al. 2020).
//!
//! # Layout
//!
//! * [`sim`] — the pure simulation core: scene, sampling, iterations, moments, solver, reference.
//! * [`jobs`] — the job runner: queue, worker slots, drivers, checkpoints (feature `server`).
//! * [`store`] — SQLite persistence of jobs and checkpoints (feature `server`).
//! * [`api`] — the HTTP API, its OpenAPI description and the dashboard (feature `server`).
//! * [`metrics`] — Prometheus metrics of requests, checkpoints and jobs (feature `server`).
//! * [`server`] — wiring and graceful shutdown of the server process (feature `server`).
//! * [`cli`] — the command line, a thin shell around all of the above.
//!
//! `main.rs` only parses the command line and calls into this library. Without the default
//! `server` feature only the core and the local CLI build: the core depends on no server crate.

#[cfg(feature = "server")]
pub mod api;
pub mod cli;
#[cfg(feature = "server")]
pub mod jobs;
#[cfg(feature = "server")]
pub mod metrics;
#[cfg(feature = "server")]
pub mod server;
pub mod sim;
#[cfg(feature = "server")]
pub mod store;
