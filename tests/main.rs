//! The integration tests, one binary: each module below was a test binary of its own (see
//! Cargo.toml's `autotests = false`). Run one module with `cargo test --release --test integration
//! MODULE::`, e.g. `cargo test --release --test integration dashboard::`.

mod common;

mod api;
mod architecture;
mod cli;
mod cluster;
mod compare;
mod crash;
mod dashboard;
mod engines;
mod faults;
mod figures;
mod formats;
mod hardening;
mod hostile_documents;
mod labels;
mod limits;
mod peers;
mod prediction;
mod radii;
mod readme;
mod recommendation;
mod references;
mod shards;
mod shares;
mod simulation;
mod slow_clients;
mod sweeps;
mod wait;
mod weights;
