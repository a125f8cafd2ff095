//! Independent references the engines are checked against: nothing here is used to compute a
//! result.
//!
//! * [`quadrature`] — the analytic reference luminance (within an evaluation budget);
//! * [`expected`] — each per-path strategy's expected luminance at the configuration's merge
//!   radius (the reference is its R → 0 limit);
//! * [`expectation`] — exact expected merge counts given the camera paths;
//! * [`equivalence`] — block-wise comparison of two engines' figures;
//! * [`references`] — each strategy's expected luminance at the job's R, as reports take it;
//! * [`published`] — the paper's Table 1 as data, and whether a job's configuration is the paper's;
//! * `effective` (tests) — the effective weights against the quadrature and their own spread.
//!
//! Imports: crate::sim::engines, crate::sim::model, crate::sim::runner, crate::sim::solve, crate::sim::spec, crate::sim::stats, crate::sim::weights

#[cfg(test)]
mod effective;
pub mod equivalence;
pub mod expectation;
pub mod expected;
pub mod published;
pub mod quadrature;
pub mod references;
