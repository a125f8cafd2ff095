//! The paper's Fig. 2 from a moments document: w₁ against r₃ of the recommended weights table,
//! one line per r₂ bin, ± 1 standard error (open markers, no bar, for a `smoothed` cell: its weight
//! comes from the penalty, not its own samples), a dashed line at r₃ = a for the spot. When the run
//! recommends a per-path strategy (no table), the table optimum at optimal_cv's λ is drawn and the
//! title says it is not the recommendation; `--lambda` draws the in-sample table at that λ (0: the
//! paper's).

use std::path::Path;

use plotters::prelude::*;

use super::solvable::Solvable;
use super::{COLORS, drawing, legend};
use crate::cli::CliError;
use crate::sim::model::params::IlluminationSpec;
use crate::sim::solve::report::WeightRow;
use crate::sim::solve::solver::CellStatus;
use crate::sim::solve::strategy::Strategy;

/// The drawing's size in SVG user units (pixels at 1×).
pub const WIDTH: u32 = 1200;
pub const HEIGHT: u32 = 800;

/// Fig. 2 as SVG, and what it shows (for the CLI's message).
pub(super) fn figure(document: &Path, lambda: Option<f64>) -> Result<(String, String), CliError> {
    let solvable = Solvable::read(document)?;
    let report = solvable.report(lambda);
    let recommended = report.recommended.as_ref().map(|r| r.strategy.to_string()).unwrap_or_else(|| "none".into());
    let (report, what) = match (lambda, report.weights.is_empty()) {
        (Some(l), _) => (report, format!("in-sample table optimum at λ = {l} (recommended: {recommended})")),
        (None, false) => (report, format!("recommended table: {recommended}")),
        (None, true) => {
            let cv = report.noise_table.iter().find(|r| r.strategy == Strategy::OptimalCv).and_then(|r| r.lambda);
            match cv {
                Some(l) => (
                    solvable.report(Some(l)),
                    format!("table optimum at optimal_cv's λ = {l} — not recommended ({recommended} is)"),
                ),
                None => {
                    return Err(CliError::Unusable {
                        path: document.to_path_buf(),
                        detail:
                            "no weights table to draw: a per-path strategy is recommended and optimal_cv has no fit"
                                .into(),
                    });
                }
            }
        }
    };
    let spot = match &solvable.doc.spec.scene.illumination {
        IlluminationSpec::Spot { a, .. } => Some(*a),
        _ => None,
    };
    let svg = draw_fig2(&report.weights, spot, &what, report.iterations).map_err(drawing)?;
    Ok((svg, what))
}

/// The r₃ a cell is drawn at: its middle, or for the open tail cell its lower edge plus the
/// width of the cell before it.
fn r3_of(w: &WeightRow, tail_width: f64) -> f64 {
    let lo = w.r3[0].unwrap_or(0.0);
    match w.r3[1] {
        Some(hi) => 0.5 * (lo + hi),
        None => lo + 0.5 * tail_width,
    }
}

fn draw_fig2(
    weights: &[WeightRow],
    spot: Option<f64>,
    what: &str,
    iterations: u64,
) -> Result<String, Box<dyn std::error::Error>> {
    let mut bins: Vec<f64> = weights.iter().map(|w| w.r2[0].unwrap_or(0.0)).collect();
    bins.sort_by(f64::total_cmp);
    bins.dedup();
    let tail_width = weights.iter().filter_map(|w| Some(w.r3[1]? - w.r3[0]?)).fold(0.0, f64::max);
    let xs: Vec<f64> = weights.iter().map(|w| r3_of(w, tail_width)).collect();
    let x_max = xs.iter().copied().fold(spot.unwrap_or(0.0), f64::max) * 1.05;
    let (mut y_lo, mut y_hi) = (0.0_f64, 1.0_f64);
    for w in weights {
        let se = w.w1_stderr.unwrap_or(0.0);
        y_lo = y_lo.min(w.w1 - se);
        y_hi = y_hi.max(w.w1 + se);
    }
    // Sparse cells can fit far outside [0, 1]: keep the axis readable, as the dashboard does.
    let (y_lo, y_hi) = (y_lo.max(-1.0) - 0.05, y_hi.min(2.0) + 0.05);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("w1 against r3 ({iterations} iterations): {what}"), ("sans-serif", 22))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc("r3 (distance of the plane-3 vertex from the axis)")
            .y_desc("w1 (± 1 standard error)")
            .label_style(("sans-serif", 16))
            .draw()?;
        if let Some(a) = spot {
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(a, y_lo), (a, y_hi)],
                    8,
                    6,
                    ShapeStyle::from(&BLACK.mix(0.6)).stroke_width(1),
                ))?
                .label(format!("r3 = a = {a}"))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.6)));
        }
        for (k, lo) in bins.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            let mut cells: Vec<(f64, &WeightRow)> =
                weights.iter().zip(&xs).filter(|(w, _)| w.r2[0].unwrap_or(0.0) == *lo).map(|(w, &x)| (x, w)).collect();
            cells.sort_by(|a, b| a.0.total_cmp(&b.0));
            let hi = weights.iter().find(|w| w.r2[0].unwrap_or(0.0) == *lo).and_then(|w| w.r2[1]);
            let name = match hi {
                Some(hi) => format!("r2 in [{lo}, {hi})"),
                None => format!("r2 ≥ {lo}"),
            };
            chart
                .draw_series(LineSeries::new(cells.iter().map(|(x, w)| (*x, w.w1)), color.stroke_width(2)))?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            chart.draw_series(cells.iter().filter_map(|(x, w)| {
                let se = w.w1_stderr.filter(|_| w.status != CellStatus::Smoothed)?;
                // Width 6: caps of 6 px, and plotters' dot at the middle (radius 3) under the marker.
                Some(ErrorBar::new_vertical(*x, w.w1 - se, w.w1, w.w1 + se, color.stroke_width(1), 6))
            }))?;
            chart.draw_series(cells.iter().map(|(x, w)| {
                let data = w.w1_stderr.is_some() && w.status != CellStatus::Smoothed;
                let style = if data { color.filled() } else { color.stroke_width(2) };
                Circle::new((*x, w.w1), 4, style)
            }))?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        root.present()?;
    }
    Ok(svg)
}
