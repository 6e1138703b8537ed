//! The value range of a volume, checked for NaN and infinities in the same pass.

use rayon::prelude::*;

/// (min, max) of `data`, or None if any sample is NaN or infinite; in parallel
/// over blocks (min and max do not depend on the order, so neither does the result).
pub fn finite_range(data: &[f32]) -> Option<(f32, f32)> {
    data.par_chunks(1 << 16)
        .map(block_range)
        .reduce(|| Some((f32::INFINITY, f32::NEG_INFINITY)), |a, b| Some((a?.0.min(b?.0), a?.1.max(b?.1))))
}

/// Smallest and largest finite sample of `data`, skipping NaN and
/// infinities (a second, filtering pass only when there are some), or None
/// if there is no finite sample.
pub fn finite_sample_range(data: &[f32]) -> Option<(f32, f32)> {
    if let Some(r) = finite_range(data)
        && r.0 <= r.1
    {
        return Some(r);
    }
    let mut lo = f32::INFINITY;
    let mut hi = f32::NEG_INFINITY;
    for &v in data.iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo <= hi).then_some((lo, hi))
}

/// The k-th smallest finite sample of `data` (k from 0), exactly, or None
/// if there are at most k finite samples. NaN and infinities are skipped.
///
/// A two-pass radix select over the samples' order-preserving 32-bit keys:
/// a histogram of the upper 16 bits finds the bucket holding the k-th key,
/// a histogram of the lower 16 bits within that bucket finds the key. It
/// reads `data` twice and allocates two 2^16-bin histograms per worker,
/// never a copy of the data, and the counts do not depend on the order.
pub fn order_statistic(data: &[f32], k: u64) -> Option<f32> {
    let none: Result<Option<f32>, std::convert::Infallible> = order_statistic_of_pieces(k, |visit| {
        visit(data);
        Ok(())
    });
    none.unwrap_or_else(|e| match e {})
}

/// [`order_statistic`] of samples that come in pieces (the blocks of a
/// slab-by-slab run): `pass(visit)` hands every piece to `visit`, in any
/// order; it is called twice (the two passes of the radix select). Its
/// first error stops the select.
pub fn order_statistic_of_pieces<E>(
    k: u64,
    mut pass: impl FnMut(&mut dyn FnMut(&[f32])) -> Result<(), E>,
) -> Result<Option<f32>, E> {
    let mut upper = KeyBuckets::new();
    pass(&mut |d| upper.add(d))?;
    order_statistic_from_buckets(k, &upper, pass)
}

/// Buckets of a radix select over f32 samples: 2^16 buckets by the upper
/// half of an order-preserving key.
const BUCKETS: usize = 1 << 16;

/// The key of `v` whose unsigned order is the order of the floats.
fn key(v: f32) -> u32 {
    let b = v.to_bits();
    if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
}

/// The first pass of [`order_statistic_of_pieces`]: counts of the finite
/// samples seen so far by the upper half of their keys. A caller that sees
/// the samples anyway (a pass computing them) keeps these, and the select
/// ([`order_statistic_from_buckets`]) then takes one pass instead of two.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Vec<u64>")]
pub struct KeyBuckets(Vec<u64>);

impl TryFrom<Vec<u64>> for KeyBuckets {
    type Error = String;

    fn try_from(counts: Vec<u64>) -> Result<KeyBuckets, String> {
        match counts.len() {
            BUCKETS => Ok(KeyBuckets(counts)),
            n => Err(format!("{n} bucket counts where {BUCKETS} were expected")),
        }
    }
}

impl Default for KeyBuckets {
    fn default() -> Self {
        KeyBuckets::new()
    }
}

impl KeyBuckets {
    /// No samples counted.
    pub fn new() -> KeyBuckets {
        KeyBuckets(vec![0; BUCKETS])
    }

    /// Counts the finite samples of `data`.
    pub fn add(&mut self, data: &[f32]) {
        count_piece(data, &|key| Some((key >> 16) as usize), &mut self.0);
    }

    /// Counts the finite samples of `data` whose key lies in upper bucket
    /// `within`, by the lower half of their key (the select's second pass).
    pub fn add_within(&mut self, within: usize, data: &[f32]) {
        count_piece(data, &|key| ((key >> 16) as usize == within).then_some((key & 0xffff) as usize), &mut self.0);
    }

    /// Adds the counts of `other` (samples counted elsewhere: a cluster's tasks).
    pub fn merge(&mut self, other: &KeyBuckets) {
        self.0.iter_mut().zip(&other.0).for_each(|(a, b)| *a += b);
    }

