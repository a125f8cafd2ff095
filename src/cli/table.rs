//! Plain-text tables of a run's report, laid out like the paper's Table 1.

use std::io::{self, Write};

use crate::sim::checks::published::{ReferenceTable, applicable, differences, figures, tables};
use crate::sim::solve::compare::Comparison;
use crate::sim::solve::noise::{HeuristicWeight, NoiseRow};
use crate::sim::solve::report::{RecommendedWeights, RunReport, WeightRow};
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
    paper: bool,
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
        Some(l) => writeln!(
            out,
            "reference (quadrature) L·10⁵ = {:.4} as R → 0; E[L] is each per-path row's expectation at this R (quadrature), z = (L − E[L])/SE",
            l * 1e5
        )?,
        None => writeln!(out, "reference (quadrature): did not converge for this geometry")?,
    }
    let published = paper.then(|| applicable(spec));
    match published.as_deref() {
        Some([]) => writeln!(
            out,
            "the paper's Table 1 does not apply: this configuration differs in {}",
            tables().first().map(|t| differences(t, spec).join(", ")).unwrap_or_default()
        )?,
        Some([t, ..]) => writeln!(
            out,
            "paper: {} ({} iterations); its optimum was fitted and scored in-sample, to compare with `optimal`; z(paper) = (ours − paper)/SE(ours), the paper giving no error",
            t.source, t.iterations
        )?,
        None => {}
    }
    writeln!(out)?;
    write_noise_rows_with(out, &report.noise_table, report.folds, report.recommended.as_ref(), published.as_deref())?;
    let m = &report.merges_per_iteration;
    writeln!(
        out,
        "\nmerge events per iteration: plane 1 {:.4} ± {:.4}, plane 2 {:.3} ± {:.3}, plane 3 {:.3} ± {:.3}",
        m.plane1.mean, m.plane1.stderr, m.plane2.mean, m.plane2.stderr, m.plane3.mean, m.plane3.stderr
    )?;
    if let Some(r) = &report.recommended {
        writeln!(out, "recommended: {} — {}", r.strategy, r.reason)?;
    }
    if let Some(g) = &report.gain {
        let se = g.stderr.map_or_else(|| "?".to_string(), |s| format!("{s:.2}"));
        writeln!(
            out,
            "gain: Var({}) / Var({}) = {:.2} ± {se} (paired jackknife over the folds)",
            g.versus, g.strategy, g.value
        )?;
    }
    for w in &report.warnings {
        let code = serde_json::to_value(w.code).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default();
        writeln!(out, "warning [{code}]: {}", w.message)?;
        if !w.cells.is_empty() {
            let cells: Vec<String> = w.cells.iter().map(ToString::to_string).collect();
            writeln!(out, "  cells: {}", cells.join(", "))?;
        }
    }
    writeln!(out)?;
    if let Some(e) = &report.solve_error {
        return writeln!(out, "optimal weights: not available: {e}");
    }
    match (&report.weights_fit, &report.recommended) {
        (Some(f), Some(r)) if r.strategy == f.strategy && r.lambda == Some(f.lambda) => {
            write_heuristics(out, &r.heuristics)?;
            writeln!(
                out,
                "recommended weights ({}, λ = {} chosen by cross-validation, fitted on all iterations; ± jackknife SE over the folds, none where the penalty sets a cell):",
                f.strategy, f.lambda
            )?
        }
        (Some(f), _) => {
            writeln!(out, "weights fitted on all iterations at λ = {} (± jackknife SE over the folds):", f.lambda)?
        }
        (None, Some(r)) => {
            return writeln!(
                out,
                "the recommended strategy, {}, weighs each merge by its whole path: it has no table",
                r.strategy
            );
        }
        (None, None) => {}
    }
    write_weights(out, &report.weights)
}

