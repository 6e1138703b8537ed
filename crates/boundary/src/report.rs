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

use crate::exact_sum::ExactSum;
use mdtf_volume::{PngColour, VolumeError, write_file_atomically};
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
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
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

/// Per-bin sums while counting (exact, so any order of voxels gives the same bits).
#[derive(Clone, Default, serde::Serialize, serde::Deserialize)]
struct Sums {
    voxels: u64,
    distance: ExactSum,
    g: ExactSum,
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

/// The report's sums over the voxels seen so far: feed it the blocks of a
/// slab-by-slab run in any order and it finishes into the report of the
/// whole volume, bit for bit (its sums are exact, see [`ExactSum`]). The
/// sums of blocks counted elsewhere (a cluster's tasks) are serialisable and
/// merge exactly ([`ReportAccumulator::merge`]).
#[derive(Clone, serde::Serialize, serde::Deserialize)]
pub struct ReportAccumulator {
    log: Vec<Sums>,
    paper: Vec<Sums>,
    sum_dot: ExactSum,
    hits: u64,
    outliers: u64,
    thresholds: ReportThresholds,
}

impl ReportAccumulator {
    /// Empty sums for a report with `thresholds`.
    pub fn new(thresholds: ReportThresholds) -> ReportAccumulator {
        ReportAccumulator {
            log: vec![Sums::default(); LOG_BINS],
            paper: vec![Sums::default(); 201],
            sum_dot: ExactSum::default(),
            hits: 0,
            outliers: 0,
            thresholds,
        }
    }

    /// Adds the voxels of `input`, leaving out hits below the thresholds.
    pub fn add(&mut self, input: ReportInput) {
        let thresholds = self.thresholds;
        for i in 0..input.hit.len() {
            if input.hit[i] != 1.0 {
                continue;
            }
            let (g, g_hit) = (input.g[i], input.g_hit[i]);
            if (g as f64) < thresholds.g_min || (g_hit as f64) < thresholds.g_hit_min {
                self.outliers += 1;
                continue;
            }
            let dot = input.dot[i];
            let p = ((dot as f64 * 100.0).round().clamp(-100.0, 100.0) as i32 + 100) as usize;
            for s in [&mut self.log[log_bin(dot as f64)], &mut self.paper[p]] {
                s.voxels += 1;
                s.distance.add(input.distance[i]);
                s.g.add(g);
            }
            self.sum_dot.add(dot);
            self.hits += 1;
        }
    }

    /// Adds the voxels `other` counted (with the same thresholds), as if
    /// they had been added here.
    pub fn merge(&mut self, other: &ReportAccumulator) {
        for (mine, theirs) in [(&mut self.log, &other.log), (&mut self.paper, &other.paper)] {
            for (a, b) in mine.iter_mut().zip(theirs) {
                a.voxels += b.voxels;
                a.distance.merge(&b.distance);
                a.g.merge(&b.g);
            }
        }
        self.sum_dot.merge(&other.sum_dot);
        self.hits += other.hits;
        self.outliers += other.outliers;
    }

    /// The report of every voxel added.
    pub fn finish(self) -> Report {
        Report::from_sums(self)
    }
}

impl Report {
    /// Builds the report from the per-voxel outputs, leaving out hits below the thresholds.
    pub fn new(input: ReportInput, thresholds: ReportThresholds) -> Report {
        let mut acc = ReportAccumulator::new(thresholds);
        acc.add(input);
        acc.finish()
    }

    fn from_sums(acc: ReportAccumulator) -> Report {
        let ReportAccumulator { log, paper, sum_dot, hits, outliers, thresholds } = acc;
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
                        mean_distance: s.distance.value() / s.voxels as f64,
                        mean_g: s.g.value() / s.voxels as f64,
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
            mean_dot: sum_dot.value() / total,
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
        let (w, h) = FIGURE_SIZE;
        let rgb = self.figure().map_err(VolumeError::Fields)?;
        let text = format!(
            "x: log10(1 - dot) from {LOG_FLOOR} to {:.2}; top: percent of voxels per bin and cumulative; middle: mean \
             distance to the boundary (world units); bottom: mean g (value units per world unit); mean dot {:.6}",
            LOG_FLOOR + LOG_BINS as f64 * LOG_BIN_WIDTH,
            self.mean_dot
        );
        mdtf_volume::write_png(&dir.join("boundary_report.png"), w as usize, h as usize, PngColour::Rgb, &rgb, &text)
    }

