//! `optimis budget`: the ray budget that reaches a target RMS soonest, per strategy, from a moments
//! document with noise components (`solve::budget`), with per-path costs measured here on the brute
//! force unless given.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::bench::time_iterations;
use super::documents::{document_job, read_document, solver_options};
use super::{CliError, thread_pool};
use crate::sim::model::config::Engine;
use crate::sim::model::params::check;
use crate::sim::solve::budget::{BestBudget, Costs, SUPPORT_RELATIVE_SE, plan};
use crate::sim::solve::predict::Budget;
use crate::sim::spec::JobSpec;

#[derive(Debug, Args)]
pub struct BudgetArgs {
    /// A moments document of a job run with `"noise_components": true`.
    pub document: PathBuf,
    /// The RMS to reach, in percent.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    pub target_rms: f64,
    /// Pixels P of the image the light paths serve.
    #[arg(long, default_value_t = 1e6, allow_hyphen_values = true)]
    pub pixels: f64,
    /// Seconds per light path (default: measured on the brute force here).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub light_cost: Option<f64>,
    /// Seconds per camera path and pixel (default: measured on the brute force here).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub camera_cost: Option<f64>,
    /// Seconds per iteration besides the paths (default: measured on the brute force here).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
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
        let config = s.validate()?.config().with_engine(Engine::Brute);
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
    let job = document_job(&doc, &args.document)?;
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
    let p = plan(&doc.moments, &job.config().cells, &solver, measured, costs, args.target_rms)
        .map_err(|e| CliError::Unusable { path: args.document.clone(), detail: e.to_string() })?;
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
    let s = &p.search;
    writeln!(
        out,
        "(predicted from {} iterations at N_F = {}, N_B = {}; searched N_F {}–{}, N_B {}–{} in half-decade steps{}; * = at the edge of that range, the optimum may lie beyond; † = no budget of that strategy is supported by this run: its RMS SE is above {:.0}% of the RMS)\n",
        doc.moments.iterations(),
        measured.light_paths,
        measured.camera_paths,
        s.light_paths[0],
        s.light_paths[1],
        s.camera_paths[0],
        s.camera_paths[1],
        if s.at_limit { ", widened to the limit of what this run can predict" } else { "" },
        SUPPORT_RELATIVE_SE * 100.0
    )?;
    if let Some(h) = p.headline.and_then(|h| p.best.iter().find(|b| b.point.strategy == h)) {
        let speed = match (h.speedup, h.speedup_stderr) {
            (Some(x), Some(se)) => format!("{x:.1} ± {se:.1}× sooner than the paper's switch at (10⁷, 100)"),
            (Some(x), None) => format!("{x:.1}× sooner than the paper's switch at (10⁷, 100)"),
            _ => String::new(),
        };
        let edge = if h.at_edge {
            " (at the edge of what this run can predict: larger budgets may be faster still)"
        } else {
            ""
        };
        writeln!(
            out,
            "{} (recommended) at (N_F, N_B) = ({}, {}) reaches {}% {speed}{edge}",
            h.point.strategy, h.point.budget.light_paths, h.point.budget.camera_paths, args.target_rms
        )?;
        if let Some(warning) = support_warning(h) {
            writeln!(out, "warning: {warning}")?;
        }
    }
    if let Some(note) = &p.headline_note {
        writeln!(out, "note: {note}")?;
    }
    writeln!(out)?;
    writeln!(
        out,
        "{:<28} {:>12} {:>8} {:>14} {:>12} {:>14} {:>14}",
        "strategy", "N_F", "N_B", "RMS % / it", "s / it", "s to target", "speed-up"
    )?;
    for b in &p.best {
        let pt = &b.point;
        let mut label = pt.strategy.to_string();
        if b.at_edge {
            label.push('*');
        }
        if !b.supported {
            label.push('†');
        }
        let se = pt.rms_percent_stderr.map_or_else(String::new, |s| format!(" ± {s:.1}"));
        let speed = match (b.speedup, b.speedup_stderr) {
            (Some(x), Some(e)) => format!("{x:.2} ± {e:.2}"),
            (Some(x), None) => format!("{x:.2}"),
            _ => "—".to_string(),
        };
        let outside = if pt.respects_fixed { "" } else { "  outside the fixed weights (not ranked)" };
        writeln!(
            out,
            "{label:<28} {:>12} {:>8} {:>14} {:>12.4} {:>14.1} {speed:>14}{outside}",
            pt.budget.light_paths,
            pt.budget.camera_paths,
            format!("{:.1}{se}", pt.rms_percent),
            pt.seconds_per_iteration,
            pt.seconds_to_target
        )?;
    }
    if let Some(paper) = &p.paper {
        writeln!(
            out,
            "{:<28} {:>12} {:>8} {:>14.1} {:>12.4} {:>14.1}",
            "switch (paper)",
            paper.budget.light_paths,
            paper.budget.camera_paths,
            paper.rms_percent,
            paper.seconds_per_iteration,
            paper.seconds_to_target
        )?;
    }
    if let Some(f) = &p.fixed_time {
        writeln!(
            out,
            "\nRMS % after T = {:.3e} s (the paper's switch at (10⁷, 100) to {}%), per ratio N_F/N_B at its best budget on the grid (‡ = not one iteration fits in T: extrapolated)\n",
            f.seconds, args.target_rms
        )?;
        writeln!(out, "{:<28} {:>9} {:>20} {:>12}", "strategy", "N_F/N_B", "best (N_F, N_B)", "RMS % at T")?;
        for c in &f.curve {
            let at = format!("({}, {})", c.budget.light_paths, c.budget.camera_paths);
            let flag = if c.iterations < 1.0 { "‡" } else { "" };
            writeln!(out, "{:<28} {:>9.1e} {at:>20} {:>12.2}{flag}", c.strategy, c.ratio, c.rms_percent)?;
        }
    }
    Ok(())
}

/// What the headline's figures cannot tell, when the run's noise left budgets unsupported.
fn support_warning(b: &BestBudget) -> Option<String> {
    let limit = SUPPORT_RELATIVE_SE * 100.0;
    if !b.supported {
        Some(format!(
            "no budget of {} is supported by this run (every predicted RMS has an SE above {limit:.0}% of itself): the figures above are noise more than prediction; run longer before planning",
            b.point.strategy
        ))
    } else if b.faster_unsupported {
        Some(format!(
            "budgets predicted to be faster for {} have an RMS SE above {limit:.0}% of the RMS, which this run cannot support: they are left aside (a longer run, or one nearer them, can resolve them)",
            b.point.strategy
        ))
    } else {
        None
    }
}
