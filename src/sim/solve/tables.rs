//! The noise table as text for papers and notes — Markdown and LaTeX (`GET
//! /v1/jobs/{id}/result?format=markdown|latex`, `optimis report --format`): per strategy L ± SE in
//! units of 10⁻⁵ of the model's luminance, RMS % ± SE of one iteration, and the paper's figures
//! where its Table 1 applies. The LaTeX is a plain `tabular` (no packages) that compiles as is
//! inside any document.

use super::row::NoiseRow;
use super::strategy::Strategy;

/// One row's cells: name, L ± SE, RMS ± SE, paper L, paper RMS (empty where absent).
fn cells(row: &NoiseRow, paper: Option<(f64, f64)>, pm: &str) -> [String; 5] {
    let with = |v: Option<f64>, se: Option<f64>, scale: f64, digits: usize| match (v, se) {
        (Some(v), Some(se)) => format!("{:.digits$}{pm}{:.digits$}", v * scale, se * scale),
        (Some(v), None) => format!("{:.digits$}", v * scale),
        _ => "—".to_string(),
    };
    let name = if row.in_sample { format!("{} (in-sample)", row.strategy) } else { row.strategy.to_string() };
    [
        name,
        with(row.luminance, row.luminance_stderr, 1e5, 3),
        with(row.rms_percent, row.rms_percent_stderr, 1.0, 1),
        paper.map(|p| format!("{:.3}", p.0 * 1e5)).unwrap_or_default(),
        paper.map(|p| format!("{:.0}", p.1)).unwrap_or_default(),
    ]
}

/// The noise table as a Markdown (GitHub) table; the paper's columns only when a row has them.
pub fn noise_table_markdown(rows: &[NoiseRow], paper: impl Fn(&Strategy) -> Option<(f64, f64)>) -> String {
    let with_paper = rows.iter().any(|r| paper(&r.strategy).is_some());
    let mut out = String::from("| strategy | L·10⁵ ± SE | RMS % ± SE |");
    out.push_str(if with_paper { " paper L·10⁵ | paper RMS % |\n" } else { "\n" });
    out.push_str(if with_paper { "|---|---:|---:|---:|---:|\n" } else { "|---|---:|---:|\n" });
    for row in rows {
        let c = cells(row, paper(&row.strategy), " ± ");
        let n = if with_paper { 5 } else { 3 };
        out.push_str(&format!("| `{}` | {} |\n", c[0], c[1..n].join(" | ")));
    }
    out
}

/// The noise table as a LaTeX `tabular` (core LaTeX only); the paper's columns only when a row
/// has them.
pub fn noise_table_latex(rows: &[NoiseRow], paper: impl Fn(&Strategy) -> Option<(f64, f64)>) -> String {
    let with_paper = rows.iter().any(|r| paper(&r.strategy).is_some());
    let mut out = String::from(
        "% The noise table of an optimis run: L in units of 10^-5, RMS of one iteration in percent of L.\n",
    );
    out.push_str(if with_paper { "\\begin{tabular}{lrrrr}\n\\hline\n" } else { "\\begin{tabular}{lrr}\n\\hline\n" });
    out.push_str("Strategy & $L \\cdot 10^{5}$ & RMS \\%");
    out.push_str(if with_paper {
        " & Paper $L \\cdot 10^{5}$ & Paper RMS \\% \\\\\n\\hline\n"
    } else {
        " \\\\\n\\hline\n"
    });
    for row in rows {
        let c = cells(row, paper(&row.strategy), " $\\pm$ ");
        let n = if with_paper { 5 } else { 3 };
        let name = c[0].replace('_', "\\_");
        let rest: Vec<String> = c[1..n].iter().map(|s| s.replace('—', "--")).collect();
        out.push_str(&format!("{name} & {} \\\\\n", rest.join(" & ")));
    }
    out.push_str("\\hline\n\\end{tabular}\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(strategy: Strategy, l: f64, se: f64, rms: f64, rse: f64) -> NoiseRow {
        let mut r = NoiseRow::from_sums(strategy, 0.0, 0.0, 0.0, None);
        (r.luminance, r.luminance_stderr, r.rms_percent, r.rms_percent_stderr) =
            (Some(l), Some(se), Some(rms), Some(rse));
        r
    }

    #[test]
    fn markdown_and_latex_hold_every_row_and_the_papers_columns() {
        let rows = [
            row(Strategy::Switch, 26.673e-5, 0.177e-5, 66.4, 3.1),
            row(Strategy::OptimalCv, 26.5e-5, 0.15e-5, 59.1, 2.4),
        ];
        let paper = |s: &Strategy| (*s == Strategy::Switch).then_some((26.352e-5, 61.0));
        let md = noise_table_markdown(&rows, paper);
        assert!(md.contains("| `switch` | 26.673 ± 0.177 | 66.4 ± 3.1 | 26.352 | 61 |"), "{md}");
        assert!(md.contains("| `optimal_cv` | 26.500 ± 0.150 | 59.1 ± 2.4 |  |  |"), "{md}");
        let tex = noise_table_latex(&rows, paper);
        assert!(tex.contains("optimal\\_cv & 26.500 $\\pm$ 0.150 & 59.1 $\\pm$ 2.4 &  &  \\\\"), "{tex}");
        assert!(tex.starts_with('%') && tex.ends_with("\\end{tabular}\n"));
        // Without a published figure, no paper columns.
        assert!(!noise_table_markdown(&rows, |_| None).contains("paper"));
        assert!(noise_table_latex(&rows, |_| None).contains("{lrr}"));
    }
}
