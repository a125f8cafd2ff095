//! A run's [`RadiusReport`]s: the report of the moments at each radius it tallied and at its own,
//! each row's bias from the quadrature (per-path rows) or the run's own estimate (fitted rows).

use super::expectation::ExpectedLuminance;
use super::noise::merge_rates;
use super::options::SolverOptions;
use super::radii::{BiasSource, QUADRATURE_RELATIVE_ERROR, RadiusReport, RadiusRow};
use super::report::{ReportInputs, build_report};
use crate::sim::model::config::SimConfig;
use crate::sim::stats::moments::Moments;

/// The figures at each radius the run tallied and at its own, ascending by radius (its own alone
/// without `radii`). `expected(config)` gives each per-path strategy's expected luminance at
/// `config`'s radius (the server caches it by fingerprint), `reference` the R → 0 value L.
pub fn radius_reports(
    config: &SimConfig,
    moments: &Moments,
    solver: &SolverOptions,
    reference: Option<f64>,
    expected: &dyn Fn(&SimConfig) -> Vec<ExpectedLuminance>,
) -> Vec<RadiusReport> {
    let mut out: Vec<RadiusReport> = config
        .radii()
        .iter()
        .zip(&moments.radii)
        .map(|(sub, m)| radius_report(sub, m, solver, reference, &expected(sub), false))
        .collect();
    out.push(radius_report(config, moments, solver, reference, &expected(config), true));
    out
}

fn radius_report(
    config: &SimConfig,
    moments: &Moments,
    solver: &SolverOptions,
    reference: Option<f64>,
    expected: &[ExpectedLuminance],
    own: bool,
) -> RadiusReport {
    let inputs = ReportInputs { reference, expected: Some(expected), weights: None };
    let report = build_report(moments, config.cells(), solver, &inputs);
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
        recommended: report.recommended.map(|r| r.strategy),
        rows,
    }
}
