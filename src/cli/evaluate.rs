//! `optimis evaluate`: given weights — another run's result (`optimis run --json`, `GET
//! /v1/jobs/{id}/result`) or a table of one's own — scored on a moments document
//! (`solve::evaluate`): how a researcher checks weights on independent iterations.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::documents::{document_job, read_document};
use super::{CliError, table};
use crate::sim::model::params::SpecError;
use crate::sim::solve::evaluate::{Evaluation, GivenWeights, evaluate as score};
use crate::sim::weights::artifact::{WEIGHTS_FORMAT, WeightsArtifact};
use crate::sim::weights::build::given_weights;
use crate::sim::weights::function::WeightFunction;

#[derive(Debug, Args)]
pub struct EvaluateArgs {
    /// The moments document to score on (another seed's run, for an independent check).
    pub document: PathBuf,
    /// The weights: a weights artifact (`optimis weights`), a result document (its recommended
    /// table, heuristics included), or a JSON object with `weights` (one entry per cell, as in a
    /// result) and optionally `heuristics`.
    #[arg(long, value_name = "FILE")]
    pub weights: PathBuf,
    /// Print the evaluation as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn evaluate(args: EvaluateArgs) -> Result<(), CliError> {
    let doc = read_document(&args.document)?;
    let job = document_job(&doc, &args.document)?;
    let path = &args.weights;
    let bytes = std::fs::read(path).map_err(|source| CliError::Read { path: path.clone(), source })?;
    let value: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|source| CliError::Json { path: path.clone(), source })?;
    // A weights artifact (`optimis weights`) is scored exactly as the result it came from.
    let given: GivenWeights = if value.get("format").and_then(serde_json::Value::as_str) == Some(WEIGHTS_FORMAT) {
        let artifact: WeightsArtifact =
            serde_json::from_value(value).map_err(|source| CliError::Json { path: path.clone(), source })?;
        WeightFunction::new(artifact.clone())
            .map_err(|e| CliError::Unusable { path: path.clone(), detail: e.to_string() })?;
        given_weights(&artifact).map_err(|detail| CliError::Unusable { path: path.clone(), detail })?
    } else {
        serde_json::from_value(value).map_err(|source| CliError::Json { path: path.clone(), source })?
    };
    let evaluation = score(&doc.moments, &job.config().cells, &given, &job.spec().solver.fixed)
        .map_err(|e| CliError::Invalid { what: "weights", source: SpecError::new(e.field, e.message) })?;
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &evaluation).map_err(std::io::Error::from)?;
        writeln!(out)?;
        return Ok(());
    }
    Ok(write_evaluation(&mut out, &evaluation, &args.weights)?)
}

fn write_evaluation(out: &mut impl Write, e: &Evaluation, weights: &std::path::Path) -> std::io::Result<()> {
    let source = e.source.map_or_else(|| "a weights table".to_string(), |s| format!("{s} weights"));
    writeln!(out, "{source} from {} scored on {} iterations ({} folds)", weights.display(), e.iterations, e.folds)?;
    if e.evaluated.in_sample {
        writeln!(
            out,
            "warning: the weights were fitted on iterations these moments also hold: the figures are in-sample (optimistic)"
        )?;
    }
    writeln!(out)?;
    table::write_noise_rows(out, std::slice::from_ref(&e.evaluated), e.folds, None)?;
    writeln!(out, "\nthe run's per-path strategies, and Var(strategy)/Var(evaluated weights) on the same iterations:")?;
    let rows: Vec<_> = e.versus.iter().map(|v| v.row.clone()).collect();
    table::write_noise_rows(out, &rows, e.folds, None)?;
    for v in &e.versus {
        if let Some(r) = v.variance_ratio {
            let se = v.variance_ratio_stderr.map_or_else(String::new, |s| format!(" ± {s:.3}"));
            writeln!(out, "  {:<28} variance ratio {r:.3}{se}", v.row.strategy.name())?;
        }
    }
    Ok(())
}
