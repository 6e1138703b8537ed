//! Percentile clipping of automatic axis ranges: the exact order statistics
//! at each end, found from the tails alone.
//!
//! Clipping p percent of n samples at the low end keeps the range from
//! x_(k), k = floor(p / 100 * n), the (k+1)-th smallest finite sample (and
//! likewise from the top). The tails are tiny (Teem qbert clips 0.002 % and
//! 0.004 %), so instead of a fine histogram of the whole range, a strided
//! sample gives thresholds that the tails lie beyond, one pass gathers the
//! samples past them, and the order statistic is selected among those.

use rayon::prelude::*;

/// Samples in the strided sample that sets the thresholds.
const SAMPLE: usize = 1 << 16;
/// Block of the gathering pass: one branch-free test per block, the
/// element-wise look only in blocks that hold a tail sample.
const BLOCK: usize = 64;

/// [lo, hi] (the finite range of `data`) with `clip` percent of the finite
/// samples removed at each end (low, high): x_(k_lo) and x_(n-1-k_hi) with
/// k = floor(clip / 100 * n). Falls back to [lo, hi] when the clipped range
/// would be empty.
pub(crate) fn percentile_range(data: &[f32], lo: f64, hi: f64, clip: (f64, f64)) -> (f64, f64) {
    if clip.0 <= 0.0 && clip.1 <= 0.0 || hi <= lo {
        return (lo, hi);
    }
    let mut sample = spread_sample(data);
    sample.sort_unstable_by(f32::total_cmp);
    let stride = data.len() as f64 / SAMPLE.min(data.len()).max(1) as f64;
    // Expected tail size from the fraction of `data` (NaN included, so an
    // over-estimate of the finite count's cut); the margin grows on retry.
    let want = |p: f64| (p / 100.0 * data.len() as f64).floor() + 1.0;
    let mut margin = 2.0;
    loop {
        // threshold rank in the sample: ~margin x the tail, or the extreme itself
        let rank = |p: f64| (margin * want(p) / stride).ceil() as usize + 8;
        let t_lo = if clip.0 > 0.0 { sample.get(rank(clip.0)).map_or(hi as f32, |&v| v) } else { f32::NEG_INFINITY };
        let t_hi = if clip.1 > 0.0 {
            sample.len().checked_sub(rank(clip.1) + 1).map_or(lo as f32, |r| sample[r])
        } else {
            f32::INFINITY
        };
        let last = (clip.0 <= 0.0 || rank(clip.0) >= sample.len()) && (clip.1 <= 0.0 || rank(clip.1) >= sample.len());
        let tails = gather(data, t_lo, t_hi);
        let cut = |p: f64| (p / 100.0 * tails.finite as f64).floor() as usize;
        let min = if clip.0 > 0.0 { tails.low.order_statistic(cut(clip.0), t_lo, false) } else { Some(lo as f32) };
        let max = if clip.1 > 0.0 { tails.high.order_statistic(cut(clip.1), t_hi, true) } else { Some(hi as f32) };
        if let (Some(min), Some(max)) = (min, max) {
            let (min, max) = (min as f64, max as f64);
            return if max > min { (min, max) } else { (lo, hi) };
        }
        if last {
            // every finite sample was gathered: only a clip of 100 % or more ends here
            return (lo, hi);
        }
        // the sample over-estimated a tail's density: wider thresholds (at worst the extremes)
        margin *= 16.0;
    }
}

/// The finite values among [`SAMPLE`] samples of `data` spread over it by a
/// Weyl sequence (index m * step mod len, step about len / golden ratio): a
/// plain stride would sample one column of an x-fastest volume whose row
/// length divides it.
fn spread_sample(data: &[f32]) -> Vec<f32> {
    if data.len() <= SAMPLE {
        return data.iter().copied().filter(|v| v.is_finite()).collect();
    }
    (0..SAMPLE).map(|m| data[sample_index(m, data.len())]).filter(|v| v.is_finite()).collect()
}

/// Index of the m-th spread sample of `len` samples (len > [`SAMPLE`]).
fn sample_index(m: usize, len: usize) -> usize {
    let step = ((len as f64 * 0.618_033_988_749_895) as u64) | 1;
    ((m as u64 * step) % len as u64) as usize
}

/// The samples strictly past a threshold, and how many equal it.
#[derive(Default)]
struct Tail {
    beyond: Vec<f32>,
    at: usize,
}

