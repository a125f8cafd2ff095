//! Plain-text tables of a run's report, laid out like the paper's Table 1.

use std::io::{self, Write};

use crate::sim::solve::report::RunReport;
use crate::sim::spec::JobSpec;

fn num(x: Option<f64>, scale: f64, width: usize, precision: usize) -> String {
    match x {
        Some(v) => format!("{:>width$.precision$}", v * scale),
        None => format!("{:>width$}", "—"),
    }
}

fn bound(x: Option<f64>) -> String {
    x.map_or_else(|| "∞".to_string(), |v| format!("{v}"))
}

/// Writes the noise table, merge rates and weights table.
/// `timing` is (seconds, threads) of a run, shown in the header.
pub fn write_report(
    out: &mut impl Write,
    spec: &JobSpec,
    report: &RunReport,
    timing: Option<(f64, usize)>,
) -> io::Result<()> {
    let when = timing.map_or_else(String::new, |(seconds, threads)| format!(" ({seconds:.1} s on {threads} threads)"));
    writeln!(
        out,
        "{} iterations × N_F = {} light paths × N_B = {} camera paths, R = {}{when}",
        report.iterations, spec.light_paths, spec.camera_paths, spec.merge_radius
    )?;
    let covered: Vec<String> = report
        .coverage
        .seeds()
        .iter()
        .map(|s| {
            let ranges: Vec<String> = s.ranges.iter().map(|r| format!("[{}, {})", r[0], r[1])).collect();
            format!("seed {}: {}", s.seed, ranges.join(" "))
        })
        .collect();
    writeln!(out, "iterations covered: {}", covered.join("; "))?;
    match report.reference_luminance {
        Some(l) => writeln!(out, "reference (quadrature) L·10⁵ = {:.4}", l * 1e5)?,
        None => writeln!(out, "reference (quadrature): did not converge for this geometry")?,
    }
    writeln!(out)?;
    writeln!(out, "{:<16} {:>10} {:>9} {:>9} {:>8}  note", "strategy", "L·10⁵", "± SE", "RMS %", "± SE")?;
    for row in &report.noise_table {
        let mut note = String::new();
        if let Some(l) = row.lambda {
            note.push_str(&format!("λ = {l:e}"));
        }
        if let Some(h) = row.holdout_rms_percent {
            note.push_str(&format!(", hold-out RMS {h:.1}%"));
        }
        if let Some(e) = &row.error {
            note.push_str(e);
        }
        writeln!(
            out,
            "{:<16} {} {} {} {}  {}",
            row.strategy,
            num(row.luminance, 1e5, 10, 4),
            num(row.luminance_stderr, 1e5, 9, 4),
            num(row.rms_percent, 1.0, 9, 1),
            num(row.rms_percent_stderr, 1.0, 8, 1),
            note
        )?;
    }
    let m = &report.merges_per_iteration;
    writeln!(
        out,
        "\nmerge events per iteration: plane 1 {:.4} ± {:.4}, plane 2 {:.3} ± {:.3}, plane 3 {:.3} ± {:.3}",
        m.plane1.mean, m.plane1.stderr, m.plane2.mean, m.plane2.stderr, m.plane3.mean, m.plane3.stderr
    )?;
    writeln!(out)?;
    if let Some(e) = &report.solve_error {
        return writeln!(out, "optimal weights: not available: {e}");
    }
    writeln!(out, "optimal weights (λ = {}):", spec.solver.lambda)?;
    writeln!(
        out,
        "{:<16} {:<18} {:<14} {:>8} {:>8} {:>8} {:>9}  status",
        "r2", "r3", "φ", "w0", "w1", "w2", "samples"
    )?;
    for w in &report.weights {
        writeln!(
            out,
            "{:<16} {:<18} {:<14} {:>8.4} {:>8.4} {:>8.4} {:>9}  {:?}",
            format!("[{}, {})", bound(w.r2[0]), bound(w.r2[1])),
            format!("[{}, {})", bound(w.r3[0]), bound(w.r3[1])),
            format!("[{:.3}, {:.3})", w.phi[0].unwrap_or(0.0), w.phi[1].unwrap_or(0.0)),
            w.w0,
            w.w1,
            w.w2,
            w.samples,
            w.status
        )?;
    }
    Ok(())
}
