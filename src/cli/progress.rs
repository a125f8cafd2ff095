//! What a long local run tells the person (or the batch log) watching it: a progress bar on a
//! terminal; plain lines every few seconds when stderr is not one (a Slurm log, a pipe), where a
//! bar draws nothing; nothing with `--quiet`.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Debug, Clone, Args)]
pub struct ProgressArgs {
    /// Print no progress on stderr (errors still go there).
    #[arg(long)]
    pub quiet: bool,
    /// When stderr is not a terminal, seconds between progress lines.
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub progress_seconds: f64,
}

/// The progress of one run of `total` iterations of `light_paths` light paths each.
pub enum Progress {
    Bar(ProgressBar),
    Lines { label: String, total: u64, light_paths: u64, every: Duration, started: Instant, last: Instant },
    Quiet,
}

impl Progress {
    pub fn new(args: &ProgressArgs, label: &str, total: u64, light_paths: u64) -> Self {
        if args.quiet {
            return Self::Quiet;
        }
        if std::io::stderr().is_terminal() {
            let bar = ProgressBar::new(total).with_style(
                ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} iterations, ETA {eta} {msg}")
                    .expect("a valid template")
                    .progress_chars("=> "),
            );
            return Self::Bar(bar);
        }
        let now = Instant::now();
        let every = Duration::from_secs_f64(args.progress_seconds.clamp(0.1, 86_400.0));
        Self::Lines { label: label.to_string(), total, light_paths, every, started: now, last: now }
    }

    /// `done` of the iterations are finished.
    pub fn update(&mut self, done: u64, started: Instant, light_paths: u64) {
        let rate = (done * light_paths) as f64 / started.elapsed().as_secs_f64().max(1e-9);
        match self {
            Self::Bar(bar) => {
                bar.set_message(format!("{rate:.3e} light paths/s"));
                bar.set_position(done);
            }
            Self::Lines { label, total, every, started, last, .. } => {
                if last.elapsed() < *every {
                    return;
                }
                *last = Instant::now();
                let elapsed = started.elapsed().as_secs_f64();
                let eta = if done > 0 { (*total - done) as f64 * elapsed / done as f64 } else { f64::NAN };
                eprintln!(
                    "optimis: {label}{done}/{total} iterations ({:.1}%), {rate:.3e} light paths/s, {elapsed:.0} s elapsed, ETA {eta:.0} s",
                    100.0 * done as f64 / (*total).max(1) as f64
                );
            }
            Self::Quiet => {}
        }
    }

    /// The run ended.
    pub fn finish(self) {
        match self {
            Self::Bar(bar) => bar.finish_and_clear(),
            Self::Lines { label, total, light_paths, started, .. } => {
                let elapsed = started.elapsed().as_secs_f64();
                eprintln!(
                    "optimis: {label}{total} iterations done in {elapsed:.1} s ({:.3e} light paths/s)",
                    (total * light_paths) as f64 / elapsed.max(1e-9)
                );
            }
            Self::Quiet => {}
        }
    }
}
