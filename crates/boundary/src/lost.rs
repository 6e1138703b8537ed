//! Boundaries the thresholds take out of the outputs.
//!
//! Every voxel at or above the noise floor is traced, whatever g_min and
//! g_hit_min say, and the g at each zero crossing goes into a histogram.
//! A boundary shows there as a peak: the voxels on both of its sides reach
//! the same crossing, so they share its peak g (the stretched histogram's
//! rows). A peak that holds at least [`LOST_MIN_SHARE`] of the crossings,
//! lies above the default g_hit_min (so it is not noise) and below the
//! thresholds in force is a boundary whose voxels were all rejected or not
//! traced; the stage warns about it.

use serde::{Deserialize, Serialize};

/// Bins of the crossing histogram, over [0, the largest g].
pub(crate) const BINS: usize = 256;
/// Least share of the crossings a peak (its bin and two on each side) must hold to count as a boundary.
pub const LOST_MIN_SHARE: f64 = 0.01;

/// Counts of g at the zero crossings.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct CrossingHistogram {
    /// Upper end of the g axis (the largest g in the volume).
    max: f32,
    counts: Vec<u64>,
}

impl CrossingHistogram {
    pub(crate) fn new(max: f32) -> CrossingHistogram {
        CrossingHistogram { max: if max > 0.0 { max } else { 1.0 }, counts: vec![0; BINS] }
    }

    /// Counts one crossing's g (above the axis: the last bin).
    #[inline]
    pub(crate) fn add(&mut self, g_hit: f32) {
        if g_hit.is_nan() {
            return;
        }
        let b = (g_hit / self.max * BINS as f32) as usize;
        self.counts[b.min(BINS - 1)] += 1;
    }

    pub(crate) fn merge(&mut self, other: &CrossingHistogram) {
        self.counts.iter_mut().zip(&other.counts).for_each(|(a, b)| *a += b);
    }

    fn centre(&self, b: usize) -> f64 {
        (b as f64 + 0.5) * self.max as f64 / BINS as f64
    }
}

/// A boundary taken out of the outputs by g_min or g_hit_min.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LostBoundary {
    /// Its peak g (the crossing histogram's bin centre), value units per world unit.
    pub g_peak: f64,
    /// Crossings in the peak (its bin and two on each side).
    pub voxels: u64,
    /// Share of all crossings.
    pub share: f64,
}

/// The peaks of `h` in (floor, cut): bins highest over the run of bins
/// around them holding at least half their count (and over two bins on
/// each side), whose bin and two on each side hold at least
/// [`LOST_MIN_SHARE`] of the crossings. A noisy boundary's top splits into
/// local maxima a few bins apart; the half-height run makes it one peak.
pub(crate) fn lost_boundaries(h: &CrossingHistogram, floor: f64, cut: f64) -> Vec<LostBoundary> {
    let total: u64 = h.counts.iter().sum();
    if total == 0 {
        return vec![];
    }
    let c = &h.counts;
    let window = |b: usize| b.saturating_sub(2)..(b + 3).min(BINS);
    // the bins around b holding at least half of its count (and two on each side)
    let half_run = |b: usize| {
        let half = |o: &usize| 2 * c[*o] >= c[b];
        let first = (0..b).rev().take_while(half).last().unwrap_or(b).min(window(b).start);
        let last = (b + 1..BINS).take_while(half).last().unwrap_or(b).max(window(b).end - 1);
        first..last + 1
    };
    (0..BINS)
        .filter(|&b| {
            let centre = h.centre(b);
            // ties go to the lowest bin of a plateau
            centre > floor
                && centre < cut
                && c[b] > 0
                && half_run(b).all(|o| o == b || (o < b && c[o] < c[b]) || (o > b && c[o] <= c[b]))
        })
        .filter_map(|b| {
            let voxels: u64 = c[window(b)].iter().sum();
            let share = voxels as f64 / total as f64;
            (share >= LOST_MIN_SHARE).then_some(LostBoundary { g_peak: h.centre(b), voxels, share })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_peak_between_floor_and_cut_is_lost_and_a_spread_of_noise_is_not() {
        let mut h = CrossingHistogram::new(256.0);
        // noise: a smooth decline from g = 0; a boundary at g = 100.5; another at 200.5
        for g in 0..60 {
            for _ in 0..(600 - 10 * g) {
                h.add(g as f32 + 0.5);
            }
        }
        for (g, n) in [(99.5, 100), (100.5, 900), (101.5, 150), (200.5, 5000)] {
            for _ in 0..n {
                h.add(g);
            }
        }
        let lost = lost_boundaries(&h, 10.0, 150.0);
        assert_eq!(lost.len(), 1, "{lost:?}");
        assert_eq!(lost[0].g_peak, 100.5);
        assert_eq!(lost[0].voxels, 1150);
        // below the floor the noise's top is no boundary; above the cut nothing is lost
        assert!(lost_boundaries(&h, 10.0, 99.0).is_empty());
        assert!(lost_boundaries(&h, 1.0, 5.0).is_empty());
    }

    #[test]
    fn a_noisy_peak_split_in_two_tops_is_one_boundary() {
        // one boundary whose crossings' g spread over 95..106 with two tops 4 bins apart and a
        // shallow dip between them (the split seen with g_hit_min above a noisy sphere's peak)
        let mut h = CrossingHistogram::new(256.0);
        let counts = [100, 300, 600, 800, 700, 650, 700, 820, 600, 300, 100];
        for (k, n) in counts.iter().enumerate() {
            for _ in 0..*n {
                h.add(95.5 + k as f32);
            }
        }
        let lost = lost_boundaries(&h, 10.0, 150.0);
        assert_eq!(lost.len(), 1, "{lost:?}");
        // the higher top
        assert_eq!(lost[0].g_peak, 102.5);
    }
}
