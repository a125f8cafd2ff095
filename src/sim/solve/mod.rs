//! From moments to answers: the solver options, the cell-wise optimal weights, the noise table of
//! every strategy and the result document.
//!
//! * [`options`] — how the weights are fitted, and the one way to patch and validate that;
//! * [`solver`] — the optimal weights by direct minimisation of the variance;
//! * [`crossfit`] — K-fold cross-fitting of fitted weights and the jackknife over the fold fits;
//! * [`row`] — one row of the noise table (L, RMS and their standard errors) and the per-path rows;
//! * [`fitted`] — the fitted rows: the table, the stacked optimum, each heuristic corrected;
//! * [`expectation`] — each per-path row's exact expectation, its z, and a tail missing from the
//!   run;
//! * [`anchor`] — the per-path row a run stands on: the correlation-aware prior unless another
//!   beats it beyond the guard;
//! * [`recommend`] — which row to recommend, with its guard, and the gain; [`trust`] — how far a
//!   fit may move from the best per-path row to be trusted;
//! * [`rms_error`] — the standard error of a fitted row's RMS;
//! * [`noise`] — the noise table: every row, the recommendation and the gain;
//! * [`ystats`] — the moments of a set of iterations as the solver reads them;
//! * [`warnings`] — what the data cannot support, machine-readable;
//! * [`strategy`] — the rows of the noise table, by name;
//! * [`effective`] — a weight function's effective weights per (r2, r3) bin (Fig. 2 of any
//!   recommendation) and the fold fits behind their errors;
//! * [`report`] — the result document of a run; [`export`] — its tables as CSV; [`tables`] — the
//!   noise table as Markdown and LaTeX;
//! * [`predict`] — the noise table and re-fitted weights at another ray budget, from one run's
//!   noise components;
//! * [`budget`] — the (N_F, N_B) that reaches a target noise soonest, per strategy, and with
//!   [`budget::error`] the (N_F, N_B, R′) that reaches a target error, bias included;
//! * [`radii`] — a run's noise table and biases at each smaller radius it tallied, and
//!   [`radius_reports`] that computes them;
//! * [`evaluate`] — any weights (another run's recommendation, a table) scored on a run;
//! * [`compare`] — runs compared strategy by strategy, ratios and differences with their SEs.
//!
//! Imports: crate::sim::engines, crate::sim::math, crate::sim::model, crate::sim::stats

pub mod anchor;
pub mod budget;
pub mod compare;
pub mod crossfit;
pub mod effective;
pub mod evaluate;
pub mod expectation;
pub mod export;
pub mod fitted;
pub mod noise;
pub mod options;
pub mod predict;
pub mod radii;
pub mod radius_reports;
pub mod recommend;
pub mod report;
pub mod rms_error;
pub mod row;
pub mod solver;
pub mod strategy;
pub mod tables;
pub mod trust;
pub mod warnings;
pub mod ystats;
