//! Convergence as a figure, from a job's history (`GET /v1/jobs/{id}/history`): above, each
//! strategy's L with its ± 1 SE band (SE = |L|·RMS/√M, the band the dashboard draws); below, its
//! RMS noise of one iteration; both against the iterations on a log axis. Fitted rows' figures are
//! cross-fitted at every checkpoint, as in the history.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Deserialize;

use super::{COLORS, drawing};
use super::{HEIGHT, WIDTH};
use crate::cli::CliError;

/// The strategies drawn by default (those the history has): the paper's four cases and the rows a
/// reader compares them with.
const DEFAULT: [&str; 7] =
    ["plane1", "plane2", "plane3", "switch", "optimal_cv", "optimal_stacked", "correlation_aware_planes23"];
/// One colour per curve: more curves would not read apart.
const MAX_CURVES: usize = COLORS.len();
/// The legend's column, right of both panels (it would hide the curves inside them).
const LEGEND_WIDTH: u32 = 290;
/// L is drawn in units of 10⁻⁵, as the paper prints it.
const SCALE: f64 = 1e5;
/// Checkpoints read: the server thins a history to 1,000; a hand-made file gets the same bound.
const MAX_POINTS: usize = 10_000;

#[derive(Debug, Deserialize)]
struct History {
    job_id: Option<i64>,
    points: Vec<Point>,
}

#[derive(Debug, Deserialize)]
struct Point {
    iterations: u64,
    strategies: Vec<Figures>,
}

#[derive(Debug, Deserialize)]
struct Figures {
    strategy: String,
    luminance: Option<f64>,
    rms_percent: Option<f64>,
}

/// One strategy's curve: (iterations, L, SE of L, RMS %) at every checkpoint that has figures.
struct Curve {
    name: String,
    points: Vec<(f64, f64, f64, f64)>,
}

fn unusable(document: &Path, detail: impl Into<String>) -> CliError {
    CliError::Unusable { path: document.to_path_buf(), detail: detail.into() }
}

/// The convergence figure as SVG, and what it shows.
pub(super) fn figure(document: &Path, wanted: &[String]) -> Result<(String, String), CliError> {
    let bytes = std::fs::read(document).map_err(|source| CliError::Read { path: document.to_path_buf(), source })?;
    let history: History = serde_json::from_slice(&bytes)
        .map_err(|e| unusable(document, format!("not a job history (GET /v1/jobs/{{id}}/history): {e}")))?;
    if history.points.len() > MAX_POINTS {
        return Err(unusable(
            document,
            format!("{} checkpoints: at most {MAX_POINTS} are drawn", history.points.len()),
        ));
    }
    let present: Vec<&str> =
        history.points.last().map(|p| p.strategies.iter().map(|s| s.strategy.as_str()).collect()).unwrap_or_default();
    let names: Vec<String> = if wanted.is_empty() {
        DEFAULT.iter().filter(|d| present.contains(d)).map(|d| d.to_string()).collect()
    } else {
        if let Some(missing) = wanted.iter().find(|w| !present.contains(&w.as_str())) {
            return Err(CliError::Config(format!(
                "invalid argument --strategies: the history has no {missing:?} (it has: {})",
                present.join(", ")
            )));
        }
        wanted.to_vec()
    };
    if names.len() > MAX_CURVES {
        return Err(CliError::Config(format!(
            "invalid argument --strategies: at most {MAX_CURVES} curves, got {}",
            names.len()
        )));
    }
    let curves: Vec<Curve> = names
        .iter()
        .map(|name| Curve {
            name: name.clone(),
            points: history
                .points
                .iter()
                .filter(|p| p.iterations > 0)
                .filter_map(|p| {
                    let f = p.strategies.iter().find(|s| &s.strategy == name)?;
                    let (l, rms) = (f.luminance?, f.rms_percent?);
                    let m = p.iterations as f64;
                    Some((m, l, l.abs() * rms / 100.0 / m.sqrt(), rms))
                })
                .filter(|(_, l, se, rms)| l.is_finite() && se.is_finite() && rms.is_finite())
                .collect(),
        })
        .filter(|c| !c.points.is_empty())
        .collect();
    if curves.is_empty() {
        return Err(unusable(document, "no checkpoint with figures to draw"));
    }
    let job = history.job_id.map(|id| format!("job {id}: ")).unwrap_or_default();
    let what = format!("{job}L ± 1 SE and RMS against iterations ({} checkpoints)", history.points.len());
    let svg = draw(&curves, &what).map_err(drawing)?;
    Ok((svg, what))
}

