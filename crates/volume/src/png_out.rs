//! 8-bit PNG pictures (histograms, previews), written atomically with a
//! description in a tEXt chunk, and the font their text is drawn in.

use crate::error::Result;
use crate::output::write_file_atomically;
use std::path::Path;

/// Samples per pixel of an 8-bit PNG.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PngColour {
    /// One grey sample.
    Grey,
    /// Red, green, blue.
    Rgb,
}

/// Writes `pixels` (rows from the top, `width` x `height`, one or three
/// bytes per pixel as `colour` says) as an 8-bit PNG with `description` in a
/// tEXt chunk ("Description"). Atomic.
pub fn write_png(
    path: &Path,
    width: usize,
    height: usize,
    colour: PngColour,
    pixels: &[u8],
    description: &str,
) -> Result<()> {
    write_file_atomically(path, |out| {
        let mut enc = png::Encoder::new(out, width as u32, height as u32);
        enc.set_color(match colour {
            PngColour::Grey => png::ColorType::Grayscale,
            PngColour::Rgb => png::ColorType::Rgb,
        });
        enc.set_depth(png::BitDepth::Eight);
        enc.add_text_chunk("Description".into(), description.to_string()).map_err(std::io::Error::other)?;
        let mut writer = enc.write_header().map_err(std::io::Error::other)?;
        writer.write_image_data(pixels).map_err(std::io::Error::other)?;
        writer.finish().map_err(std::io::Error::other)
    })
}

/// Registers the bundled DejaVu Sans as plotters' "sans-serif" (once per
/// process), so that figures need no system font. A failure would cost the
/// text of a figure, not the figure, so it is not reported.
pub fn register_figure_font() {
    static FONT: std::sync::Once = std::sync::Once::new();
    FONT.call_once(|| {
        let _ =
            plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, dejavu::sans::regular());
    });
}
