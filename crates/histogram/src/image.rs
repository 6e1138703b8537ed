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

/// Height in pixels of a 1D histogram's picture.
pub const BAR_HEIGHT: usize = 128;

/// Grey level of the log-scale bars in a 1D histogram's picture (the linear ones are white).
pub const LOG_BAR_GREY: u8 = 96;

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
    /// The picture of a 2D histogram (one pixel per bin, grey by `scale`;
    /// axis 0 to the right, axis 1 upward) or of a 1D histogram: bars
    /// [`BAR_HEIGHT`] pixels tall on both scales at once, as Kniss et al.'s
    /// Fig. 9.1 overlays them: the log bar in grey [`LOG_BAR_GREY`] behind
    /// the linear bar in white (the log scale shows the small peaks of
    /// boundaries, the linear scale the materials' relative sizes).
    pub fn image(&self, scale: Scale) -> Grey {
        let max = self.max();
        if self.axes.len() == 1 {
            let (w, h) = (self.axes[0].bins, BAR_HEIGHT);
            let mut pixels = vec![0u8; w * h];
            let bar = |c: u64, scale: Scale| (grey_level(c, max, scale) as usize * h).div_ceil(255);
            for (x, &c) in self.counts.iter().enumerate() {
                for (height, grey) in [(bar(c, Scale::Log), LOG_BAR_GREY), (bar(c, Scale::Linear), 255)] {
                    for y in 0..height {
                        pixels[(h - 1 - y) * w + x] = grey;
                    }
                }
            }
            return Grey { width: w, height: h, pixels };
        }
        let (w, h) = (self.axes[0].bins, self.axes[1].bins);
        let mut pixels = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                pixels[(h - 1 - y) * w + x] = grey_level(self.counts[y * w + x], max, scale);
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
        let scale = if self.axes.len() == 1 {
            "bars on log (grey) and linear (white) scales overlaid".to_string()
        } else {
            format!("{scale:?} scale")
        };
        format!("{}; {scale}; max count {}", axes.join("; "), self.max())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::Axis;

    #[test]
    fn a_1d_picture_overlays_linear_bars_on_log_bars() {
        let h = Histogram {
            axes: vec![Axis { name: "v".into(), min: 0.0, max: 5.0, bins: 5, unit: None }],
            counts: vec![1000, 100, 10, 1, 0],
        };
        let img = h.image(Scale::Log);
        assert_eq!((img.width, img.height), (5, 128));
        let column = |x: usize, grey: u8| (0..128).filter(|y| img.pixels[y * 5 + x] == grey).count();
        // linear: 128 c / 1000 rounded up, via the 8-bit level (100: level 26, 14 pixels; 10: level 3, 2)
        let white: Vec<usize> = (0..5).map(|x| column(x, 255)).collect();
        assert_eq!(white, [128, 14, 2, 0, 0]);
        // log: 128 ln(1 + c) / ln(1001) (100: level 170, 86 pixels; 10: level 89, 45; 1: level 26, 14)
        let lit: Vec<usize> = (0..5).map(|x| column(x, 255) + column(x, LOG_BAR_GREY)).collect();
        assert_eq!(lit, [128, 86, 45, 14, 0]);
        // bars stand on the bottom row
        assert_eq!(img.pixels[127 * 5 + 3], LOG_BAR_GREY);
        assert!(h.describe(Scale::Log).contains("log (grey) and linear (white)"));
    }
}
