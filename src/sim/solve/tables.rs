//! The noise table as text for papers and notes — Markdown and LaTeX (`GET
//! /v1/jobs/{id}/result?format=markdown|latex`, `optimis report --format`): per strategy L ± SE in
//! units of 10⁻⁵ of the model's luminance, RMS % ± SE of one iteration, and where the paper's
//! Table 1 applies its figures with z = (ours − paper)/SE. The rows can be chosen, the recommended
//! row is marked, and the LaTeX is a `table` float with a caption (or the bare `tabular`), in core
//! LaTeX only, narrow enough for an article's text width (issue 42, item 8).

use super::row::NoiseRow;
use super::strategy::Strategy;

/// What a text table shows besides the rows: which rows, the recommended one, a caption.
#[derive(Debug, Clone, Default)]
pub struct TextTable {
    /// The strategies to show, in this order (`None`: every row of the table, in its order).
    pub rows: Option<Vec<Strategy>>,
    /// The row marked as recommended (bold and `*`), if any.
    pub recommended: Option<Strategy>,
    /// The caption (LaTeX: the float's; Markdown: a line above the table). `None`: one that says
    /// the units and the marks.
    pub caption: Option<String>,
    /// LaTeX only: the `tabular` without the float and its caption (for a table of one's own), in a
    /// group that keeps its small type to itself.
    pub bare: bool,
}

/// Why a row selection cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RowsError {
    /// A name that is no strategy.
    #[error("`{0}` is not a strategy (the names are the noise table's, e.g. switch,optimal_cv)")]
    Unknown(String),
    /// A strategy the table has no row of.
    #[error("the noise table has no row `{0}`")]
    Absent(String),
    /// Nothing chosen.
    #[error("names no strategy")]
    Empty,
    /// More names than the table could hold.
    #[error("names more than {0} strategies")]
    TooMany(usize),
}

/// Most names a row selection may list (every strategy, with room for repeats refused).
const MAX_ROWS: usize = 64;

/// The strategies of a comma-separated list (`switch,optimal_cv`), each a row of `table`.
pub fn parse_rows(list: &str, table: &[NoiseRow]) -> Result<Vec<Strategy>, RowsError> {
    let names: Vec<&str> = list.split(',').map(str::trim).filter(|n| !n.is_empty()).collect();
    if names.is_empty() {
        return Err(RowsError::Empty);
    }
    if names.len() > MAX_ROWS {
        return Err(RowsError::TooMany(MAX_ROWS));
    }
    names
        .into_iter()
        .map(|name| match table.iter().find(|r| r.strategy.name() == name) {
            Some(row) => Ok(row.strategy),
            None if serde_json::from_value::<Strategy>(serde_json::Value::String(name.into())).is_ok() => {
                Err(RowsError::Absent(name.to_string()))
            }
            None => Err(RowsError::Unknown(clip(name))),
        })
        .collect()
}

/// A name as an error may quote it: at most 40 characters.
fn clip(name: &str) -> String {
    name.chars().take(40).collect()
}

/// The rows to print, in order, whether any has the paper's figures, and whether any is in-sample.
fn chosen<'a>(
    table: &'a [NoiseRow],
    paper: &impl Fn(&Strategy) -> Option<(f64, f64)>,
    opts: &TextTable,
) -> (Vec<&'a NoiseRow>, bool, bool) {
    let rows: Vec<&NoiseRow> = match &opts.rows {
        None => table.iter().collect(),
        Some(rows) => rows.iter().filter_map(|s| table.iter().find(|r| r.strategy == *s)).collect(),
    };
    let with_paper = rows.iter().any(|r| paper(&r.strategy).is_some());
    let in_sample = rows.iter().any(|r| r.in_sample);
    (rows, with_paper, in_sample)
}

