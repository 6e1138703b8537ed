//! Counting: joint histograms of 1 to 3 channels, in parallel, with integer
//! counts (so the result does not depend on the thread count).

use crate::HistogramError;
use crate::axis::{Axis, Binner};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Counts over 1, 2 or 3 axes; the first axis varies fastest in `counts`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Histogram {
    /// The axes, in order.
    pub axes: Vec<Axis>,
    /// Counts, length = product of the bin counts (u64: a bin of a
    /// 4096^3 volume's histogram holds more than 2^32 voxels).
    pub counts: Vec<u64>,
}

impl Histogram {
    /// Gives each axis the unit of its channel in the input's `units`
    /// ([`mdtf_volume::Units::of_channel`]; None where the input states none).
    pub fn set_units(&mut self, units: &mdtf_volume::Units) {
        for a in &mut self.axes {
            a.unit = units.of_channel(&a.name);
        }
    }

    /// Linear index of a bin tuple.
    pub fn index(&self, bins: &[usize]) -> usize {
        let mut idx = 0;
        for (a, &b) in bins.iter().enumerate().rev() {
            idx = idx * self.axes[a].bins + b;
        }
        idx
    }

    /// Sum of all counts (the voxels inside every axis range, within the mask).
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Largest count.
    pub fn max(&self) -> u64 {
        self.counts.iter().copied().max().unwrap_or(0)
    }

    /// The 2D projection onto axes (a, b) of a 3D histogram (summing the third).
    pub fn project(&self, a: usize, b: usize) -> Histogram {
        let c = 3 - a - b;
        let (na, nb, nc) = (self.axes[a].bins, self.axes[b].bins, self.axes[c].bins);
        let mut counts = vec![0u64; na * nb];
        let mut t = [0usize; 3];
        for ia in 0..na {
            for ib in 0..nb {
                let mut sum = 0;
                for ic in 0..nc {
                    t[a] = ia;
                    t[b] = ib;
                    t[c] = ic;
                    sum += self.counts[self.index(&t)];
                }
                counts[ib * na + ia] = sum;
            }
        }
        Histogram { axes: vec![self.axes[a].clone(), self.axes[b].clone()], counts }
    }
}

/// The stretched histogram's pair over the voxels whose tracing kept a hit
/// (`hit` code 1, and `mask` true where given): the (v, g) histogram over
/// `axes` and the (v, g_hit) one over the same axes, the second named
/// `g_hit` (one g axis, so that the two compare bin for bin).
pub fn stretched_pair(
    [v, g, g_hit]: [&[f32]; 3],
    hit: &[f32],
    axes: &[Axis],
    mask: Option<&[bool]>,
) -> Result<(Histogram, Histogram), HistogramError> {
    let mut traced = crate::hit_mask(hit);
    if let Some(m) = mask {
        traced.iter_mut().zip(m).for_each(|(t, &m)| *t &= m);
    }
    let normal = count(&[v, g], axes.to_vec(), Some(&traced))?;
    let mut stretched_axes = axes.to_vec();
    if let Some(a) = stretched_axes.get_mut(1) {
        a.name = "g_hit".into();
    }
    let stretched = count(&[v, g_hit], stretched_axes, Some(&traced))?;
    Ok((normal, stretched))
}

/// Counts the voxels of `channels` (one slice per axis, all the same length)
/// into `axes`; voxels outside any axis range, or where `mask` is false, are
/// not counted.
pub fn count(channels: &[&[f32]], axes: Vec<Axis>, mask: Option<&[bool]>) -> Result<Histogram, HistogramError> {
    if channels.is_empty() || channels.len() > 3 || channels.len() != axes.len() {
        return Err(HistogramError::BadAxis(format!(
            "{} channels and {} axes: give 1 to 3 of each, one axis per channel",
            channels.len(),
            axes.len()
        )));
    }
    let n = channels[0].len();
    if channels.iter().any(|c| c.len() != n) || mask.is_some_and(|m| m.len() != n) {
        return Err(HistogramError::Geometry("channels (and mask) must have the same number of voxels".into()));
    }
    let total_bins = check_size(&axes)?;
    let strides: Vec<usize> = axes
        .iter()
        .scan(1usize, |s, a| {
            let here = *s;
            *s *= a.bins;
            Some(here)
        })
        .collect();
    let binners: Vec<_> = axes.iter().map(Axis::binner).collect();
    // parts of at most u32::MAX voxels: a part counts into one table's u32 counts
    let parts = rayon::current_num_threads().clamp(1, 64).max(n.div_ceil(u32::MAX as usize));
    let part_len = n.div_ceil(parts).max(1);
    let range_of = |p: usize| (p * part_len).min(n)..((p + 1) * part_len).min(n);
    // One private table per worker, summed in a fixed order.
    let mut partial: Vec<SparseCounts> = (0..parts)
        .into_par_iter()
        .map(|p| {
            let mut local = SparseCounts::new(total_bins);
            let range = range_of(p);
            local.make_room(range.len() as u64);
            count_part(channels, &binners, &strides, mask, range, &mut |idx, run| local.add(idx, run));
            local
        })
        .collect();
    let mut counts = partial.swap_remove(0);
    for local in &partial {
        counts.merge(local);
    }
    Ok(Histogram { axes, counts: counts.into_totals() })
}

