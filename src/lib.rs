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
//! * [`jobs`] — the job runner: manager, scheduler, drivers, job state, checkpoints, policy,
//!   statistics operations, peers (feature `server`).
//! * [`metrics`] — Prometheus metrics of requests, checkpoints and jobs (feature `server`).
//! * [`store`] — SQLite persistence of jobs, their typed states and checkpoints (feature `server`).
//! * [`sim`] — the pure simulation core in folders by concept: math → model → engines → stats →
//!   solve → spec/document/runner → checks.
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
mod process_metrics;
#[cfg(feature = "server")]
pub mod server;
pub mod sim;
#[cfg(feature = "server")]
pub mod store;
