//! Counting: joint histograms of 1 to 3 channels, in parallel, with integer
//! counts (so the result does not depend on the thread count).

use crate::HistogramError;
use crate::axis::Axis;
use rayon::prelude::*;
use serde::Serialize;

/// Counts over 1, 2 or 3 axes; the first axis varies fastest in `counts`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Histogram {
    /// The axes, in order.
    pub axes: Vec<Axis>,
    /// Counts, length = product of the bin counts (u32: inputs hold fewer than 2^32 voxels).
    pub counts: Vec<u32>,
}

impl Histogram {
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
        self.counts.iter().map(|&c| c as u64).sum()
    }

    /// Largest count.
    pub fn max(&self) -> u64 {
        self.counts.iter().copied().max().unwrap_or(0) as u64
    }

    /// The 2D projection onto axes (a, b) of a 3D histogram (summing the third).
    pub fn project(&self, a: usize, b: usize) -> Histogram {
        let c = 3 - a - b;
        let (na, nb, nc) = (self.axes[a].bins, self.axes[b].bins, self.axes[c].bins);
        let mut counts = vec![0u32; na * nb];
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
    let total_bins: usize = axes.iter().map(|a| a.bins).product();
    if n as u64 >= u32::MAX as u64 {
        return Err(HistogramError::Geometry(format!("{n} voxels: histograms count at most 2^32 - 1")));
    }
    if total_bins > 1 << 28 {
        return Err(HistogramError::BadAxis(format!("{total_bins} bins is too many (at most 2^28)")));
    }
    let strides: Vec<usize> = axes
        .iter()
        .scan(1usize, |s, a| {
            let here = *s;
            *s *= a.bins;
            Some(here)
        })
        .collect();
    let binners: Vec<_> = axes.iter().map(Axis::binner).collect();
    let parts = rayon::current_num_threads().clamp(1, 64);
    let part_len = n.div_ceil(parts).max(1);
    let range_of = |p: usize| (p * part_len).min(n)..((p + 1) * part_len).min(n);
    // One private table per worker, summed in a fixed order.
    let mut partial: Vec<Vec<u32>> = (0..parts)
        .into_par_iter()
        .map(|p| {
            let mut local = vec![0u32; total_bins];
            let mut add = |idx: usize| local[idx] += 1;
            count_part(channels, &binners, &strides, mask, range_of(p), &mut add);
            local
        })
        .collect();
    let mut counts = partial.swap_remove(0);
    for local in &partial {
        counts.par_chunks_mut(1 << 16).zip(local.par_chunks(1 << 16)).for_each(|(c, l)| {
            c.iter_mut().zip(l).for_each(|(c, &l)| *c += l);
        });
    }
    Ok(Histogram { axes, counts })
}

/// Calls `add(bin index)` for every counted voxel of `range`.
fn count_part(
    channels: &[&[f32]],
    binners: &[crate::axis::Binner],
    strides: &[usize],
    mask: Option<&[bool]>,
    range: std::ops::Range<usize>,
    add: &mut impl FnMut(usize),
) {
    match channels.len() {
        1 => count_n::<1>(channels, binners, strides, mask, range, add),
        2 => count_n::<2>(channels, binners, strides, mask, range, add),
        _ => count_n::<3>(channels, binners, strides, mask, range, add),
    }
}

/// [`count_part`] monomorphised per channel count so the axis loop unrolls.
fn count_n<const N: usize>(
    channels: &[&[f32]],
    binners: &[crate::axis::Binner],
    strides: &[usize],
    mask: Option<&[bool]>,
    range: std::ops::Range<usize>,
    add: &mut impl FnMut(usize),
) {
    let ch: [&[f32]; N] = std::array::from_fn(|a| &channels[a][range.clone()]);
    let bn: [crate::axis::Binner; N] = std::array::from_fn(|a| binners[a]);
    let st: [usize; N] = std::array::from_fn(|a| strides[a]);
    let m = mask.map(|m| &m[range.clone()]);
    'voxel: for i in 0..range.len() {
        if let Some(m) = m
            && !m[i]
        {
            continue;
        }
        let mut idx = 0;
        for a in 0..N {
            match bn[a].bin(ch[a][i]) {
                Some(b) => idx += b * st[a],
                None => continue 'voxel,
            }
        }
        add(idx);
    }
}
