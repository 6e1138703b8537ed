//! Per-row evaluation of the requested items from the derivative rows.

use crate::engine::Scratch;
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
}

impl Layout {
    /// Lays out `items` for `fields` input fields.
    pub fn new(items: &[Item], fields: usize, epsilon: f32) -> Layout {
        let mut next = 0;
        let items = items
            .iter()
            .map(|&item| {
                let n = if item == Item::Jacobian { 3 * fields } else { item.components().len() };
                let entry = (item, next, n);
                next += n;
                entry
            })
            .collect();
        Layout { items, epsilon, fields }
    }

    /// Total number of output components.
    pub fn components(&self) -> usize {
        self.items.iter().map(|(_, _, n)| n).sum()
    }

    /// Writes row `j` of every item into `outs` (one slice per component, each one z-slice).
    #[inline(always)]
    pub fn write_row(&self, scratch: &Scratch, j: usize, outs: &mut [&mut [f32]]) {
        let eps = self.epsilon;
        let r = scratch.rows(0);
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
                Item::F2 => {
                    let out = &mut outs[first][span.clone()];
                    // Slices of one length let the compiler drop bounds checks and vectorise.
                    let (gx, gy, gz, gi) = (&r.gx[..nx], &r.gy[..nx], &r.gz[..nx], &r.g_inv[..nx]);
                    let (hxx, hyy, hzz) = (&r.hxx[..nx], &r.hyy[..nx], &r.hzz[..nx]);
                    let (hxy, hxz, hyz) = (&r.hxy[..nx], &r.hxz[..nx], &r.hyz[..nx]);
                    for i in 0..out.len().min(nx) {
                        let (x, y, z) = (gx[i], gy[i], gz[i]);
                        let q = x * x * hxx[i]
                            + y * y * hyy[i]
                            + z * z * hzz[i]
                            + 2.0 * (x * y * hxy[i] + x * z * hxz[i] + y * z * hyz[i]);
                        out[i] = q * gi[i] * gi[i];
                    }
                }
                Item::Laplacian => {
                    let out = &mut outs[first][span.clone()];
                    for (o, ((a, b), c)) in out.iter_mut().zip(r.hxx.iter().zip(r.hyy).zip(r.hzz)) {
                        *o = a + b + c;
                    }
                }
                Item::InvG => {
                    for (o, &g) in outs[first][span.clone()].iter_mut().zip(r.g) {
                        *o = 1.0 / if g > eps { g } else { eps };
                    }
                }
                Item::Gnorm => {
                    let out = &mut outs[first][span.clone()];
                    for (i, o) in out.iter_mut().enumerate() {
                        let mut m = [0.0f32; 6]; // xx xy xz yy yz zz
                        for f in 0..self.fields {
                            let rf = scratch.rows(f);
                            let (x, y, z) = (rf.gx[i], rf.gy[i], rf.gz[i]);
                            m[0] += x * x;
                            m[1] += x * y;
                            m[2] += x * z;
                            m[3] += y * y;
                            m[4] += y * z;
                            m[5] += z * z;
                        }
                        *o =
                            (m[0] * m[0] + m[3] * m[3] + m[5] * m[5] + 2.0 * (m[1] * m[1] + m[2] * m[2] + m[4] * m[4]))
                                .sqrt();
                    }
                }
                Item::Jacobian => {
                    for f in 0..n / 3 {
                        let rf = scratch.rows(f);
                        outs[first + 3 * f][span.clone()].copy_from_slice(rf.gx);
                        outs[first + 3 * f + 1][span.clone()].copy_from_slice(rf.gy);
                        outs[first + 3 * f + 2][span.clone()].copy_from_slice(rf.gz);
                    }
                }
            }
        }
    }
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
