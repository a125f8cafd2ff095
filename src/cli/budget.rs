//! `optimis budget`: the ray budget that reaches a target RMS soonest, per strategy, from a moments
//! document with noise components (`solve::budget`), with per-path costs measured here on the brute
//! force unless given.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::bench::time_iterations;
use super::documents::{read_document, solver_options};
use super::{CliError, thread_pool};
use crate::sim::model::config::Engine;
use crate::sim::model::params::check;
use crate::sim::solve::budget::{Costs, PAPER_BUDGET, log_grid, plan};
use crate::sim::solve::predict::Budget;
use crate::sim::spec::{JobSpec, SpecError};

#[derive(Debug, Args)]
pub struct BudgetArgs {
    /// A moments document of a job run with `"noise_components": true`.
    pub document: PathBuf,
    /// The RMS to reach, in percent.
    #[arg(long, default_value_t = 1.0)]
    pub target_rms: f64,
    /// Pixels P of the image the light paths serve.
    #[arg(long, default_value_t = 1e6)]
    pub pixels: f64,
    /// Seconds per light path (default: measured on the brute force here).
    #[arg(long, value_name = "S")]
    pub light_cost: Option<f64>,
    /// Seconds per camera path and pixel (default: measured on the brute force here).
    #[arg(long, value_name = "S")]
    pub camera_cost: Option<f64>,
    /// Seconds per iteration besides the paths (default: measured on the brute force here).
    #[arg(long, value_name = "S")]
    pub iteration_cost: Option<f64>,
    /// Print the plan (every point evaluated) as JSON.
    #[arg(long)]
    pub json: bool,
}

/// t(N_F, N_B) = t_F·N_F + t_B·N_B + t_0 of the brute force, from three timed configurations.
fn measure_costs(spec: &JobSpec) -> Result<[f64; 3], CliError> {
    let pool = thread_pool(None)?;
    let time = |light: u64, camera: u64| -> Result<f64, CliError> {
        let mut s = spec.clone();
        s.light_paths = light;
        s.camera_paths = camera;
        s.noise_components = false;
        let config = s.validate()?.config.with_engine(Engine::Brute);
        let iterations = 20;
        Ok(pool.install(|| time_iterations(&config, iterations)) / iterations as f64)
    };
    let base = time(1_000_000, 100)?;
    let light = time(2_000_000, 100)?;
    let camera = time(1_000_000, 1000)?;
    let t_f = ((light - base) / 1e6).max(0.0);
    let t_b = ((camera - base) / 900.0).max(0.0);
    let t_0 = (base - t_f * 1e6 - t_b * 100.0).max(0.0);
    Ok([t_f, t_b, t_0])
}

