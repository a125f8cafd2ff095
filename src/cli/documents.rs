//! `optimis merge` and `optimis report`: moments documents on the command line.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;
use serde_json::Value;

use super::run::{write_atomically, write_csv};
use super::{CliError, table};
use crate::sim::checks::published::{applicable, figures};
use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::document::{MomentsDocument, merge_documents_at};
use crate::sim::model::params::check;
use crate::sim::solve::crossfit::{CrossFitting, nested_selection};
use crate::sim::solve::noise::NoiseRow;
use crate::sim::solve::options::MAX_LAMBDA;
use crate::sim::solve::options::SolverOptions;
use crate::sim::solve::report::{ReportInputs, WeightsQuery, build_report};
use crate::sim::solve::strategy::Strategy;
use crate::sim::solve::tables::{TextTable, noise_table_latex, noise_table_markdown, parse_rows};
use crate::sim::spec::{SpecError, ValidJob};

#[derive(Debug, Args)]
pub struct MergeArgs {
    /// Moments documents (from `optimis run --out` or `GET /v1/jobs/{id}/moments`).
    #[arg(required = true)]
    pub documents: Vec<PathBuf>,
    /// Where to write the merged document.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Accept only documents signed by this Ed25519 public key (PEM); repeatable, as the server's
    /// `--trust`.
    #[cfg(feature = "server")]
    #[arg(long, value_name = "FILE")]
    pub trust: Vec<PathBuf>,
    /// Sign the merged document with this Ed25519 private key (PKCS#8 PEM), as the server's
    /// `--signing-key`.
    #[cfg(feature = "server")]
    #[arg(long, value_name = "FILE")]
    pub signing_key: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// A moments document.
    pub document: PathBuf,
    /// Print the result document as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Show the paper's published figures (Table 1) beside the noise table when the run's
    /// configuration is the paper's; otherwise say in which fields it differs.
    #[arg(long, conflicts_with = "json")]
    pub paper: bool,
    /// Print the noise table only, as `markdown` or `latex` (a `table` float with a caption, the
    /// paper's columns and z where its Table 1 applies, the recommended row marked), instead of the tables.
    #[arg(long, value_parser = ["markdown", "latex"], conflicts_with_all = ["json", "paper"])]
    pub format: Option<String>,
    /// With --format: the rows to show, in this order (e.g. `switch,optimal_cv`; default: every row).
    #[arg(long, value_name = "STRATEGIES", requires = "format")]
    pub rows: Option<String>,
    /// With --format: the table's caption (default: one that says the units and the marks).
    #[arg(long, value_name = "TEXT", requires = "format")]
    pub caption: Option<String>,
    /// With --format latex: the bare `tabular`, without the `table` float and its caption.
    #[arg(long, requires = "format")]
    pub bare: bool,
    /// Solver options to change, as JSON (e.g. '{"lambda": 0.1}' or '{"fixed": {"w0": null}}').
    #[arg(long, value_name = "JSON")]
    pub solver: Option<String>,
    /// Show the weights fitted in-sample on all iterations at this λ (e.g. 0, the paper's
    /// procedure) instead of the recommended weights.
    #[arg(long, value_name = "LAMBDA")]
    pub weights_lambda: Option<f64>,
    /// With --weights-lambda: the fitted row whose weights to show (`optimal`, the table alone, by
    /// default; `optimal_stacked` or a `…_corrected` row for a table with heuristics stacked on it).
    #[arg(long, value_name = "STRATEGY", requires = "weights_lambda", value_parser = parse_strategy)]
    pub weights_of: Option<Strategy>,
    /// Also measure how optimistic the cross-validated choice of λ is, by nested cross-validation
    /// (K λ searches: slower than the report itself).
    #[arg(long)]
    pub nested_cv: bool,
    /// Write the noise table as CSV (one row per strategy).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write the weights table as CSV (one row per cell; for a per-path recommendation, which has
    /// no table, its effective weights per (r2, r3) bin).
    #[arg(long, value_name = "FILE")]
    pub weights_csv: Option<PathBuf>,
}

/// A strategy by its result name (`optimal_stacked`).
pub(super) fn parse_strategy(name: &str) -> Result<Strategy, String> {
    serde_json::from_value(Value::String(name.to_string())).map_err(|_| format!("no strategy named {name:?}"))
}

/// Reads and verifies a moments document.
pub(super) fn read_document(path: &PathBuf) -> Result<MomentsDocument, CliError> {
    let bytes = std::fs::read(path).map_err(|source| CliError::Read { path: path.clone(), source })?;
    MomentsDocument::from_json(&bytes).map_err(|source| CliError::Document { path: path.clone(), source })
}

/// The job of a moments document read from `path`, validated again (a document written by an
/// older version may carry a specification this one refuses): an error names the file.
pub(super) fn document_job(doc: &MomentsDocument, path: &std::path::Path) -> Result<ValidJob, CliError> {
    doc.spec.validate().map_err(|e| CliError::Unusable {
        path: path.to_path_buf(),
        detail: format!("the document's job specification is not valid: {e}"),
    })
}

