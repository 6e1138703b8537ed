//! Empty-space skipping for the ray caster: per block of [`BLOCK`]^3 cells,
//! whether any sample inside can add to a pixel, from each channel's
//! min..max over the block and the classifier's tables or primitives.
//! Interpolated values stay within a block's min..max, so a block found
//! invisible is skipped without changing a pixel (the Gaussian classifier:
//! by less than [`GAUSSIAN_SKIP_TOLERANCE`] of a level).

use crate::load::Table;
use crate::render::Classifier;
use crate::samples::Samples;
use rayon::prelude::*;

/// Which blocks of the grid `dims` can show with `classifier`, and the block
/// counts per axis; None where the classifier has no skipping (or lacks the
/// channel it needs). `table_chans` are the classifier's table channels in
/// axis order, `distance` and `v` the pack's channels, `path_voxels` the
/// longest ray's length in voxels.
pub(crate) fn visible_blocks_of(
    classifier: &Classifier,
    table_chans: &[Option<Samples>],
    distance: Option<Samples>,
    v_data: Option<Samples>,
    dims: [usize; 3],
    path_voxels: f64,
) -> Option<(Vec<bool>, [usize; 3])> {
    match classifier {
        Classifier::Lut(t) | Classifier::Chord { tf: t, .. } => Some(visible_blocks(t, table_chans, dims)),
        Classifier::Distance { alpha_d, .. } => distance.map(|d| visible_distance_blocks(alpha_d, d, dims)),
        Classifier::Peak { peak_table, preintegration, .. } => {
            v_data.map(|v| visible_peak_blocks(peak_table, preintegration, v, dims))
        }
        Classifier::Gaussian { primitives, sqrt_last, .. } => {
            let far = gaussian_far_exponent(primitives, path_voxels);
            Some(visible_gaussian_blocks(primitives, table_chans, *sqrt_last, far, dims))
        }
        // a product is 0 wherever one factor is: a block shows only if every factor can there
        Classifier::Product { factors, .. } if !factors.is_empty() => {
            let mut at = 0;
            let mut all: Option<(Vec<bool>, [usize; 3])> = None;
            for t in factors {
                let n = t.axes.len();
                let (visible, nb) = visible_blocks(t, &table_chans[at..at + n], dims);
                at += n;
                all = Some(match all {
                    None => (visible, nb),
                    Some((acc, nb)) => (acc.iter().zip(&visible).map(|(a, b)| *a && *b).collect(), nb),
                });
            }
            all
        }
        _ => None,
    }
}

/// The index of the block holding voxel-space position `p`, of `nb` blocks per axis.
pub(crate) fn block_at(nb: [usize; 3], p: [f64; 3]) -> usize {
    let b = [0, 1, 2].map(|a| ((p[a].max(0.0) as usize) / BLOCK).min(nb[a] - 1));
    (b[2] * nb[1] + b[1]) * nb[0] + b[0]
}

/// The last sample, from sample `s` at voxel-space position `p` on a ray
/// advancing `per_sample` voxels per sample, that certainly lies in the
/// cube of blocks within `reach - 1` blocks (Chebyshev) of the block of `s`
/// (of `nb` per axis, as [`block_at`] assigns them; reach 1: that block
/// alone): the samples between lie in it too (a box is convex), so a ray
/// may jump over them where those blocks are invisible. One sample short
/// of the box's edge, for the rounding of the positions; `usize::MAX` when
/// the ray never leaves the box.
pub(crate) fn last_sample_in_reach(nb: [usize; 3], p: [f64; 3], per_sample: [f64; 3], s: usize, reach: u8) -> usize {
    let r = usize::from(reach.max(1)) - 1;
    let mut samples = f64::INFINITY;
    for a in 0..3 {
        let d = per_sample[a];
        let b = ((p[a].max(0.0) as usize) / BLOCK).min(nb[a] - 1);
        // the first and last blocks reach beyond the grid (block_at clamps)
        let edge = match d {
            d if d > 0.0 && b + r + 1 < nb[a] => ((b + r + 1) * BLOCK) as f64,
            d if d < 0.0 && b > r => ((b - r) * BLOCK) as f64,
            _ => continue,
        };
        // samples s + j with j < (edge - p) / d stay on this side of the edge
        samples = samples.min((edge - p[a]) / d);
    }
    if samples.is_finite() { s + (samples.ceil() as usize).saturating_sub(2) } else { usize::MAX }
}