impl Tail {
    /// The k-th sample (0-based) counted from the extreme inward (`from_top`:
    /// descending), if the tail reaches that far; samples equal to the
    /// threshold come after those strictly beyond it.
    fn order_statistic(mut self, k: usize, threshold: f32, from_top: bool) -> Option<f32> {
        if k < self.beyond.len() {
            let (_, v, _) = if from_top {
                self.beyond.select_nth_unstable_by(k, |a, b| b.total_cmp(a))
            } else {
                self.beyond.select_nth_unstable_by(k, f32::total_cmp)
            };
            Some(*v)
        } else if k < self.beyond.len() + self.at {
            Some(threshold)
        } else {
            None
        }
    }

    fn merge(mut self, mut o: Tail) -> Tail {
        self.beyond.append(&mut o.beyond);
        self.at += o.at;
        self
    }
}

/// Both tails and the finite count of `data`.
#[derive(Default)]
struct Tails {
    low: Tail,
    high: Tail,
    finite: usize,
}

/// One pass over `data`: the finite samples below `t_lo` and above `t_hi`,
/// and those equal to each.
fn gather(data: &[f32], t_lo: f32, t_hi: f32) -> Tails {
    data.par_chunks(1 << 16).map(|chunk| gather_chunk(chunk, t_lo, t_hi)).reduce(Tails::default, |a, b| Tails {
        low: a.low.merge(b.low),
        high: a.high.merge(b.high),
        finite: a.finite + b.finite,
    })
}

#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn gather_chunk(chunk: &[f32], t_lo: f32, t_hi: f32) -> Tails {
    let mut t = Tails::default();
    for block in chunk.chunks(BLOCK) {
        // branch-free: the finite count, the ties with each threshold, and
        // whether any sample lies strictly beyond one (NaN compares false)
        let (mut finite, mut at_lo, mut at_hi) = (0usize, 0usize, 0usize);
        let mut beyond = false;
        for &v in block {
            finite += usize::from(v.is_finite());
            at_lo += usize::from(v == t_lo);
            at_hi += usize::from(v == t_hi);
            beyond |= (v < t_lo) | (v > t_hi);
        }
        t.finite += finite;
        t.low.at += at_lo;
        t.high.at += at_hi;
        if !beyond {
            continue;
        }
        for &v in block.iter().filter(|v| v.is_finite()) {
            if v < t_lo {
                t.low.beyond.push(v);
            }
            if v > t_hi {
                t.high.beyond.push(v);
            }
        }
    }
    t
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

    fn range(data: &[f32], clip: (f64, f64)) -> (f64, f64) {
        let (lo, hi) = mdtf_volume::finite_sample_range(data).unwrap_or((0.0, 0.0));
        percentile_range(data, lo as f64, hi as f64, clip)
    }

    #[test]
    fn equals_the_order_statistics_of_a_sort() {
        // deterministic pseudo-random data with heavy ties (a zero background), NaN and infinities
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for len in [1000usize, 70_001, 400_000] {
            let data: Vec<f32> = (0..len)
                .map(|_| match next() % 100 {
                    0..=59 => 0.0,
                    60 => f32::NAN,
                    61 => f32::INFINITY,
                    62 => -3.0,
                    _ => ((next() % 1_000_000) as f32 / 1000.0 - 200.0).powi(3) * 1e-4,
                })
                .collect();
            for clip in [(0.002, 0.002), (0.004, 0.0), (0.0, 0.5), (1.0, 1.0), (45.0, 5.0), (30.0, 30.0)] {
                assert_eq!(range(&data, clip), by_sorting(&data, clip), "len {len} clip {clip:?}");
            }
        }
    }

    #[test]
    fn a_sample_that_over_estimates_a_tail_still_gives_the_exact_answer() {
        // the large values sit exactly where the sample looks: it sees them
        // 4.6 times as often as they occur, so the first round gathers too few
        let mut data = vec![1.0f32; 300_000];
        for m in 0..300 {
            data[sample_index(m, 300_000)] = 1000.0 + m as f32;
        }
        let clip = (0.0, 0.05);
        assert_eq!(range(&data, clip), by_sorting(&data, clip));
        assert_eq!(range(&data, clip).1, 1149.0);
        // and a clip of everything falls back to the whole range
        assert_eq!(range(&data, (0.0, 100.0)), (1.0, 1299.0));
    }
}