/// The heuristics stacked on a table, with β and its standard error, and how to use them.
pub fn write_heuristics(out: &mut impl Write, heuristics: &[HeuristicWeight]) -> io::Result<()> {
    if heuristics.is_empty() {
        return Ok(());
    }
    let terms: Vec<String> = heuristics
        .iter()
        .map(|h| {
            let se = h.beta_stderr.map_or_else(String::new, |s| format!(" ± {s:.3}"));
            format!("β({}) = {:.3}{se}", h.strategy, h.beta)
        })
        .collect();
    writeln!(out, "stacked heuristics: {}", terms.join(", "))?;
    writeln!(
        out,
        "per-path weights w_m = the cell's table weight + Σ β·(the heuristic's w_m); each cell's table sums to 1 − Σβ"
    )
}

/// The noise table's rows with their notes (λ, in-sample or cross-fitted, recommended, outside
/// the fixed weights, errors).
pub fn write_noise_rows(
    out: &mut impl Write,
    rows: &[NoiseRow],
    folds: usize,
    recommended: Option<&RecommendedWeights>,
) -> io::Result<()> {
    write_noise_rows_with(out, rows, folds, recommended, None)
}

/// [`write_noise_rows`] with the published figures of `paper` beside each row that has them
/// (columns only when a table applies).
pub fn write_noise_rows_with(
    out: &mut impl Write,
    rows: &[NoiseRow],
    folds: usize,
    recommended: Option<&RecommendedWeights>,
    paper: Option<&[ReferenceTable]>,
) -> io::Result<()> {
    let paper = paper.filter(|p| !p.is_empty());
    let paper_header = if paper.is_some() {
        format!(" {:>12} {:>6} {:>9} {:>6}", "paper L·10⁵", "z", "paper RMS", "z")
    } else {
        String::new()
    };
    writeln!(
        out,
        "{:<36} {:>10} {:>9} {:>9} {:>8} {:>10} {:>6}{paper_header}  note",
        "strategy", "L·10⁵", "± SE", "RMS %", "± SE", "E[L]·10⁵", "z"
    )?;
    for row in rows {
        let mut notes = Vec::new();
        if let Some(l) = row.lambda {
            notes.push(format!("λ = {l}"));
        }
        if row.unstable {
            notes.push("unstable".to_string());
        }
        if row.tail_missing {
            notes.push("tail missing (L far below its expectation)".to_string());
        }
        if row.beyond_trust_region {
            notes.push(match row.deviation {
                Some(d) => format!("beyond trust region (deviation {d:.2})"),
                None => "beyond trust region".to_string(),
            });
        }
        if row.in_sample {
            notes.push("in-sample (optimistic)".to_string());
        } else if row.lambda.is_some() {
            notes.push(format!("{}-fold cross-fitted", folds));
        }
        if let Some(h) = row.in_sample_rms_percent {
            notes.push(format!("in-sample RMS {h:.1}%"));
        }
        if recommended.is_some_and(|r| r.strategy == row.strategy) {
            notes.push("recommended".to_string());
        }
        if !row.respects_fixed {
            notes.push("outside the fixed weights".to_string());
        }
        if let Some(e) = &row.error {
            notes.push(e.clone());
        }
        let note = notes.join(", ");
        let published = match paper {
            Some(tables) => {
                let p = figures(tables, row.strategy.name());
                // How many of our standard errors the paper's figure lies away.
                let z = |ours: Option<f64>, se: Option<f64>, theirs: Option<f64>| {
                    ours.zip(se).zip(theirs).filter(|((_, se), _)| *se > 0.0).map(|((v, se), t)| (v - t) / se)
                };
                format!(
                    " {} {} {} {}",
                    num(p.map(|p| p.0), 1e5, 12, 3),
                    num(z(row.luminance, row.luminance_stderr, p.map(|p| p.0)), 1.0, 6, 1),
                    num(p.map(|p| p.1), 1.0, 9, 0),
                    num(z(row.rms_percent, row.rms_percent_stderr, p.map(|p| p.1)), 1.0, 6, 1)
                )
            }
            None => String::new(),
        };
        writeln!(
            out,
            "{:<36} {} {} {} {} {} {}{published}  {}",
            row.strategy,
            num(row.luminance, 1e5, 10, 4),
            num(row.luminance_stderr, 1e5, 9, 4),
            num(row.rms_percent, 1.0, 9, 1),
            num(row.rms_percent_stderr, 1.0, 8, 1),
            num(row.expected_luminance, 1e5, 10, 4),
            num(row.z, 1.0, 6, 1),
            note
        )?;
    }
    Ok(())
}

