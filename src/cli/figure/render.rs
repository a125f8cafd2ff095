//! A figure's SVG as PNG (resvg) or PDF (svg2pdf): one drawing, three files. Both need the text's
//! font: the system's fonts are loaded and the SVG's `sans-serif` (plotters' family) is mapped to
//! the first of a few common sans-serif families found; with no font at all the command fails
//! rather than write a figure without its labels.

use std::sync::Arc;

use resvg::tiny_skia::{Pixmap, Transform};
use resvg::usvg::{self, fontdb};

use crate::cli::CliError;

/// Sans-serif families tried in order (Debian's fonts-dejavu-core, fonts-liberation, Noto).
const SANS: [&str; 4] = ["DejaVu Sans", "Liberation Sans", "Noto Sans", "Arial"];

fn failed(what: &str, e: impl std::fmt::Display) -> CliError {
    CliError::Config(format!("cannot write the figure as {what}: {e}"))
}

/// The SVG parsed with the system's fonts.
fn tree(svg: &str) -> Result<usvg::Tree, CliError> {
    let mut db = fontdb::Database::new();
    db.load_system_fonts();
    let families: Vec<String> = db.faces().flat_map(|f| f.families.iter().map(|(name, _)| name.clone())).collect();
    let sans = SANS
        .iter()
        .find(|s| families.iter().any(|f| f == *s))
        .map(|s| s.to_string())
        .or_else(|| families.first().cloned())
        .ok_or_else(|| {
            CliError::Config(
                "no fonts found to draw the figure's text: install one (e.g. Debian's fonts-dejavu-core), or write SVG"
                    .into(),
            )
        })?;
    db.set_sans_serif_family(sans);
    let options = usvg::Options { fontdb: Arc::new(db), ..usvg::Options::default() };
    usvg::Tree::from_str(svg, &options).map_err(|e| failed("SVG", e))
}

/// The figure as a PNG `width` pixels wide (the height in proportion), on its white background.
pub fn png(svg: &str, width: u32) -> Result<Vec<u8>, CliError> {
    let tree = tree(svg)?;
    let size = tree.size();
    let scale = width as f32 / size.width();
    let height = (size.height() * scale).ceil() as u32;
    let mut pixmap = Pixmap::new(width, height).ok_or_else(|| failed("PNG", format!("{width} × {height} pixels")))?;
    resvg::render(&tree, Transform::from_scale(scale, scale), &mut pixmap.as_mut());
    pixmap.encode_png().map_err(|e| failed("PNG", e))
}

/// The figure as a one-page vector PDF of the drawing's size (1 px = 1 pt at svg2pdf's 72 dpi).
/// Its text is drawn as outlines — shaped with the system's font here, so it looks as in the PNG
/// — unless the build has the `pdf-text` feature, which embeds the font (selectable text).
pub fn pdf(svg: &str) -> Result<Vec<u8>, CliError> {
    let tree = tree(svg)?;
    #[cfg(not(feature = "pdf-text"))]
    let tree = {
        // usvg writes the text it shaped as paths; the SVG read back has no text left to embed.
        let outlined = tree.to_string(&usvg::WriteOptions { preserve_text: false, ..usvg::WriteOptions::default() });
        usvg::Tree::from_str(&outlined, &usvg::Options::default()).map_err(|e| failed("PDF", e))?
    };
    svg2pdf::to_pdf(&tree, svg2pdf::ConversionOptions::default(), svg2pdf::PageOptions::default())
        .map_err(|e| failed("PDF", e))
}
