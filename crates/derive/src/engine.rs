//! The fused separable pass: for one output z-slice at a time, row by row,
//! filter along z into a small ring of rows, then along y and x, producing
//! every derivative the requested items need in one sweep over the data.
//!
//! Per thread and field the working set is a ring of 3 x (2 R_y + 1)
//! z-filtered rows plus a few padded rows (a few tens of KiB: it stays in
//! L1/L2), so there are no full-volume or even full-plane temporaries. Every
//! voxel's arithmetic is the same whatever slice order or thread runs it, so
//! results are bit-identical for any thread count.

use crate::border::Border;
use crate::items::Needs;
use crate::kernel::{AxisTaps, Taps};
use crate::measures::Layout;

/// Taps along x, y and z (in world units) for one field.
#[derive(Debug, Clone)]
pub(crate) struct Stencil {
    pub x: AxisTaps,
    pub y: AxisTaps,
    pub z: AxisTaps,
}

/// One input field and its stencil.
pub(crate) struct FieldInput<'a> {
    pub data: &'a [f32],
    pub stencil: Stencil,
}

/// Derivative rows of one field at the current output row; vectors that the
/// requested items do not need stay empty.
#[derive(Debug, Default)]
pub(crate) struct Rows {
    pub value: Vec<f32>,
    pub gx: Vec<f32>,
    pub gy: Vec<f32>,
    pub gz: Vec<f32>,
    pub g: Vec<f32>,
    /// 1 / g where g >= epsilon, else 0 (so normals and f'' are 0 there).
    pub g_inv: Vec<f32>,
    pub hxx: Vec<f32>,
    pub hyy: Vec<f32>,
    pub hzz: Vec<f32>,
    pub hxy: Vec<f32>,
    pub hxz: Vec<f32>,
    pub hyz: Vec<f32>,
}

/// Borrowed derivative rows of one field at the current output row (each nx
/// samples; empty where not needed). Where the x value kernel is the
/// identity, value, gy, gz, hyy, hzz and hyz are views of the y-filtered
/// rows instead of copies.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RowsView<'s> {
    pub value: &'s [f32],
    pub gx: &'s [f32],
    pub gy: &'s [f32],
    pub gz: &'s [f32],
    pub g: &'s [f32],
    pub g_inv: &'s [f32],
    pub hxx: &'s [f32],
    pub hyy: &'s [f32],
    pub hzz: &'s [f32],
    pub hxy: &'s [f32],
    pub hxz: &'s [f32],
    pub hyz: &'s [f32],
}

/// Per-thread working memory for one field.
struct FieldScratch {
    /// Ring of z-filtered rows (value, first, second derivative along z):
    /// row position p (j + dy, unclamped) lives in slot (p + R_y) mod (2 R_y + 1).
    z: [Vec<Vec<f32>>; 3],
    /// y-then-z combinations as padded rows: 00, 01, 10, 02, 20, 11 (z order, y order).
    c: [Vec<f32>; 6],
    rows: Rows,
}

/// Per-thread working memory of the engine.
pub(crate) struct Scratch {
    fields: Vec<FieldScratch>,
    pad: usize,
    x_identity: bool,
}

impl Scratch {
    /// Derivative rows of field `f` for the row just computed.
    pub fn rows(&self, f: usize) -> RowsView<'_> {
        self.fields[f].view(self.pad, self.x_identity)
    }
}

impl FieldScratch {
    fn view(&self, pad: usize, x_identity: bool) -> RowsView<'_> {
        let (r, c) = (&self.rows, &self.c);
        let mid = |k: usize, own| x0_row(c, k, own, pad, x_identity);
        RowsView {
            value: mid(C00, &r.value),
            gx: &r.gx,
            gy: mid(C01, &r.gy),
            gz: mid(C10, &r.gz),
            g: &r.g,
            g_inv: &r.g_inv,
            hxx: &r.hxx,
            hyy: mid(C02, &r.hyy),
            hzz: mid(C20, &r.hzz),
            hxy: &r.hxy,
            hxz: &r.hxz,
            hyz: mid(C11, &r.hyz),
        }
    }
}