    /// How many finite samples were counted.
    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }
}

/// [`median`] of the samples `upper` counted: the lower median, taken by
/// one more pass (`pass(visit)` hands out the same samples), or None without finite samples.
pub fn median_from_buckets<E>(
    upper: &KeyBuckets,
    pass: impl FnMut(&mut dyn FnMut(&[f32])) -> Result<(), E>,
) -> Result<Option<f32>, E> {
    let Some(last) = upper.total().checked_sub(1) else { return Ok(None) };
    order_statistic_from_buckets(last / 2, upper, pass)
}

/// Counts the finite samples of `data` into `into` by the bucket `select` gives each key (None: not counted).
fn count_piece(data: &[f32], select: &(dyn Fn(u32) -> Option<usize> + Sync), into: &mut [u64]) {
    let h = data
        .par_chunks(1 << 18)
        .map(|c| {
            let mut h = vec![0u64; BUCKETS];
            for &v in c.iter().filter(|v| v.is_finite()) {
                if let Some(b) = select(key(v)) {
                    h[b] += 1;
                }
            }
            h
        })
        .reduce(
            || vec![0u64; BUCKETS],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        );
    into.iter_mut().zip(&h).for_each(|(x, y)| *x += y);
}

/// The bucket holding the k-th key, and how many keys lie in lower buckets.
fn find(h: &[u64], k: u64) -> Option<(usize, u64)> {
    let mut below = 0u64;
    for (b, &n) in h.iter().enumerate() {
        if below + n > k {
            return Some((b, below));
        }
        below += n;
    }
    None
}

/// [`order_statistic_of_pieces`] whose first pass is done: `upper` counted
/// every piece `pass(visit)` hands out (called once more here, with the same samples).
pub fn order_statistic_from_buckets<E>(
    k: u64,
    upper: &KeyBuckets,
    mut pass: impl FnMut(&mut dyn FnMut(&[f32])) -> Result<(), E>,
) -> Result<Option<f32>, E> {
    let Some(within) = upper_bucket_of(k, upper) else { return Ok(None) };
    let mut lower = KeyBuckets::new();
    pass(&mut |d| lower.add_within(within, d))?;
    Ok(order_statistic_from_counts(k, upper, &lower))
}

/// The upper bucket of [`KeyBuckets`] `upper` that holds the k-th smallest
/// sample counted (0-based), if there are that many: the second pass of the
/// select counts the samples of that bucket ([`KeyBuckets::add_within`]).
pub fn upper_bucket_of(k: u64, upper: &KeyBuckets) -> Option<usize> {
    find(&upper.0, k).map(|(hi, _)| hi)
}

/// The k-th smallest sample (0-based) from the two passes' counts: `upper`
/// of every sample, `lower` of those in the upper bucket holding it
/// ([`upper_bucket_of`]), which may be counted piece by piece anywhere and
/// merged. None if there are not that many samples.
pub fn order_statistic_from_counts(k: u64, upper: &KeyBuckets, lower: &KeyBuckets) -> Option<f32> {
    let (hi, below) = find(&upper.0, k)?;
    let (lo, _) = find(&lower.0, k - below)?;
    let key = ((hi as u32) << 16) | lo as u32;
    let bits = if key >> 31 == 1 { key & 0x7fff_ffff } else { !key };
    Some(f32::from_bits(bits))
}

/// The median of the finite samples of `data` (the lower one of an even
/// count: the ((n - 1) / 2)-th smallest), or None without finite samples.
pub fn median(data: &[f32]) -> Option<f32> {
    let finite = data.iter().filter(|v| v.is_finite()).count() as u64;
    order_statistic(data, finite.checked_sub(1)? / 2)
}

/// [`median`] of samples that come in pieces: `pass(visit)` hands every
/// piece to `visit`; it is called twice (the two passes of a radix select,
/// the first also counting the finite samples), and must hand out the same
/// samples each time.
pub fn median_of_pieces<E>(mut pass: impl FnMut(&mut dyn FnMut(&[f32])) -> Result<(), E>) -> Result<Option<f32>, E> {
    let mut upper = KeyBuckets::new();
    pass(&mut |d| upper.add(d))?;
    median_from_buckets(&upper, pass)
}

/// Lanes of the block loop: two AVX-512 registers, so that the min, max and
/// NaN chains of one register do not wait on the previous iteration's.
const LANES: usize = 32;

