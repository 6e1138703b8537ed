//! Pictures of histograms: 8-bit grey PNGs with log or linear scaling, the
//! first axis horizontal and the second increasing upward, axis ranges in
//! the PNG's text chunk.

use crate::count::Histogram;
use mdtf_volume::{VolumeError, write_file_atomically};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How counts map to grey levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scale {
    /// 255 log(1 + c) / log(1 + max) (Inviwo, Voreen).
    #[default]
    Log,
    /// 255 c / max.
    Linear,
}

/// An 8-bit grey image, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Grey {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixels, row-major from the top row.
    pub pixels: Vec<u8>,
}

/// Grey level of count c for the largest count `max`.
pub fn grey_level(c: u64, max: u64, scale: Scale) -> u8 {
    if max == 0 {
        return 0;
    }
    let f = match scale {
        Scale::Log => (1.0 + c as f64).ln() / (1.0 + max as f64).ln(),
        Scale::Linear => c as f64 / max as f64,
    };
    (255.0 * f).round().clamp(0.0, 255.0) as u8
}

impl Histogram {
    /// The picture of a 2D histogram (one pixel per bin; axis 0 to the right,
    /// axis 1 upward) or of a 1D histogram (bars 128 pixels tall).
    pub fn image(&self, scale: Scale) -> Grey {
        let max = self.max();
        if self.axes.len() == 1 {
            let (w, h) = (self.axes[0].bins, 128usize);
            let mut pixels = vec![0u8; w * h];
            for (x, &c) in self.counts.iter().enumerate() {
                let height = (grey_level(c as u64, max, scale) as usize * h).div_ceil(255);
                for y in 0..height {
                    pixels[(h - 1 - y) * w + x] = 255;
                }
            }
            return Grey { width: w, height: h, pixels };
        }
        let (w, h) = (self.axes[0].bins, self.axes[1].bins);
        let mut pixels = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                pixels[(h - 1 - y) * w + x] = grey_level(self.counts[y * w + x] as u64, max, scale);
            }
        }
        Grey { width: w, height: h, pixels }
    }

    /// Text describing the axes, for the PNG text chunk and the sidecar.
    pub fn describe(&self, scale: Scale) -> String {
        let axes: Vec<String> = self
            .axes
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let dir = ["horizontal", "vertical (up)", "depth"][i.min(2)];
                format!("{} {dir}: [{}, {}] in {} bins", a.name, a.min, a.max, a.bins)
            })
            .collect();
        format!("{}; {:?} scale; max count {}", axes.join("; "), scale, self.max())
    }
}

/// Two images side by side with a 4-pixel grey gap (heights padded at the bottom).
pub fn side_by_side(a: &Grey, b: &Grey) -> Grey {
    let gap = 4;
    let (w, h) = (a.width + gap + b.width, a.height.max(b.height));
    let mut pixels = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..gap {
            pixels[y * w + a.width + x] = 128;
        }
        if y < a.height {
            pixels[y * w..y * w + a.width].copy_from_slice(&a.pixels[y * a.width..(y + 1) * a.width]);
        }
        if y < b.height {
            let o = y * w + a.width + gap;
            pixels[o..o + b.width].copy_from_slice(&b.pixels[y * b.width..(y + 1) * b.width]);
        }
    }
    Grey { width: w, height: h, pixels }
}

/// Writes a grey PNG with `description` in a tEXt chunk ("Description"). Atomic.
pub fn write_png(path: &Path, img: &Grey, description: &str) -> Result<(), VolumeError> {
    mdtf_volume::write_png(path, img.width, img.height, mdtf_volume::PngColour::Grey, &img.pixels, description)
}

/// Writes a 2D histogram's counts as a one-channel ("Y") f32 OpenEXR image,
/// first axis to the right, second axis upward (rows from the top), for
/// image tools. Atomic.
pub fn write_exr(path: &Path, h: &Histogram) -> Result<(), VolumeError> {
    use exr::prelude::*;
    let io = |e: exr::error::Error| VolumeError::Io {
        path: path.to_path_buf(),
        cause: std::io::Error::other(e.to_string()),
    };
    if h.axes.len() != 2 {
        return Err(VolumeError::Fields("EXR output is for 2D histograms".into()));
    }
    let (w, hgt) = (h.axes[0].bins, h.axes[1].bins);
    let mut values = vec![0f32; w * hgt];
    for y in 0..hgt {
        for x in 0..w {
            values[(hgt - 1 - y) * w + x] = h.counts[y * w + x] as f32;
        }
    }
    let channel = AnyChannel::new("Y", FlatSamples::F32(values));
    let mut attributes = LayerAttributes::named("histogram");
    attributes.comments = Some(Text::from(h.describe(Scale::Linear).as_str()));
    let layer =
        Layer::new((w, hgt), attributes, Encoding::FAST_LOSSLESS, AnyChannels::sort(SmallVec::from_vec(vec![channel])));
    let mut buffer = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut buffer).map_err(io)?;
    let bytes = buffer.into_inner();
    write_file_atomically(path, |out| out.write_all(&bytes))
}
