//! Independent references the engines are checked against: nothing here is used to compute a
//! result.
//!
//! * [`quadrature`] — the analytic reference luminance (within an evaluation budget);
//! * [`expectation`] — exact expected merge counts given the camera paths;
//! * [`equivalence`] — block-wise comparison of two engines' figures.

pub mod equivalence;
pub mod expectation;
pub mod quadrature;