/// The number of bins of `axes`, checked against what u32 bin indices hold.
pub(crate) fn check_size(axes: &[Axis]) -> Result<usize, HistogramError> {
    let bins: Vec<String> = axes.iter().map(|a| a.bins.to_string()).collect();
    match axes.iter().try_fold(1usize, |p, a| p.checked_mul(a.bins)) {
        Some(total) if total <= 1 << 28 => Ok(total),
        _ => Err(HistogramError::BadAxis(format!("{} bins is too many (at most 2^28)", bins.join(" x ")))),
    }
}

/// Bins per block of the merge's touched-block bookkeeping (one 4 KiB page of u32 counts).
const MERGE_BLOCK: usize = 1024;

/// One thread's counts, noting which blocks of bins it touched. A fresh
/// (calloc) count array costs a page fault only where it is written, and a
/// merge reads only touched blocks, so sparse histograms (the 16.7 M bins of
/// a histogram volume) never fault in or scan their empty pages. Counts are
/// made in u32 (half the memory the counting loop touches) and spill into
/// u64 totals before they could overflow: room for the voxels to come is
/// made first ([`SparseCounts::make_room`]).
pub(crate) struct SparseCounts {
    /// Counts per bin since the last spill.
    narrow: Vec<u32>,
    touched: Vec<bool>,
    /// Voxels in `narrow` (or room made for them): at most u32::MAX.
    held: u64,
    /// Counts spilled from `narrow` (empty until the first spill).
    wide: Vec<u64>,
}

impl SparseCounts {
    /// Zero counts over `bins` bins.
    pub fn new(bins: usize) -> SparseCounts {
        SparseCounts { narrow: vec![0; bins], touched: vec![false; bins.div_ceil(MERGE_BLOCK)], held: 0, wide: vec![] }
    }

    /// Bins counted.
    pub fn bins(&self) -> usize {
        self.narrow.len()
    }

    /// Makes room for `voxels` more voxels (at most u32::MAX) in the u32
    /// counts, spilling them into the u64 totals first when needed.
    pub fn make_room(&mut self, voxels: u64) {
        if self.held + voxels > u64::from(u32::MAX) {
            self.spill();
        }
        self.held += voxels;
    }

    /// Moves the u32 counts into the u64 totals, block by touched block.
    fn spill(&mut self) {
        if self.wide.is_empty() {
            // calloc memory: a page costs memory only once a count is spilled into it
            self.wide = vec![0; self.narrow.len()];
        }
        let n = self.narrow.len();
        for (b, touched) in self.touched.iter_mut().enumerate().filter(|(_, t)| **t) {
            let block = b * MERGE_BLOCK..((b + 1) * MERGE_BLOCK).min(n);
            for (w, c) in self.wide[block.clone()].iter_mut().zip(&mut self.narrow[block]) {
                *w += u64::from(std::mem::take(c));
            }
            *touched = false;
        }
        self.held = 0;
    }

    /// Adds `run` to bin `idx` (room made for it).
    #[inline(always)]
    pub fn add(&mut self, idx: usize, run: u32) {
        self.narrow[idx] += run;
        self.touched[idx / MERGE_BLOCK] = true;
    }

    /// Adds another table's non-zero counts (bin, count), made room for
    /// at once when they fit the u32 counts together.
    pub fn add_counts(&mut self, counts: &[(u32, u64)]) {
        let total = counts.iter().try_fold(0u64, |t, &(_, n)| t.checked_add(n).filter(|&t| t <= u64::from(u32::MAX)));
        match total {
            Some(total) => {
                self.make_room(total);
                // each count is at most the total, which fits u32
                counts.iter().for_each(|&(bin, n)| self.add(bin as usize, n as u32));
            }
            None => counts.iter().for_each(|&(bin, n)| self.add_count(bin as usize, n)),
        }
    }

    /// Adds `n` to bin `idx` (another table's count).
    pub fn add_count(&mut self, idx: usize, n: u64) {
        match u32::try_from(n) {
            Ok(small) => {
                self.make_room(n);
                self.add(idx, small);
            }
            Err(_) => {
                if self.wide.is_empty() {
                    self.wide = vec![0; self.narrow.len()];
                }
                self.wide[idx] += n;
            }
        }
    }

