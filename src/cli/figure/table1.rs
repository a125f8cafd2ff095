//! Table 1 as a figure: each strategy's RMS noise of one iteration as a bar with ± 1 standard
//! error, in the noise table's order, the recommended row marked, the fitted rows told apart from
//! the per-path ones, and the paper's published RMS beside its five rows where its table applies
//! to the run (`sim::checks::published`). An in-sample row (`optimal`) says so in its label.

use std::path::Path;

use plotters::prelude::*;

use super::solvable::Solvable;
use super::{COLORS, drawing, legend};
use super::{HEIGHT, WIDTH};
use crate::cli::CliError;
use crate::sim::checks::published::{applicable, figures};
use crate::sim::solve::row::NoiseRow;

/// One bar: the row's label, RMS, SE, the paper's RMS, and how it is drawn.
struct Bar {
    label: String,
    rms: f64,
    stderr: Option<f64>,
    paper: Option<f64>,
    fitted: bool,
    recommended: bool,
}

/// Table 1 as SVG, and what it shows.
pub(super) fn figure(document: &Path) -> Result<(String, String), CliError> {
    let solvable = Solvable::read(document)?;
    let report = solvable.report(None);
    let published = applicable(&solvable.doc.spec);
    let chosen = report.recommended.as_ref().map(|r| r.strategy);
    let bars: Vec<Bar> = report
        .noise_table
        .iter()
        .filter_map(|r: &NoiseRow| {
            let rms = r.rms_percent?;
            let name = r.strategy.to_string();
            let mut label = if r.in_sample { format!("{name} (in-sample)") } else { name.clone() };
            if Some(r.strategy) == chosen {
                label.push_str(" ← recommended");
            }
            Some(Bar {
                label,
                rms,
                stderr: r.rms_percent_stderr,
                paper: figures(&published, &name).map(|p| p.1),
                fitted: r.lambda.is_some() || r.in_sample,
                recommended: Some(r.strategy) == chosen,
            })
        })
        .collect();
    if bars.is_empty() {
        return Err(CliError::Unusable { path: document.to_path_buf(), detail: "no row has an RMS to draw".into() });
    }
    let with_paper = bars.iter().any(|b| b.paper.is_some());
    let what = format!(
        "RMS of one iteration, ± 1 SE, {} iterations{}",
        report.iterations,
        if with_paper { ", the paper's Table 1 beside it" } else { " (the paper's Table 1 does not apply)" }
    );
    let svg = draw(&bars, &what).map_err(drawing)?;
    Ok((svg, what))
}

fn draw(bars: &[Bar], title: &str) -> Result<String, Box<dyn std::error::Error>> {
    let n = bars.len() as i32;
    let x_max =
        bars.iter().map(|b| (b.rms + b.stderr.unwrap_or(0.0)).max(b.paper.unwrap_or(0.0))).fold(0.0, f64::max) * 1.08;
    // Row i is segment n − 1 − i: the table's first row at the top.
    let segment = |i: usize| n - 1 - i as i32;
    let labels: Vec<String> = bars.iter().rev().map(|b| b.label.clone()).collect();
    let (per_path, fitted, chosen) = (COLORS[0], COLORS[3], COLORS[1]);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(330)
            .build_cartesian_2d(0.0..x_max, (0..n - 1).into_segmented())?;
        chart
            .configure_mesh()
            .disable_y_mesh()
            .y_labels(bars.len())
            .y_label_formatter(&|v| match v {
                SegmentValue::CenterOf(k) => labels.get(*k as usize).cloned().unwrap_or_default(),
                _ => String::new(),
            })
            .x_desc("RMS noise of one iteration (% of L)")
            .label_style(("sans-serif", 16))
            .draw()?;
        chart.draw_series(bars.iter().enumerate().map(|(i, b)| {
            let color = if b.recommended {
                chosen
            } else if b.fitted {
                fitted
            } else {
                per_path
            };
            let y = segment(i);
            let mut bar = Rectangle::new(
                [(0.0, SegmentValue::Exact(y)), (b.rms, SegmentValue::Exact(y + 1))],
                color.mix(0.75).filled(),
            );
            bar.set_margin(5, 5, 0, 0);
            bar
        }))?;
        chart.draw_series(bars.iter().enumerate().filter_map(|(i, b)| {
            let se = b.stderr?;
            let y = SegmentValue::CenterOf(segment(i));
            Some(ErrorBar::new_horizontal(y, b.rms - se, b.rms, b.rms + se, BLACK.stroke_width(2), 10))
        }))?;
        // The legend's entries: the three bar colours, then the paper's marker.
        let swatch = |color: RGBColor| {
            move |(x, y): (i32, i32)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], color.mix(0.75).filled())
        };
        for (name, color) in [("per-path weights", per_path), ("fitted weights", fitted), ("recommended", chosen)] {
            chart
                .draw_series(std::iter::empty::<Circle<(f64, SegmentValue<i32>), i32>>())?
                .label(name)
                .legend(swatch(color));
        }
        if bars.iter().any(|b| b.paper.is_some()) {
            chart
                .draw_series(bars.iter().enumerate().filter_map(|(i, b)| {
                    Some(TriangleMarker::new((b.paper?, SegmentValue::CenterOf(segment(i))), 8, BLACK.filled()))
                }))?
                .label("the paper's Table 1")
                .legend(|(x, y)| TriangleMarker::new((x + 9, y), 8, BLACK.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        root.present()?;
    }
    Ok(svg)
}
