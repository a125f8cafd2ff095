//! `optimis budget`: the ray budget that reaches a target RMS soonest, per strategy, from a moments
//! document with noise components (`solve::budget`). A cost not given is the reference's
//! (`Costs::REFERENCE`), as in the API and the dashboard, so one document and one set of costs give
//! one plan everywhere; `--measure-costs` times the brute force on this machine instead.

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::bench::time_iterations;
use super::documents::{document_job, read_document, solver_options};
use super::{CliError, thread_pool};
use crate::sim::model::config::Engine;
use crate::sim::model::params::check;
use crate::sim::solve::budget::error::error_plan_of;
use crate::sim::solve::budget::{BestBudget, BudgetPlan, CostSource, Costs, SUPPORT_RELATIVE_SE, plan};
use crate::sim::solve::predict::Budget;
use crate::sim::spec::JobSpec;

#[derive(Debug, Args)]
pub struct BudgetArgs {
    /// A moments document of a job run with `"noise_components": true`.
    pub document: PathBuf,
    /// The RMS to reach, in percent.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    pub target_rms: f64,
    /// Pixels P of the image the light paths serve (default 10^6).
    #[arg(long, allow_hyphen_values = true)]
    pub pixels: Option<f64>,
    /// Seconds per light path of your renderer (default: the reference's, 7.3e-9, as in the API).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub light_cost: Option<f64>,
    /// Seconds per camera path and pixel (default: the reference's, 4.1e-6, as in the API).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub camera_cost: Option<f64>,
    /// Seconds per iteration besides the paths (default: the reference's, 1.9e-4, as in the API).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub iteration_cost: Option<f64>,
    /// Time this crate's brute force on this machine (3 × 20 iterations) for the costs not given,
    /// instead of taking the reference's: the plan then depends on the machine and the moment.
    #[arg(long)]
    pub measure_costs: bool,
    /// Plan to a target RMSE about the true pixel value instead — noise and the merge radius's
    /// bias together — over the run's own R and every radius it tallied (`radii`): the fastest
    /// (N_F, N_B, R′, strategy), beside the best at the run's R, the paper's setup and a
    /// progressive schedule (docs/model.md §13). In percent.
    #[arg(long, value_name = "P", allow_hyphen_values = true)]
    pub target_rmse: Option<f64>,
    /// With --target-rmse: seconds per merge event and pixel (default: the reference's, 8e-8).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub merge_cost: Option<f64>,
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
    let solver = solver_options(&doc.spec.solver, None)?;
    let base = if args.measure_costs {
        eprintln!("measuring the brute force's per-path costs on this machine (3 × 20 iterations)…");
        let [light_path, camera_path, iteration] = measure_costs(&doc.spec)?;
        Costs { light_path, camera_path, iteration, source: CostSource::Measured, ..Costs::REFERENCE }
    } else {
        Costs::REFERENCE
    };
    let costs = base
        .with_given(args.light_cost, args.camera_cost, args.iteration_cost, args.pixels)
        .with_merge(args.merge_cost);
    check(costs.pixels.is_finite() && (1.0..=1e10).contains(&costs.pixels), "--pixels", || {
        format!("must be in [1, 10^10], got {}", costs.pixels)
    })?;
    for (name, v) in [
        ("--light-cost", costs.light_path),
        ("--camera-cost", costs.camera_path),
        ("--iteration-cost", costs.iteration),
        ("--merge-cost", costs.merge),
    ] {
        check(v.is_finite() && (0.0..=1e6).contains(&v), name, || format!("must be in [0, 10^6] seconds, got {v}"))?;
    }
    if let Some(target) = args.target_rmse {
        check(target.is_finite() && target > 0.0, "--target-rmse", || {
            format!("must be a positive percentage, got {target}")
        })?;
        let config = job.config();
        let reports = thread_pool(None)?.install(|| super::radii::reports(config, &doc.moments, &solver, None));
        let p = error_plan_of(config, &doc.moments, &reports, &solver, costs, target)
            .map_err(|e| CliError::Unusable { path: args.document.clone(), detail: e.to_string() })?;
        let mut out = std::io::stdout().lock();
        if args.json {
            serde_json::to_writer_pretty(&mut out, &p).map_err(std::io::Error::from)?;
            writeln!(out)?;
        } else {
            super::radii::write_error_plan(&mut out, &p)?;
        }
        return Ok(());
    }
    let measured = Budget { light_paths: doc.spec.light_paths, camera_paths: doc.spec.camera_paths };
    let p = plan(&doc.moments, &job.config().cells, &solver, measured, costs, args.target_rms)
        .map_err(|e| CliError::Unusable { path: args.document.clone(), detail: e.to_string() })?;
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &p).map_err(std::io::Error::from)?;
        writeln!(out)?;
        return Ok(());
    }
    print_header(&mut out, &p, doc.moments.iterations(), measured)?;
    print_headline(&mut out, &p)?;
    print_table(&mut out, &p)?;
    print_fixed_time(&mut out, &p)?;
    Ok(())
}