    /// The figure: three panels over the shared axis log10(1 - dot) (the
    /// share of voxels per bin and its running sum, the mean distance, the
    /// mean g), with labelled axes in their units and a legend;
    /// [`FIGURE_SIZE`] RGB pixels, rows from the top.
    pub fn figure(&self) -> Result<Vec<u8>, String> {
        use plotters::prelude::*;
        let err = |e: &dyn std::fmt::Debug| format!("drawing the boundary report: {e:?}");
        mdtf_volume::register_figure_font();
        let (w, h) = FIGURE_SIZE;
        let mut pixels = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
            let title = format!(
                "boundary tracing: {} voxels with a kept boundary ({} outliers left out), mean dot {:.5}",
                self.hits, self.outliers, self.mean_dot
            );
            let root = root.titled(&title, ("sans-serif", 16)).map_err(|e| err(&e))?;
            let panels = root.split_evenly((3, 1));
            let x_range = LOG_FLOOR..LOG_FLOOR + LOG_BINS as f64 * LOG_BIN_WIDTH;
            let centre = |b: &ReportBin| 0.5 * (b.lo + b.hi);
            let curves: [(&str, f64, RGBColor); 3] = [
                ("voxels (percent)", 100.0, BLACK),
                ("mean distance to the boundary (world units)", 1.1 * self.max_distance(), RGBColor(200, 30, 30)),
                ("mean g (value units per world unit)", 1.1 * self.max_g(), RGBColor(30, 60, 200)),
            ];
            for (k, (panel, (label, top, colour))) in panels.iter().zip(curves).enumerate() {
                let mut chart = ChartBuilder::on(panel)
                    .margin(8)
                    .x_label_area_size(if k == 2 { 44 } else { 20 })
                    .y_label_area_size(64)
                    .build_cartesian_2d(x_range.clone(), 0.0..top)
                    .map_err(|e| err(&e))?;
                let mut mesh = chart.configure_mesh();
                mesh.light_line_style(RGBColor(235, 235, 235)).y_desc(label).axis_desc_style(("sans-serif", 12));
                mesh.label_style(("sans-serif", 11));
                if k == 2 {
                    mesh.x_desc("log10(1 - dot): how far the gradient at the voxel turns from the one at its boundary");
                }
                mesh.draw().map_err(|e| err(&e))?;
                if k == 0 {
                    let grey = RGBColor(170, 170, 170);
                    chart
                        .draw_series(
                            self.bins.iter().map(|b| Rectangle::new([(b.lo, 0.0), (b.hi, b.percent)], grey.filled())),
                        )
                        .map_err(|e| err(&e))?
                        .label("per bin")
                        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], grey.filled()));
                    chart
                        .draw_series(LineSeries::new(
                            self.bins.iter().map(|b| (centre(b), b.cumulative_percent)),
                            BLACK.stroke_width(2),
                        ))
                        .map_err(|e| err(&e))?
                        .label("cumulative, from the most aligned")
                        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLACK.stroke_width(2)));
                    chart
                        .configure_series_labels()
                        .position(SeriesLabelPosition::UpperRight)
                        .background_style(WHITE.mix(0.85))
                        .border_style(BLACK)
                        .label_font(("sans-serif", 12))
                        .draw()
                        .map_err(|e| err(&e))?;
                } else {
                    let value = |b: &ReportBin| if k == 1 { b.mean_distance } else { b.mean_g };
                    chart
                        .draw_series(LineSeries::new(
                            self.bins.iter().map(|b| (centre(b), value(b))),
                            colour.stroke_width(2),
                        ))
                        .map_err(|e| err(&e))?;
                    chart
                        .draw_series(self.bins.iter().map(|b| Circle::new((centre(b), value(b)), 3, colour.filled())))
                        .map_err(|e| err(&e))?;
                }
            }
            root.present().map_err(|e| err(&e))?;
        }
        Ok(pixels)
    }

    fn max_distance(&self) -> f64 {
        self.bins.iter().map(|b| b.mean_distance).fold(0.0, f64::max).max(1e-9)
    }

    fn max_g(&self) -> f64 {
        self.bins.iter().map(|b| b.mean_g).fold(0.0, f64::max).max(1e-9)
    }
}

