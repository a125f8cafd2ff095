//! A run's [`RadiusReport`]s: the report of the moments at each radius it tallied and at its own,
//! each row's bias from the quadrature (per-path rows) or the run's own estimate (fitted rows).

use super::expectation::ExpectedLuminance;
use super::noise::merge_rates;
use super::options::SolverOptions;
use super::radii::{BiasSource, QUADRATURE_RELATIVE_ERROR, RadiusReport, RadiusRow};
use super::report::{ReportInputs, RunReport, build_report};
use crate::sim::model::config::SimConfig;
use crate::sim::stats::moments::Moments;

/// The figures at each radius the run tallied and at its own, ascending by radius (its own alone
/// without `radii`). `expected(config)` gives each per-path strategy's expected luminance at
/// `config`'s radius (the server caches it by fingerprint), `reference` the R → 0 value L; `own`
/// the run's report at R with these inputs when the caller has it (it is not built twice).
pub fn radius_reports(
    config: &SimConfig,
    moments: &Moments,
    solver: &SolverOptions,
    reference: Option<f64>,
    expected: &dyn Fn(&SimConfig) -> Vec<ExpectedLuminance>,
    own: Option<&RunReport>,
) -> Vec<RadiusReport> {
    let report_at = |config: &SimConfig, moments: &Moments| {
        let expected = expected(config);
        build_report(
            moments,
            config.cells(),
            solver,
            &ReportInputs { reference, expected: Some(&expected), weights: None },
        )
    };
    let mut out: Vec<RadiusReport> = config
        .radii()
        .iter()
        .zip(&moments.radii)
        .map(|(sub, m)| radius_report(&report_at(sub, m), sub, m, reference, false))
        .collect();
    let built;
    let own_report = match own {
        Some(report) => report,
        None => {
            built = report_at(config, moments);
            &built
        }
    };
    out.push(radius_report(own_report, config, moments, reference, true));
    out
}

/// One radius's figures from its report.
fn radius_report(
    report: &RunReport,
    config: &SimConfig,
    moments: &Moments,
    reference: Option<f64>,
    own: bool,
) -> RadiusReport {
    let rows = report
        .noise_table
        .iter()
        .filter(|r| !r.in_sample)
        .map(|r| {
            let (bias, bias_se, source) = match (reference, r.expected_luminance, r.strategy.path()) {
                (Some(l), Some(e), Some(_)) => {
                    (Some(100.0 * (e - l) / l), Some(100.0 * QUADRATURE_RELATIVE_ERROR), BiasSource::Quadrature)
                }
                (Some(l), _, None) => (
                    r.luminance.map(|x| 100.0 * (x - l) / l),
                    r.luminance_stderr.map(|se| 100.0 * se / l),
                    BiasSource::MonteCarlo,
                ),
                _ => (None, None, BiasSource::Quadrature),
            };
            RadiusRow {
                strategy: r.strategy,
                luminance: r.luminance,
                luminance_stderr: r.luminance_stderr,
                rms_percent: r.rms_percent,
                rms_percent_stderr: r.rms_percent_stderr,
                bias_percent: bias,
                bias_percent_stderr: bias_se,
                bias_source: source,
                respects_fixed: r.respects_fixed,
            }
        })
        .collect();
    RadiusReport {
        merge_radius: config.merge_radius(),
        own,
        merges_per_iteration: merge_rates(moments).map(|r| r.mean),
        recommended: report.recommended.as_ref().map(|r| r.strategy),
        rows,
    }
}
