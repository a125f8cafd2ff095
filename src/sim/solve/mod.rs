//! From moments to answers: the solver options, the cell-wise optimal weights, the noise table of
//! every strategy and the result document.
//!
//! * [`options`] — how the weights are fitted, and the one way to patch and validate that;
//! * [`solver`] — the optimal weights by direct minimisation of the variance;
//! * [`crossfit`] — K-fold cross-fitting of fitted weights and the jackknife over the fold fits;
//! * [`noise`] — luminance and RMS of every strategy with standard errors, the recommended weights
//!   and the gain;
//! * [`ystats`] — the moments of a set of iterations as the solver reads them;
//! * [`warnings`] — what the data cannot support, machine-readable;
//! * [`strategy`] — the rows of the noise table, by name;
//! * [`report`] — the result document of a run; [`export`] — its tables as CSV;
//! * [`predict`] — the noise table and re-fitted weights at another ray budget, from one run's
//!   noise components;
//! * [`budget`] — the (N_F, N_B) that reaches a target noise soonest, per strategy.

pub mod budget;
pub mod crossfit;
pub mod export;
pub mod noise;
pub mod options;
pub mod predict;
pub mod report;
pub mod solver;
pub mod strategy;
pub mod warnings;
pub mod ystats;
