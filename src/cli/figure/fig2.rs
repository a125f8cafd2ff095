//! The paper's Fig. 2 from a moments document, in two panels.
//!
//! * **What is recommended** (left): the recommended row's *effective* w₁ and w₂ against r₃, one
//!   colour per r₂ bin, ± 1 SE — the contribution-weighted average of each technique's weight over
//!   the bin's full paths (`sim::weights::effective`), so a heuristic, a table and a stack are drawn
//!   alike, with the sampling and fit errors combined. `--strategy` draws another row's.
//! * **The paper's procedure** (right): the in-sample table optimum at λ (`--weights-lambda`, default 0,
//!   as the paper fits it) cell by cell, labelled as an in-sample fit. Its cells can be noise far
//!   outside [0, 1]: the axis is fixed to [−0.5, 1.5] and an off-scale cell is a triangle at the
//!   frame's edge with its value written beside it, never clipped silently. Cells whose weights were
//!   copied from a neighbour (`empty`, `uninformative`) are not data and are not drawn; an r₂ bin
//!   with nothing else says so in the legend (in the paper's preset no path reaches r₂ ≥ 0.5).

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::solvable::Solvable;
use super::{COLORS, drawing};
use crate::cli::CliError;
use crate::sim::model::params::IlluminationSpec;
use crate::sim::solve::effective::{EffectiveBin, EffectiveWeights};
use crate::sim::solve::report::{RunReport, WeightRow};
use crate::sim::solve::solver::CellStatus;
use crate::sim::solve::strategy::Strategy;

/// The drawing's size in SVG user units (pixels at 1×): two panels side by side.
pub const WIDTH: u32 = 1600;
pub const HEIGHT: u32 = 700;

/// The λ = 0 panel's fixed w₁ range: wide enough for every honest weight, narrow enough to read.
const PAPER_RANGE: (f64, f64) = (-0.5, 1.5);

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// What the panels draw on: any plotters backend whose errors can be boxed (SVG here).
trait Backend: DrawingBackend<ErrorType: 'static> {}
impl<DB: DrawingBackend<ErrorType: 'static>> Backend for DB {}

/// Fig. 2 as SVG, and what it shows (for the CLI's message).
pub(super) fn figure(
    document: &Path,
    lambda: Option<f64>,
    strategy: Option<Strategy>,
) -> Result<(String, String), CliError> {
    let solvable = Solvable::read(document)?;
    let effective = solvable.effective(strategy).map_err(|detail| CliError::Unusable {
        path: document.to_path_buf(),
        detail: format!("no effective weights to draw: {detail}"),
    })?;
    let lambda = lambda.unwrap_or(0.0);
    let paper = solvable.report(Some(lambda));
    let spot = match &solvable.doc.spec.scene.illumination {
        IlluminationSpec::Spot { a, .. } => Some(*a),
        _ => None,
    };
    let recommended = paper.recommended.as_ref().map(|r| r.strategy.to_string());
    let mark = if recommended.as_deref() == Some(effective.strategy.as_str()) { " (recommended)" } else { "" };
    let what = format!(
        "effective weights of {}{mark}, a {}; the in-sample table at λ = {lambda}",
        effective.strategy, effective.kind
    );
    let svg = draw(&effective, &paper, lambda, spot).map_err(drawing)?;
    Ok((svg, what))
}

fn draw(
    effective: &EffectiveWeights,
    paper: &RunReport,
    lambda: f64,
    spot: Option<f64>,
) -> Result<String, Box<dyn std::error::Error>> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let root =
            root.titled(&format!("Fig. 2: w1 against r3 ({} iterations)", paper.iterations), ("sans-serif", 24))?;
        let (left, right) = root.split_horizontally(WIDTH / 2);
        effective_panel(&left, effective, spot)?;
        paper_panel(&right, paper, lambda, spot)?;
        root.present()?;
    }
    Ok(svg)
}

/// The r₃ a bin or cell is drawn at: its middle, or for the open tail its lower edge plus half the
/// width of the widest finite bin.
fn r3_of(r3: [Option<f64>; 2], tail_width: f64) -> f64 {
    let lo = r3[0].unwrap_or(0.0);
    match r3[1] {
        Some(hi) => 0.5 * (lo + hi),
        None => lo + 0.5 * tail_width,
    }
}

fn tail_width<'a>(r3: impl Iterator<Item = &'a [Option<f64>; 2]>) -> f64 {
    r3.filter_map(|r| Some(r[1]? - r[0]?)).fold(0.0, f64::max)
}