/// A weights table, each weight with its standard error where there is one.
pub fn write_weights(out: &mut impl Write, weights: &[WeightRow]) -> io::Result<()> {
    writeln!(
        out,
        "{:>4} {:<12} {:<16} {:<14} {:>16} {:>16} {:>16} {:>9}  status",
        "cell", "r2", "r3", "φ", "w0", "w1", "w2", "samples"
    )?;
    let with_se = |w: f64, se: Option<f64>| match se {
        Some(se) => format!("{w:.4} ± {se:.4}"),
        None => format!("{w:.4}   (no SE)"),
    };
    for (alpha, w) in weights.iter().enumerate() {
        let status =
            serde_json::to_value(w.status).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default();
        writeln!(
            out,
            "{:>4} {:<12} {:<16} {:<14} {:>16} {:>16} {:>16} {:>9}  {status}",
            alpha,
            format!("[{}, {})", bound(w.r2[0]), bound(w.r2[1])),
            format!("[{}, {})", bound(w.r3[0]), bound(w.r3[1])),
            format!("[{:.3}, {:.3})", w.phi[0].unwrap_or(0.0), w.phi[1].unwrap_or(0.0)),
            with_se(w.w0, w.w0_stderr),
            with_se(w.w1, w.w1_stderr),
            with_se(w.w2, w.w2_stderr),
            w.samples,
        )?;
    }
    Ok(())
}

/// A comparison of runs: per strategy, each run's L and RMS, and against the first run the ratio
/// and difference of L and the ratio of RMS, each ± its standard error, and z.
pub fn write_comparison(out: &mut impl Write, c: &Comparison) -> io::Result<()> {
    let runs: Vec<String> = c.runs.iter().map(|r| format!("{} ({} iterations)", r.label, r.iterations)).collect();
    writeln!(out, "baseline {}; compared {}", runs[0], runs[1..].join(", "))?;
    let width = c.runs.iter().map(|r| r.label.chars().count()).max().unwrap_or(4).max(4);
    writeln!(
        out,
        "\n{:<36} {:<width$} {:>10} {:>8} {:>8} {:>7} {:>15} {:>17} {:>6} {:>15}",
        "strategy", "run", "L·10⁵", "± SE", "RMS %", "± SE", "L / base ± SE", "ΔL·10⁵ ± SE", "z", "RMS / base ± SE"
    )?;
    let pair = |v: Option<f64>, se: Option<f64>, scale: f64, width: usize, precision: usize| match (v, se) {
        (Some(v), Some(se)) => format!("{:>width$}", format!("{:.precision$} ± {:.precision$}", v * scale, se * scale)),
        _ => format!("{:>width$}", "—"),
    };
    for s in &c.strategies {
        let name = if s.in_sample { format!("{} (in-sample)", s.strategy) } else { s.strategy.to_string() };
        for (i, (f, run)) in s.runs.iter().zip(&c.runs).enumerate() {
            let against = if i == 0 {
                String::new()
            } else {
                format!(
                    " {} {} {} {}",
                    pair(f.luminance_ratio, f.luminance_ratio_stderr, 1.0, 15, 3),
                    pair(f.luminance_difference, f.luminance_difference_stderr, 1e5, 17, 3),
                    num(f.z, 1.0, 6, 1),
                    pair(f.rms_ratio, f.rms_ratio_stderr, 1.0, 15, 3)
                )
            };
            writeln!(
                out,
                "{:<36} {:<width$} {} {} {} {}{against}",
                if i == 0 { name.as_str() } else { "" },
                run.label,
                num(f.luminance, 1e5, 10, 4),
                num(f.luminance_stderr, 1e5, 8, 4),
                num(f.rms_percent, 1.0, 8, 1),
                num(f.rms_percent_stderr, 1.0, 7, 1),
            )?;
        }
    }
    for note in &c.notes {
        writeln!(out, "\nnote: {note}")?;
    }
    Ok(())
}
