//! `optimis figure fig2|table1|convergence DOC --out F.svg|png|pdf`: publication figures without a
//! browser. Each figure is drawn once, as SVG, by plotters (`fig2`, `table1`, `convergence`); PNG
//! and PDF are that SVG rendered by resvg and converted by svg2pdf (`render`), so the three files
//! show the same drawing.
//!
//! Imports: crate::cli, crate::sim

mod convergence;
mod fig2;
mod render;
mod solvable;
mod table1;

use std::path::{Path, PathBuf};

use clap::Args;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::CliError;
use super::documents::{lambda_flag, parse_strategy};
use super::run::write_atomically;
use crate::sim::model::params::check;

/// The size of a one-panel drawing (table1, convergence) in SVG user units (pixels at 1×);
/// fig2's two panels have their own (`fig2::WIDTH`).
pub const WIDTH: u32 = 1200;
pub const HEIGHT: u32 = 800;

/// The largest PNG width: 8192 px is beyond any journal's column at 600 dpi and bounds the pixmap
/// (8192 × 5462 × 4 bytes ≈ 180 MB).
const MAX_WIDTH: u32 = 8192;

#[derive(Debug, Args)]
pub struct FigureArgs {
    /// Which figure: `fig2` (the paper's Fig. 2: the recommended weights' effective w₁ and w₂
    /// against r₃, and the in-sample table the paper draws), `table1`
    /// (each strategy's RMS ± SE, the paper's values beside them where they apply) — both from a
    /// moments document —, or `convergence` (L ± SE and RMS against iterations, from a job's
    /// history: `GET /v1/jobs/{id}/history`).
    #[arg(value_parser = ["fig2", "table1", "convergence"])]
    pub which: String,
    /// A moments document (`optimis run --out`, `GET /v1/jobs/{id}/moments`) for fig2 and table1;
    /// a history document (`GET /v1/jobs/{id}/history`) for convergence.
    pub document: PathBuf,
    /// Where to write the figure: FILE.svg, FILE.png or FILE.pdf.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// PNG only: the image's width in pixels (default twice the drawing's: 3200 for fig2, 2400
    /// for the others).
    #[arg(long, value_name = "PX")]
    pub width: Option<u32>,
    /// fig2 only: the λ of the right panel, the in-sample table optimum (default 0: the paper's
    /// procedure). (Table 1's rows do not depend on it: each fitted row has its own λ.) The same
    /// name as `optimis report --weights-lambda`; `--lambda` is kept as an alias.
    #[arg(long = "weights-lambda", alias = "lambda", allow_hyphen_values = true)]
    pub lambda: Option<f64>,
    /// fig2 only: the noise-table row whose effective weights the left panel draws (default: the
    /// recommended row).
    #[arg(long, value_name = "STRATEGY")]
    pub strategy: Option<String>,
    /// convergence only: the strategies to draw, comma-separated (default: the paper's four cases,
    /// and optimal_cv, optimal_stacked and correlation_aware_planes23 where the history has them).
    #[arg(long, value_delimiter = ',')]
    pub strategies: Vec<String>,
}

/// The file formats a figure is written in.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Svg,
    Png { width: u32 },
    Pdf,
}

fn format_of(args: &FigureArgs) -> Result<Format, CliError> {
    let extension = args.out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let format = match extension.as_deref() {
        Some("svg") => Format::Svg,
        Some("png") => {
            let drawing = if args.which == "fig2" { fig2::WIDTH } else { WIDTH };
            Format::Png { width: args.width.unwrap_or(2 * drawing) }
        }
        Some("pdf") => Format::Pdf,
        _ => {
            return Err(CliError::Config(format!(
                "--out {}: figures are written as FILE.svg, FILE.png or FILE.pdf",
                args.out.display()
            )));
        }
    };
    if let Some(w) = args.width {
        check(matches!(format, Format::Png { .. }), "--width", || {
            "applies to PNG output only (--out FILE.png)".into()
        })?;
        check((100..=MAX_WIDTH).contains(&w), "--width", || format!("must be in [100, {MAX_WIDTH}] pixels, got {w}"))?;
    }
    Ok(format)
}

pub fn figure(args: FigureArgs) -> Result<(), CliError> {
    let format = format_of(&args)?;
    check(args.which == "convergence" || args.strategies.is_empty(), "--strategies", || {
        "applies to the convergence figure only".into()
    })?;
    check(args.which == "fig2" || args.lambda.is_none(), "--weights-lambda", || {
        "applies to fig2 only (table1's fitted rows each have their own λ; a history holds no moments to solve)".into()
    })?;
    check(args.which == "fig2" || args.strategy.is_none(), "--strategy", || "applies to fig2 only".into())?;
    lambda_flag("--weights-lambda", args.lambda)?;
    let strategy = args
        .strategy
        .as_deref()
        .map(parse_strategy)
        .transpose()
        .map_err(|e| CliError::Config(format!("--strategy: {e}")))?;
    let (svg, what) = match args.which.as_str() {
        "fig2" => fig2::figure(&args.document, args.lambda, strategy)?,
        "table1" => table1::figure(&args.document)?,
        _ => convergence::figure(&args.document, &args.strategies)?,
    };
    write_figure(&args.out, &svg, format)?;
    eprintln!("wrote {} ({what})", args.out.display());
    Ok(())
}

/// Writes `svg` in `format` to `out`, atomically.
fn write_figure(out: &Path, svg: &str, format: Format) -> Result<(), CliError> {
    let bytes = match format {
        Format::Svg => svg.as_bytes().to_vec(),
        Format::Png { width } => render::png(svg, width)?,
        Format::Pdf => render::pdf(svg)?,
    };
    write_atomically(out, &bytes)
}

/// The series colours, matplotlib's ten: distinct in print and for most colour vision.
const COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Draws `chart`'s series labels at `position` in the figures' one legend style.
fn legend<'a, Y: Ranged>(
    chart: &mut ChartContext<'a, SVGBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    position: SeriesLabelPosition,
) -> Result<(), Box<dyn std::error::Error>> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()?;
    Ok(())
}

/// A drawing error as the CLI reports it.
fn drawing(e: impl std::fmt::Display) -> CliError {
    CliError::Config(format!("cannot draw the figure: {e}"))
}
