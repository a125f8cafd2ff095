//! `optimis weights`: the weight function of a run as a portable artifact a renderer can use
//! (`sim::weights`, docs/weights-lookup.md) — the recommended row's by default, any row's by name —
//! and, optionally, test vectors to check a port of the evaluator against the engine.

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use serde_json::Value;

use super::CliError;
use super::documents::document_job;
use super::run::{read_json, write_atomically};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::document::MomentsDocument;
use crate::sim::solve::report::{ReportInputs, RunReport};
use crate::sim::solve::strategy::Strategy;
use crate::sim::spec::{SpecError, ValidJob, parse_job_spec};
use crate::sim::weights::artifact::WeightsArtifact;
use crate::sim::weights::build::{RowWeights, artifact, artifact_of_moments, recommended_row};
use crate::sim::weights::samples::{engine_artifact_weight, join_paths};

/// Most test vectors one call writes.
const MAX_VECTORS: usize = 10_000_000;

#[derive(Debug, Args)]
pub struct WeightsArgs {
    /// A moments document (`optimis run --out`, `GET /v1/jobs/{id}/moments`), or a result
    /// (`optimis run --json`, `GET /v1/jobs/{id}/result`) with `--spec`.
    pub source: PathBuf,
    /// With a result: its job specification (the document `POST /v1/jobs` took, or a preset's
    /// name as `{"preset": "…"}`), which states the scene the weights refer to.
    #[arg(long, value_name = "FILE")]
    pub spec: Option<PathBuf>,
    /// The row whose weights to write (default: the recommended one). Another fitted row needs
    /// the moments document (its fit is recomputed at its λ).
    #[arg(long, value_name = "STRATEGY", value_parser = super::documents::parse_strategy)]
    pub strategy: Option<Strategy>,
    /// Where to write the artifact (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also write test vectors (CSV): join paths drawn with the engine's samplers and the engine's
    /// weight of each merge under these weights — to check an evaluator (a port to your renderer)
    /// against it: `technique,x2_x,x2_y,x3_x,x3_y,x3l_x,x3l_y,weight`.
    #[arg(long, value_name = "FILE")]
    pub vectors: Option<PathBuf>,
    /// How many join paths the vectors hold (at least).
    #[arg(long, default_value_t = 100_000)]
    pub vector_count: usize,
}

pub fn weights(args: WeightsArgs) -> Result<(), CliError> {
    let value = read_json(&args.source)?;
    let is_document = value.get("kind").and_then(Value::as_str) == Some("optimis-moments");
    let artifact = if is_document { from_document(&args)? } else { from_result(&args, value)? };
    let text = serde_json::to_vec_pretty(&artifact).map_err(std::io::Error::from)?;
    write_atomically(&args.out, &text)?;
    eprintln!(
        "{} weights ({:?}{}) → {}",
        artifact.strategy,
        artifact.kind,
        if artifact.recommended { ", recommended" } else { "" },
        args.out.display()
    );
    if let Some(path) = &args.vectors {
        if args.vector_count == 0 || args.vector_count > MAX_VECTORS {
            return Err(SpecError::new("--vector-count", format!("must be in [1, {MAX_VECTORS}]")).into());
        }
        let job = job_of(&args, is_document)?;
        write_atomically(path, vectors(&job, &artifact, args.vector_count).as_bytes())?;
        eprintln!("test vectors ({} merges) → {}", args.vector_count, path.display());
    }
    Ok(())
}

/// The job the weights refer to: the document's, or the `--spec` given with a result.
fn job_of(args: &WeightsArgs, is_document: bool) -> Result<ValidJob, CliError> {
    if is_document {
        let doc = super::documents::read_document(&args.source)?;
        return document_job(&doc, &args.source);
    }
    let path = args.spec.as_ref().ok_or_else(|| {
        SpecError::new("--spec", "a result does not state its scene: give its job specification with --spec FILE")
    })?;
    Ok(parse_job_spec(&read_json(path)?)?.validate()?)
}

/// The artifact of a row of a moments document's report (its recommendation, or `--strategy`).
fn from_document(args: &WeightsArgs) -> Result<WeightsArtifact, CliError> {
    let doc: MomentsDocument = super::documents::read_document(&args.source)?;
    let job = document_job(&doc, &args.source)?;
    let config = job.config();
    let expected = expected_luminances(config);
    let inputs =
        ReportInputs { reference: reference_luminance(&config.scene).ok(), expected: Some(&expected), weights: None };
    artifact_of_moments(&doc.moments, &job, &inputs, args.strategy).map_err(|e| unusable(args, &e))
}

/// The artifact of a result's recommended row, or of one of its per-path rows.
fn from_result(args: &WeightsArgs, value: Value) -> Result<WeightsArtifact, CliError> {
    let report: RunReport = serde_json::from_value(value)
        .map_err(|e| unusable(args, &format!("neither a moments document nor a result: {e}")))?;
    let job = job_of(args, false)?;
    if job.config().fingerprint() != report.fingerprint {
        return Err(unusable(args, "the result's configuration is not the --spec's (their fingerprints differ)"));
    }
    let recommended = report.recommended.as_ref().map(|r| r.strategy);
    let chosen = args.strategy.or(recommended).ok_or_else(|| unusable(args, "the result recommends no row"))?;
    if Some(chosen) != recommended && chosen.path().is_none() {
        return Err(unusable(
            args,
            &format!("a result holds the table of its recommended row only; for {chosen}, give the moments document"),
        ));
    }
    row_artifact(args, &job, &report, chosen)
}

/// The artifact of the recommended row or a per-path row of `report`.
fn row_artifact(
    args: &WeightsArgs,
    job: &ValidJob,
    report: &RunReport,
    chosen: Strategy,
) -> Result<WeightsArtifact, CliError> {
    let recommended = report.recommended.as_ref().map(|r| r.strategy);
    let row = match recommended_row(report) {
        Some(row) if Some(chosen) == recommended => row,
        _ => RowWeights { strategy: chosen, recommended: false, table: &[], heuristics: Vec::new(), lambda: None },
    };
    artifact(job.config(), report, &row).map_err(|e| unusable(args, &e))
}

fn unusable(args: &WeightsArgs, detail: &str) -> CliError {
    CliError::Unusable { path: args.source.clone(), detail: detail.to_string() }
}

/// The test vectors of `artifact` on `job`'s scene: at least `count` merges.
fn vectors(job: &ValidJob, artifact: &WeightsArtifact, count: usize) -> String {
    let config = job.config();
    let mut out = String::from("technique,x2_x,x2_y,x3_x,x3_y,x3l_x,x3l_y,weight\n");
    for s in join_paths(config, 1, count) {
        let w = engine_artifact_weight(config, artifact, &s);
        let _ = writeln!(
            out,
            "{},{:e},{:e},{:e},{:e},{:e},{:e},{:e}",
            s.technique, s.x2[0], s.x2[1], s.x3[0], s.x3[1], s.x3_light[0], s.x3_light[1], w
        );
    }
    out
}
