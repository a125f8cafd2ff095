//! The weight function a run recommends, as a portable artifact a renderer can use (issue 41,
//! docs/weights-lookup.md): its format, its reference evaluator in Rust, and what checks the
//! evaluators against the engine.
//!
//! * [`artifact`] — the `optimis-weights` document: a table, a heuristic or a stack, the scene its
//!   coordinates refer to, each heuristic's formula and parameters, provenance;
//! * [`function`] — the reference evaluator: the weight of a merge by technique m from the
//!   artifact, the path's cell coordinates and its vertex densities (no engine involved);
//! * [`densities`] — those vertex densities for the model scene's join paths;
//! * [`build`] — an artifact from a run's result, and back into the weights `solve::evaluate`
//!   scores;
//! * [`effective`] — a weight function's effective weights per (r2, r3) bin, from the engine's
//!   camera paths (what Fig. 2 draws for any kind of recommendation);
//! * [`samples`] — join paths drawn with the engine's samplers, and the engine's weights on them.
//!
//! Imports: crate::sim::engines, crate::sim::math, crate::sim::model, crate::sim::signature, crate::sim::solve, crate::sim::spec, crate::sim::stats

pub mod artifact;
pub mod build;
pub mod densities;
pub mod effective;
pub mod function;
pub mod samples;
#[cfg(test)]
mod tests;
