//! Per-row evaluation of the requested items from the derivative rows.

use crate::engine::{RowSet, RowsView};
use crate::fused::{FusedOut, Spare, Voxel};
use crate::items::Item;

/// Where each requested item's components go in the list of output buffers.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// (item, index of its first component, number of components).
    pub items: Vec<(Item, usize, usize)>,
    /// Threshold below which g counts as zero (value units per world unit).
    pub epsilon: f32,
    /// Number of fields (for the Jacobian's components).
    pub fields: usize,
    /// Where g, normal and f'' go when the engine is fused (its items are a
    /// subset of those three), else None.
    pub fused: Option<FusedSlots>,
}

/// Output component indices of the fused loop's items (None: not requested).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct FusedSlots {
    pub g: Option<usize>,
    pub normal: Option<usize>,
    pub f2: Option<usize>,
}

/// Whether the fused loop should compute all of `items`: f2 (whose Hessian
/// the loop always computes) with at most g and the normal besides.
pub(crate) fn fusable_items(items: &[Item]) -> bool {
    items.contains(&Item::F2) && items.iter().all(|i| matches!(i, Item::G | Item::Normal | Item::F2))
}

impl Layout {
    /// Lays out `items` for `fields` input fields; `fused`: the engine
    /// leaves g, normal and f'' to [`RowSet::fused_g_normal_f2`].
    pub fn new(items: &[Item], fields: usize, epsilon: f32, fused: bool) -> Layout {
        let mut next = 0;
        let items: Vec<(Item, usize, usize)> = items
            .iter()
            .map(|&item| {
                let n = if item == Item::Jacobian { 3 * fields } else { item.components().len() };
                let entry = (item, next, n);
                next += n;
                entry
            })
            .collect();
        let fused = fused.then(|| {
            let slot = |item: Item| items.iter().find(|e| e.0 == item).map(|e| e.1);
            FusedSlots { g: slot(Item::G), normal: slot(Item::Normal), f2: slot(Item::F2) }
        });
        Layout { items, epsilon, fields, fused }
    }

    /// Total number of output components.
    pub fn components(&self) -> usize {
        self.items.iter().map(|(_, _, n)| n).sum()
    }

    /// Writes row `j` of every item into `outs` (one slice per component, each one z-slice).
    #[inline(always)]
    pub fn write_row(&self, rows: &RowSet, j: usize, outs: &mut [&mut [f32]], spare: &mut Spare) {
        if let Some(slots) = self.fused {
            return write_fused(rows, slots, j, outs, spare);
        }
        let eps = self.epsilon;
        let r = rows.field(0);
        let nx = r.value.len().max(r.gx.len()).max(r.hxx.len());
        let span = j * nx..(j + 1) * nx;
        for &(item, first, n) in &self.items {
            match item {
                Item::Value => outs[first][span.clone()].copy_from_slice(r.value),
                Item::Grad => {
                    outs[first][span.clone()].copy_from_slice(r.gx);
                    outs[first + 1][span.clone()].copy_from_slice(r.gy);
                    outs[first + 2][span.clone()].copy_from_slice(r.gz);
                }
                // shade holds g until the whole volume is done (it needs g_max).
                Item::G | Item::Shade => outs[first][span.clone()].copy_from_slice(r.g),
                Item::Normal => {
                    for (c, d) in [r.gx, r.gy, r.gz].into_iter().enumerate() {
                        for ((o, &d), &gi) in outs[first + c][span.clone()].iter_mut().zip(d).zip(r.g_inv) {
                            *o = d * gi;
                        }
                    }
                }
                Item::Hessian => {
                    for (c, h) in [r.hxx, r.hxy, r.hxz, r.hyy, r.hyz, r.hzz].into_iter().enumerate() {
                        outs[first + c][span.clone()].copy_from_slice(h);
                    }
                }
                Item::F2 => per_voxel(&r, nx, &mut outs[first][span.clone()], |v, g_inv| v.f2(g_inv)),
                Item::Laplacian => {
                    let out = &mut outs[first][span.clone()];
                    for (o, ((a, b), c)) in out.iter_mut().zip(r.hxx.iter().zip(r.hyy).zip(r.hzz)) {
                        *o = a + b + c;
                    }
                }
                // -div(grad f / g) / 2, with div(n) = (Laplacian - n^T H n) / g
                Item::Curvature => per_voxel(&r, nx, &mut outs[first][span.clone()], |v, g_inv| {
                    0.5 * g_inv * (v.f2(g_inv) - (v.hxx + v.hyy + v.hzz))
                }),
                Item::InvG if self.fields > 1 => {
                    for (i, o) in outs[first][span.clone()].iter_mut().enumerate() {
                        let g = gnorm_at(rows, self.fields, i).sqrt();
                        *o = 1.0 / if g > eps { g } else { eps };
                    }
                }
                Item::InvG => {
                    for (o, &g) in outs[first][span.clone()].iter_mut().zip(r.g) {
                        *o = 1.0 / if g > eps { g } else { eps };
                    }
                }
                Item::Gnorm => {
                    for (i, o) in outs[first][span.clone()].iter_mut().enumerate() {
                        *o = gnorm_at(rows, self.fields, i);
                    }
                }
                Item::Jacobian => {
                    for f in 0..n / 3 {
                        let rf = rows.field(f);
                        outs[first + 3 * f][span.clone()].copy_from_slice(rf.gx);
                        outs[first + 3 * f + 1][span.clone()].copy_from_slice(rf.gy);
                        outs[first + 3 * f + 2][span.clone()].copy_from_slice(rf.gz);
                    }
                }
            }
        }
    }
}

