//! What an automatic axis range needs to know of a channel, gathered in one
//! streaming pass: the finite range, whether every finite sample is an
//! integer, and the exact order statistics at which percentile clipping
//! cuts.
//!
//! Clipping p percent of n finite samples at the low end starts the range at
//! x_(k), k = floor(p / 100 * n), the (k+1)-th smallest (likewise from the
//! top). The tails are tiny (Teem qbert clips 0.002 % and 0.004 %), so a
//! [`ChannelStats`] keeps only the samples that can still be among the
//! `keep` smallest or largest: a candidate list whose threshold rises as it
//! fills. The data may arrive in any pieces and any order (slices of a
//! streamed derive pass, blocks of a stored volume); the result is the same.

use crate::HistogramError;
use crate::axis::{Axis, AxisSpec, DEFAULT_BINS, MAX_INTEGER_BINS};
use rayon::prelude::*;

/// Block of the pass: one branch-free test per block; the element-wise look
/// only in blocks that hold a candidate.
const BLOCK: usize = 64;

/// One end's candidates: every sample seen strictly beyond `threshold`, and
/// enough of them that the `keep` most extreme samples are among them.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Tail {
    keep: usize,
    candidates: Vec<f32>,
    /// Samples not strictly beyond this can no longer be among the `keep` most extreme.
    threshold: f32,
    from_top: bool,
}

impl Tail {
    fn new(keep: usize, from_top: bool) -> Tail {
        let threshold = match (keep, from_top) {
            (0, false) => f32::NEG_INFINITY,
            (0, true) => f32::INFINITY,
            (_, false) => f32::INFINITY,
            (_, true) => f32::NEG_INFINITY,
        };
        Tail { keep, candidates: Vec::new(), threshold, from_top }
    }

    /// Ordering from the extreme inward.
    fn order(&self) -> impl Fn(&f32, &f32) -> std::cmp::Ordering + use<> {
        let from_top = self.from_top;
        move |a: &f32, b: &f32| if from_top { b.total_cmp(a) } else { a.total_cmp(b) }
    }

    #[inline]
    fn offer(&mut self, v: f32) {
        let beyond = if self.from_top { v > self.threshold } else { v < self.threshold };
        if beyond {
            self.candidates.push(v);
            if self.candidates.len() >= 2 * self.keep.max(BLOCK) {
                self.shrink();
            }
        }
    }

    /// Keeps the `keep` most extreme candidates; the threshold moves to the
    /// least extreme of them (a later sample equal to it cannot change the
    /// keep-th value).
    fn shrink(&mut self) {
        if self.keep == 0 || self.candidates.len() <= self.keep {
            return;
        }
        let order = self.order();
        let (_, &mut t, _) = self.candidates.select_nth_unstable_by(self.keep - 1, &order);
        self.candidates.truncate(self.keep);
        self.threshold = t;
    }

    fn merge(&mut self, mut o: Tail) {
        self.candidates.append(&mut o.candidates);
        self.threshold = if self.from_top { self.threshold.max(o.threshold) } else { self.threshold.min(o.threshold) };
        self.shrink();
    }

    /// The k-th sample (0-based) from the extreme, if it is among the candidates.
    fn order_statistic(mut self, k: usize) -> Option<f32> {
        if k >= self.candidates.len() {
            return None;
        }
        let order = self.order();
        Some(*self.candidates.select_nth_unstable_by(k, order).1)
    }
}

/// Range, integer-ness and percentile tails of one channel (see the module
/// docs). Serialisable, so that statistics taken elsewhere (a cluster's
/// tasks) merge here; keep every f32 bit (a binary format: JSON has no infinity).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ChannelStats {
    clip: (f64, f64),
    low: Tail,
    high: Tail,
    lo: f32,
    hi: f32,
    finite: u64,
    integer: bool,
}

impl ChannelStats {
    /// Empty statistics for clipping `clip` percent (low, high) of at most
    /// `total` samples (the channel's voxel count: it sets how many
    /// candidates each end keeps).
    pub fn new(clip: (f64, f64), total: usize) -> ChannelStats {
        let keep = |p: f64| if p > 0.0 { ((p / 100.0 * total as f64).floor() as usize + 1).min(total) } else { 0 };
        ChannelStats {
            clip,
            low: Tail::new(keep(clip.0), false),
            high: Tail::new(keep(clip.1), true),
            lo: f32::INFINITY,
            hi: f32::NEG_INFINITY,
            finite: 0,
            integer: true,
        }
    }

