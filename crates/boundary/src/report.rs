//! The validation report of the distance paper's Fig. 2: over the voxels
//! with a kept boundary that pass the paper's two outlier thresholds (g at
//! the voxel, g at the hit), per bin of the dot product between the unit
//! gradients at the voxel and at its boundary, the share of voxels (and its
//! running sum), the mean distance and the mean g.
//!
//! The paper bins dot x 100. On clean data nearly every voxel has
//! 1 - dot between 1e-7 and 1e-3, so all of them fall into the bin 100 and
//! the plot is one dot; the first table (and the plot) therefore bins
//! log10(1 - dot) in quarter decades. The paper's binning is the CSV's
//! second table.

use mdtf_volume::{VolumeError, write_file_atomically};
use std::fmt::Write as _;
use std::path::Path;

/// The smallest 1 - dot told apart: below it (including dot = 1) a voxel
/// counts in the first bin. f32 resolves 1 - dot to about 6e-8.
pub const LOG_FLOOR: f64 = -7.0;
/// Width of a log bin, decades.
pub const LOG_BIN_WIDTH: f64 = 0.25;
/// Log bins from [`LOG_FLOOR`] up to log10(2) (dot = -1).
const LOG_BINS: usize = 30;

/// One bin of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportBin {
    /// The bin's lower edge: log10(1 - dot) for the log table, dot x 100 for the paper's.
    pub lo: f64,
    /// The bin's upper edge (equal to `lo` for the paper's integer bins).
    pub hi: f64,
    /// Voxels in this bin.
    pub voxels: u64,
    /// Percentage of the report's voxels.
    pub percent: f64,
    /// Running sum of `percent`, from the bin of the most aligned gradients
    /// (log table) or from the lowest dot (paper's table).
    pub cumulative_percent: f64,
    /// Mean distance to the boundary, world units.
    pub mean_distance: f64,
    /// Mean g at the voxels.
    pub mean_g: f64,
}

/// The Fig. 2 thresholds: outliers the report leaves out (the outputs keep them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReportThresholds {
    /// Least g at the voxel (the paper's 5 on 8-bit data), value units per world unit.
    pub g_min: f64,
    /// Least g at the boundary (the paper's 20 on 8-bit data).
    pub g_hit_min: f64,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Non-empty bins of log10(1 - dot), most aligned first.
    pub bins: Vec<ReportBin>,
    /// Non-empty bins of dot x 100 rounded (the paper's), lowest first.
    pub paper_bins: Vec<ReportBin>,
    /// Mean dot product over the report's voxels.
    pub mean_dot: f64,
    /// Voxels in the report (kept hits passing the thresholds).
    pub hits: u64,
    /// Kept hits the thresholds left out.
    pub outliers: u64,
    /// The thresholds applied.
    pub thresholds: ReportThresholds,
}

/// Per-bin sums while counting.
#[derive(Clone, Copy, Default)]
struct Sums {
    voxels: u64,
    distance: f64,
    g: f64,
}

/// The per-voxel volumes the report reads, as flat samples.
#[derive(Debug, Clone, Copy)]
pub struct ReportInput<'a> {
    /// Hit codes (1 = kept boundary).
    pub hit: &'a [f32],
    /// Dot products.
    pub dot: &'a [f32],
    /// Distances, world units.
    pub distance: &'a [f32],
    /// g at the voxels.
    pub g: &'a [f32],
    /// g at the hits.
    pub g_hit: &'a [f32],
}

fn log_bin(dot: f64) -> usize {
    let l = (1.0 - dot).max(10f64.powf(LOG_FLOOR)).log10();
    (((l - LOG_FLOOR) / LOG_BIN_WIDTH).floor().max(0.0) as usize).min(LOG_BINS - 1)
}

impl Report {
    /// Builds the report from the per-voxel outputs, leaving out hits below the thresholds.
    pub fn new(input: ReportInput, thresholds: ReportThresholds) -> Report {
        let mut log = vec![Sums::default(); LOG_BINS];
        let mut paper = vec![Sums::default(); 201];
        let (mut sum_dot, mut hits, mut outliers) = (0.0, 0u64, 0u64);
        for i in 0..input.hit.len() {
            if input.hit[i] != 1.0 {
                continue;
            }
            let (g, g_hit) = (input.g[i] as f64, input.g_hit[i] as f64);
            if g < thresholds.g_min || g_hit < thresholds.g_hit_min {
                outliers += 1;
                continue;
            }
            let dot = input.dot[i] as f64;
            let p = ((dot * 100.0).round().clamp(-100.0, 100.0) as i32 + 100) as usize;
            for s in [&mut log[log_bin(dot)], &mut paper[p]] {
                s.voxels += 1;
                s.distance += input.distance[i] as f64;
                s.g += g;
            }
            sum_dot += dot;
            hits += 1;
        }
        let total = hits.max(1) as f64;
        let table = |sums: &[Sums], edges: &dyn Fn(usize) -> (f64, f64)| {
            let mut cumulative = 0.0;
            sums.iter()
                .enumerate()
                .filter(|(_, s)| s.voxels > 0)
                .map(|(b, s)| {
                    let percent = 100.0 * s.voxels as f64 / total;
                    cumulative += percent;
                    let (lo, hi) = edges(b);
                    ReportBin {
                        lo,
                        hi,
                        voxels: s.voxels,
                        percent,
                        cumulative_percent: cumulative,
                        mean_distance: s.distance / s.voxels as f64,
                        mean_g: s.g / s.voxels as f64,
                    }
                })
                .collect()
        };
        let log_edges = |b: usize| {
            let lo = LOG_FLOOR + b as f64 * LOG_BIN_WIDTH;
            (lo, lo + LOG_BIN_WIDTH)
        };
        let paper_edges = |b: usize| (b as f64 - 100.0, b as f64 - 100.0);
        Report {
            bins: table(&log, &log_edges),
            paper_bins: table(&paper, &paper_edges),
            mean_dot: sum_dot / total,
            hits,
            outliers,
            thresholds,
        }
    }

