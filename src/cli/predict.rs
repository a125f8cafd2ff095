//! `optimis predict`: the noise table and re-fitted weights of a moments document at another ray
//! budget (`solve::predict`).

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use crate::sim::model::params::parse_count;

use super::documents::{document_job, read_document, solver_options};
use super::{CliError, table};
use crate::sim::model::params::check_path_counts;
use crate::sim::solve::predict::{Budget, predict as predict_budget};

#[derive(Debug, Args)]
pub struct PredictArgs {
    /// A moments document of a job run with `"noise_components": true`.
    pub document: PathBuf,
    /// N_F to predict for (default: the run's).
    #[arg(long, value_name = "N", value_parser = parse_count, allow_hyphen_values = true)]
    pub light_paths: Option<u64>,
    /// N_B to predict for (default: the run's).
    #[arg(long, value_name = "M", value_parser = parse_count, allow_hyphen_values = true)]
    pub camera_paths: Option<u64>,
    /// Print the prediction as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Solver options to change, as JSON (as for `optimis report`).
    #[arg(long, value_name = "JSON")]
    pub solver: Option<String>,
}

pub fn predict(args: PredictArgs) -> Result<(), CliError> {
    let doc = read_document(&args.document)?;
    let job = document_job(&doc, &args.document)?;
    let solver = solver_options(&doc.spec.solver, args.solver.as_deref())?;
    let measured = Budget { light_paths: doc.spec.light_paths, camera_paths: doc.spec.camera_paths };
    let to = Budget {
        light_paths: args.light_paths.unwrap_or(measured.light_paths),
        camera_paths: args.camera_paths.unwrap_or(measured.camera_paths),
    };
    check_path_counts(to.light_paths, to.camera_paths, ["--light-paths", "--camera-paths"])?;
    let prediction = predict_budget(&doc.moments, &job.config().cells, &solver, measured, to)
        .map_err(|e| CliError::Unusable { path: args.document.clone(), detail: e.to_string() })?;
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &prediction).map_err(std::io::Error::from)?;
        writeln!(out)?;
        return Ok(());
    }
    writeln!(
        out,
        "predicted for N_F = {} light paths × N_B = {} camera paths from {} iterations at N_F = {} × N_B = {} (noise components; L ± SE for as many iterations at the new budget)\n",
        to.light_paths, to.camera_paths, prediction.iterations, measured.light_paths, measured.camera_paths
    )?;
    table::write_noise_rows(&mut out, &prediction.noise_table, prediction.folds, prediction.recommended.as_ref())?;
    writeln!(out)?;
    if !prediction.unsupported.is_empty() {
        let names: Vec<String> = prediction.unsupported.iter().map(|s| s.to_string()).collect();
        writeln!(
            out,
            "warning [unsupported]: this run does not support the predictions of {} at this budget (RMS SE above {:.0}% of the RMS): shown, not recommended; a longer run narrows them",
            names.join(", "),
            prediction.support_relative_se * 100.0
        )?;
    }
    match (&prediction.recommended, &prediction.solve_error) {
        (Some(r), _) => {
            writeln!(out, "recommended at this budget: {} — {}", r.strategy, r.reason)?;
            if let Some(lambda) = r.lambda {
                table::write_heuristics(&mut out, &r.heuristics)?;
                writeln!(
                    out,
                    "its weights re-fitted for this budget (λ = {lambda} chosen by cross-validation; ± jackknife SE over the folds):",
                )?;
                table::write_weights(&mut out, &prediction.weights)?;
            }
        }
        (None, Some(e)) => writeln!(out, "optimal weights: not available: {e}")?,
        (None, None) => {}
    }
    Ok(())
}
