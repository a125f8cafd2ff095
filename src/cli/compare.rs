//! `optimis compare`: runs compared strategy by strategy — moments documents (each reported here)
//! or, with `--server`, jobs of a running server (`GET /v1/compare`) — each run's L and RMS, and
//! against the first run the ratio and difference of L and the ratio of RMS with their standard
//! errors and z.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::documents::{document_job, read_document, solver_options};
use super::{CliError, table};
use crate::sim::configuration::configuration_differences;
use crate::sim::solve::compare::{Compared, Comparison, MAX_COMPARED, compare as compare_runs};
use crate::sim::solve::report::{ReportInputs, RunReport, build_report};

#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Moments documents (`optimis run --out`, `GET /v1/jobs/{id}/moments`), or with `--server`
    /// job ids; 2 to 8, the first is the baseline.
    #[arg(required = true, num_args = 2..=MAX_COMPARED)]
    pub runs: Vec<String>,
    /// Compare jobs of this server instead (`localhost:8080`; `OPTIMIS_TOKEN` is sent if set).
    #[arg(long, value_name = "URL")]
    pub server: Option<String>,
    /// Print the comparison as JSON (the document `GET /v1/compare` answers).
    #[arg(long)]
    pub json: bool,
}

pub fn compare(args: CompareArgs) -> Result<(), CliError> {
    let comparison = match &args.server {
        #[cfg(feature = "server")]
        Some(base) => remote(base, &args.runs)?,
        #[cfg(not(feature = "server"))]
        Some(_) => return Err(CliError::Config("--server needs a build with the `server` feature".into())),
        None => local(&args.runs)?,
    };
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &comparison).map_err(std::io::Error::from)?;
        writeln!(out)?;
        return Ok(());
    }
    Ok(table::write_comparison(&mut out, &comparison)?)
}

/// Documents, each reported with its own solver options.
fn local(paths: &[String]) -> Result<Comparison, CliError> {
    let mut reports: Vec<RunReport> = Vec::with_capacity(paths.len());
    let mut specs = Vec::with_capacity(paths.len());
    for path in paths {
        let path = PathBuf::from(path);
        let doc = read_document(&path)?;
        specs.push(doc.spec.clone());
        let job = document_job(&doc, &path)?;
        let solver = solver_options(&doc.spec.solver, None)?;
        let inputs = ReportInputs { reference: None, expected: None, weights: None };
        reports.push(build_report(&doc.moments, &job.config().cells, &solver, &inputs));
    }
    let runs: Vec<Compared<'_>> = reports
        .iter()
        .zip(paths)
        .map(|(r, label)| Compared { label, rows: &r.noise_table, fingerprint: &r.fingerprint, coverage: &r.coverage })
        .collect();
    let mut comparison = compare_runs(&runs);
    // What differs between the runs, named (issue 42: "other seeds or other configurations" left
    // the reader to find out which).
    for (spec, label) in specs.iter().zip(paths).skip(1) {
        let mut fields = configuration_differences(&specs[0], spec);
        for (name, a, b) in [("seed", spec.seed, specs[0].seed), ("iterations", spec.iterations, specs[0].iterations)] {
            if a != b {
                fields.push(format!("{name}: {a} vs {b}"));
            }
        }
        comparison.notes.push(if fields.is_empty() {
            format!("{label} has the configuration, seed and iterations of {}", paths[0])
        } else {
            format!("{label} differs from {} in {}", paths[0], fields.join(", "))
        });
    }
    Ok(comparison)
}

/// Jobs of a server, compared by the server.
#[cfg(feature = "server")]
fn remote(base: &str, ids: &[String]) -> Result<Comparison, CliError> {
    for id in ids {
        if !id.parse::<u64>().is_ok_and(|n| n > 0) {
            return Err(CliError::Config(format!("with --server, runs are job ids; got {id:?}")));
        }
    }
    let server = super::remote::Server::new(base, std::time::Duration::from_secs(120))?;
    let path = format!("/v1/compare?ids={}", ids.join(","));
    let value = super::remote::runtime()?.block_on(server.get_json(&path))?;
    serde_json::from_value(value).map_err(|e| CliError::Refused {
        url: server.url(&path),
        status: 200,
        detail: format!("not a comparison: {e}"),
    })
}