/// z = (ours − paper)/SE(ours): how many of our standard errors the paper's figure lies away.
fn z(ours: Option<f64>, se: Option<f64>, paper: f64) -> Option<f64> {
    ours.zip(se).filter(|(_, se)| *se > 0.0).map(|(v, se)| (v - paper) / se)
}

/// One row's cells: name, L ± SE, RMS ± SE, and with the paper's figures paper L, its z, paper
/// RMS, its z (empty where absent).
fn cells(row: &NoiseRow, paper: Option<(f64, f64)>, pm: &str, minus: &str) -> [String; 7] {
    let with = |v: Option<f64>, se: Option<f64>, scale: f64, digits: usize| match (v, se) {
        (Some(v), Some(se)) => format!("{:.digits$}{pm}{:.digits$}", v * scale, se * scale),
        (Some(v), None) => format!("{:.digits$}", v * scale),
        _ => "—".to_string(),
    };
    let signed = |z: Option<f64>| z.map(|z| format!("{:.1}", z).replace('-', minus)).unwrap_or_default();
    [
        row.strategy.to_string(),
        with(row.luminance, row.luminance_stderr, 1e5, 3),
        with(row.rms_percent, row.rms_percent_stderr, 1.0, 1),
        paper.map(|p| format!("{:.3}", p.0 * 1e5)).unwrap_or_default(),
        paper.and_then(|p| z(row.luminance, row.luminance_stderr, p.0)).map_or(String::new(), |z| signed(Some(z))),
        paper.map(|p| format!("{:.0}", p.1)).unwrap_or_default(),
        paper.and_then(|p| z(row.rms_percent, row.rms_percent_stderr, p.1)).map_or(String::new(), |z| signed(Some(z))),
    ]
}

/// The caption: the given one, or what the columns and marks mean.
fn caption(opts: &TextTable, with_paper: bool, any_in_sample: bool, latex: bool) -> String {
    if let Some(c) = &opts.caption {
        return c.clone();
    }
    let mut parts = vec![if latex {
        "Noise of each MIS strategy: $L$ in units of $10^{-5}$ and the RMS of one iteration in percent of $L$, each $\\pm$ one standard error.".to_string()
    } else {
        "Noise of each MIS strategy: L in units of 10⁻⁵ and the RMS of one iteration in percent of L, each ± one standard error.".to_string()
    }];
    if opts.recommended.is_some() {
        parts.push("Recommended row in bold, marked *.".to_string());
    }
    if any_in_sample {
        parts.push(
            if latex {
                "$^\\dagger$ in-sample: fitted and scored on the same iterations (optimistic)."
            } else {
                "† in-sample: fitted and scored on the same iterations (optimistic)."
            }
            .to_string(),
        );
    }
    if with_paper {
        parts.push(
            "Paper: Ershov et al. (2020), Table 1; z = (ours - paper) / SE(ours), the paper giving no error."
                .replace(" - ", if latex { " $-$ " } else { " − " }),
        );
    }
    parts.join(" ")
}

/// The noise table as a Markdown (GitHub) table under its caption; the paper's columns only when a
/// row has them.
pub fn noise_table_markdown(
    rows: &[NoiseRow],
    paper: impl Fn(&Strategy) -> Option<(f64, f64)>,
    opts: &TextTable,
) -> String {
    let (rows, with_paper, in_sample) = chosen(rows, &paper, opts);
    let mut out = format!("{}\n\n", caption(opts, with_paper, in_sample, false));
    out.push_str("| strategy | L·10⁵ ± SE | RMS % ± SE |");
    out.push_str(if with_paper { " paper L·10⁵ | z | paper RMS % | z |\n" } else { "\n" });
    out.push_str(if with_paper { "|---|---:|---:|---:|---:|---:|---:|\n" } else { "|---|---:|---:|\n" });
    for row in rows {
        let c = cells(row, paper(&row.strategy), " ± ", "−");
        let n = if with_paper { 7 } else { 3 };
        let mark = if row.in_sample { " †" } else { "" };
        let name = if opts.recommended == Some(row.strategy) {
            format!("**`{}`**{mark} *", c[0])
        } else {
            format!("`{}`{mark}", c[0])
        };
        out.push_str(&format!("| {name} | {} |\n", c[1..n].join(" | ")));
    }
    out
}