/// The largest reach of empty space this table records, blocks.
const MAX_REACH: u8 = 8;

/// Per block of `visible` (`nb` per axis): 0 where it is visible, else the
/// largest k (up to [`MAX_REACH`]) such that every block of the grid within
/// k - 1 blocks of it (Chebyshev) is invisible; from k - 1 erosions of the
/// invisible blocks by the 3 x 3 x 3 cube, axis by axis.
pub(crate) fn empty_reach(visible: &[bool], nb: [usize; 3]) -> Vec<u8> {
    let mut empty: Vec<bool> = visible.iter().map(|v| !v).collect();
    let mut reach: Vec<u8> = empty.iter().map(|&e| u8::from(e)).collect();
    let strides = [1, nb[0], nb[0] * nb[1]];
    for k in 2..=MAX_REACH {
        for (a, &stride) in strides.iter().enumerate() {
            let before = empty.clone();
            for (b, e) in empty.iter_mut().enumerate() {
                let i = (b / stride) % nb[a];
                *e = before[b] && (i == 0 || before[b - stride]) && (i + 1 == nb[a] || before[b + stride]);
            }
        }
        if !empty.iter().any(|&e| e) {
            break;
        }
        for (r, &e) in reach.iter_mut().zip(&empty) {
            if e {
                *r = k;
            }
        }
    }
    reach
}

/// Edge of the blocks of empty-space skipping, voxels.
const BLOCK: usize = 8;

/// For a LUT classifier: per block of BLOCK^3 cells (trilinear cells, i.e.
/// voxels plus the next one along each axis), whether any sample inside can
/// get a non-zero opacity. Interpolated values stay within the block's
/// min..max of each channel, so a block whose box of LUT cells holds only
/// zero opacity is skipped without changing a pixel.
fn visible_blocks(t: &Table, chans: &[Option<Samples>], dims: [usize; 3]) -> (Vec<bool>, [usize; 3]) {
    let opaque = OpaqueCells::new(t);
    let ranges: Vec<Option<Vec<(f32, f32)>>> = chans.iter().map(|c| c.map(|d| block_ranges(d, dims))).collect();
    per_block(dims, |b| {
        let cells: Vec<(usize, usize)> = t
            .axes
            .iter()
            .zip(&ranges)
            .map(|(axis, r)| {
                let (vmin, vmax) = r.as_ref().map_or((0.0, 0.0), |r| r[b]);
                (table_cell(axis, vmin), table_cell(axis, vmax))
            })
            .collect();
        opaque.any(&cells)
    })
}

/// For the distance classifier: per block (as [`visible_blocks`]), whether
/// alpha_d can be non-zero there. alpha_d is 0 where the interpolated
/// distance is negative (no boundary), so a block whose distances are all
/// negative, or whose non-negative ones fall only on transparent alpha_d
/// cells, changes no pixel.
fn visible_distance_blocks(alpha_d: &Table, distance: Samples, dims: [usize; 3]) -> (Vec<bool>, [usize; 3]) {
    let opaque = OpaqueCells::new(alpha_d);
    let ranges = block_ranges(distance, dims);
    per_block(dims, |b| {
        let (dmin, dmax) = ranges[b];
        let Some(axis) = alpha_d.axes.first() else { return true };
        dmax >= 0.0 && opaque.any(&[(table_cell(axis, dmin.max(0.0)), table_cell(axis, dmax))])
    })
}

