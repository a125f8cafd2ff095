//! From moments to answers: the solver options, the cell-wise optimal weights, the noise table of
//! every strategy and the result document.
//!
//! * [`options`] — how the weights are fitted, and the one way to patch and validate that;
//! * [`solver`] — the optimal weights by direct minimisation of the variance;
//! * [`noise`] — luminance and RMS of every strategy, with standard errors and hold-out figures;
//! * [`strategy`] — the rows of the noise table, by name;
//! * [`report`] — the result document of a run.

pub mod noise;
pub mod options;
pub mod report;
pub mod solver;
pub mod strategy;
