//! The validation report of the distance paper's Fig. 2: per dot-product
//! bin (dot x 100), the share of traced voxels (and its running sum), the
//! mean distance and the mean g; written as CSV and as a PNG plot.

use mdtf_volume::{VolumeError, write_file_atomically};
use std::fmt::Write as _;
use std::path::Path;

/// One dot-product bin.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportBin {
    /// dot x 100 rounded to the nearest integer, -100 ..= 100.
    pub dot_x100: i32,
    /// Voxels with a kept hit in this bin.
    pub voxels: u64,
    /// Percentage of all hit voxels.
    pub percent: f64,
    /// Running sum of `percent` from the lowest bin up.
    pub cumulative_percent: f64,
    /// Mean distance to the boundary, world units.
    pub mean_distance: f64,
    /// Mean g at the voxels.
    pub mean_g: f64,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Non-empty bins, lowest first.
    pub bins: Vec<ReportBin>,
    /// Mean dot product over every hit voxel.
    pub mean_dot: f64,
    /// Voxels with a kept hit.
    pub hits: u64,
}

impl Report {
    /// Builds the report from per-voxel hit flags, dot products, distances and g.
    pub fn new(hit: &[f32], dot: &[f32], distance: &[f32], g: &[f32]) -> Report {
        let mut count = vec![0u64; 201];
        let mut sum_d = vec![0f64; 201];
        let mut sum_g = vec![0f64; 201];
        let mut sum_dot = 0.0;
        let mut hits = 0u64;
        for i in 0..hit.len() {
            if hit[i] != 1.0 {
                continue;
            }
            let b = ((dot[i] as f64 * 100.0).round().clamp(-100.0, 100.0) as i32 + 100) as usize;
            count[b] += 1;
            sum_d[b] += distance[i] as f64;
            sum_g[b] += g[i] as f64;
            sum_dot += dot[i] as f64;
            hits += 1;
        }
        let total = hits.max(1) as f64;
        let mut cumulative = 0.0;
        let bins = (0..201)
            .filter(|&b| count[b] > 0)
            .map(|b| {
                let percent = 100.0 * count[b] as f64 / total;
                cumulative += percent;
                ReportBin {
                    dot_x100: b as i32 - 100,
                    voxels: count[b],
                    percent,
                    cumulative_percent: cumulative,
                    mean_distance: sum_d[b] / count[b] as f64,
                    mean_g: sum_g[b] / count[b] as f64,
                }
            })
            .collect();
        Report { bins, mean_dot: sum_dot / total, hits }
    }

    /// The CSV text: a comment line with the mean dot product, then one row per bin.
    pub fn csv(&self) -> String {
        let mut s = format!("# mean dot product {:.6} over {} voxels with a boundary\n", self.mean_dot, self.hits);
        s += "dot_x100,voxels,percent,cumulative_percent,mean_distance,mean_g\n";
        for b in &self.bins {
            let _ = writeln!(
                s,
                "{},{},{:.6},{:.6},{:.6},{:.6}",
                b.dot_x100, b.voxels, b.percent, b.cumulative_percent, b.mean_distance, b.mean_g
            );
        }
        s
    }