/// The range of `values` with a margin (a flat series gets ± 1% of its value).
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = ((hi - lo) * 0.05).max(hi.abs().max(lo.abs()) * 0.01).max(f64::MIN_POSITIVE);
    (lo - pad, hi + pad)
}

fn draw(curves: &[Curve], title: &str) -> Result<String, Box<dyn std::error::Error>> {
    let all = || curves.iter().flat_map(|c| c.points.iter());
    let (m_lo, m_hi) = all().fold((f64::INFINITY, 0.0_f64), |(lo, hi), p| (lo.min(p.0), hi.max(p.0)));
    let m_hi = if m_hi > m_lo { m_hi } else { m_lo * 10.0 };
    let (l_lo, l_hi) = range(all().flat_map(|p| [(p.1 - p.2) * SCALE, (p.1 + p.2) * SCALE]));
    // RMS: the settled part sets the axis (the first checkpoints of a fitted row can be 10× off).
    let settled: Vec<f64> = curves.iter().flat_map(|c| c.points.iter().skip(c.points.len() / 4).map(|p| p.3)).collect();
    let (_, r_hi) = range(settled.iter().copied());
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 22))?;
        let (charts, legend) = root.split_horizontally(WIDTH - LEGEND_WIDTH);
        let (top, bottom) = charts.split_vertically(HEIGHT as i32 * 47 / 100);
        panel(&top, curves, (m_lo, m_hi), (l_lo, l_hi), "L × 10⁵ (model units), ± 1 SE", |p| {
            (p.1 * SCALE, Some(((p.1 - p.2) * SCALE, (p.1 + p.2) * SCALE)))
        })?;
        panel(&bottom, curves, (m_lo, m_hi), (0.0, r_hi), "RMS of one iteration (%)", |p| (p.3, None))?;
        for (k, c) in curves.iter().enumerate() {
            let y = 60 + 28 * k as i32;
            let color = COLORS[k];
            legend.draw(&PathElement::new(vec![(10, y), (40, y)], color.stroke_width(3)))?;
            legend.draw(&Text::new(c.name.clone(), (48, y - 9), ("sans-serif", 16).into_font()))?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// A log axis's label at 1, 2 and 5 × 10ᵏ only (plotters offers every integer step, which crowd).
fn decade_label(m: &f64) -> String {
    let mantissa = m / 10f64.powf(m.log10().floor());
    if [1.0, 2.0, 5.0].iter().any(|d| (mantissa - d).abs() < 1e-6) { format!("{m:.0}") } else { String::new() }
}

type Value = fn(&(f64, f64, f64, f64)) -> (f64, Option<(f64, f64)>);

/// One panel: every curve's value against the iterations (log axis), with its band if any.
fn panel(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    curves: &[Curve],
    (m_lo, m_hi): (f64, f64),
    (y_lo, y_hi): (f64, f64),
    y_desc: &str,
    value: Value,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut chart = ChartBuilder::on(area)
        .margin(15)
        .margin_right(35)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d((m_lo..m_hi).log_scale(), y_lo..y_hi)?;
    chart
        .configure_mesh()
        .x_desc("iterations")
        .y_desc(y_desc)
        .x_label_formatter(&decade_label)
        .label_style(("sans-serif", 15))
        .draw()?;
    for (k, c) in curves.iter().enumerate() {
        let color = COLORS[k];
        let band: Vec<(f64, f64, f64)> =
            c.points.iter().filter_map(|p| value(p).1.map(|(lo, hi)| (p.0, lo.max(y_lo), hi.min(y_hi)))).collect();
        if band.len() > 1 {
            let outline = band.iter().map(|b| (b.0, b.2)).chain(band.iter().rev().map(|b| (b.0, b.1)));
            chart.draw_series(std::iter::once(Polygon::new(outline.collect::<Vec<_>>(), color.mix(0.12).filled())))?;
        }
        let line: Vec<(f64, f64)> = c.points.iter().map(|p| (p.0, value(p).0.clamp(y_lo, y_hi))).collect();
        chart.draw_series(LineSeries::new(line, color.stroke_width(2)))?;
    }
    Ok(())
}