/// [`finite_range`] of one block, in [`LANES`] lanes so that the loop vectorises.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn block_range(data: &[f32]) -> Option<(f32, f32)> {
    let mut lo = [f32::INFINITY; LANES];
    let mut hi = [f32::NEG_INFINITY; LANES];
    let mut poison = [0.0f32; LANES]; // v * 0 is NaN exactly for NaN and infinities
    let (chunks, tail) = data.as_chunks::<LANES>();
    for c in chunks {
        for l in 0..LANES {
            lo[l] = if c[l] < lo[l] { c[l] } else { lo[l] };
            hi[l] = if c[l] > hi[l] { c[l] } else { hi[l] };
            poison[l] += c[l] * 0.0;
        }
    }
    for &v in tail {
        lo[0] = lo[0].min(v);
        hi[0] = hi[0].max(v);
        poison[0] += v * 0.0;
    }
    if poison.iter().any(|p| p.is_nan()) {
        return None;
    }
    Some((lo.iter().copied().fold(f32::INFINITY, f32::min), hi.iter().copied().fold(f32::NEG_INFINITY, f32::max)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_statistics_of_pieces_equal_those_of_a_sorted_copy_and_pass_errors_on() {
        let data: Vec<f32> = (0..5000u32).map(|i| ((i * 7919) % 5003) as f32 * 0.37 - 300.0).collect();
        let mut sorted = data.clone();
        sorted.sort_by(f32::total_cmp);
        for k in [0u64, 1, 2499, 4998, 4999] {
            let pieces = |visit: &mut dyn FnMut(&[f32])| -> Result<(), ()> {
                // uneven pieces, out of order
                for r in [3000..5000, 0..1, 1..3000] {
                    visit(&data[r]);
                }
                Ok(())
            };
            assert_eq!(order_statistic_of_pieces(k, pieces), Ok(Some(sorted[k as usize])), "k = {k}");
        }
        assert_eq!(
            order_statistic_of_pieces(5000, |v: &mut dyn FnMut(&[f32])| -> Result<(), ()> {
                v(&data);
                Ok(())
            }),
            Ok(None)
        );
        assert_eq!(order_statistic_of_pieces(3, |_: &mut dyn FnMut(&[f32])| Err("disk")), Err("disk"));
        // the median of pieces (NaN skipped) is the lower median of the whole, as median() takes it
        let mut with_nan = data.clone();
        with_nan[17] = f32::NAN;
        let pieces = |visit: &mut dyn FnMut(&[f32])| -> Result<(), ()> {
            for r in [2000..5000, 0..2000] {
                visit(&with_nan[r]);
            }
            Ok(())
        };
        assert_eq!(median_of_pieces(pieces), Ok(median(&with_nan)));
        assert_eq!(median_of_pieces(|_: &mut dyn FnMut(&[f32])| Ok::<(), ()>(())), Ok(None));
    }

    #[test]
    fn order_statistics_equal_those_of_a_sorted_copy() {
        let mut state = 11u64;
        let mut data: Vec<f32> = (0..300_001)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.3) * 1e3
            })
            .collect();
        data[5] = f32::NAN;
        data[9] = f32::INFINITY;
        data[17] = -0.0;
        data[18] = 0.0;
        let mut sorted: Vec<f32> = data.iter().copied().filter(|v| v.is_finite()).collect();
        sorted.sort_by(f32::total_cmp);
        for k in [0u64, 1, 1000, 150_000, 299_998] {
            assert_eq!(order_statistic(&data, k), Some(sorted[k as usize]), "k = {k}");
        }
        assert_eq!(order_statistic(&data, sorted.len() as u64), None);
        assert_eq!(order_statistic(&[], 0), None);
    }

    #[test]
    fn agrees_with_a_plain_fold_and_catches_every_non_finite_position() {
        // lengths around the lane and block sizes, values from a fixed LCG
        let mut state = 7u64;
        for len in [1usize, 31, 32, 33, 1000, (1 << 16) + 5, 3 << 16] {
            let data: Vec<f32> = (0..len)
                .map(|_| {
                    state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 1e4
                })
                .collect();
            let plain = data.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
            assert_eq!(finite_range(&data), Some(plain), "len {len}");
            for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                for at in [0, len / 2, len - 1] {
                    let mut d = data.clone();
                    d[at] = bad;
                    assert_eq!(finite_range(&d), None, "len {len}, {bad} at {at}");
                }
            }
        }
    }
}