/// The x0-filtered row of combination `k`: the middle of the padded row when
/// the x value kernel is the identity, else the row computed into `own`.
#[inline(always)]
fn x0_row<'s>(c: &'s [Vec<f32>; 6], k: usize, own: &'s [f32], pad: usize, x_identity: bool) -> &'s [f32] {
    let row = &c[k];
    if x_identity && !row.is_empty() { &row[pad..row.len() - pad] } else { own }
}

/// The fused derivative pass over a volume of dims (nx, ny, nz).
pub(crate) struct Engine<'a> {
    fields: Vec<FieldInput<'a>>,
    dims: [usize; 3],
    border: Border,
    needs: Needs,
    epsilon: f32,
    pad: usize,
    ry: usize,
    /// Every field's x value kernel is the identity (interpolating kernels).
    x_identity: bool,
    /// Every field's z value kernel is the identity: the z-filtered value
    /// rows are the input rows themselves, read in place instead of copied.
    z_identity: bool,
}

const C00: usize = 0;
const C01: usize = 1;
const C10: usize = 2;
const C02: usize = 3;
const C20: usize = 4;
const C11: usize = 5;

/// out = sum of w * src_at(o) over the taps (o, w), in tap order. Up to five
/// taps are summed in one loop (one store per sample instead of one per tap);
/// longer kernels (Gaussians) accumulate five taps at a time.
#[inline(always)]
fn combine<'s>(out: &mut [f32], taps: &Taps, src_at: impl Fn(isize) -> &'s [f32]) {
    let n = out.len();
    let src = |t: usize| &src_at(taps[t].0)[..n];
    let w = |t: usize| taps[t].1;
    match taps.len() {
        0 => out.fill(0.0),
        1 => {
            let (s0, w0) = (src(0), w(0));
            for (o, a) in out.iter_mut().zip(s0) {
                *o = w0 * a;
            }
        }
        2 => {
            let (s0, s1, w0, w1) = (src(0), src(1), w(0), w(1));
            for ((o, a), b) in out.iter_mut().zip(s0).zip(s1) {
                *o = w0 * a + w1 * b;
            }
        }
        3 => {
            let (s0, s1, s2) = (src(0), src(1), src(2));
            let (w0, w1, w2) = (w(0), w(1), w(2));
            for (((o, a), b), c) in out.iter_mut().zip(s0).zip(s1).zip(s2) {
                *o = w0 * a + w1 * b + w2 * c;
            }
        }
        4 => {
            let (s0, s1, s2, s3) = (src(0), src(1), src(2), src(3));
            let (w0, w1, w2, w3) = (w(0), w(1), w(2), w(3));
            for ((((o, a), b), c), d) in out.iter_mut().zip(s0).zip(s1).zip(s2).zip(s3) {
                *o = w0 * a + w1 * b + w2 * c + w3 * d;
            }
        }
        len => {
            let (s0, s1, s2, s3, s4) = (src(0), src(1), src(2), src(3), src(4));
            let (w0, w1, w2, w3, w4) = (w(0), w(1), w(2), w(3), w(4));
            for (((((o, a), b), c), d), e) in out.iter_mut().zip(s0).zip(s1).zip(s2).zip(s3).zip(s4) {
                *o = w0 * a + w1 * b + w2 * c + w3 * d + w4 * e;
            }
            for t in 5..len {
                let (st, wt) = (src(t), w(t));
                for (o, a) in out.iter_mut().zip(st) {
                    *o += wt * a;
                }
            }
        }
    }
}

/// x-filters a padded row (`pad` border samples each side) into `dst`.
#[inline(always)]
fn x_pass(dst: &mut [f32], src: &[f32], xtaps: &Taps, pad: usize) {
    combine(dst, xtaps, |o| &src[(pad as isize + o) as usize..]);
}

