//! A run's figures at each radius it tallied (`radii`): computed for `optimis run` and `optimis
//! report` (the expected luminances at each R′ by quadrature, about a second each), printed as one
//! table per radius of RMS and bias with their errors, and the plan to a target error that
//! `optimis budget --target-rmse` prints (`solve::budget::error`).

use std::io::{self, Write};

use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references::expected_luminances;
use crate::sim::model::config::SimConfig;
use crate::sim::solve::budget::error::{ErrorPlan, ErrorPoint};
use crate::sim::solve::options::SolverOptions;
use crate::sim::solve::radii::{BiasSource, RadiusReport};
use crate::sim::solve::radius_reports::radius_reports;
use crate::sim::solve::report::RunReport;
use crate::sim::stats::moments::Moments;

/// The reports at every radius of the run (its own alone without `radii`), the run's own report at
/// R reused when given (it was built with the same reference and expectations).
pub(super) fn reports(
    config: &SimConfig,
    moments: &Moments,
    solver: &SolverOptions,
    own: Option<&RunReport>,
) -> Vec<RadiusReport> {
    let reference = own.map_or_else(|| reference_luminance(config.scene()).ok(), |r| r.reference_luminance);
    radius_reports(config, moments, solver, reference, &|c| expected_luminances(c), own)
}

/// The reports when the run tallied radii (none otherwise: the report's own table is R's), from
/// the run's report at R.
pub(super) fn tallied(
    config: &SimConfig,
    moments: &Moments,
    solver: &SolverOptions,
    own: &RunReport,
) -> Vec<RadiusReport> {
    if config.radii().is_empty() { Vec::new() } else { reports(config, moments, solver, Some(own)) }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_string(), |x| format!("{x:.digits$}"))
}

/// One table per radius: RMS ± SE and bias ± error of every row.
pub(super) fn write_radii(out: &mut impl Write, radii: &[RadiusReport]) -> io::Result<()> {
    if radii.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "\nat each radius the run tallied (the merges within R′ of the same iterations: what a run at R′ gives); bias = E[C] at R′ − L (R → 0), % of L; q = quadrature (error its tolerance), mc = this run's L̂ − L (fitted rows)"
    )?;
    for r in radii {
        let m = r.merges_per_iteration;
        writeln!(
            out,
            "\nR′ = {}{}: merges per iteration {:.3} / {:.2} / {:.2}{}",
            r.merge_radius,
            if r.own { " (the run's own)" } else { "" },
            m[0],
            m[1],
            m[2],
            r.recommended.map_or_else(String::new, |s| format!("; recommended {s}"))
        )?;
        writeln!(out, "  {:<36} {:>9} {:>8} {:>10} {:>9}", "strategy", "RMS%", "± SE", "bias%", "± err")?;
        for row in &r.rows {
            let source = match row.bias_source {
                BiasSource::Quadrature => "q",
                BiasSource::MonteCarlo => "mc",
            };
            writeln!(
                out,
                "  {:<36} {:>9} {:>8} {:>10} {:>9} {source}",
                row.strategy.name(),
                opt(row.rms_percent, 2),
                opt(row.rms_percent_stderr, 2),
                opt(row.bias_percent, 4),
                row.bias_percent_stderr.map_or_else(|| "—".to_string(), |e| format!("{e:.1e}"))
            )?;
        }
    }
    Ok(())
}

fn point_words(p: &ErrorPoint) -> String {
    let se = p.seconds_to_target_stderr.map_or_else(String::new, |s| format!(" ± {s:.3e}"));
    format!(
        "{} at R′ = {}, (N_F, N_B) = ({}, {}): RMS {:.2}%/iteration, bias {:+.4}%, {:.3e} iterations of {:.3e} s = {:.3e}{se} s",
        p.strategy,
        p.merge_radius,
        p.budget.light_paths,
        p.budget.camera_paths,
        p.rms_percent,
        p.bias_percent,
        p.iterations,
        p.seconds_per_iteration,
        p.seconds_to_target
    )
}

/// The plan to a target error, in words and a table.
pub(super) fn write_error_plan(out: &mut impl Write, p: &ErrorPlan) -> io::Result<()> {
    let c = &p.costs;
    writeln!(
        out,
        "time to {}% RMSE about the true value (noise and bias) with P = {} pixels, t_F = {:.3e}, t_B = {:.3e}, t_0 = {:.3e}, t_M = {:.3e} s per merge and pixel; radii searched: {:?}\n",
        p.target_rmse_percent, c.pixels, c.light_path, c.camera_path, c.iteration, c.merge, p.radii
    )?;
    match &p.best {
        Some(b) => writeln!(out, "fastest: {}", point_words(b))?,
        None => writeln!(out, "fastest: none")?,
    }
    if let Some(b) = &p.at_own_radius {
        writeln!(out, "at the run's own R: {}", point_words(b))?;
    }
    if let Some(b) = &p.paper {
        writeln!(out, "the paper's setup: {}", point_words(b))?;
    }
    let speed = |x: Option<f64>, se: Option<f64>| match (x, se) {
        (Some(x), Some(se)) => format!("{x:.2} ± {se:.2}×"),
        (Some(x), None) => format!("{x:.2}×"),
        _ => "—".to_string(),
    };
    writeln!(
        out,
        "speed-up of the fastest: over the paper's setup {}, over the best at the run's own R {}",
        speed(p.speedup_over_paper, p.speedup_over_paper_stderr),
        speed(p.speedup_over_own_radius, p.speedup_over_own_radius_stderr)
    )?;
    if let Some(g) = &p.progressive {
        let se = g.seconds_to_target_stderr.map_or_else(String::new, |s| format!(" ± {s:.3e}"));
        match (g.iterations, g.seconds_to_target) {
            (Some(n), Some(t)) => writeln!(
                out,
                "progressive (R_i² ∝ i^(α−1), α = {:.3}, {} at ({}, {})): from R₁ = {} to {:.4}{}: {n:.3e} iterations, {t:.3e}{se} s",
                g.alpha,
                g.strategy,
                g.budget.light_paths,
                g.budget.camera_paths,
                g.first_radius,
                g.last_radius,
                if g.floored { " (held at the smallest radius tallied)" } else { "" }
            )?,
            _ => writeln!(out, "progressive: does not reach the target within 10^12 iterations")?,
        }
    }
    for o in &p.out_of_reach {
        writeln!(
            out,
            "out of reach: {} at R′ = {}: its bias {:+.3}% alone exceeds the target",
            o.strategy, o.merge_radius, o.bias_percent
        )?;
    }
    for n in &p.notes {
        writeln!(out, "note: {n}")?;
    }
    writeln!(
        out,
        "\n{:<30} {:>7} {:>11} {:>7} {:>8} {:>9} {:>11} {:>11}",
        "strategy", "R′", "N_F", "N_B", "RMS%", "bias%", "seconds", "± SE"
    )?;
    for x in &p.candidates {
        writeln!(
            out,
            "{:<30} {:>7} {:>11} {:>7} {:>8.2} {:>9.4} {:>11.3e} {:>11}{}",
            x.strategy.name(),
            x.merge_radius,
            x.budget.light_paths,
            x.budget.camera_paths,
            x.rms_percent,
            x.bias_percent,
            x.seconds_to_target,
            x.seconds_to_target_stderr.map_or_else(|| "—".to_string(), |s| format!("{s:.3e}")),
            match (x.respects_fixed, x.supported) {
                (false, _) => " (does not keep the fixed weights)",
                (true, false) => " (not supported by this run)",
                _ => "",
            }
        )?;
    }
    Ok(())
}