/// `out[i] = measure(voxel i's gradient and Hessian, its 1/g)` over a row
/// of `nx` samples.
#[inline(always)]
fn per_voxel(r: &RowsView, nx: usize, out: &mut [f32], measure: impl Fn(Voxel, f32) -> f32) {
    // Slices of one length let the compiler drop bounds checks and vectorise.
    let (gx, gy, gz, gi) = (&r.gx[..nx], &r.gy[..nx], &r.gz[..nx], &r.g_inv[..nx]);
    let (hxx, hyy, hzz) = (&r.hxx[..nx], &r.hyy[..nx], &r.hzz[..nx]);
    let (hxy, hxz, hyz) = (&r.hxy[..nx], &r.hxz[..nx], &r.hyz[..nx]);
    for i in 0..out.len().min(nx) {
        let v = Voxel {
            gx: gx[i],
            gy: gy[i],
            gz: gz[i],
            hxx: hxx[i],
            hyy: hyy[i],
            hzz: hzz[i],
            hxy: hxy[i],
            hxz: hxz[i],
            hyz: hyz[i],
        };
        out[i] = measure(v, gi[i]);
    }
}

/// ||G||, the Frobenius norm of G = Df^T Df, at sample `i` of the row (Kniss et al. 9.3.2).
#[inline(always)]
fn gnorm_at(rows: &RowSet, fields: usize, i: usize) -> f32 {
    let mut m = [0.0f32; 6]; // xx xy xz yy yz zz
    for f in 0..fields {
        let rf = rows.field(f);
        let (x, y, z) = (rf.gx[i], rf.gy[i], rf.gz[i]);
        m[0] += x * x;
        m[1] += x * y;
        m[2] += x * z;
        m[3] += y * y;
        m[4] += y * z;
        m[5] += z * z;
    }
    (m[0] * m[0] + m[3] * m[3] + m[5] * m[5] + 2.0 * (m[1] * m[1] + m[2] * m[2] + m[4] * m[4])).sqrt()
}

/// Row `j` of the fused items: the requested ones into `outs`, the others
/// into spare rows.
#[inline(always)]
fn write_fused(rows: &RowSet, slots: FusedSlots, j: usize, outs: &mut [&mut [f32]], spare: &mut Spare) {
    let [s_g, s_n0, s_n1, s_n2, s_f2] = &mut spare.0;
    let nx = s_g.len();
    let span = j * nx..(j + 1) * nx;
    let (mut g, mut f2, mut normal) = (None, None, [None, None, None]);
    for (index, out) in outs.iter_mut().enumerate() {
        let row = &mut out[span.clone()];
        if slots.g == Some(index) {
            g = Some(row);
        } else if slots.f2 == Some(index) {
            f2 = Some(row);
        } else if let Some(c) = slots.normal.and_then(|first| index.checked_sub(first)).filter(|c| *c < 3) {
            normal[c] = Some(row);
        }
    }
    let [n0, n1, n2] = normal;
    rows.fused_g_normal_f2(FusedOut {
        g: g.unwrap_or(s_g),
        normal: [n0.unwrap_or(s_n0), n1.unwrap_or(s_n1), n2.unwrap_or(s_n2)],
        f2: f2.unwrap_or(s_f2),
    });
}

/// Turns g (stored in the shade buffer during the pass) into the shading
/// weight 1 - (1 - g / g_max)^2, g_max being the largest g of the volume.
pub(crate) fn finish_shade(buffer: &mut [f32]) {
    let g_max = buffer.iter().copied().fold(0.0f32, f32::max);
    if g_max > 0.0 {
        for v in buffer.iter_mut() {
            let t = 1.0 - *v / g_max;
            *v = 1.0 - t * t;
        }
    }
}
