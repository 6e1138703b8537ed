//! The colour-volume picture of a 3-channel histogram (Kniss et al.'s
//! Fig. 9.4a, the RGB histogram "visualized as projections on the primary
//! planes"): the three projections (0,1), (0,2), (1,2) side by side, the
//! first channel read as red, the second as green, the third as blue.
//!
//! A pixel's brightness is the scaled count of its projected bin; its hue
//! is the colour of that point of the colour cube: the two shown axes'
//! positions, and for the axis summed away its count-weighted mean
//! position. Channels are lifted to 0.25 + 0.75 x so that dark corners of
//! the cube stay visible.

use crate::count::Histogram;
use crate::image::{Scale, grey_level};
use mdtf_volume::VolumeError;
use std::path::Path;

/// An 8-bit RGB image, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Rgb {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixels (r, g, b), row-major from the top row.
    pub pixels: Vec<u8>,
}

/// Gap between the panels, pixels (mid grey).
pub(crate) const GAP: usize = 4;

impl Histogram {
    /// The three primary-plane projections of a 3D histogram as one RGB
    /// picture (None for 1D and 2D histograms). In each panel the first
    /// shown axis runs to the right and the second upward.
    pub fn rgb_projections(&self, scale: Scale) -> Option<Rgb> {
        if self.axes.len() != 3 {
            return None;
        }
        let panels = [(0usize, 1usize), (0, 2), (1, 2)];
        let bins: Vec<usize> = self.axes.iter().map(|a| a.bins).collect();
        let width = bins[0] + GAP + bins[0] + GAP + bins[1];
        let height = bins[1].max(bins[2]);
        let mut pixels = vec![0u8; width * height * 3];
        let pos = |i: usize, n: usize| if n > 1 { i as f64 / (n - 1) as f64 } else { 0.5 };
        let mut x0 = 0;
        for (p, &(a, b)) in panels.iter().enumerate() {
            let c = 3 - a - b;
            // projected counts and the count-weighted mean position along c
            let (na, nb, nc) = (bins[a], bins[b], bins[c]);
            let mut sums = vec![(0u64, 0f64); na * nb];
            let mut t = [0usize; 3];
            for ia in 0..na {
                for ib in 0..nb {
                    let (mut n, mut m) = (0u64, 0f64);
                    for ic in 0..nc {
                        t[a] = ia;
                        t[b] = ib;
                        t[c] = ic;
                        let k = self.counts[self.index(&t)];
                        n += k;
                        m += k as f64 * pos(ic, nc);
                    }
                    sums[ib * na + ia] = (n, if n > 0 { m / n as f64 } else { 0.0 });
                }
            }
            let max = sums.iter().map(|s| s.0).max().unwrap_or(0);
            for ib in 0..nb {
                let y = height - 1 - ib;
                for ia in 0..na {
                    let (n, mean_c) = sums[ib * na + ia];
                    let level = grey_level(n, max, scale) as f64 / 255.0;
                    let mut colour = [0f64; 3];
                    colour[a] = pos(ia, na);
                    colour[b] = pos(ib, nb);
                    colour[c] = mean_c;
                    let at = (y * width + x0 + ia) * 3;
                    for k in 0..3 {
                        pixels[at + k] = (255.0 * level * (0.25 + 0.75 * colour[k])).round() as u8;
                    }
                }
            }
            x0 += na;
            if p < 2 {
                for y in 0..height {
                    for x in x0..x0 + GAP {
                        pixels[(y * width + x) * 3..(y * width + x) * 3 + 3].fill(128);
                    }
                }
                x0 += GAP;
            }
        }
        Some(Rgb { width, height, pixels })
    }
}

/// Writes an RGB PNG with `description` in a tEXt chunk. Atomic.
pub fn write_rgb_png(path: &Path, img: &Rgb, description: &str) -> Result<(), VolumeError> {
    mdtf_volume::write_png(path, img.width, img.height, mdtf_volume::PngColour::Rgb, &img.pixels, description)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::AxisSpec;

    fn axis(name: &str, bins: usize) -> crate::Axis {
        AxisSpec { bins: Some(bins), range: Some((0.0, 1.0)), clip_percent: (0.0, 0.0) }
            .resolve(name, &[0.0, 1.0])
            .unwrap()
    }

    #[test]
    fn one_bin_shows_its_colour_in_every_panel() {
        // all counts in bin (3, 0, 1) of a 4 x 4 x 4 histogram: red full, green none, blue 1/3
        let axes = vec![axis("r", 4), axis("g", 4), axis("b", 4)];
        let mut h = Histogram { axes, counts: vec![0; 64] };
        let at = h.index(&[3, 0, 1]);
        h.counts[at] = 10;
        let img = h.rgb_projections(Scale::Linear).unwrap();
        assert_eq!((img.width, img.height), (4 + GAP + 4 + GAP + 4, 4));
        let px = |x: usize, y_up: usize| {
            let at = ((img.height - 1 - y_up) * img.width + x) * 3;
            [img.pixels[at], img.pixels[at + 1], img.pixels[at + 2]]
        };
        let lift = |x: f64| (255.0 * (0.25 + 0.75 * x)).round() as u8;
        let expect = [lift(1.0), lift(0.0), lift(1.0 / 3.0)];
        assert_eq!(px(3, 0), expect, "(r, g) panel at r = 3, g = 0");
        assert_eq!(px(4 + GAP + 3, 1), expect, "(r, b) panel at r = 3, b = 1");
        assert_eq!(px(2 * (4 + GAP), 1), expect, "(g, b) panel at g = 0, b = 1");
        // everything else is black, the gaps grey
        let lit = img.pixels.chunks_exact(3).filter(|p| p.iter().any(|&c| c > 0) && *p != [128, 128, 128]).count();
        assert_eq!(lit, 3);
        assert!(Histogram { axes: vec![axis("a", 4)], counts: vec![0; 4] }.rgb_projections(Scale::Log).is_none());
    }

    #[test]
    fn the_summed_axis_shows_its_count_weighted_mean() {
        // bins (0, 0, 0) x 1 and (0, 0, 3) x 3: in the (r, g) panel blue = (0 + 3 x 1) / 4 = 0.75
        let axes = vec![axis("r", 4), axis("g", 4), axis("b", 4)];
        let mut h = Histogram { axes, counts: vec![0; 64] };
        let (i0, i3) = (h.index(&[0, 0, 0]), h.index(&[0, 0, 3]));
        h.counts[i0] = 1;
        h.counts[i3] = 3;
        let img = h.rgb_projections(Scale::Linear).unwrap();
        let at = ((img.height - 1) * img.width) * 3;
        let lift = |x: f64| (255.0 * (0.25 + 0.75 * x)).round() as u8;
        assert_eq!(&img.pixels[at..at + 3], &[lift(0.0), lift(0.0), lift(0.75)]);
    }
}
