//! `optimis bench`: iterations and light paths per second of the simulation core at the paper's
//! parameters, for each engine asked for, the restricted engine's speed-up over the brute force,
//! and the restricted engine's rate on one thread beside its rate on all of them (the parallel
//! speed-up and efficiency: the serial part of a run — merging the workers' moments — shows here).

use std::io::Write;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use clap::{Args, ValueEnum};
use serde_json::{Value, json};

use super::{CliError, cores, thread_pool};
use crate::sim::model::config::Proposals;
use crate::sim::model::config::{Engine, SimConfig};
use crate::sim::model::params::parse_count;
use crate::sim::runner::{BatchMoments, run_iterations};
use crate::sim::spec::parse_job_spec;
use crate::sim::stats::moments::Moments;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BenchEngine {
    Brute,
    Restricted,
}

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Engines to time (repeat the flag for several; default: both, and their ratio).
    #[arg(long = "engine", value_enum)]
    pub engines: Vec<BenchEngine>,
    /// Brute-force iterations to time (after one untimed warm-up iteration); the restricted engine
    /// times 1000 times as many.
    #[arg(long, default_value_t = 10)]
    pub iterations: u64,
    /// Light paths per iteration (default: the paper's 10⁷).
    #[arg(long, value_parser = parse_count, allow_hyphen_values = true)]
    pub light_paths: Option<u64>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print the measurements as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Seconds to run `iterations` iterations (after one warm-up iteration).
pub(super) fn time_iterations(config: &SimConfig, iterations: u64) -> f64 {
    let never = AtomicBool::new(false);
    let mut moments = Moments::new(config);
    let go_on = |_: &mut dyn BatchMoments, _| std::ops::ControlFlow::Continue(());
    run_iterations(config, 1, 0..1, &mut moments, &never, go_on).expect("warm-up");
    let started = Instant::now();
    run_iterations(config, 1, 1..1 + iterations, &mut moments, &never, go_on).expect("bench run");
    started.elapsed().as_secs_f64()
}

pub fn bench(args: BenchArgs) -> Result<(), CliError> {
    let mut doc = json!({ "preset": "paper-table1" });
    if let Some(n) = args.light_paths {
        doc["light_paths"] = json!(n);
    }
    let job = parse_job_spec(&doc)?.validate()?;
    let pool = thread_pool(args.threads)?;
    let threads = pool.current_num_threads();
    let engines =
        if args.engines.is_empty() { vec![BenchEngine::Restricted, BenchEngine::Brute] } else { args.engines.clone() };
    let base = args.iterations.max(1);
    let mut results: Vec<(BenchEngine, Value)> = Vec::new();
    for engine in engines {
        let (config, iterations) = match engine {
            BenchEngine::Brute => (job.config().with_engine(Engine::Brute), base),
            BenchEngine::Restricted => (job.config().with_engine(Engine::Restricted(Proposals::Auto)), base * 1000),
        };
        let seconds = pool.install(|| time_iterations(&config, iterations));
        let per_second = iterations as f64 / seconds;
        let name = match engine {
            BenchEngine::Brute => "brute",
            BenchEngine::Restricted => "restricted",
        };
        results.push((
            engine,
            json!({
                "engine": name,
                "iterations": iterations,
                "seconds": seconds,
                "iterations_per_second": per_second,
                // For the restricted engine: light paths of the brute force it stands in for.
                "light_paths_per_second": per_second * config.light_paths as f64,
            }),
        ));
    }
    let rate =
        |e: BenchEngine| results.iter().find(|(x, _)| *x == e).and_then(|(_, v)| v["iterations_per_second"].as_f64());
    // The same restricted run on one thread, timed after the others (same warm caches).
    let scaling = match rate(BenchEngine::Restricted) {
        Some(many) if threads > 1 => {
            let config = job.config().with_engine(Engine::Restricted(Proposals::Auto));
            let one = thread_pool(Some(1))?.install(|| time_iterations(&config, base * 1000));
            let single = (base * 1000) as f64 / one;
            Some(json!({
                "threads": threads,
                "iterations_per_second_1_thread": single,
                "iterations_per_second": many,
                "speed_up": many / single,
                "efficiency": many / single / threads as f64,
            }))
        }
        _ => None,
    };
    let speedup = rate(BenchEngine::Restricted).zip(rate(BenchEngine::Brute)).map(|(r, b)| r / b);
    let config = &job.config();
    // Written with `?`, not println!: a closed pipe (`optimis bench | head -1`) is the reader
    // leaving, which main() treats as success instead of a panic.
    let mut out = std::io::stdout().lock();
    if args.json {
        let doc = json!({
            "engines": results.iter().map(|(_, v)| v.clone()).collect::<Vec<_>>(),
            "restricted_over_brute": speedup,
            "restricted_scaling": scaling,
            "light_paths_per_iteration": config.light_paths,
            "camera_paths_per_iteration": config.camera_paths,
            "threads": threads,
            "cores": cores(),
        });
        writeln!(out, "{doc}")?;
    } else {
        for (_, v) in &results {
            writeln!(
                out,
                "{:<10} {:>12.4e} iterations/s  {:>12.4e} light paths/s  ({} iterations in {:.2} s)",
                v["engine"].as_str().unwrap_or("?"),
                v["iterations_per_second"].as_f64().unwrap_or(0.0),
                v["light_paths_per_second"].as_f64().unwrap_or(0.0),
                v["iterations"],
                v["seconds"].as_f64().unwrap_or(0.0),
            )?;
        }
        if let Some(s) = speedup {
            writeln!(out, "restricted / brute: {s:.0}× per iteration")?;
        }
        if let Some(s) = &scaling {
            writeln!(
                out,
                "restricted on 1 thread: {:.4e} iterations/s; on {threads}: speed-up {:.2}× (parallel efficiency {:.0}%)",
                s["iterations_per_second_1_thread"].as_f64().unwrap_or(0.0),
                s["speed_up"].as_f64().unwrap_or(0.0),
                100.0 * s["efficiency"].as_f64().unwrap_or(0.0),
            )?;
        }
        writeln!(
            out,
            "(N_F = {}, N_B = {}; {threads} threads on {} cores)",
            config.light_paths,
            config.camera_paths,
            cores()
        )?;
    }
    Ok(())
}
