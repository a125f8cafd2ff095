//! The simulation core: a pure, deterministic model of the paper's scene, with no I/O.
//!
//! # Layout
//!
//! Folders by concept, each importing only from the folders above it in this list (and from
//! its own files), never the other way — `tests/architecture.rs` checks it:
//!
//! * [`math`] — random streams, fast trigonometry, exact sums, Poisson variates, pure samplers,
//!   SHA-256;
//! * [`model`] — the scene's parameters and their validation, the light's profile, the planes and
//!   the lobe, the cell grid, the heuristics, closed-form densities, and the configuration with its
//!   fingerprint;
//! * [`engines`] — one iteration: camera paths and grids, merges and tallies, the brute force and
//!   the restricted engine, and the expected work of an iteration;
//! * [`stats`] — exact, mergeable moments and the iterations they cover;
//! * [`solve`] — solver options, the optimal weights, the noise table, the result document;
//! * [`spec`], [`configuration`], [`document`], [`signature`], [`runner`], [`sweep`] — the job
//!   document users submit (presets, validation), which of its fields make the configuration (and
//!   how two differ), the portable moments document and what its signature attests, the runner
//!   that puts iterations into moments, and sweeps (a job document varied along axes, and their
//!   table);
//! * [`weights`] — the recommended weight function as a portable artifact, its reference
//!   evaluator, and the engine's weights the evaluators are checked against;
//! * [`checks`] — independent references: the quadrature, exact merge expectations, engine
//!   equivalence.
//!
//! Nothing here touches a file, a socket, a clock or a database, so all of it is testable and
//! benchmarkable alone; the CLI and the server wrap it.
//!
//! Imports: nothing from the crate

pub mod checks;
pub mod configuration;
pub mod document;
pub mod engines;
pub mod math;
pub mod model;
pub mod runner;
pub mod signature;
pub mod solve;
pub mod spec;
pub mod stats;
pub mod sweep;
pub mod weights;
