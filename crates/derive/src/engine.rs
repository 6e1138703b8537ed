//! The fused separable pass: for one output z-slice at a time, row by row,
//! filter along z into a small ring of rows, then along y and x, producing
//! every derivative the requested items need in one sweep over the data.
//!
//! Per thread and field the working set is a ring of 3 x (2 R_y + 1)
//! z-filtered rows plus a few more rows (a few tens of KiB: it stays in
//! L1/L2), so there are no full-volume or even full-plane temporaries. Every
//! voxel's arithmetic is the same whatever slice order or thread runs it, so
//! results are bit-identical for any thread count.
//!
//! When f'' is requested with at most g and the normal besides (and the
//! kernel suits it), rows stop after the y pass and the caller's
//! [`RowSet::fused_g_normal_f2`] does the x pass and the measures in one
//! voxel loop (see [`crate::fused`]).

use crate::border::Border;
use crate::fused::{self, Combinations, Spare};
use crate::items::Needs;
use crate::kernel::{AxisTaps, Taps};
use crate::measures::Layout;
use crate::padding::PaddingMask;

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

/// Derivative rows of one field at the current output row, computed by the x
/// pass; vectors that the requested items do not need (or that an identity x
/// value kernel lets the y-filtered rows stand in for) stay empty.
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
/// samples; empty where not needed). Some are views of rows computed earlier
/// in the pass, or of the input itself, rather than copies: with an identity
/// x value kernel value, gy, gz, hyy, hzz and hyz are the y-filtered rows,
/// and with an identity y value kernel those are the z-filtered rows.
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
    /// y-then-z combinations 00, 01, 10, 02, 20, 11 (z order, y order), nx
    /// samples each; empty where not needed, and 00, 10, 20 also where an
    /// identity y value kernel lets the z-filtered rows stand in.
    c: [Vec<f32>; 6],
    rows: Rows,
}

/// Per-thread working memory of the engine.
pub(crate) struct Scratch {
    fields: Vec<FieldScratch>,
    spare: Spare,
}

/// The derivative rows of every field at output row (k, j), as `slice`
/// hands them to its caller.
pub(crate) struct RowSet<'s, 'a> {
    engine: &'s Engine<'a>,
    fields: &'s [FieldScratch],
    k: usize,
    j: usize,
}

impl<'s> RowSet<'s, '_> {
    /// Derivative rows of field `f`.
    #[inline(always)]
    pub fn field(&self, f: usize) -> RowsView<'s> {
        let e = self.engine;
        let (field, fs) = (&e.fields[f], &self.fields[f]);
        let n = e.needs;
        let combination = |c: usize| e.combination(field, fs, c, self.k, self.j);
        let x0 = |c: usize, own: &'s Vec<f32>| if e.x_identity { combination(c) } else { own.as_slice() };
        let r = &fs.rows;
        let none: &'s [f32] = &[];
        let (grad, hess) = (n.grad, n.hessian);
        RowsView {
            value: if n.value { x0(C00, &r.value) } else { none },
            gx: &r.gx,
            gy: if grad { x0(C01, &r.gy) } else { none },
            gz: if grad { x0(C10, &r.gz) } else { none },
            g: &r.g,
            g_inv: &r.g_inv,
            hxx: &r.hxx,
            hyy: if hess { x0(C02, &r.hyy) } else { none },
            hzz: if hess { x0(C20, &r.hzz) } else { none },
            hxy: &r.hxy,
            hxz: &r.hxz,
            hyz: if hess { x0(C11, &r.hyz) } else { none },
        }
    }

    /// Writes g, the normal and f'' of field 0 at this row (a fused engine
    /// computes only the y-then-z combinations; see [`fused`]).
    #[inline(always)]
    pub fn fused_g_normal_f2(&self, out: fused::FusedOut) {
        let e = self.engine;
        let (field, fs) = (&e.fields[0], &self.fields[0]);
        let c = |c: usize| e.combination(field, fs, c, self.k, self.j);
        let combinations =
            Combinations { c00: c(C00), c01: c(C01), c10: c(C10), c02: c(C02), c20: c(C20), c11: c(C11) };
        fused::g_normal_f2(&field.stencil.x, &combinations, e.border, e.epsilon, out);
    }
}

/// The fused derivative pass over a volume of dims (nx, ny, nz).
pub(crate) struct Engine<'a> {
    fields: Vec<FieldInput<'a>>,
    dims: [usize; 3],
    border: Border,
    needs: Needs,
    epsilon: f32,
    ry: usize,
    /// Every field's x value kernel is the identity (interpolating kernels).
    x_identity: bool,
    /// The fused loop reads the y-then-z combinations 00, 10 and 20 as the
    /// z-filtered rows themselves (every field's y value kernel is the
    /// identity); the general pass copies them into padded rows.
    borrow_y0: bool,
    /// Border samples each side of the combination rows: the x taps'
    /// radius for the general pass, so that its x pass runs over whole rows
    /// without end cases; 0 for the fused loop, which handles the ends.
    pad: usize,
    /// Every field's z value kernel is the identity: the z-filtered value
    /// rows are the input rows themselves, read in place instead of copied.
    z_identity: bool,
    /// The caller writes g, normal and f'' straight from the y-then-z
    /// combinations ([`RowSet::fused_g_normal_f2`]): no x pass here.
    fused: bool,
    /// Scanner padding whose derivatives are NaN.
    padding: Option<PaddingMask<'a>>,
}