/// Where the costs come from, in words.
fn cost_source(source: CostSource) -> &'static str {
    match source {
        CostSource::Reference => {
            "the reference costs: this crate's brute force on the paper's scene, 2 cores — give your renderer's with --light-cost, --camera-cost, --iteration-cost"
        }
        CostSource::Given => "your costs",
        CostSource::Mixed => "your costs, the others the reference's",
        CostSource::Measured => {
            "measured on this machine now (--measure-costs): another machine or moment plans differently"
        }
    }
}

/// The costs and what was searched.
fn print_header(out: &mut impl Write, p: &BudgetPlan, iterations: u64, measured: Budget) -> std::io::Result<()> {
    let c = &p.costs;
    writeln!(
        out,
        "time to {}% RMS with P = {} pixels, t_F = {:.3e} s per light path, t_B = {:.3e} s per camera path and pixel, t_0 = {:.3e} s per iteration ({})",
        p.target_rms_percent,
        c.pixels,
        c.light_path,
        c.camera_path,
        c.iteration,
        cost_source(c.source)
    )?;
    let s = &p.search;
    writeln!(
        out,
        "(predicted from {} iterations at N_F = {}, N_B = {}; searched N_F {}–{}, N_B {}–{} in half-decade steps{}; * = at the edge of that range, the optimum may lie beyond; † = no budget of that strategy is supported by this run: its RMS SE is above {:.0}% of the RMS)\n",
        iterations,
        measured.light_paths,
        measured.camera_paths,
        s.light_paths[0],
        s.light_paths[1],
        s.camera_paths[0],
        s.camera_paths[1],
        if s.at_limit { ", widened to the limit of what this run can predict" } else { "" },
        SUPPORT_RELATIVE_SE * 100.0
    )
}

/// A speed-up ± SE over the paper's configuration, in words (empty without one).
fn speed_words(b: &BestBudget) -> String {
    match (b.speedup, b.speedup_stderr) {
        (Some(x), Some(se)) => format!("{x:.1} ± {se:.1}× sooner than the paper's switch at (10⁷, 100)"),
        (Some(x), None) => format!("{x:.1}× sooner than the paper's switch at (10⁷, 100)"),
        _ => String::new(),
    }
}

/// The headlined strategy — named the run's recommendation only when it is — its warnings, and the
/// fastest ranked strategy when that is another (as the dashboard's card says it).
fn print_headline(out: &mut impl Write, p: &BudgetPlan) -> std::io::Result<()> {
    let target = p.target_rms_percent;
    if let Some(h) = p.headline.and_then(|h| p.best.iter().find(|b| b.point.strategy == h)) {
        let role = if p.recommended == p.headline { "the run's recommendation" } else { "headlined, see the note" };
        let edge = if h.at_edge {
            " (at the edge of what this run can predict: larger budgets may be faster still)"
        } else {
            ""
        };
        let at = h.point.budget;
        writeln!(
            out,
            "{} ({role}) at (N_F, N_B) = ({}, {}) reaches {target}% {}{edge}",
            h.point.strategy,
            at.light_paths,
            at.camera_paths,
            speed_words(h)
        )?;
        if let Some(warning) = support_warning(h) {
            writeln!(out, "warning: {warning}")?;
        }
        if let Some(fastest) =
            p.best.iter().find(|b| b.point.respects_fixed).filter(|f| f.point.strategy != h.point.strategy)
        {
            let at = fastest.point.budget;
            writeln!(
                out,
                "fastest of the strategies that keep the fixed weights: {} at ({}, {}), {}",
                fastest.point.strategy,
                at.light_paths,
                at.camera_paths,
                speed_words(fastest)
            )?;
        }
    }
    if let Some(note) = &p.headline_note {
        writeln!(out, "note: {note}")?;
    }
    writeln!(out)
}

/// Every strategy's fastest budget, ranked, and the paper's configuration.
fn print_table(out: &mut impl Write, p: &BudgetPlan) -> std::io::Result<()> {
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
    Ok(())
}

/// The RMS every ratio N_F/N_B reaches in the paper configuration's time.
fn print_fixed_time(out: &mut impl Write, p: &BudgetPlan) -> std::io::Result<()> {
    if let Some(f) = &p.fixed_time {
        writeln!(
            out,
            "\nRMS % after T = {:.3e} s (the paper's switch at (10⁷, 100) to {}%), per ratio N_F/N_B at its best budget on the grid (‡ = not one iteration fits in T: extrapolated)\n",
            f.seconds, p.target_rms_percent
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