    /// The CSV text: comment lines, the log10(1 - dot) table, a blank line and the paper's dot x 100 table.
    pub fn csv(&self) -> String {
        let t = self.thresholds;
        let mut s = format!(
            "# mean dot product {:.6} over {} voxels with a boundary; {} more left out by the Fig. 2 thresholds \
             (g >= {:.4} at the voxel, g >= {:.4} at the boundary)\n",
            self.mean_dot, self.hits, self.outliers, t.g_min, t.g_hit_min
        );
        s +=
            "# table 1: bins of log10(1 - dot), a quarter decade wide; 1 - dot below 1e-7 (and dot = 1) in the first\n";
        s += "log10_1_minus_dot_lo,log10_1_minus_dot_hi,voxels,percent,cumulative_percent,mean_distance,mean_g\n";
        for b in &self.bins {
            let _ = writeln!(
                s,
                "{:.2},{:.2},{},{:.6},{:.6},{:.6},{:.6}",
                b.lo, b.hi, b.voxels, b.percent, b.cumulative_percent, b.mean_distance, b.mean_g
            );
        }
        s += "\n# table 2: the paper's bins, dot x 100 rounded to an integer\n";
        s += "dot_x100,voxels,percent,cumulative_percent,mean_distance,mean_g\n";
        for b in &self.paper_bins {
            let _ = writeln!(
                s,
                "{},{},{:.6},{:.6},{:.6},{:.6}",
                b.lo, b.voxels, b.percent, b.cumulative_percent, b.mean_distance, b.mean_g
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
            "x: log10(1 - dot) from {LOG_FLOOR} to {:.2}; black: cumulative percent (0..100); red: mean distance \
             (0..{:.3}); blue: mean g (0..{:.3}); mean dot {:.6}",
            LOG_FLOOR + LOG_BINS as f64 * LOG_BIN_WIDTH,
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

    /// A 640x400 RGB plot against log10(1 - dot) over the whole log axis:
    /// cumulative percent (black), mean distance (red) and mean g (blue),
    /// each scaled to the plot height; axis ranges go into the PNG's text chunk.
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
        let span = LOG_BINS as f64 * LOG_BIN_WIDTH;
        let to_px = |b: &ReportBin, frac: f64| {
            let centre = 0.5 * (b.lo + b.hi);
            let x = m as f64 + (centre - LOG_FLOOR) / span * (w - 2 * m) as f64;
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
            let pts: Vec<(f64, f64)> = self.bins.iter().map(|b| to_px(b, value(curve, b))).collect();
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
    fn log_bins_spread_what_the_papers_bins_lump_together() {
        let hit = [1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0];
        let dot = [1.0 - 2e-6, 1.0 - 3e-4, 0.5, 1.0, 1.0, 0.998, 0.9];
        let dist = [1.0, 2.0, 3.0, 9.0, 4.0, 5.0, 6.0];
        let g = [10.0, 20.0, 30.0, 99.0, 40.0, 50.0, 1.0];
        let g_hit = [60.0; 7];
        let input = ReportInput { hit: &hit, dot: &dot, distance: &dist, g: &g, g_hit: &g_hit };
        let r = Report::new(input, ReportThresholds { g_min: 5.0, g_hit_min: 20.0 });
        // the last voxel is below g_min; the fourth has no hit
        assert_eq!((r.hits, r.outliers), (5, 1));
        // log10(1 - dot): 1 - dot = 1 lands in the first bin; -5.70, -3.52, -2.70 and log10(0.5) by hand
        let los: Vec<f64> = r.bins.iter().map(|b| b.lo).collect();
        assert_eq!(los, vec![-7.0, -5.75, -3.75, -2.75, -0.5]);
        assert!((r.bins.last().unwrap().cumulative_percent - 100.0).abs() < 1e-9);
        // the paper's bins: 0.998, 1 - 3e-4, 1 - 2e-6 and 1 all round to 100
        assert_eq!(r.paper_bins.iter().map(|b| (b.lo, b.voxels)).collect::<Vec<_>>(), vec![(50.0, 1), (100.0, 4)]);
        assert!((r.paper_bins[1].mean_distance - (1.0 + 2.0 + 4.0 + 5.0) / 4.0).abs() < 1e-9);
        let want_dot = (dot[0] as f64 + dot[1] as f64 + 0.5 + 1.0 + dot[5] as f64) / 5.0;
        assert!((r.mean_dot - want_dot).abs() < 1e-6);
        let csv = r.csv();
        assert!(csv.contains("\ndot_x100,voxels"), "{csv}");
        assert!(csv.contains("\n50,1,20.0"), "{csv}");
        assert!(csv.contains("\n-7.00,-6.75,1,20.0"), "{csv}");
    }
}