/// The label of an r₂ bin.
fn r2_name(r2: [Option<f64>; 2]) -> String {
    let lo = r2[0].unwrap_or(0.0);
    match r2[1] {
        Some(hi) => format!("r2 in [{lo}, {hi})"),
        None => format!("r2 ≥ {lo}"),
    }
}

/// The distinct r₂ bins of `r2`, in order.
fn r2_bins(r2: impl Iterator<Item = [Option<f64>; 2]>) -> Vec<[Option<f64>; 2]> {
    let mut bins: Vec<[Option<f64>; 2]> = r2.collect();
    bins.sort_by(|a, b| a[0].unwrap_or(0.0).total_cmp(&b[0].unwrap_or(0.0)));
    bins.dedup();
    bins
}

/// Axes, the spot's guide and the caption of one panel.
fn panel<'a, DB: Backend + 'a>(
    area: &'a DrawingArea<DB, plotters::coord::Shift>,
    caption: &str,
    x_max: f64,
    (y_lo, y_hi): (f64, f64),
    spot: Option<f64>,
) -> Result<Chart<'a, DB>, Box<dyn std::error::Error>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 17))
        .margin(16)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_max, y_lo..y_hi)?;
    chart
        .configure_mesh()
        .x_desc("r3 (distance of the plane-3 vertex from the axis)")
        .y_desc("w (± 1 standard error)")
        .label_style(("sans-serif", 15))
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
    Ok(chart)
}

/// The series labels, in the figures' one legend style (`super::legend`, for any backend).
fn legend<'a, DB: Backend + 'a>(chart: &mut Chart<'a, DB>) -> Result<(), Box<dyn std::error::Error>> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::MiddleRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()?;
    Ok(())
}

/// A legend entry with no series: what the panel leaves out and why.
fn note<'a, DB: Backend + 'a>(chart: &mut Chart<'a, DB>, text: String) -> Result<(), Box<dyn std::error::Error>> {
    chart.draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?.label(text).legend(|(x, y)| {
        EmptyElement::at((x, y)) + Text::new("—", (0, -8), ("sans-serif", 14).into_font().color(&BLACK.mix(0.5)))
    });
    Ok(())
}

/// The left panel: effective w₁ (solid, filled) and w₂ (dashed, open) per r₂ bin, ± 1 SE.
fn effective_panel<DB: Backend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    effective: &EffectiveWeights,
    spot: Option<f64>,
) -> Result<(), Box<dyn std::error::Error>> {
    let tail = tail_width(effective.bins.iter().map(|b| &b.r3));
    let drawn: Vec<(f64, &EffectiveBin, [f64; 3], [f64; 3])> = effective
        .bins
        .iter()
        .filter_map(|b| Some((r3_of(b.r3, tail), b, b.w?, b.stderr.unwrap_or([0.0; 3]))))
        .collect();
    let x_max = drawn.iter().map(|d| d.0).fold(spot.unwrap_or(0.0), f64::max) * 1.05;
    let (mut y_lo, mut y_hi) = (0.0_f64, 1.0_f64);
    for (_, _, w, se) in &drawn {
        for m in 1..3 {
            y_lo = y_lo.min(w[m] - se[m]);
            y_hi = y_hi.max(w[m] + se[m]);
        }
    }
    let caption = format!(
        "{}: {} (effective weights, {} paths per side)",
        effective.strategy, effective.kind, effective.paths_per_side
    );
    let mut chart = panel(area, &caption, x_max.max(1e-9), (y_lo - 0.05, y_hi + 0.05), spot)?;
    for (k, r2) in r2_bins(effective.bins.iter().map(|b| b.r2)).into_iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let mut points: Vec<&(f64, &EffectiveBin, [f64; 3], [f64; 3])> =
            drawn.iter().filter(|d| d.1.r2 == r2).collect();
        if points.is_empty() {
            note(&mut chart, format!("{}: no sampled path carries light", r2_name(r2)))?;
            continue;
        }
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (m, dashed) in [(1usize, false), (2, true)] {
            let label = format!("{}: w{m}", r2_name(r2));
            let line: Vec<(f64, f64)> = points.iter().map(|d| (d.0, d.2[m])).collect();
            if dashed {
                chart
                    .draw_series(DashedLineSeries::new(line, 6, 4, color.stroke_width(2)))?
                    .label(label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(1)));
            } else {
                chart
                    .draw_series(LineSeries::new(line, color.stroke_width(2)))?
                    .label(label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            }
            chart.draw_series(points.iter().map(|d| {
                ErrorBar::new_vertical(d.0, d.2[m] - d.3[m], d.2[m], d.2[m] + d.3[m], color.stroke_width(1), 6)
            }))?;
            let style = if dashed { color.stroke_width(2) } else { color.filled() };
            chart.draw_series(points.iter().map(|d| Circle::new((d.0, d.2[m]), 4, style)))?;
        }
    }
    legend(&mut chart)?;
    Ok(())
}