pub fn budget(args: BudgetArgs) -> Result<(), CliError> {
    let doc = read_document(&args.document)?;
    let job = doc.spec.validate()?;
    check(args.target_rms.is_finite() && args.target_rms > 0.0, "--target-rms", || {
        format!("must be a positive percentage, got {}", args.target_rms)
    })?;
    check(args.pixels.is_finite() && args.pixels >= 1.0, "--pixels", || format!("must be ≥ 1, got {}", args.pixels))?;
    let solver = solver_options(&doc.spec.solver, None)?;
    let given = [args.light_cost, args.camera_cost, args.iteration_cost];
    let [t_f, t_b, t_0] = match given {
        [Some(a), Some(b), Some(c)] => [a, b, c],
        _ => {
            eprintln!("measuring the brute force's per-path costs (3 × 20 iterations)…");
            let m = measure_costs(&doc.spec)?;
            [given[0].unwrap_or(m[0]), given[1].unwrap_or(m[1]), given[2].unwrap_or(m[2])]
        }
    };
    for (name, v) in [("--light-cost", t_f), ("--camera-cost", t_b), ("--iteration-cost", t_0)] {
        check(v.is_finite() && v >= 0.0, name, || format!("must be ≥ 0 seconds, got {v}"))?;
    }
    let costs = Costs { light_path: t_f, camera_path: t_b, iteration: t_0, pixels: args.pixels };
    let measured = Budget { light_paths: doc.spec.light_paths, camera_paths: doc.spec.camera_paths };
    // Within a decade of the measured budget on each axis: the range over which predictions were
    // checked against direct runs (docs/results.md §7); beyond it the components' estimation noise
    // is amplified (a slightly negative estimate of a component can make a far budget look free).
    let (f, b) = (measured.light_paths, measured.camera_paths);
    let light = log_grid((f / 10).max(1), f.saturating_mul(10), 2);
    let camera = log_grid((b / 10).max(1), b.saturating_mul(10).min(1_000_000), 2);
    let p = plan(&doc.moments, &job.config.cells, &solver, measured, costs, args.target_rms, &light, &camera)
        .map_err(|e| SpecError::new("document", e.to_string()))?;
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &p).map_err(std::io::Error::from)?;
        writeln!(out)?;
        return Ok(());
    }
    writeln!(
        out,
        "time to {}% RMS with P = {} pixels, t_F = {:.3e} s per light path, t_B = {:.3e} s per camera path and pixel, t_0 = {:.3e} s per iteration",
        args.target_rms, args.pixels, t_f, t_b, t_0
    )?;
    writeln!(
        out,
        "(predicted from {} iterations at N_F = {}, N_B = {}; grid N_F {}–{}, N_B {}–{}, half-decade steps; * = at the grid's edge, the optimum may lie beyond)\n",
        doc.moments.iterations(),
        measured.light_paths,
        measured.camera_paths,
        light[0],
        light[light.len() - 1],
        camera[0],
        camera[camera.len() - 1]
    )?;
    writeln!(
        out,
        "{:<18} {:>12} {:>8} {:>12} {:>12} {:>14}",
        "strategy", "N_F", "N_B", "RMS % / it", "s / it", "s to target"
    )?;
    for b in p.best.iter().chain(&p.paper) {
        let edge = |v: u64, axis: &[u64]| v == axis[0] || v == axis[axis.len() - 1];
        let label = if p.paper.as_ref() == Some(b) && b.budget == PAPER_BUDGET {
            format!("{} (paper)", b.strategy)
        } else if edge(b.budget.light_paths, &light) || edge(b.budget.camera_paths, &camera) {
            format!("{}*", b.strategy)
        } else {
            b.strategy.to_string()
        };
        writeln!(
            out,
            "{label:<18} {:>12} {:>8} {:>12.1} {:>12.4} {:>14.1}",
            b.budget.light_paths, b.budget.camera_paths, b.rms_percent, b.seconds_per_iteration, b.seconds_to_target
        )?;
    }
    if let (Some(first), Some(paper)) = (p.best.first(), &p.paper) {
        writeln!(
            out,
            "\n{} at (N_F, N_B) = ({}, {}) reaches {}% {:.1}× sooner than the paper's switch at (10⁷, 100)",
            first.strategy,
            first.budget.light_paths,
            first.budget.camera_paths,
            args.target_rms,
            paper.seconds_to_target / first.seconds_to_target
        )?;
    }
    if let Some(f) = &p.fixed_time {
        writeln!(
            out,
            "\nRMS % after T = {:.3e} s (the paper's switch at (10⁷, 100) to {}%), per ratio N_F/N_B at its best budget on the grid (‡ = not one iteration fits in T: extrapolated)\n",
            f.seconds, args.target_rms
        )?;
        writeln!(out, "{:<18} {:>9} {:>20} {:>12}", "strategy", "N_F/N_B", "best (N_F, N_B)", "RMS % at T")?;
        for c in &f.curve {
            let at = format!("({}, {})", c.budget.light_paths, c.budget.camera_paths);
            let flag = if c.iterations < 1.0 { "‡" } else { "" };
            writeln!(out, "{:<18} {:>9.1e} {at:>20} {:>12.2}{flag}", c.strategy, c.ratio, c.rms_percent)?;
        }
    }
    Ok(())
}
