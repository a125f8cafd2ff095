//! Parameter sweeps: one job specification varied along axes, each point an ordinary job, and the
//! table that puts their noise figures side by side.
//!
//! A sweep document names a `base` job document, `axes` (a dotted path into the job document and
//! the values it takes) and a `mode`: `grid` (every combination, the last axis fastest) or `zip`
//! (the i-th value of every axis together). [`plan`](mod@plan) expands it into points and
//! validates each point's job exactly as a submitted job is validated, so a bad path or value is
//! an error naming the axis, the value and the point.
//!
//! An axis over `light_paths` or `camera_paths` may be answered **by prediction**
//! (`"by": "prediction"`): its points share one run, recorded with noise components at the base's
//! budget, and their figures are predicted from it (`solve::predict`, docs/model.md §12) instead of
//! run. The plan therefore has *runs* (jobs to execute) and *points* (rows of the table), each
//! point pointing at its run.
//!
//! [`table`] turns each point's figures (a run's report or a prediction) into the sweep's table:
//! one row per point and strategy, JSON or CSV. The server and `optimis sweep` build it with the
//! same code from the same moments, so their tables are identical.
//!
//! Imports: crate::sim::math, crate::sim::model, crate::sim::solve, crate::sim::spec, crate::sim::stats

pub mod plan;
pub mod table;

pub use plan::{Axis, AxisSource, PlannedPoint, PlannedRun, SweepMode, SweepPlan, SweepSpec, plan};
pub use table::{
    FigureSource, PointFigures, PointResults, SweepRow, SweepTable, figures_of_prediction, figures_of_report,
    point_figures,
};