    /// Adds samples (NaN and infinities are counted nowhere).
    pub fn add(&mut self, data: &[f32]) {
        add_blocks(self, data);
    }

    /// The statistics of both sample sets.
    pub fn merge(mut self, o: ChannelStats) -> ChannelStats {
        self.low.merge(o.low);
        self.high.merge(o.high);
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
        self.finite += o.finite;
        self.integer &= o.integer;
        self
    }

    /// The statistics of `data`, in parallel over blocks.
    pub fn of(data: &[f32], clip: (f64, f64)) -> ChannelStats {
        ChannelStats::of_part(data, clip, data.len())
    }

    /// The statistics of `data`, a part of a channel of `total` samples (a
    /// slab of a slab-by-slab run), in parallel over blocks: to
    /// [`merge`](ChannelStats::merge) with the other parts' statistics.
    pub fn of_part(data: &[f32], clip: (f64, f64), total: usize) -> ChannelStats {
        let n = total;
        data.par_chunks(1 << 16)
            .fold(
                || ChannelStats::new(clip, n),
                |mut s, c| {
                    s.add(c);
                    s
                },
            )
            .reduce(|| ChannelStats::new(clip, n), ChannelStats::merge)
    }

    /// How many finite samples were added.
    pub fn finite_count(&self) -> u64 {
        self.finite
    }

    /// Smallest and largest finite sample, if any.
    pub fn finite_range(&self) -> Option<(f32, f32)> {
        (self.finite > 0).then_some((self.lo, self.hi))
    }

    /// [lo, hi] with the clip removed at each end: x_(k_lo) and x_(n-1-k_hi),
    /// k = floor(clip / 100 * n) over the n finite samples; the whole finite
    /// range where the clipped one would be empty.
    pub fn clipped_range(&self) -> Option<(f64, f64)> {
        let (lo, hi) = self.finite_range()?;
        let cut = |p: f64| (p / 100.0 * self.finite as f64).floor() as usize;
        let min = if self.clip.0 > 0.0 { self.low.clone().order_statistic(cut(self.clip.0)) } else { Some(lo) };
        let max = if self.clip.1 > 0.0 { self.high.clone().order_statistic(cut(self.clip.1)) } else { Some(hi) };
        match (min, max) {
            (Some(min), Some(max)) if max > min => Some((min as f64, max as f64)),
            _ => Some((lo as f64, hi as f64)),
        }
    }

    /// The axis `spec` gives for these samples (see [`AxisSpec::resolve`]);
    /// the spec's clip must be the one these statistics were made for.
    pub fn axis(&self, spec: &AxisSpec, name: &str) -> Result<Axis, HistogramError> {
        let Some(clipped) = self.clipped_range() else {
            return Err(HistogramError::BadAxis(format!("channel {name} has no finite samples")));
        };
        let (min, max) = spec.range.unwrap_or(clipped);
        let span = max - min;
        let bins = match spec.bins {
            Some(b) => b,
            None if self.integer && spec.range.is_none() && span < MAX_INTEGER_BINS as f64 => {
                // one bin per integer: cells centred on the integers
                return Axis::new(name, min.floor() - 0.5, max.ceil() + 0.5, (max.ceil() - min.floor()) as usize + 1);
            }
            None => DEFAULT_BINS,
        };
        if span == 0.0 && spec.range.is_none() {
            return Axis::new(name, min - 0.5, max + 0.5, bins);
        }
        Axis::new(name, min, max, bins)
    }
}

/// Lanes of the branch-free loop: the min, max and count chains of one lane
/// do not wait on another's, so the loop vectorises.
const LANES: usize = 16;

