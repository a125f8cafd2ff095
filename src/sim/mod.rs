//! The simulation core: a pure, deterministic model of the paper's scene, with no I/O.
//!
//! # Layout
//!
//! Specification and configuration:
//! * [`spec`] — the JSON job specification, presets, validation (the only place values are checked);
//! * [`config`] — the validated statistical configuration and its fingerprint;
//! * [`scene`], [`illumination`], [`cells`] — geometry and BDFs, the light's profile, the cell grid.
//!
//! One iteration (camera paths → grid → streamed light paths → merges → tallies):
//! * [`rng`] — the random stream of each (seed, iteration, chunk);
//! * [`sampling`] — Lambert and lobe directions;
//! * [`camera`], [`grid`] — the N_B camera paths and the hash grid of their vertices;
//! * [`light`] — the streamed light-path loop (the hot path);
//! * [`fastmath`] — branch-free sine and cosine that the hot loop can vectorise, with tested bounds;
//! * [`merge`] — what one light path contributes: its merges at the three planes;
//! * [`restricted`] — the restricted engine: only the light paths that can merge, drawn exactly;
//! * [`heuristics`], [`tally`] — per-path MIS weights and per-chunk/per-iteration tallies.
//!
//! Statistics and results:
//! * [`exact_sum`], [`coverage`], [`moments`] — exact additive moments and what they cover;
//! * [`document`] — the portable, checksummed moments document and merging of documents;
//! * [`runner`] — runs iterations on the current rayon pool, in order;
//! * [`solver`], [`noise`], [`report`] — optimal weights, the noise table, the result document;
//! * [`quadrature`] — the analytic reference luminance (within an evaluation budget);
//! * [`cost`] — the expected work of one iteration, checked before a server accepts a job;
//! * [`equivalence`] — block-wise comparison of two engines' figures (the equivalence suite);
//! * [`expectation`] — exact expected plane-3 merges given the camera paths (an analytic check).
//!
//! Nothing here touches a file, a socket, a clock or a database, so all of it is testable and
//! benchmarkable alone; the CLI and the server wrap it.

pub mod camera;
pub mod cells;
pub mod config;
pub mod cost;
pub mod coverage;
pub mod document;
pub mod equivalence;
pub mod exact_sum;
pub mod expectation;
pub mod fastmath;
pub mod grid;
pub mod heuristics;
pub mod illumination;
pub mod light;
pub mod merge;
pub mod moments;
pub mod noise;
pub mod quadrature;
pub mod report;
pub mod restricted;
pub mod rng;
pub mod runner;
pub mod sampling;
pub mod scene;
pub mod solver;
pub mod spec;
pub mod tally;
