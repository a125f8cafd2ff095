//! A moments document read for a figure, solved as the figure asks: as the run recommends, or
//! with the in-sample table optimum at a λ.

use std::path::Path;

use crate::cli::CliError;
use crate::cli::documents::{document_job, read_document, solver_options};
use crate::sim::document::MomentsDocument;
use crate::sim::model::cells::CellGrid;
use crate::sim::solve::options::SolverOptions;
use crate::sim::solve::report::{ReportInputs, RunReport, WeightsQuery, build_report};
use crate::sim::solve::strategy::Strategy;

/// A moments document ready to be solved as a figure asks.
pub(super) struct Solvable {
    pub doc: MomentsDocument,
    cells: CellGrid,
    solver: SolverOptions,
}

impl Solvable {
    /// Reads `document`.
    pub fn read(document: &Path) -> Result<Self, CliError> {
        let doc = read_document(&document.to_path_buf())?;
        let job = document_job(&doc, document)?;
        let solver = solver_options(&doc.spec.solver, None)?;
        Ok(Self { cells: job.config().cells.clone(), solver, doc })
    }

    /// The report as the run recommends (`None`), or with the in-sample table optimum at λ.
    pub fn report(&self, lambda: Option<f64>) -> RunReport {
        let weights = lambda.map(|lambda| WeightsQuery { lambda, strategy: Strategy::Optimal });
        build_report(
            &self.doc.moments,
            &self.cells,
            &self.solver,
            &ReportInputs { reference: None, expected: None, weights },
        )
    }
}
