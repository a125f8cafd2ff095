//! A moments document read for a figure, solved as the figure asks: as the run recommends, or
//! with the in-sample table optimum at a λ — with the same expectations and reference as
//! `optimis report`, so that a figure recommends what the report does.

use std::path::Path;

use crate::cli::CliError;
use crate::cli::documents::{document_job, read_document, solver_options};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::document::MomentsDocument;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::effective::EffectiveWeights;
use crate::sim::solve::options::SolverOptions;
use crate::sim::solve::report::{ExpectedLuminance, ReportInputs, RunReport, WeightsQuery, build_report};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::ValidJob;
use crate::sim::weights::effective::{EFFECTIVE_PATHS, effective_of_moments};

/// A moments document ready to be solved as a figure asks.
pub(super) struct Solvable {
    pub doc: MomentsDocument,
    job: ValidJob,
    solver: SolverOptions,
    /// Each per-path row's exact expectation (the quadrature): a row missing its tail is not
    /// recommended, as in `optimis report`.
    expected: Vec<ExpectedLuminance>,
    reference: Option<f64>,
}

impl Solvable {
    /// Reads `document`.
    pub fn read(document: &Path) -> Result<Self, CliError> {
        let doc = read_document(&document.to_path_buf())?;
        let job = document_job(&doc, document)?;
        let solver = solver_options(&doc.spec.solver, None)?;
        let expected = expected_luminances(job.config());
        let reference = reference_luminance(&job.config().scene).ok();
        Ok(Self { job, solver, expected, reference, doc })
    }

    /// The run's configuration.
    pub fn config(&self) -> &SimConfig {
        self.job.config()
    }

    fn inputs(&self, weights: Option<WeightsQuery>) -> ReportInputs<'_> {
        ReportInputs { reference: self.reference, expected: Some(&self.expected), weights }
    }

    /// The report as the run recommends (`None`), or with the in-sample table optimum at λ.
    pub fn report(&self, lambda: Option<f64>) -> RunReport {
        let weights = lambda.map(|lambda| WeightsQuery { lambda, strategy: Strategy::Optimal });
        build_report(&self.doc.moments, self.config().cells(), &self.solver, &self.inputs(weights))
    }

    /// The effective weights of row `strategy` (none: the recommended row).
    pub fn effective(&self, strategy: Option<Strategy>) -> Result<EffectiveWeights, String> {
        effective_of_moments(&self.doc.moments, &self.job, &self.inputs(None), strategy, EFFECTIVE_PATHS)
    }
}
