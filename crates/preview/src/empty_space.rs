//! Empty-space skipping for the ray caster: per block of [`BLOCK`]^3 cells,
//! whether any sample inside can add to a pixel, from each channel's
//! min..max over the block and the classifier's tables or primitives.
//! Interpolated values stay within a block's min..max, so a block found
//! invisible is skipped without changing a pixel (the Gaussian classifier:
//! by less than [`GAUSSIAN_SKIP_TOLERANCE`] of a level).

use crate::load::Table;
use crate::render::Classifier;
use rayon::prelude::*;

/// Which blocks of the grid `dims` can show with `classifier`, and the block
/// counts per axis; None where the classifier has no skipping (or lacks the
/// channel it needs). `table_chans` are the classifier's table channels in
/// axis order, `distance` and `v` the pack's channels, `path_voxels` the
/// longest ray's length in voxels.
pub(crate) fn visible_blocks_of(
    classifier: &Classifier,
    table_chans: &[Option<&[f32]>],
    distance: Option<&[f32]>,
    v_data: Option<&[f32]>,
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

/// Edge of the blocks of empty-space skipping, voxels.
const BLOCK: usize = 8;

/// For a LUT classifier: per block of BLOCK^3 cells (trilinear cells, i.e.
/// voxels plus the next one along each axis), whether any sample inside can
/// get a non-zero opacity. Interpolated values stay within the block's
/// min..max of each channel, so a block whose box of LUT cells holds only
/// zero opacity is skipped without changing a pixel.
fn visible_blocks(t: &Table, chans: &[Option<&[f32]>], dims: [usize; 3]) -> (Vec<bool>, [usize; 3]) {
    let opaque = OpaqueCells::new(t);
    per_block(dims, |lo, hi| {
        let cells: Vec<(usize, usize)> = t
            .axes
            .iter()
            .enumerate()
            .map(|(k, axis)| {
                let (vmin, vmax) = chans[k].map_or((0.0, 0.0), |d| block_range(d, dims, lo, hi));
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
fn visible_distance_blocks(alpha_d: &Table, distance: &[f32], dims: [usize; 3]) -> (Vec<bool>, [usize; 3]) {
    let opaque = OpaqueCells::new(alpha_d);
    per_block(dims, |lo, hi| {
        let (dmin, dmax) = block_range(distance, dims, lo, hi);
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
fn visible_peak_blocks(peaks: &Table, preintegration: &Table, v: &[f32], dims: [usize; 3]) -> (Vec<bool>, [usize; 3]) {
    let opaque = OpaqueCells::new(preintegration);
    let peaked = OpaqueCells::marking(peaks, |cell| peaks.values[cell * peaks.components] >= 0.0);
    per_block(dims, |lo, hi| {
        let (vmin, vmax) = block_range(v, dims, lo, hi);
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
    chans: &[Option<&[f32]>],
    sqrt_last: bool,
    far: f64,
    dims: [usize; 3],
) -> (Vec<bool>, [usize; 3]) {
    per_block(dims, |lo, hi| {
        let mut low = Vec::with_capacity(chans.len());
        let mut high = Vec::with_capacity(chans.len());
        for (k, c) in chans.iter().enumerate() {
            let (mut a, mut b) = c.map_or((0.0, 0.0), |d| block_range(d, dims, lo, hi));
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

/// `visible(lo, hi)` for every block of BLOCK^3 cells (voxel ranges lo..hi
/// per axis, the next voxel included), in parallel; and the block counts.
fn per_block(dims: [usize; 3], visible: impl Fn([usize; 3], [usize; 3]) -> bool + Sync) -> (Vec<bool>, [usize; 3]) {
    let nb = dims.map(|n| n.saturating_sub(1).max(1).div_ceil(BLOCK));
    let mut out = vec![false; nb[0] * nb[1] * nb[2]];
    out.par_iter_mut().enumerate().for_each(|(b, o)| {
        let (bx, by, bz) = (b % nb[0], (b / nb[0]) % nb[1], b / (nb[0] * nb[1]));
        let lo = [bx * BLOCK, by * BLOCK, bz * BLOCK];
        let hi = [0, 1, 2].map(|a| ((lo[a] + BLOCK) + 1).min(dims[a]));
        *o = visible(lo, hi);
    });
    (out, nb)
}

/// Smallest and largest sample of `d` in the voxel box lo..hi (NaN ignored).
fn block_range(d: &[f32], dims: [usize; 3], lo: [usize; 3], hi: [usize; 3]) -> (f32, f32) {
    let (mut vmin, mut vmax) = (f32::INFINITY, f32::NEG_INFINITY);
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            let row = (z * dims[1] + y) * dims[0];
            for &v in &d[row + lo[0]..row + hi[0]] {
                vmin = vmin.min(v);
                vmax = vmax.max(v);
            }
        }
    }
    (vmin, vmax)
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
