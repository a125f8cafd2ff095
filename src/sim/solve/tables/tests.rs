//! The text tables: every chosen row, the paper's columns with z, the recommended mark, the caption.

use super::*;

fn row(strategy: Strategy, l: f64, se: f64, rms: f64, rse: f64) -> NoiseRow {
    let mut r = NoiseRow::from_sums(strategy, 0.0, 0.0, 0.0, None);
    (r.luminance, r.luminance_stderr, r.rms_percent, r.rms_percent_stderr) = (Some(l), Some(se), Some(rms), Some(rse));
    r
}

fn rows() -> [NoiseRow; 3] {
    [
        row(Strategy::Switch, 26.673e-5, 0.177e-5, 66.4, 3.1),
        row(Strategy::OptimalCv, 26.5e-5, 0.15e-5, 59.1, 2.4),
        row(Strategy::Balance, 26.6e-5, 0.2e-5, 70.0, 3.0),
    ]
}

fn paper(s: &Strategy) -> Option<(f64, f64)> {
    (*s == Strategy::Switch).then_some((26.352e-5, 61.0))
}

#[test]
fn markdown_and_latex_hold_every_row_the_papers_columns_and_z() {
    let rows = rows();
    let opts = TextTable::default();
    let md = noise_table_markdown(&rows, paper, &opts);
    // z of L: (26.673 − 26.352)/0.177 = 1.81; of RMS: (66.4 − 61)/3.1 = 1.74.
    assert!(md.contains("| `switch` | 26.673 ± 0.177 | 66.4 ± 3.1 | 26.352 | 1.8 | 61 | 1.7 |"), "{md}");
    assert!(md.contains("| `optimal_cv` | 26.500 ± 0.150 | 59.1 ± 2.4 |  |  |  |  |"), "{md}");
    let tex = noise_table_latex(&rows, paper, &opts);
    assert!(
        tex.contains(
            "\\raggedright optimal\\_\\allowbreak cv & 26.500 $\\pm$ 0.150 & 59.1 $\\pm$ 2.4 &  &  &  &  \\\\"
        ),
        "{tex}"
    );
    assert!(
        tex.contains("\\caption{") && tex.contains("\\label{tab:optimis-noise}") && tex.ends_with("\\end{table}\n")
    );
    // Without a published figure, no paper columns.
    assert!(!noise_table_markdown(&rows, |_| None, &opts).contains("paper"));
    assert!(noise_table_latex(&rows, |_| None, &opts).contains("{lrr}"));
    let bare = noise_table_latex(&rows, paper, &TextTable { bare: true, ..TextTable::default() });
    assert!(bare.starts_with('%') && bare.ends_with("\\end{tabular}\n}\n") && !bare.contains("caption"), "{bare}");
}

#[test]
fn chosen_rows_come_in_their_order_and_the_recommended_one_is_marked() {
    let rows = rows();
    let chosen = parse_rows("optimal_cv, switch", &rows).unwrap();
    assert_eq!(chosen, vec![Strategy::OptimalCv, Strategy::Switch]);
    let opts = TextTable { rows: Some(chosen), recommended: Some(Strategy::OptimalCv), ..TextTable::default() };
    let tex = noise_table_latex(&rows, paper, &opts);
    let cv = tex.find("optimal\\_\\allowbreak cv").unwrap();
    assert!(cv < tex.find("switch &").unwrap() && !tex.contains("balance"), "{tex}");
    assert!(
        tex.contains("\\raggedright \\textbf{optimal\\_\\allowbreak cv}* & \\textbf{26.500 $\\pm$ 0.150}"),
        "{tex}"
    );
    assert!(tex.contains("Recommended row in bold"), "{tex}");
    let md = noise_table_markdown(&rows, paper, &opts);
    assert!(md.contains("| **`optimal_cv`** * |"), "{md}");
    assert_eq!(parse_rows("switch,nonsense", &rows), Err(RowsError::Unknown("nonsense".into())));
    assert_eq!(parse_rows("plane1", &rows), Err(RowsError::Absent("plane1".into())));
    assert_eq!(parse_rows(" , ", &rows), Err(RowsError::Empty));
}

#[test]
fn a_given_caption_is_escaped_and_a_negative_z_has_a_real_minus() {
    let rows = [row(Strategy::Switch, 26.0e-5, 0.1e-5, 55.0, 2.0)];
    let opts = TextTable { caption: Some("R = 0.003 & 50% of {runs} #1_a".into()), ..TextTable::default() };
    let tex = noise_table_latex(&rows, paper, &opts);
    assert!(tex.contains("\\caption{R = 0.003 \\& 50\\% of \\{runs\\} \\#1\\_a}"), "{tex}");
    // z of L: (26.0 − 26.352)/0.1 = −3.5.
    assert!(tex.contains("$-$3.5"), "{tex}");
    assert!(noise_table_markdown(&rows, paper, &TextTable::default()).contains("| −3.5 |"));
}