#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn add_blocks(s: &mut ChannelStats, data: &[f32]) {
    let (mut lo, mut hi) = ([s.lo; LANES], [s.hi; LANES]);
    let (mut finite, mut integer) = ([0u64; LANES], [true; LANES]);
    for block in data.chunks(BLOCK) {
        // branch-free: finite count and range, integer-ness, and whether any
        // sample lies strictly beyond a threshold (NaN compares false)
        let (t_lo, t_hi) = (s.low.threshold, s.high.threshold);
        let mut beyond = [false; LANES];
        let (lanes, tail) = block.as_chunks::<LANES>();
        let mut look = |l: usize, v: f32| {
            let ok = v.is_finite();
            finite[l] += u64::from(ok);
            lo[l] = if ok && v < lo[l] { v } else { lo[l] };
            hi[l] = if ok && v > hi[l] { v } else { hi[l] };
            integer[l] &= !ok || v.fract() == 0.0;
            beyond[l] |= ok & ((v < t_lo) | (v > t_hi));
        };
        for c in lanes {
            for l in 0..LANES {
                look(l, c[l]);
            }
        }
        for &v in tail {
            look(0, v);
        }
        if beyond.iter().any(|&b| b) {
            for &v in block.iter().filter(|v| v.is_finite()) {
                s.low.offer(v);
                s.high.offer(v);
            }
        }
    }
    s.finite += finite.iter().sum::<u64>();
    s.lo = lo.iter().copied().fold(s.lo, f32::min);
    s.hi = hi.iter().copied().fold(s.hi, f32::max);
    s.integer &= integer.iter().all(|&b| b);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition, by sorting every finite sample.
    fn by_sorting(data: &[f32], clip: (f64, f64)) -> (f64, f64) {
        let mut s: Vec<f32> = data.iter().copied().filter(|v| v.is_finite()).collect();
        s.sort_unstable_by(f32::total_cmp);
        let n = s.len();
        let cut = |p: f64| (p / 100.0 * n as f64).floor() as usize;
        let (min, max) = (s[cut(clip.0)] as f64, s[n - 1 - cut(clip.1)] as f64);
        // an empty clipped range falls back to the whole finite range
        if max > min { (min, max) } else { (s[0] as f64, s[n - 1] as f64) }
    }

    /// Pseudo-random data with heavy ties (a zero background), NaN and infinities.
    fn data(len: usize, seed: u64) -> Vec<f32> {
        let mut x = seed;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        (0..len)
            .map(|_| match next() % 100 {
                0..=59 => 0.0,
                60 => f32::NAN,
                61 => f32::INFINITY,
                62 => -3.0,
                _ => ((next() % 1_000_000) as f32 / 1000.0 - 200.0).powi(3) * 1e-4,
            })
            .collect()
    }

    const CLIPS: [(f64, f64); 6] = [(0.002, 0.002), (0.004, 0.0), (0.0, 0.5), (1.0, 1.0), (45.0, 5.0), (30.0, 30.0)];

    #[test]
    fn clipped_range_equals_the_order_statistics_of_a_sort() {
        for len in [1000usize, 70_001, 400_000] {
            let d = data(len, 0x9e37_79b9_7f4a_7c15);
            for clip in CLIPS {
                let s = ChannelStats::of(&d, clip);
                assert_eq!(s.clipped_range(), Some(by_sorting(&d, clip)), "len {len} clip {clip:?}");
            }
        }
    }

    #[test]
    fn pieces_in_any_order_give_the_same_statistics() {
        let d = data(123_457, 42);
        for clip in CLIPS {
            let whole = ChannelStats::of(&d, clip).clipped_range();
            // slices of 1000 added to one accumulator in reverse order, and pieces merged pairwise
            let mut one = ChannelStats::new(clip, d.len());
            for piece in d.chunks(1000).rev() {
                one.add(piece);
            }
            let merged = d
                .chunks(777)
                .map(|p| {
                    let mut s = ChannelStats::new(clip, d.len());
                    s.add(p);
                    s
                })
                .reduce(ChannelStats::merge);
            assert_eq!(one.clipped_range(), whole, "{clip:?}");
            assert_eq!(merged.and_then(|m| m.clipped_range()), whole, "{clip:?}");
        }
    }

    #[test]
    fn range_and_integers_are_tracked_and_nan_only_has_no_range() {
        let s = ChannelStats::of(&[3.0, f32::NAN, -2.0, 7.0, f32::NEG_INFINITY], (0.0, 0.0));
        assert_eq!(s.finite_range(), Some((-2.0, 7.0)));
        assert!(s.integer);
        assert!(!ChannelStats::of(&[3.0, 2.5], (0.0, 0.0)).integer);
        assert_eq!(ChannelStats::of(&[f32::NAN; 5], (0.1, 0.1)).clipped_range(), None);
        // clipping everything falls back to the whole range
        assert_eq!(ChannelStats::of(&[1.0, 5.0, 9.0], (100.0, 0.0)).clipped_range(), Some((1.0, 9.0)));
    }
}