/// The most a skipped block may change a pixel, in 8-bit levels (a pixel
/// changes only where its exact value lies this close to a rounding edge).
const GAUSSIAN_SKIP_TOLERANCE: f64 = 1e-3;

/// The exponent beyond which the Gaussian primitives add less than
/// [`GAUSSIAN_SKIP_TOLERANCE`] of a level to any pixel, for rays of at most
/// `path` voxels: each sample adds at most 1 - exp(-l sum_k tau_k e^-E) <=
/// l sum_k tau_k e^-E of opacity (and as much colour), and the samples of a
/// ray sum to `path` voxels.
fn gaussian_far_exponent(primitives: &[mdtf_pack::GaussianPrimitive], path: f64) -> f64 {
    let tau: f64 = primitives.iter().map(|gp| gp.alpha_max.abs()).sum();
    (tau * path.max(1.0) * 255.0 / GAUSSIAN_SKIP_TOLERANCE).ln().max(0.0)
}

/// For the peak classifier: per block (as [`visible_blocks`]), whether a
/// sample there can show: some cell of the pre-integration table over the
/// block's (v, v) box is opaque, or some cell of the peak table there holds
/// a peak. The ray skips a sample of an invisible block only when the sample
/// before was in the same block (a segment from another block may cross a
/// peak), so the segment's values stay in the box.
fn visible_peak_blocks(peaks: &Table, preintegration: &Table, v: Samples, dims: [usize; 3]) -> (Vec<bool>, [usize; 3]) {
    let opaque = OpaqueCells::new(preintegration);
    let peaked = OpaqueCells::marking(peaks, |cell| peaks.values[cell * peaks.components] >= 0.0);
    let ranges = block_ranges(v, dims);
    per_block(dims, |b| {
        let (vmin, vmax) = ranges[b];
        if vmin > vmax {
            return true;
        }
        let box_of = |t: &Table| -> Vec<(usize, usize)> {
            t.axes.iter().map(|axis| (table_cell(axis, vmin), table_cell(axis, vmax))).collect()
        };
        opaque.any(&box_of(preintegration)) || peaked.any(&box_of(peaks))
    })
}

/// For the Gaussian classifier: per block (as [`visible_blocks`]), whether
/// any primitive can add anything there: a block whose box of TF coordinates
/// (each channel's min..max, the square root of the last where the
/// classifier takes it) keeps every primitive's exponent at least `far`
/// ([`gaussian_far_exponent`]) is skipped. A block holding NaN shows.
fn visible_gaussian_blocks(
    primitives: &[mdtf_pack::GaussianPrimitive],
    chans: &[Option<Samples>],
    sqrt_last: bool,
    far: f64,
    dims: [usize; 3],
) -> (Vec<bool>, [usize; 3]) {
    let ranges: Vec<Option<Vec<(f32, f32)>>> = chans.iter().map(|c| c.map(|d| block_ranges(d, dims))).collect();
    per_block(dims, |block| {
        let mut low = Vec::with_capacity(chans.len());
        let mut high = Vec::with_capacity(chans.len());
        for (k, r) in ranges.iter().enumerate() {
            let (mut a, mut b) = r.as_ref().map_or((0.0, 0.0), |r| r[block]);
            if a > b || a.is_nan() || b.is_nan() {
                return true;
            }
            if sqrt_last && k + 1 == chans.len() {
                (a, b) = (a.max(0.0).sqrt(), b.max(0.0).sqrt());
            }
            low.push(a as f64);
            high.push(b as f64);
        }
        primitives.iter().any(|gp| gp.exponent_lower_bound(&low, &high) < far)
    })
}

/// Blocks per axis of a grid of `dims`.
fn block_counts(dims: [usize; 3]) -> [usize; 3] {
    dims.map(|n| n.saturating_sub(1).max(1).div_ceil(BLOCK))
}

