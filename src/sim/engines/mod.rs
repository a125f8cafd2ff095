//! One iteration, two ways: the camera paths and their merge grids, then the light paths — all N_F
//! of them streamed by the brute force, or only those that can merge, drawn exactly by the
//! restricted engine — merged and tallied the same way.
//!
//! * [`camera`], [`grid`] — the N_B camera paths and the hash grids of their vertices;
//! * [`strategies`] — the per-path strategies (their weights on a join path) and the techniques;
//! * [`merge`], [`tally`] — what a light path contributes, and the per-chunk/per-iteration tallies;
//! * [`layout`] — what each moments format keeps of a tally (strategies, moment-vector columns);
//! * [`pixel`] — the exact pixel tests and the last step of a lobe draw, shared by both engines;
//! * [`brute`] — the streamed light-path loop (the hot path), in blocks;
//! * [`restricted`] — the restricted engine: a Poisson process on the light paths that can merge;
//! * [`cost`] — the expected work of one iteration, checked before a server accepts a job.
//!
//! Imports: crate::sim::math, crate::sim::model

pub mod brute;
pub mod camera;
pub mod cost;
pub mod grid;
pub mod layout;
pub mod merge;
pub mod pixel;
pub mod restricted;
pub mod strategies;
pub mod tally;
