//! `optimis bench`: light paths per second of the simulation core at the paper's parameters.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use clap::Args;
use serde_json::json;

use super::{CliError, cores, thread_pool};
use crate::sim::moments::Moments;
use crate::sim::runner::run_iterations;
use crate::sim::spec::parse_job_spec;

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Iterations to time (after one untimed warm-up iteration).
    #[arg(long, default_value_t = 10)]
    pub iterations: u64,
    /// Light paths per iteration (default: the paper's 10⁷).
    #[arg(long)]
    pub light_paths: Option<u64>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print the measurement as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn bench(args: BenchArgs) -> Result<(), CliError> {
    let mut doc = json!({ "preset": "paper-table1" });
    if let Some(n) = args.light_paths {
        doc["light_paths"] = json!(n);
    }
    let job = parse_job_spec(&doc)?.validate()?;
    let config = &job.config;
    let pool = thread_pool(args.threads)?;
    let never = AtomicBool::new(false);
    let mut moments = Moments::new(config);
    let iterations = args.iterations.max(1);
    let seconds = pool.install(|| {
        let go_on = |_: &Moments, _| std::ops::ControlFlow::Continue(());
        run_iterations(config, 1, 0..1, &mut moments, &never, go_on).expect("warm-up");
        let started = Instant::now();
        run_iterations(config, 1, 1..1 + iterations, &mut moments, &never, go_on).expect("bench run");
        started.elapsed().as_secs_f64()
    });
    let paths = (iterations * config.light_paths) as f64;
    let rate = paths / seconds;
    let threads = pool.current_num_threads();
    if args.json {
        let out = json!({
            "light_paths_per_second": rate,
            "iterations_per_second": iterations as f64 / seconds,
            "light_paths_per_iteration": config.light_paths,
            "camera_paths_per_iteration": config.camera_paths,
            "iterations": iterations,
            "seconds": seconds,
            "threads": threads,
            "cores": cores(),
        });
        println!("{out}");
    } else {
        println!(
            "{rate:.4e} light paths/s ({iterations} iterations of N_F = {} and N_B = {} in {seconds:.2} s; {threads} threads on {} cores)",
            config.light_paths,
            config.camera_paths,
            cores()
        );
    }
    Ok(())
}