    /// The non-zero counts (bin, count), read block by touched block (an
    /// untouched block's pages were never faulted in) until counts spill.
    pub fn nonzero(&self) -> Vec<(u32, u64)> {
        let n = self.narrow.len();
        if !self.wide.is_empty() {
            let total = |i: usize| self.wide[i] + u64::from(self.narrow[i]);
            return (0..n).filter(|&i| total(i) > 0).map(|i| (i as u32, total(i))).collect();
        }
        let touched = self.touched.iter().enumerate().filter(|(_, t)| **t);
        let blocks = touched.map(|(b, _)| b * MERGE_BLOCK..((b + 1) * MERGE_BLOCK).min(n));
        blocks.flat_map(|r| r.filter(|&i| self.narrow[i] > 0).map(|i| (i as u32, u64::from(self.narrow[i])))).collect()
    }

    /// Adds `other`'s counts, block by touched block.
    pub fn merge(&mut self, other: &SparseCounts) {
        self.make_room(other.held);
        let n = self.narrow.len();
        for (b, _) in other.touched.iter().enumerate().filter(|(_, t)| **t) {
            let block = b * MERGE_BLOCK..((b + 1) * MERGE_BLOCK).min(n);
            self.narrow[block.clone()].iter_mut().zip(&other.narrow[block]).for_each(|(c, &o)| *c += o);
            self.touched[b] = true;
        }
        if !other.wide.is_empty() {
            if self.wide.is_empty() {
                self.wide = vec![0; n];
            }
            self.wide.iter_mut().zip(&other.wide).for_each(|(c, &o)| *c += o);
        }
    }

    /// Every bin's count (pages of bins never counted stay unmapped zeros).
    pub fn into_totals(mut self) -> Vec<u64> {
        self.spill();
        self.wide
    }
}

/// Calls `add(bin index, n)` for every run of n consecutive counted voxels of `range` in one bin.
fn count_part(
    channels: &[&[f32]],
    binners: &[Binner],
    strides: &[usize],
    mask: Option<&[bool]>,
    range: std::ops::Range<usize>,
    add: &mut impl FnMut(usize, u32),
) {
    match channels.len() {
        1 => count_n::<1, _>(channels, binners, strides, mask, range, add),
        2 => count_n::<2, _>(channels, binners, strides, mask, range, add),
        _ => count_n::<3, _>(channels, binners, strides, mask, range, add),
    }
}

/// Voxels binned together before counting: the binning of a block is a
/// branch-free loop that vectorises; only the counting is scalar.
pub(crate) const BIN_BLOCK: usize = 64;

/// Marks a voxel that is masked out or outside an axis range.
pub(crate) const OUTSIDE: u32 = u32::MAX;

/// Bin indices (sum of bin x stride over the `N` axes, or [`OUTSIDE`]) of
/// voxels `start..start + out.len()` of `channels` into `out`.
#[inline(always)]
pub(crate) fn bin_block<const N: usize>(
    channels: &[&[f32]; N],
    binners: &[Binner; N],
    strides: &[u32; N],
    mask: Option<&[bool]>,
    start: usize,
    out: &mut [u32],
) {
    let len = out.len();
    let ch: [&[f32]; N] = std::array::from_fn(|a| &channels[a][start..start + len]);
    for (l, o) in out.iter_mut().enumerate() {
        let mut idx = 0u32;
        let mut inside = true;
        for a in 0..N {
            let (b, ok) = binners[a].bin_unchecked(ch[a][l]);
            idx += b * strides[a];
            inside &= ok;
        }
        *o = if inside { idx } else { OUTSIDE };
    }
    if let Some(m) = mask {
        for (o, &keep) in out.iter_mut().zip(&m[start..start + len]) {
            if !keep {
                *o = OUTSIDE;
            }
        }
    }
}

/// Calls `on_run(bin, voxels)` for every run of consecutive voxels of
/// `range` that share a bin (index as [`bin_block`] gives it), skipping
/// voxels outside the ranges or the mask. Neighbouring voxels often share a
/// bin (the background): a run is one call, where counting voxel by voxel
/// would be a chain of increments of one counter through memory.
#[inline(always)]
pub(crate) fn for_each_run<const N: usize>(
    channels: &[&[f32]; N],
    binners: &[Binner; N],
    strides: &[u32; N],
    mask: Option<&[bool]>,
    range: std::ops::Range<usize>,
    mut on_run: impl FnMut(u32, std::ops::Range<usize>),
) {
    let mut block = [0u32; BIN_BLOCK];
    let (mut bin, mut first) = (OUTSIDE, range.start);
    for start in range.clone().step_by(BIN_BLOCK) {
        let out = &mut block[..BIN_BLOCK.min(range.end - start)];
        bin_block(channels, binners, strides, mask, start, out);
        for (l, &here) in out.iter().enumerate() {
            if here != bin {
                if bin != OUTSIDE {
                    on_run(bin, first..start + l);
                }
                (bin, first) = (here, start + l);
            }
        }
    }
    if bin != OUTSIDE {
        on_run(bin, first..range.end);
    }
}