/// Whether a cell's weights are data of its own (not copied from a neighbour).
fn is_data(w: &WeightRow) -> bool {
    !matches!(w.status, CellStatus::Empty | CellStatus::Uninformative)
}

/// The right panel: the in-sample table at λ, fitted cells only, off-scale cells marked.
fn paper_panel<DB: Backend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    report: &RunReport,
    lambda: f64,
    spot: Option<f64>,
) -> Result<(), Box<dyn std::error::Error>> {
    let weights = &report.weights;
    let tail = tail_width(weights.iter().map(|w| &w.r3));
    let x_max = weights.iter().map(|w| r3_of(w.r3, tail)).fold(spot.unwrap_or(0.0), f64::max) * 1.05;
    let caption = format!("the paper's procedure: table fitted in-sample at λ = {lambda} (not an honest estimate)");
    let (y_lo, y_hi) = PAPER_RANGE;
    let mut chart = panel(area, &caption, x_max.max(1e-9), (y_lo, y_hi), spot)?;
    if let Some(error) = &report.solve_error {
        note(&mut chart, format!("no fit at λ = {lambda}: {error}"))?;
    }
    let mut off_scale = 0;
    for (k, r2) in r2_bins(weights.iter().map(|w| w.r2)).into_iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let mut cells: Vec<(f64, &WeightRow)> =
            weights.iter().filter(|w| w.r2 == r2 && is_data(w)).map(|w| (r3_of(w.r3, tail), w)).collect();
        let copied = weights.iter().filter(|w| w.r2 == r2 && !is_data(w)).count();
        if cells.is_empty() {
            note(&mut chart, format!("{}: every cell copied from a neighbour (no merges), not drawn", r2_name(r2)))?;
            continue;
        }
        cells.sort_by(|a, b| a.0.total_cmp(&b.0));
        let on_scale = |w: f64| (y_lo..=y_hi).contains(&w);
        let name = if copied > 0 { format!("{} ({copied} copied cells not drawn)", r2_name(r2)) } else { r2_name(r2) };
        // The line breaks where a cell leaves the frame: a segment to the edge would be a value
        // the cell does not have.
        for run in cells.split(|(_, w)| !on_scale(w.w1)) {
            chart.draw_series(LineSeries::new(run.iter().map(|(x, w)| (*x, w.w1)), color.stroke_width(2)))?;
        }
        chart
            .draw_series(cells.iter().filter(|(_, w)| on_scale(w.w1)).map(|(x, w)| {
                let style = if w.w1_stderr.is_some() && w.status != CellStatus::Smoothed {
                    color.filled()
                } else {
                    color.stroke_width(2)
                };
                Circle::new((*x, w.w1), 4, style)
            }))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        chart.draw_series(cells.iter().filter(|(_, w)| on_scale(w.w1)).filter_map(|(x, w)| {
            let se = w.w1_stderr.filter(|_| w.status != CellStatus::Smoothed)?;
            let clamp = |v: f64| v.clamp(y_lo, y_hi);
            Some(ErrorBar::new_vertical(*x, clamp(w.w1 - se), w.w1, clamp(w.w1 + se), color.stroke_width(1), 6))
        }))?;
        for (x, w) in cells.iter().filter(|(_, w)| !on_scale(w.w1)) {
            let up = w.w1 > y_hi;
            let edge = if up { y_hi } else { y_lo };
            let value = match w.w1_stderr {
                Some(se) => format!("{:.2} ± {se:.2}", w.w1),
                None => format!("{:.2}", w.w1),
            };
            // Neighbouring off-scale cells would write over each other: three staggered rows.
            let row = 15 * (off_scale % 3);
            chart.draw_series(std::iter::once(
                EmptyElement::at((*x, edge))
                    + Polygon::new(
                        if up { vec![(0, 0), (-6, 11), (6, 11)] } else { vec![(0, 0), (-6, -11), (6, -11)] },
                        color.filled(),
                    )
                    + Text::new(
                        value,
                        (8, if up { 10 + row } else { -22 - row }),
                        ("sans-serif", 13).into_font().color(&color),
                    ),
            ))?;
            off_scale += 1;
        }
    }
    if off_scale > 0 {
        note(&mut chart, format!("▲▼ {off_scale} cells off the scale [{y_lo}, {y_hi}], value ± SE beside"))?;
    }
    legend(&mut chart)?;
    Ok(())
}