/// The noise table as LaTeX (core LaTeX only): a `table` float, `\footnotesize` with narrow column
/// gaps so that every row fits an article's text width, its caption and a label — or with
/// `opts.bare` the `tabular` alone. The paper's columns only when a row has them.
pub fn noise_table_latex(
    rows: &[NoiseRow],
    paper: impl Fn(&Strategy) -> Option<(f64, f64)>,
    opts: &TextTable,
) -> String {
    let (rows, with_paper, in_sample) = chosen(rows, &paper, opts);
    let mut out = String::from(
        "% The noise table of an optimis run: L in units of 10^-5, RMS of one iteration in percent of L.\n",
    );
    // Small type and narrow gaps, in the float or (bare) in a group that keeps them to the table.
    out.push_str(if opts.bare { "{\\noindent\n" } else { "\\begin{table}[htbp]\n\\centering\n" });
    out.push_str("\\footnotesize\n\\setlength{\\tabcolsep}{3pt}\n");
    // With the paper's four columns the longest names (`correlation_aware_planes23_corrected`)
    // wrap at their underscores in a 2.3 cm column: the table then fits an article's 345 pt.
    out.push_str(if with_paper {
        "\\begin{tabular}{p{2.3cm}rrrrrr}\n\\hline\n"
    } else {
        "\\begin{tabular}{lrr}\n\\hline\n"
    });
    out.push_str("Strategy & $L \\cdot 10^{5}$ & RMS \\%");
    out.push_str(if with_paper { " & Paper $L$ & $z$ & Paper RMS & $z$ \\\\\n\\hline\n" } else { " \\\\\n\\hline\n" });
    for row in rows {
        let c = cells(row, paper(&row.strategy), " $\\pm$ ", "$-$");
        let n = if with_paper { 7 } else { 3 };
        let mut name = escape(&c[0]);
        if row.in_sample {
            name.push_str("$^\\dagger$");
        }
        let mut rest: Vec<String> = c[1..n].iter().map(|s| s.replace('—', "--")).collect();
        if opts.recommended == Some(row.strategy) {
            name = format!("\\textbf{{{name}}}*");
            rest = rest.into_iter().map(|s| if s.is_empty() { s } else { format!("\\textbf{{{s}}}") }).collect();
        }
        if with_paper {
            // Safe in the first column: its cell ends at `&`, not at the row's `\\`.
            name = format!("\\raggedright {name}");
        }
        out.push_str(&format!("{name} & {} \\\\\n", rest.join(" & ")));
    }
    out.push_str("\\hline\n\\end{tabular}\n");
    if opts.bare {
        out.push_str("}\n");
    } else {
        out.push_str(&format!("\\caption{{{}}}\n", escape_caption(&caption(opts, with_paper, in_sample, true), opts)));
        out.push_str("\\label{tab:optimis-noise}\n\\end{table}\n");
    }
    out
}

/// A strategy name in LaTeX text, breakable after each underscore.
fn escape(text: &str) -> String {
    text.replace('_', "\\_\\allowbreak ")
}

/// A caption in LaTeX: the default one is LaTeX already; a given one is text, its special
/// characters escaped so that any string compiles.
fn escape_caption(text: &str, opts: &TextTable) -> String {
    if opts.caption.is_none() {
        return text.to_string();
    }
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '\\' => out.push_str("\\textbackslash{}"),
            '{' | '}' | '$' | '&' | '#' | '_' | '%' => {
                out.push('\\');
                out.push(c);
            }
            '^' => out.push_str("\\^{}"),
            '~' => out.push_str("\\~{}"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests;
