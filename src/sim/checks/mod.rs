//! Independent references the engines are checked against: nothing here is used to compute a
//! result.
//!
//! * [`quadrature`] — the analytic reference luminance (within an evaluation budget);
//! * [`expectation`] — exact expected merge counts given the camera paths;
//! * [`equivalence`] — block-wise comparison of two engines' figures;
//! * [`references`] — each strategy's expected luminance at the job's R, as reports take it.

pub mod equivalence;
pub mod expectation;
pub mod quadrature;
pub mod references;