/// Size of the report's figure, pixels.
pub const FIGURE_SIZE: (u32, u32) = (780, 720);

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

        // the figure: the mean distance in red in the middle third, the mean g in blue in the
        // bottom third, the points further right the less aligned their bin
        let fig = r.figure().unwrap();
        let (w, h) = (FIGURE_SIZE.0 as usize, FIGURE_SIZE.1 as usize);
        let where_is = |c: [u8; 3]| -> Vec<(usize, usize)> {
            (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .filter(|&(x, y)| fig[3 * (y * w + x)..3 * (y * w + x) + 3] == c)
                .collect()
        };
        let (red, blue) = (where_is([200, 30, 30]), where_is([30, 60, 200]));
        assert!(red.len() > 50 && red.iter().all(|p| p.1 > h / 3 && p.1 < 2 * h / 3), "{}", red.len());
        assert!(blue.len() > 50 && blue.iter().all(|p| p.1 > 2 * h / 3), "{}", blue.len());
        // the five bins span log10(1 - dot) -7 .. -0.25 of the axis -7 .. 0.5: the points reach 90 % across
        let (lo, hi) = (red.iter().map(|p| p.0).min().unwrap(), red.iter().map(|p| p.0).max().unwrap());
        assert!((hi - lo) as f64 > 0.75 * w as f64, "{lo}..{hi}");
    }

    #[test]
    fn sums_counted_apart_and_merged_give_the_whole_report_bit_for_bit() {
        // 3000 voxels of widely spread sizes, whose f64 running sums depend on the order
        let n = 3000;
        let hit: Vec<f32> = (0..n).map(|i| if i % 7 == 3 { 0.0 } else { 1.0 }).collect();
        let dot: Vec<f32> = (0..n).map(|i| 1.0 - ((i * 7919) % 1000) as f32 * 1e-3).collect();
        let distance: Vec<f32> = (0..n).map(|i| ((i * 31) % 97) as f32 * if i % 2 == 0 { 1e-4 } else { 1e3 }).collect();
        let g: Vec<f32> = (0..n).map(|i| ((i * 13) % 101) as f32 * if i % 3 == 0 { 1e5 } else { 0.37 }).collect();
        let g_hit = vec![50.0; n];
        let thresholds = ReportThresholds { g_min: 1.0, g_hit_min: 20.0 };
        let part = |r: std::ops::Range<usize>| ReportInput {
            hit: &hit[r.clone()],
            dot: &dot[r.clone()],
            distance: &distance[r.clone()],
            g: &g[r.clone()],
            g_hit: &g_hit[r],
        };
        let whole = Report::new(part(0..n), thresholds);
        // three pieces counted apart, merged in another order than the voxels'
        let mut pieces: Vec<ReportAccumulator> = [0..1100, 1100..1101, 1101..n]
            .into_iter()
            .map(|r| {
                let mut acc = ReportAccumulator::new(thresholds);
                acc.add(part(r));
                acc
            })
            .collect();
        let mut merged = pieces.pop().unwrap();
        pieces.iter().for_each(|p| merged.merge(p));
        let merged = merged.finish();
        assert_eq!(merged, whole);
        assert!(whole.hits > 2000 && whole.outliers > 0, "{} {}", whole.hits, whole.outliers);
        // the largest paper bin's mean distance, brute force in f64
        let big = whole.paper_bins.iter().max_by_key(|b| b.voxels).unwrap();
        let kept = (0..n).filter(|&i| hit[i] == 1.0 && g[i] >= 1.0 && (dot[i] as f64 * 100.0).round() == big.lo);
        let (count, sum) = kept.fold((0u64, 0.0f64), |(c, s), i| (c + 1, s + distance[i] as f64));
        assert_eq!(count, big.voxels);
        assert!(
            (sum / count as f64 - big.mean_distance).abs() <= 1e-12 * big.mean_distance.abs(),
            "{}",
            big.mean_distance
        );
    }
}