/// `visible(b)` for every block b of BLOCK^3 cells, in parallel; and the block counts.
fn per_block(dims: [usize; 3], visible: impl Fn(usize) -> bool + Sync) -> (Vec<bool>, [usize; 3]) {
    let nb = block_counts(dims);
    let mut out = vec![false; nb[0] * nb[1] * nb[2]];
    out.par_iter_mut().enumerate().for_each(|(b, o)| *o = visible(b));
    (out, nb)
}

/// The blocks (of `nb` along an axis) whose voxels (BLOCK + 1 of them: the
/// corners of their cells) include voxel `i`: its own, and the one before
/// on a block's edge.
fn blocks_holding(i: usize, nb: usize) -> impl Iterator<Item = usize> {
    let own = i / BLOCK;
    let before = (i.is_multiple_of(BLOCK) && own > 0).then(|| own - 1);
    (own < nb).then_some(own).into_iter().chain(before)
}

/// The smallest and largest sample of `d` (NaN ignored; infinity and minus
/// infinity where a block holds no other) over each block's voxels, in
/// block order: one pass over the samples, the z-rows of blocks in parallel.
fn block_ranges(d: Samples, dims: [usize; 3]) -> Vec<(f32, f32)> {
    let nb = block_counts(dims);
    let [nx, ny, nz] = dims;
    let plane = nb[0] * nb[1];
    let mut out = vec![(f32::INFINITY, f32::NEG_INFINITY); plane * nb[2]];
    out.par_chunks_mut(plane).enumerate().for_each(|(bz, acc)| {
        for z in bz * BLOCK..(bz * BLOCK + BLOCK + 1).min(nz) {
            for y in 0..ny {
                let row = (z * ny + y) * nx;
                for bx in 0..nb[0] {
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    for v in (row + bx * BLOCK..row + (bx * BLOCK + BLOCK + 1).min(nx)).map(|i| d.at(i)) {
                        // comparisons are false for NaN: NaN is passed over
                        lo = if v < lo { v } else { lo };
                        hi = if v > hi { v } else { hi };
                    }
                    for by in blocks_holding(y, nb[1]) {
                        let r = &mut acc[by * nb[0] + bx];
                        *r = (r.0.min(lo), r.1.max(hi));
                    }
                }
            }
        }
    });
    out
}

/// For the chord search of the chord classifiers: whether some chord from
/// f0 to f1 can meet a non-zero opacity, from the box of table cells the
/// chord spans in each table (a product's factors each over their own
/// coordinates; a product is 0 where one factor is).
pub(crate) struct ChordBoxes {
    /// Each table's opaque cells and its number of axes.
    tables: Vec<(OpaqueCells, usize)>,
    /// Each table's axes, one table after another.
    axes: Vec<(String, usize, f64, f64)>,
}

impl ChordBoxes {
    /// The boxes of the tables `tables` (a chord classifier's, or a product's factors).
    pub(crate) fn new(tables: &[&Table]) -> ChordBoxes {
        ChordBoxes {
            tables: tables.iter().map(|t| (OpaqueCells::new(t), t.axes.len())).collect(),
            axes: tables.iter().flat_map(|t| t.axes.iter().cloned()).collect(),
        }
    }

    /// Whether every point of the chord from `f0` to `f1` (coordinates of
    /// the tables one after another) has zero opacity: some table's box of
    /// the cells between theirs, one cell wider on each side (the chord's
    /// points are rounded), holds no opaque cell.
    pub(crate) fn all_transparent(&self, f0: &[f32], f1: &[f32]) -> bool {
        let mut at = 0;
        self.tables.iter().any(|(opaque, n)| {
            // (tables of up to 3 axes have counts; others always may show)
            let mut cells = [(0, 0); 3];
            for (c, k) in cells.iter_mut().zip(at..at + n) {
                let (a, b) = (table_cell(&self.axes[k], f0[k]), table_cell(&self.axes[k], f1[k]));
                *c = (a.min(b).saturating_sub(1), (a.max(b) + 1).min(self.axes[k].1 - 1));
            }
            at += n;
            !opaque.any(&cells[..(*n).min(3)])
        })
    }
}