impl<'a> Engine<'a> {
    /// An engine for these fields (all of dims `dims`) computing what `needs` asks.
    /// `epsilon`: g below it counts as 0 for the inverse gradient row.
    pub fn new(
        fields: Vec<FieldInput<'a>>,
        dims: [usize; 3],
        border: Border,
        needs: Needs,
        epsilon: f32,
    ) -> Engine<'a> {
        let pad = fields.iter().map(|f| f.stencil.x.radius()).max().unwrap_or(0);
        let ry = fields.iter().map(|f| f.stencil.y.radius()).max().unwrap_or(0);
        let x_identity = fields.iter().all(|f| f.stencil.x.d0 == [(0, 1.0)]);
        let z_identity = fields.iter().all(|f| f.stencil.z.d0 == [(0, 1.0)]);
        Engine { fields, dims, border, needs, epsilon, pad, ry, x_identity, z_identity }
    }

    fn z_types(&self) -> usize {
        if self.needs.hessian {
            3
        } else if self.needs.grad {
            2
        } else {
            1
        }
    }

    /// Fresh working memory for one thread.
    pub fn scratch(&self) -> Scratch {
        let nx = self.dims[0];
        let ring = 2 * self.ry + 1;
        let padded = nx + 2 * self.pad;
        let n = self.needs;
        let row = |needed: bool| if needed { vec![0.0f32; nx] } else { Vec::new() };
        let fields = self
            .fields
            .iter()
            .map(|_| FieldScratch {
                z: std::array::from_fn(|t| if t < self.z_types() { vec![vec![0.0; nx]; ring] } else { Vec::new() }),
                c: std::array::from_fn(|c| {
                    let needed = match c {
                        C00 => true,
                        C01 | C10 => n.grad || n.hessian,
                        _ => n.hessian,
                    };
                    if needed { vec![0.0; padded] } else { Vec::new() }
                }),
                rows: Rows {
                    value: row(n.value),
                    gx: row(n.grad),
                    gy: row(n.grad),
                    gz: row(n.grad),
                    g: row(n.grad),
                    g_inv: row(n.grad),
                    hxx: row(n.hessian),
                    hyy: row(n.hessian),
                    hzz: row(n.hessian),
                    hxy: row(n.hessian),
                    hxz: row(n.hessian),
                    hyz: row(n.hessian),
                },
            })
            .collect();
        Scratch { fields, pad: self.pad, x_identity: self.x_identity }
    }

    /// Computes output slice `k`, calling `emit(j, scratch)` after each row j.
    /// Always inlined, so that it is compiled for the caller's target features.
    #[inline(always)]
    pub fn slice(&self, k: usize, scratch: &mut Scratch, mut emit: impl FnMut(usize, &Scratch)) {
        let ny = self.dims[1];
        let ry = self.ry as isize;
        for (field, fs) in self.fields.iter().zip(scratch.fields.iter_mut()) {
            for p in -ry..ry {
                self.z_row(field, fs, k, p);
            }
        }
        for j in 0..ny {
            for (field, fs) in self.fields.iter().zip(scratch.fields.iter_mut()) {
                self.z_row(field, fs, k, j as isize + ry);
                self.row(field, fs, k, j);
            }
            emit(j, scratch);
        }
    }

    /// Ring slot of row position p.
    #[inline]
    fn slot(&self, p: isize) -> usize {
        (p + self.ry as isize).rem_euclid(2 * self.ry as isize + 1) as usize
    }

    /// z-filters source row position p (clamped by the border policy) of slice k into its ring slot.
    #[inline(always)]
    fn z_row(&self, field: &FieldInput, fs: &mut FieldScratch, k: usize, p: isize) {
        let [nx, ny, nz] = self.dims;
        let border = self.border;
        let jj = border.index(p, ny);
        let slot = self.slot(p);
        let st = &field.stencil;
        let ztaps = [&st.z.d0, &st.z.d1, &st.z.d2];
        for t in usize::from(self.z_identity)..self.z_types() {
            let at = |o: isize| {
                let kk = border.index(k as isize + o, nz);
                let start = (kk * ny + jj) * nx;
                &field.data[start..start + nx]
            };
            combine(&mut fs.z[t][slot], ztaps[t], at);
        }
    }

    /// y-filters the ring rows around row j into a padded row (border values in the padding).
    #[inline(always)]
    fn y_pass<'r>(&self, dst: &mut [f32], rows: impl Fn(isize) -> &'r [f32], ytaps: &Taps) {
        let (nx, pad, border) = (self.dims[0], self.pad, self.border);
        combine(&mut dst[pad..pad + nx], ytaps, rows);
        for p in 0..pad {
            dst[pad - 1 - p] = dst[pad + border.index(-1 - p as isize, nx)];
            dst[pad + nx + p] = dst[pad + border.index((nx + p) as isize, nx)];
        }
    }

    /// Fills the derivative rows of output row j from the z-filtered planes.
    #[inline(always)]
    fn row(&self, field: &FieldInput, fs: &mut FieldScratch, k: usize, j: usize) {
        let (pad, n) = (self.pad, self.needs);
        let [nx, ny, _] = self.dims;
        let st = &field.stencil;
        let FieldScratch { z, c, rows } = fs;
        // the z-filtered rows at y offset o from j: the ring, or for an
        // identity z value kernel the input rows of slice k themselves
        let ring = |t: usize| {
            let z = &z[t];
            move |o: isize| z[self.slot(j as isize + o)].as_slice()
        };
        let input = |o: isize| {
            let start = (k * ny + self.border.index(j as isize + o, ny)) * nx;
            &field.data[start..start + nx]
        };
        let z0 = |o: isize| if self.z_identity { input(o) } else { ring(0)(o) };
        // y pass: combination (z order, y order) as a padded row.
        self.y_pass(&mut c[C00], z0, &st.y.d0);
        if n.grad || n.hessian {
            self.y_pass(&mut c[C01], z0, &st.y.d1);
            self.y_pass(&mut c[C10], ring(1), &st.y.d0);
        }
        if n.hessian {
            self.y_pass(&mut c[C02], z0, &st.y.d2);
            self.y_pass(&mut c[C20], ring(2), &st.y.d0);
            self.y_pass(&mut c[C11], ring(1), &st.y.d1);
        }
        // x pass: shifted reads of the padded rows. With an identity x value
        // kernel the x0 rows are the middles of the padded rows (see `view`).
        let copy_x0 = !self.x_identity;
        if n.value && copy_x0 {
            x_pass(&mut rows.value, &c[C00], &st.x.d0, pad);
        }
        if n.grad {
            x_pass(&mut rows.gx, &c[C00], &st.x.d1, pad);
            if copy_x0 {
                x_pass(&mut rows.gy, &c[C01], &st.x.d0, pad);
                x_pass(&mut rows.gz, &c[C10], &st.x.d0, pad);
            }
        }
        if n.hessian {
            x_pass(&mut rows.hxx, &c[C00], &st.x.d2, pad);
            x_pass(&mut rows.hxy, &c[C01], &st.x.d1, pad);
            x_pass(&mut rows.hxz, &c[C10], &st.x.d1, pad);
            if copy_x0 {
                x_pass(&mut rows.hyy, &c[C02], &st.x.d0, pad);
                x_pass(&mut rows.hzz, &c[C20], &st.x.d0, pad);
                x_pass(&mut rows.hyz, &c[C11], &st.x.d0, pad);
            }
        }
        if n.grad {
            let Rows { g, g_inv, gx, gy, gz, .. } = rows;
            let gy = x0_row(c, C01, gy, pad, self.x_identity);
            let gz = x0_row(c, C10, gz, pad, self.x_identity);
            let eps = self.epsilon;
            for ((((g, gi), x), y), zz) in g.iter_mut().zip(g_inv.iter_mut()).zip(gx.iter()).zip(gy).zip(gz) {
                *g = (x * x + y * y + zz * zz).sqrt();
                // a select, not a branch, so the loop vectorises
                *gi = if *g >= eps { 1.0 / *g } else { 0.0 };
            }
        }
    }
}

/// Computes slice `k` of every requested item into `outs` (one z-slice per
/// component). Compiled for AVX2 as well as the baseline instruction set and
/// picked at run time; no FMA is enabled, so both paths give the same bits.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
pub(crate) fn compute_slice(
    engine: &Engine,
    layout: &Layout,
    k: usize,
    scratch: &mut Scratch,
    outs: &mut [&mut [f32]],
) {
    engine.slice(k, scratch, |j, s| layout.write_row(s, j, outs));
}