const C00: usize = 0;
const C01: usize = 1;
const C10: usize = 2;
const C02: usize = 3;
const C20: usize = 4;
const C11: usize = 5;

/// out = sum of w * src_at(o) over the taps (o, w), in tap order. Up to five
/// taps are summed in one loop (one store per sample instead of one per tap);
/// longer kernels (Gaussians) accumulate five taps at a time. The sum is
/// left to right either way, as the fused loop's `dot` sums.
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
    /// `fused`: stop each row after the y pass; only for fields that are
    /// [`Engine::fusable`].
    pub fn new(
        fields: Vec<FieldInput<'a>>,
        dims: [usize; 3],
        border: Border,
        needs: Needs,
        epsilon: f32,
        fused: bool,
    ) -> Engine<'a> {
        let ry = fields.iter().map(|f| f.stencil.y.radius()).max().unwrap_or(0);
        let identity = |taps: &Taps| taps.as_slice() == [(0, 1.0)];
        let x_identity = fields.iter().all(|f| identity(&f.stencil.x.d0));
        let y_identity = fields.iter().all(|f| identity(&f.stencil.y.d0));
        let z_identity = fields.iter().all(|f| identity(&f.stencil.z.d0));
        let borrow_y0 = fused && y_identity;
        let pad = if fused { 0 } else { fields.iter().map(|f| f.stencil.x.radius()).max().unwrap_or(0) };
        Engine {
            fields,
            dims,
            border,
            needs,
            epsilon,
            ry,
            x_identity,
            borrow_y0,
            pad,
            z_identity,
            fused,
            padding: None,
        }
    }

    /// The engine with scanner padding left out of its outputs (see [`PaddingMask`]).
    pub fn with_padding(mut self, padding: Option<PaddingMask<'a>>) -> Engine<'a> {
        self.padding = padding;
        self
    }

    /// Whether the fused g / normal / f'' loop can serve these fields: one
    /// field whose x taps [`fused::supports`].
    pub fn fusable(fields: &[FieldInput]) -> bool {
        matches!(fields, [f] if fused::supports(&f.stencil.x))
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
        let n = self.needs;
        let row = |needed: bool| if needed { vec![0.0f32; nx] } else { Vec::new() };
        // the x pass's rows (none for the fused loop, which keeps them in registers)
        let x_row = |needed: bool| row(needed && !self.fused);
        let x0_row = |needed: bool| x_row(needed && !self.x_identity);
        let fields = self
            .fields
            .iter()
            .map(|_| FieldScratch {
                z: std::array::from_fn(|t| if t < self.z_types() { vec![vec![0.0; nx]; ring] } else { Vec::new() }),
                c: std::array::from_fn(|c| {
                    let needed = match c {
                        C00 => !self.borrow_y0,
                        C01 => n.grad || n.hessian,
                        C10 => (n.grad || n.hessian) && !self.borrow_y0,
                        C20 => n.hessian && !self.borrow_y0,
                        _ => n.hessian,
                    };
                    if needed { vec![0.0f32; nx + 2 * self.pad] } else { Vec::new() }
                }),
                rows: Rows {
                    value: x0_row(n.value),
                    gx: x_row(n.grad),
                    gy: x0_row(n.grad),
                    gz: x0_row(n.grad),
                    g: x_row(n.grad),
                    g_inv: x_row(n.grad),
                    hxx: x_row(n.hessian),
                    hyy: x0_row(n.hessian),
                    hzz: x0_row(n.hessian),
                    hxy: x_row(n.hessian),
                    hxz: x_row(n.hessian),
                    hyz: x0_row(n.hessian),
                },
            })
            .collect();
        Scratch { fields, spare: Spare::new(if self.fused { nx } else { 0 }) }
    }

    /// Computes output slice `k`, calling `emit(j, rows, spare)` after each
    /// row j. Always inlined, so that it is compiled for the caller's target
    /// features.
    #[inline(always)]
    pub fn slice(&self, k: usize, scratch: &mut Scratch, mut emit: impl FnMut(usize, &RowSet, &mut Spare)) {
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
            emit(j, &RowSet { engine: self, fields: &scratch.fields, k, j }, &mut scratch.spare);
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

    /// The z-filtered row of derivative order `t` at row position p of slice
    /// k: a ring slot, or for an identity z value kernel the input row itself.
    #[inline(always)]
    fn z_filtered<'s>(
        &'s self,
        field: &'s FieldInput,
        z: &'s [Vec<Vec<f32>>; 3],
        t: usize,
        k: usize,
        p: isize,
    ) -> &'s [f32] {
        if t == 0 && self.z_identity {
            let [nx, ny, _] = self.dims;
            let start = (k * ny + self.border.index(p, ny)) * nx;
            &field.data[start..start + nx]
        } else {
            &z[t][self.slot(p)]
        }
    }

    /// The y-then-z combination `c` at output row (k, j): computed into the
    /// scratch, or for an identity y value kernel the z-filtered row itself.
    #[inline(always)]
    fn combination<'s>(
        &'s self,
        field: &'s FieldInput,
        fs: &'s FieldScratch,
        c: usize,
        k: usize,
        j: usize,
    ) -> &'s [f32] {
        let own = || {
            let row = &fs.c[c];
            if row.is_empty() { row.as_slice() } else { &row[self.pad..row.len() - self.pad] }
        };
        let z_order = match c {
            C00 => 0,
            C10 => 1,
            C20 => 2,
            _ => return own(),
        };
        if self.borrow_y0 { self.z_filtered(field, &fs.z, z_order, k, j as isize) } else { own() }
    }

    /// y-filters the rows `rows(o)` around row j into a padded row (border values in the padding).
    #[inline(always)]
    fn y_pass<'r>(&self, dst: &mut [f32], rows: impl Fn(isize) -> &'r [f32], ytaps: &Taps) {
        let (nx, pad, border) = (self.dims[0], self.pad, self.border);
        combine(&mut dst[pad..pad + nx], ytaps, rows);
        for p in 0..pad {
            dst[pad - 1 - p] = dst[pad + border.index(-1 - p as isize, nx)];
            dst[pad + nx + p] = dst[pad + border.index((nx + p) as isize, nx)];
        }
    }

    /// Fills the derivative rows of output row j from the z-filtered rows.
    #[inline(always)]
    fn row(&self, field: &FieldInput, fs: &mut FieldScratch, k: usize, j: usize) {
        let (n, pad, borrow_y0) = (self.needs, self.pad, self.borrow_y0);
        let st = &field.stencil;
        {
            // y pass: combination (z order, y order) from the z-filtered rows around j.
            let FieldScratch { z, c, .. } = &mut *fs;
            let z = &*z;
            let around = |t: usize| move |o: isize| self.z_filtered(field, z, t, k, j as isize + o);
            let [c00, c01, c10, c02, c20, c11] = c;
            if !borrow_y0 {
                self.y_pass(c00, around(0), &st.y.d0);
            }
            if n.grad || n.hessian {
                self.y_pass(c01, around(0), &st.y.d1);
                if !borrow_y0 {
                    self.y_pass(c10, around(1), &st.y.d0);
                }
            }
            if n.hessian {
                self.y_pass(c02, around(0), &st.y.d2);
                if !borrow_y0 {
                    self.y_pass(c20, around(2), &st.y.d0);
                }
                self.y_pass(c11, around(1), &st.y.d1);
            }
        }
        if self.fused {
            return;
        }
        // x pass. With an identity x value kernel the x0 rows are the
        // combinations themselves (see `RowSet::field`).
        let copy_x0 = !self.x_identity;
        let mut rows = std::mem::take(&mut fs.rows);
        let combination = |c: usize| self.combination(field, fs, c, k, j);
        let padded = |c: usize| fs.c[c].as_slice();
        if n.value && copy_x0 {
            x_pass(&mut rows.value, padded(C00), &st.x.d0, pad);
        }
        if n.grad {
            x_pass(&mut rows.gx, padded(C00), &st.x.d1, pad);
            if copy_x0 {
                x_pass(&mut rows.gy, padded(C01), &st.x.d0, pad);
                x_pass(&mut rows.gz, padded(C10), &st.x.d0, pad);
            }
        }
        if n.hessian {
            x_pass(&mut rows.hxx, padded(C00), &st.x.d2, pad);
            x_pass(&mut rows.hxy, padded(C01), &st.x.d1, pad);
            x_pass(&mut rows.hxz, padded(C10), &st.x.d1, pad);
            if copy_x0 {
                x_pass(&mut rows.hyy, padded(C02), &st.x.d0, pad);
                x_pass(&mut rows.hzz, padded(C20), &st.x.d0, pad);
                x_pass(&mut rows.hyz, padded(C11), &st.x.d0, pad);
            }
        }
        if n.grad {
            let Rows { g, g_inv, gx, gy, gz, .. } = &mut rows;
            let gy = if copy_x0 { gy.as_slice() } else { combination(C01) };
            let gz = if copy_x0 { gz.as_slice() } else { combination(C10) };
            let eps = self.epsilon;
            for ((((g, gi), &x), &y), &z) in g.iter_mut().zip(g_inv.iter_mut()).zip(gx.iter()).zip(gy).zip(gz) {
                *g = fused::magnitude(x, y, z);
                *gi = fused::inverse(*g, eps);
            }
        }
        fs.rows = rows;
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
    engine.slice(k, scratch, |j, rows, spare| layout.write_row(rows, j, outs, spare));
    if let Some(padding) = &engine.padding {
        padding.apply(k, outs);
    }
}