/// The table cell of value x along `axis` (clamped, as [`lookup`] picks it).
fn table_cell((_, n, min, max): &(String, usize, f64, f64), x: f32) -> usize {
    ((x as f64 - min) / (max - min) * *n as f64).clamp(0.0, (*n - 1) as f64) as usize
}

/// Where a table (of up to 3 axes) has non-zero opacity, as a summed-area
/// table of opaque-cell counts: whether a box of cells holds any opaque one
/// costs 8 reads, where walking the box could cost all its cells (a 2D TF
/// over (v, 1/g) has boxes of thousands of cells where g is small).
struct OpaqueCells {
    /// Cells per axis, padded to 3 axes with 1; None for tables of more axes.
    n: Option<[usize; 3]>,
    /// Opaque cells with indices below (x, y, z) per axis, at
    /// ((z (ny + 1)) + y) (nx + 1) + x.
    below: Vec<u32>,
}

impl OpaqueCells {
    /// The cells of `t` with a non-zero opacity.
    fn new(t: &Table) -> OpaqueCells {
        OpaqueCells::marking(t, |cell| {
            let alpha = if t.components == 4 { t.values[cell * 4 + 3] } else { t.values[cell] };
            alpha > 0.0
        })
    }

    /// The cells of `t` (by flat index) for which `marked` holds.
    fn marking(t: &Table, marked: impl Fn(usize) -> bool) -> OpaqueCells {
        if t.axes.len() > 3 {
            return OpaqueCells { n: None, below: Vec::new() };
        }
        let n: [usize; 3] = std::array::from_fn(|a| t.axes.get(a).map_or(1, |axis| axis.1));
        let (px, py) = (n[0] + 1, n[1] + 1);
        let mut below = vec![0u32; px * py * (n[2] + 1)];
        let at = |x: usize, y: usize, z: usize| (z * py + y) * px + x;
        for z in 0..n[2] {
            for y in 0..n[1] {
                for x in 0..n[0] {
                    let cell = (z * n[1] + y) * n[0] + x;
                    // inclusion-exclusion over the seven lower neighbours
                    let sum = u32::from(marked(cell)) as i64
                        + below[at(x, y + 1, z + 1)] as i64
                        + below[at(x + 1, y, z + 1)] as i64
                        + below[at(x + 1, y + 1, z)] as i64
                        - below[at(x, y, z + 1)] as i64
                        - below[at(x, y + 1, z)] as i64
                        - below[at(x + 1, y, z)] as i64
                        + below[at(x, y, z)] as i64;
                    below[at(x + 1, y + 1, z + 1)] = sum as u32;
                }
            }
        }
        OpaqueCells { n: Some(n), below }
    }