/// [`count_part`] monomorphised per channel count so the axis loop unrolls.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn count_n<const N: usize, F: FnMut(usize, u32)>(
    channels: &[&[f32]],
    binners: &[Binner],
    strides: &[usize],
    mask: Option<&[bool]>,
    range: std::ops::Range<usize>,
    add: &mut F,
) {
    let ch: [&[f32]; N] = std::array::from_fn(|a| channels[a]);
    let bn: [Binner; N] = std::array::from_fn(|a| binners[a]);
    let st: [u32; N] = std::array::from_fn(|a| strides[a] as u32);
    for_each_run(&ch, &bn, &st, mask, range, |bin, voxels| add(bin as usize, voxels.len() as u32));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stretched_pair_counts_only_the_hits_in_the_mask_each_on_its_own_channel() {
        // 4 x 4 bins over [0, 4); hit codes 0 (none), 1 (hit), 2 (lost to a threshold)
        let v = [0.5f32, 1.5, 2.5, 3.5, 0.5, 1.5];
        let g = [0.5f32, 0.5, 1.5, 1.5, 2.5, 3.5];
        let g_hit = [3.5f32, 2.5, 2.5, 0.5, 0.5, 1.5];
        let hit = [1.0f32, 1.0, 0.0, 1.0, 2.0, 1.0];
        let mask = [true, true, true, true, true, false];
        let axes = vec![Axis::new("v", 0.0, 4.0, 4).unwrap(), Axis::new("g", 0.0, 4.0, 4).unwrap()];
        let (normal, stretched) = stretched_pair([&v, &g, &g_hit], &hit, &axes, Some(&mask)).unwrap();
        // brute force: voxels 0, 1 and 3 are hits inside the mask
        let mut want_normal = vec![0u64; 16];
        let mut want_stretched = vec![0u64; 16];
        for i in [0, 1, 3] {
            want_normal[g[i] as usize * 4 + v[i] as usize] += 1;
            want_stretched[g_hit[i] as usize * 4 + v[i] as usize] += 1;
        }
        assert_eq!(normal.counts, want_normal);
        assert_eq!(stretched.counts, want_stretched);
        assert_eq!((stretched.axes[1].name.as_str(), normal.axes[1].name.as_str()), ("g_hit", "g"));
    }

    #[test]
    fn a_bin_holds_more_than_2_to_the_32_voxels_merged_from_tables() {
        // two tasks' tables, each with 3e9 voxels in one bin: 6e9 merged, exactly
        let (mut a, mut b) = (SparseCounts::new(4096), SparseCounts::new(4096));
        a.add_count(2000, 3_000_000_000);
        b.add_count(2000, 3_000_000_000);
        b.add(7, 5);
        a.merge(&b);
        assert_eq!(a.nonzero(), vec![(7, 5), (2000, 6_000_000_000)]);
        let h = Histogram { axes: vec![Axis::new("v", 0.0, 1.0, 4096).unwrap()], counts: a.into_totals() };
        assert_eq!((h.total(), h.max()), (6_000_000_005, 6_000_000_000));
    }

    #[test]
    fn u32_counts_spill_into_u64_totals_before_they_overflow() {
        let mut t = SparseCounts::new(3000);
        // nearly full: room for u32::MAX - 1 voxels, of which bin 1500 holds them all
        t.make_room(u64::from(u32::MAX) - 1);
        t.add(1500, u32::MAX - 1);
        t.add(2, 0);
        // ten more voxels do not fit: the u32 counts spill first
        t.make_room(10);
        t.add(1500, 10);
        t.add(2999, 1);
        let mut other = SparseCounts::new(3000);
        other.make_room(7);
        other.add(1500, 7);
        t.merge(&other);
        let want = u64::from(u32::MAX) - 1 + 10 + 7;
        assert_eq!(t.nonzero(), vec![(1500, want), (2999, 1)]);
        // another table's counts, small and large, added as a part absorbed elsewhere is
        let mut absorbed = SparseCounts::new(3000);
        absorbed.add_counts(&[(3, 5), (1500, 6)]);
        absorbed.add_counts(&[(1500, 5_000_000_000), (3, 1)]);
        assert_eq!(absorbed.nonzero(), vec![(3, 6), (1500, 5_000_000_006)]);
        let totals = t.into_totals();
        assert_eq!((totals[1500], totals[2999], totals.iter().sum::<u64>()), (want, 1, want + 1));
    }
}