    /// Writes `boundary_report.csv` and `boundary_report.png` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<(), VolumeError> {
        let csv = self.csv();
        write_file_atomically(&dir.join("boundary_report.csv"), |w| w.write_all(csv.as_bytes()))?;
        let (w, h, rgb) = self.plot();
        let text = format!(
            "x: dot product x 100 from {} to 100; black: cumulative percent (0..100); red: mean distance (0..{:.3}); \
             blue: mean g (0..{:.3}); mean dot {:.6}",
            self.bins.first().map_or(0, |b| b.dot_x100),
            self.max_distance(),
            self.max_g(),
            self.mean_dot
        );
        write_file_atomically(&dir.join("boundary_report.png"), |out| {
            let mut enc = png::Encoder::new(out, w, h);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            enc.add_text_chunk("Description".into(), text.clone()).map_err(std::io::Error::other)?;
            let mut writer = enc.write_header().map_err(std::io::Error::other)?;
            writer.write_image_data(&rgb).map_err(std::io::Error::other)?;
            writer.finish().map_err(std::io::Error::other)
        })
    }

    fn max_distance(&self) -> f64 {
        self.bins.iter().map(|b| b.mean_distance).fold(0.0, f64::max).max(1e-9)
    }

    fn max_g(&self) -> f64 {
        self.bins.iter().map(|b| b.mean_g).fold(0.0, f64::max).max(1e-9)
    }

    /// A 640x400 RGB plot: cumulative percent (black), mean distance (red) and
    /// mean g (blue) against dot x 100, each scaled to the plot height; axis
    /// ranges go into the PNG's text chunk.
    fn plot(&self) -> (u32, u32, Vec<u8>) {
        let (w, h, m) = (640usize, 400usize, 40usize);
        let mut img = vec![255u8; w * h * 3];
        let put = |img: &mut Vec<u8>, x: usize, y: usize, c: [u8; 3]| {
            if x < w && y < h {
                img[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&c);
            }
        };
        for x in m..w - m {
            put(&mut img, x, h - m, [0, 0, 0]);
        }
        for y in m..h - m {
            put(&mut img, m, y, [0, 0, 0]);
        }
        let x0 = self.bins.first().map_or(0, |b| b.dot_x100).min(99) as f64;
        let to_px = |dot: f64, frac: f64| {
            let x = m as f64 + (dot - x0) / (100.0 - x0) * (w - 2 * m) as f64;
            let y = (h - m) as f64 - frac.clamp(0.0, 1.0) * (h - 2 * m) as f64;
            (x, y)
        };
        let (dmax, gmax) = (self.max_distance(), self.max_g());
        // (height fraction of a bin, colour) per curve
        let value = |curve: usize, b: &ReportBin| match curve {
            0 => b.cumulative_percent / 100.0,
            1 => b.mean_distance / dmax,
            _ => b.mean_g / gmax,
        };
        let colours = [[0u8, 0, 0], [200, 30, 30], [30, 60, 200]];
        for (curve, colour) in colours.iter().enumerate() {
            let pts: Vec<(f64, f64)> = self.bins.iter().map(|b| to_px(b.dot_x100 as f64, value(curve, b))).collect();
            for pair in pts.windows(2) {
                let ((xa, ya), (xb, yb)) = (pair[0], pair[1]);
                let steps = ((xb - xa).abs().max((yb - ya).abs()).ceil() as usize).max(1);
                for s in 0..=steps {
                    let t = s as f64 / steps as f64;
                    put(
                        &mut img,
                        (xa + t * (xb - xa)).round() as usize,
                        (ya + t * (yb - ya)).round() as usize,
                        *colour,
                    );
                }
            }
            for &(x, y) in &pts {
                for dx in 0..3 {
                    for dy in 0..3 {
                        put(
                            &mut img,
                            (x.round() as usize + dx).saturating_sub(1),
                            (y.round() as usize + dy).saturating_sub(1),
                            *colour,
                        );
                    }
                }
            }
        }
        (w as u32, h as u32, img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_accumulate_to_one_hundred_percent() {
        let hit = [1.0, 1.0, 1.0, 0.0, 1.0];
        let dot = [0.995, 0.999, 0.5, 1.0, 1.0];
        let dist = [1.0, 2.0, 3.0, 9.0, 4.0];
        let g = [10.0, 20.0, 30.0, 99.0, 40.0];
        let r = Report::new(&hit, &dot, &dist, &g);
        assert_eq!(r.hits, 4);
        assert_eq!(r.bins.iter().map(|b| b.dot_x100).collect::<Vec<_>>(), vec![50, 100]);
        assert!((r.bins.last().unwrap().cumulative_percent - 100.0).abs() < 1e-9);
        assert_eq!(r.bins[1].voxels, 3);
        assert!((r.bins[1].mean_distance - 7.0 / 3.0).abs() < 1e-9);
        assert!((r.mean_dot - (0.995 + 0.999 + 0.5 + 1.0) / 4.0).abs() < 1e-6);
        assert!(r.csv().lines().nth(2).unwrap().starts_with("50,1,25.0"));
    }
}