pub fn merge(args: MergeArgs) -> Result<(), CliError> {
    let documents = args.documents.iter().map(read_document).collect::<Result<Vec<_>, _>>()?;
    #[cfg(feature = "server")]
    let (provenance, signers) = {
        use crate::trust::signing::Provenance;
        let provenance =
            Provenance::load(args.signing_key.as_deref(), &args.trust).map_err(|e| CliError::Config(e.to_string()))?;
        let mut signers = Vec::with_capacity(documents.len());
        for (doc, path) in documents.iter().zip(&args.documents) {
            signers.push(provenance.vouch(doc, "").map_err(|e| CliError::Config(format!("{}: {e}", path.display())))?);
        }
        (provenance, signers)
    };
    // The error names the input at fault (the first that conflicts with those before it).
    let merged = merge_documents_at(&documents)
        .map_err(|(i, source)| CliError::Document { path: args.documents[i].clone(), source })?;
    #[cfg(feature = "server")]
    let merged = {
        use crate::sim::document::{Attestation, AttestationBasis};
        // Signed as `merged` if a trusted key (or this one) signed every input; otherwise the
        // key's holder vouches for files it could not check, and the signature says so.
        let basis =
            if signers.iter().all(Option::is_some) { AttestationBasis::Merged } else { AttestationBasis::Asserted };
        let mut keys: Vec<String> = signers.into_iter().flatten().collect();
        keys.sort_unstable();
        keys.dedup();
        if provenance.key.is_some() && basis == AttestationBasis::Asserted {
            eprintln!("note: not every input carries a trusted signature; the output's signature says \"asserted\"");
        }
        provenance.sign(merged, Attestation { basis, keys })
    };
    write_atomically(&args.out, &merged.to_json())?;
    eprintln!(
        "merged {} documents: {} iterations → {}",
        documents.len(),
        merged.moments.iterations(),
        args.out.display()
    );
    Ok(())
}

/// A λ given as a flag (`flag`), checked against the solver's range.
pub(super) fn lambda_flag(flag: &str, lambda: Option<f64>) -> Result<(), CliError> {
    match lambda {
        Some(l) => Ok(check(l.is_finite() && (0.0..=MAX_LAMBDA).contains(&l), flag, || {
            format!("must be in [0, {MAX_LAMBDA:e}], got {l}")
        })?),
        None => Ok(()),
    }
}

/// The document's solver options changed by `--solver` (see [`SolverOptions::patched`]).
pub(super) fn solver_options(base: &SolverOptions, patch: Option<&str>) -> Result<SolverOptions, CliError> {
    let Some(text) = patch else { return Ok(base.clone()) };
    let patch: Value = serde_json::from_str(text).map_err(|e| SpecError::new("--solver", format!("not JSON: {e}")))?;
    Ok(base.patched(&patch)?)
}

pub fn report(args: ReportArgs) -> Result<(), CliError> {
    let doc = read_document(&args.document)?;
    let job = document_job(&doc, &args.document)?;
    let solver = solver_options(&doc.spec.solver, args.solver.as_deref())?;
    let reference = reference_luminance(&job.config().scene).ok();
    lambda_flag("--weights-lambda", args.weights_lambda)?;
    let expected = expected_luminances(job.config());
    let strategy = args.weights_of.unwrap_or(Strategy::Optimal);
    let weights = args.weights_lambda.map(|lambda| WeightsQuery { lambda, strategy });
    let inputs = ReportInputs { reference, expected: Some(&expected), weights };
    let mut report = build_report(&doc.moments, &job.config().cells, &solver, &inputs);
    report.radii = super::radii::tallied(job.config(), &doc.moments, &solver, &report);
    let mut spec = doc.spec.clone();
    spec.solver = solver.clone();
    write_csv(&spec, job.config(), &report, args.csv.as_deref(), args.weights_csv.as_deref())?;
    let mut out = std::io::stdout().lock();
    if args.nested_cv {
        let cf = CrossFitting::new(&doc.moments, &doc.moments.pooled());
        let [m, s1, s2] = nested_selection(&cf, &job.config().cells, &solver.fixed, &solver.cv_lambdas, &[])
            .map_err(|e| SpecError::new("--nested-cv", e))?;
        let nested = NoiseRow::from_sums(Strategy::OptimalCv, m, s1, s2, None);
        let selected = report.noise_table.iter().find(|r| r.strategy == Strategy::OptimalCv);
        eprintln!(
            "nested cross-validation of optimal_cv (λ chosen inside each outer fold): L·10⁵ = {:.4} ± {:.4}, RMS {:.2}%; optimal_cv's cross-fitted RMS at the λ chosen on all folds: {:.2}%",
            nested.luminance.unwrap_or(f64::NAN) * 1e5,
            nested.luminance_stderr.unwrap_or(f64::NAN) * 1e5,
            nested.rms_percent.unwrap_or(f64::NAN),
            selected.and_then(|r| r.rms_percent).unwrap_or(f64::NAN)
        );
    }
    if let Some(format) = &args.format {
        let published = applicable(&spec);
        let paper = |s: &Strategy| figures(&published, s.name());
        let table = &report.noise_table;
        let rows = match args.rows.as_deref() {
            Some(list) => Some(parse_rows(list, table).map_err(|e| SpecError::new("--rows", e.to_string()))?),
            None => None,
        };
        let opts = TextTable {
            rows,
            recommended: report.recommended.as_ref().map(|r| r.strategy),
            caption: args.caption.clone(),
            bare: args.bare,
        };
        let text = if format == "latex" {
            noise_table_latex(table, paper, &opts)
        } else {
            noise_table_markdown(table, paper, &opts)
        };
        out.write_all(text.as_bytes())?;
    } else if args.json {
        serde_json::to_writer_pretty(&mut out, &report).map_err(std::io::Error::from)?;
        writeln!(out)?;
    } else {
        table::write_report(&mut out, &spec, &report, None, args.paper)?;
        super::radii::write_radii(&mut out, &report.radii)?;
    }
    Ok(())
}