    /// Whether any cell in the box (inclusive index ranges per axis, one
    /// per table axis) is opaque. Tables of more than 3 axes: always true.
    fn any(&self, cells: &[(usize, usize)]) -> bool {
        let Some(n) = self.n else { return true };
        // half-open ranges; an axis the table lacks (size 1) is 0..1
        let r: [(usize, usize); 3] = std::array::from_fn(|a| cells.get(a).map_or((0, 1), |&(lo, hi)| (lo, hi + 1)));
        if (0..3).any(|a| r[a].0 >= r[a].1 || r[a].1 > n[a]) {
            return false;
        }
        let (px, py) = (n[0] + 1, n[1] + 1);
        let at = |x: usize, y: usize, z: usize| self.below[(z * py + y) * px + x] as i64;
        let ((x0, x1), (y0, y1), (z0, z1)) = (r[0], r[1], r[2]);
        let count = at(x1, y1, z1) - at(x0, y1, z1) - at(x1, y0, z1) - at(x1, y1, z0)
            + at(x0, y0, z1)
            + at(x0, y1, z0)
            + at(x1, y0, z0)
            - at(x0, y0, z0);
        count > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether any cell of the box is opaque, by walking it.
    fn walk(t: &Table, cells: &[(usize, usize)], axis: usize, offset: usize, stride: usize) -> bool {
        if axis == cells.len() {
            return if t.components == 4 { t.values[offset * 4 + 3] > 0.0 } else { t.values[offset] > 0.0 };
        }
        let (lo, hi) = cells[axis];
        (lo..=hi).any(|i| walk(t, cells, axis + 1, offset + i * stride, stride * t.axes[axis].1))
    }

    #[test]
    fn empty_reach_is_the_largest_cube_of_invisible_blocks() {
        let nb = [9, 7, 5];
        let n = nb[0] * nb[1] * nb[2];
        let visible: Vec<bool> = (0..n).map(|b| (b * 7919) % 61 == 3).collect();
        let reach = empty_reach(&visible, nb);
        let at = |b: usize| [b % nb[0], (b / nb[0]) % nb[1], b / (nb[0] * nb[1])];
        for b in 0..n {
            // brute force: the largest k whose cube of radius k - 1 (within the grid) is all invisible
            let clear = |r: usize| {
                (0..n).all(|o| {
                    let (p, q) = (at(b), at(o));
                    (0..3).any(|a| p[a].abs_diff(q[a]) > r) || !visible[o]
                })
            };
            let want = if visible[b] { 0 } else { (1..=MAX_REACH).take_while(|&k| clear(usize::from(k) - 1)).count() };
            assert_eq!(usize::from(reach[b]), want, "block {:?}", at(b));
        }
        assert!(reach.iter().any(|&r| r >= 2), "the test has empty space wider than a block");
    }

    #[test]
    fn a_jump_never_passes_a_block_beyond_the_reach() {
        let nb = [6, 5, 7];
        let mut state = 5u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..3000 {
            let p = [0, 1, 2].map(|a| next() * (nb[a] * BLOCK) as f64);
            let per_sample = [0, 1, 2].map(|_| (next() * 2.0 - 1.0) * 1.5);
            let reach = 1 + (next() * 3.0) as u8;
            let last = last_sample_in_reach(nb, p, per_sample, 0, reach);
            let b0 = [0, 1, 2].map(|a| ((p[a].max(0.0) as usize) / BLOCK).min(nb[a] - 1));
            for j in 0..=last.min(400) {
                let q = [0, 1, 2].map(|a| p[a] + j as f64 * per_sample[a]);
                let b = [0, 1, 2].map(|a| ((q[a].max(0.0) as usize) / BLOCK).min(nb[a] - 1));
                let off = (0..3).map(|a| b[a].abs_diff(b0[a])).max().unwrap_or(0);
                assert!(
                    off < usize::from(reach),
                    "{p:?} {per_sample:?} reach {reach}: sample {j} of {last} is {off} blocks off"
                );
            }
        }
    }

    #[test]
    fn a_chord_found_transparent_meets_no_opacity() {
        let mut state = 9u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // a sparse 2D table over (0..10, -1..1) and a 1D factor over 0..4
        let t2 = Table {
            axes: vec![("a".into(), 40, 0.0, 10.0), ("b".into(), 30, -1.0, 1.0)],
            components: 4,
            values: (0..40 * 30 * 4).map(|i| if i % 4 == 3 && (i / 4) % 97 == 5 { 0.7 } else { 0.2 }).collect(),
        };
        let t1 = Table {
            axes: vec![("c".into(), 16, 0.0, 4.0)],
            components: 1,
            values: (0..16).map(|i| if i == 11 { 0.5 } else { 0.0 }).collect(),
        };
        let alpha = |t: &Table, x: &[f32]| {
            let e = (0..t.axes.len()).fold((0, 1), |(e, stride), k| {
                let cell = table_cell(&t.axes[k], x[k]);
                (e + cell * stride, stride * t.axes[k].1)
            });
            t.values[e.0 * t.components + t.components - 1]
        };
        let boxes = ChordBoxes::new(&[&t2, &t1]);
        let mut transparent = 0;
        for _ in 0..4000 {
            let f0 = [next() * 12.0 - 1.0, next() * 2.4 - 1.2, next() * 5.0 - 0.5].map(|x| x as f32);
            let f1 = [f0[0] + (next() as f32 - 0.5), f0[1] + (next() as f32 - 0.5) * 0.2, next() as f32 * 5.0 - 0.5];
            if !boxes.all_transparent(&f0, &f1) {
                continue;
            }
            transparent += 1;
            // every point the chord search may visit has a zero product of opacities
            for k in 0..=1000 {
                let s = k as f32 / 1000.0;
                let p: Vec<f32> = (0..3).map(|i| f0[i] + s * (f1[i] - f0[i])).collect();
                assert_eq!(alpha(&t2, &p[..2]) * alpha(&t1, &p[2..]), 0.0, "{f0:?} -> {f1:?} at {s}");
            }
        }
        assert!(transparent > 100, "{transparent} transparent chords");
    }

    #[test]
    fn block_ranges_are_each_blocks_voxels_min_and_max() {
        for dims in [[20, 17, 9], [9, 1, 33], [1, 1, 1], [16, 8, 17]] {
            let n = dims[0] * dims[1] * dims[2];
            let d: Vec<f32> =
                (0..n).map(|i| if i % 13 == 5 { f32::NAN } else { ((i * 7919) % 1000) as f32 - 500.0 }).collect();
            let nb = block_counts(dims);
            let got = block_ranges(Samples::Floats(&d), dims);
            assert_eq!(got.len(), nb[0] * nb[1] * nb[2]);
            for (b, &(lo, hi)) in got.iter().enumerate() {
                let at = [b % nb[0], (b / nb[0]) % nb[1], b / (nb[0] * nb[1])];
                // brute force: every voxel of the block's BLOCK + 1 per axis
                let (mut want_lo, mut want_hi) = (f32::INFINITY, f32::NEG_INFINITY);
                for z in at[2] * BLOCK..(at[2] * BLOCK + BLOCK + 1).min(dims[2]) {
                    for y in at[1] * BLOCK..(at[1] * BLOCK + BLOCK + 1).min(dims[1]) {
                        for x in at[0] * BLOCK..(at[0] * BLOCK + BLOCK + 1).min(dims[0]) {
                            let v = d[(z * dims[1] + y) * dims[0] + x];
                            want_lo = want_lo.min(v);
                            want_hi = want_hi.max(v);
                        }
                    }
                }
                assert_eq!((lo, hi), (want_lo, want_hi), "{dims:?} block {at:?}");
            }
        }
    }

    #[test]
    fn opaque_cell_counts_answer_boxes_as_walking_them_does() {
        let mut state = 3u64;
        let mut next = |m: usize| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) as usize) % m
        };
        for sizes in [vec![9], vec![7, 5], vec![4, 6, 3], vec![16, 16]] {
            for components in [1, 4] {
                let cells: usize = sizes.iter().product();
                // sparse opacity, so that many boxes are empty
                let values: Vec<f32> = (0..cells * components)
                    .map(|i| if i % components == components - 1 && next(7) == 0 { 0.5 } else { 0.0 })
                    .collect();
                let axes = sizes.iter().map(|&n| ("c".to_string(), n, 0.0, 1.0)).collect();
                let t = Table { axes, components, values };
                let opaque = OpaqueCells::new(&t);
                for _ in 0..300 {
                    let b: Vec<(usize, usize)> = sizes
                        .iter()
                        .map(|&n| {
                            let (p, q) = (next(n), next(n));
                            (p.min(q), p.max(q))
                        })
                        .collect();
                    assert_eq!(opaque.any(&b), walk(&t, &b, 0, 0, 1), "{sizes:?} {components} {b:?}");
                }
            }
        }
    }
}
