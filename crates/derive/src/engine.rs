//! The fused separable pass: for one output z-slice at a time, filter along
//! z into whole planes, then along y and x row by row, producing every
//! derivative the requested items need in one sweep over the data.
//!
//! Per output slice and field the working set is at most three z-filtered
//! planes plus a few rows, so there are no full-volume temporaries. Every
//! voxel's arithmetic is the same whatever slice order or thread runs it, so
//! results are bit-identical for any thread count.

use crate::border::Border;
use crate::items::Needs;
use crate::kernel::{AxisTaps, Taps};

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
    pub hxx: Vec<f32>,
    pub hyy: Vec<f32>,
    pub hzz: Vec<f32>,
    pub hxy: Vec<f32>,
    pub hxz: Vec<f32>,
    pub hyz: Vec<f32>,
}

/// Per-thread working memory for one field.
struct FieldScratch {
    /// z-filtered planes: value, first and second derivative along z.
    z: [Vec<f32>; 3],
    /// y-then-z combinations as padded rows: 00, 01, 10, 02, 20, 11 (z order, y order).
    c: [Vec<f32>; 6],
    rows: Rows,
}

/// Per-thread working memory of the engine.
pub(crate) struct Scratch {
    fields: Vec<FieldScratch>,
}

impl Scratch {
    /// Derivative rows of field `f` for the row just computed.
    pub fn rows(&self, f: usize) -> &Rows {
        &self.fields[f].rows
    }
}

/// The fused derivative pass over a volume of dims (nx, ny, nz).
pub(crate) struct Engine<'a> {
    fields: Vec<FieldInput<'a>>,
    dims: [usize; 3],
    border: Border,
    needs: Needs,
    pad: usize,
}

const C00: usize = 0;
const C01: usize = 1;
const C10: usize = 2;
const C02: usize = 3;
const C20: usize = 4;
const C11: usize = 5;

/// out = sum of w * src[offset-shifted] over taps; `src_at(o)` gives the source for offset o.
#[inline]
fn combine<'s>(out: &mut [f32], taps: &Taps, src_at: impl Fn(isize) -> &'s [f32]) {
    let mut first = true;
    for &(o, w) in taps {
        let src = &src_at(o)[..out.len()];
        if first {
            out.iter_mut().zip(src).for_each(|(d, s)| *d = w * s);
            first = false;
        } else {
            out.iter_mut().zip(src).for_each(|(d, s)| *d += w * s);
        }
    }
    if first {
        out.fill(0.0);
    }
}

impl<'a> Engine<'a> {
    /// An engine for these fields (all of dims `dims`) computing what `needs` asks.
    pub fn new(fields: Vec<FieldInput<'a>>, dims: [usize; 3], border: Border, needs: Needs) -> Engine<'a> {
        let pad = fields.iter().map(|f| f.stencil.x.radius()).max().unwrap_or(0);
        Engine { fields, dims, border, needs, pad }
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
        let [nx, ny, _] = self.dims;
        let plane = nx * ny;
        let padded = nx + 2 * self.pad;
        let n = self.needs;
        let row = |needed: bool| if needed { vec![0.0f32; nx] } else { Vec::new() };
        let fields = self
            .fields
            .iter()
            .map(|_| FieldScratch {
                z: std::array::from_fn(|t| if t < self.z_types() { vec![0.0; plane] } else { Vec::new() }),
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
                    hxx: row(n.hessian),
                    hyy: row(n.hessian),
                    hzz: row(n.hessian),
                    hxy: row(n.hessian),
                    hxz: row(n.hessian),
                    hyz: row(n.hessian),
                },
            })
            .collect();
        Scratch { fields }
    }

    /// Computes output slice `k`, calling `emit(j, scratch)` after each row j.
    pub fn slice(&self, k: usize, scratch: &mut Scratch, mut emit: impl FnMut(usize, &Scratch)) {
        let [nx, ny, nz] = self.dims;
        let plane = nx * ny;
        let border = self.border;
        for (field, fs) in self.fields.iter().zip(scratch.fields.iter_mut()) {
            let st = &field.stencil;
            let ztaps = [&st.z.d0, &st.z.d1, &st.z.d2];
            for t in 0..self.z_types() {
                let at = |o: isize| {
                    let kk = border.index(k as isize + o, nz);
                    &field.data[kk * plane..(kk + 1) * plane]
                };
                combine(&mut fs.z[t], ztaps[t], at);
            }
        }
        for j in 0..ny {
            for (field, fs) in self.fields.iter().zip(scratch.fields.iter_mut()) {
                self.row(field, fs, j);
            }
            emit(j, scratch);
        }
    }

    /// Fills the derivative rows of output row j from the z-filtered planes.
    fn row(&self, field: &FieldInput, fs: &mut FieldScratch, j: usize) {
        let [nx, ny, _] = self.dims;
        let (pad, border, n) = (self.pad, self.border, self.needs);
        let st = &field.stencil;
        let FieldScratch { z, c, rows } = fs;
        // y pass: combination (z order, y order) as a padded row.
        let ypass = |dst: &mut Vec<f32>, zt: usize, ytaps: &Taps| {
            let plane = &z[zt];
            let at = |o: isize| {
                let jj = border.index(j as isize + o, ny);
                &plane[jj * nx..(jj + 1) * nx]
            };
            combine(&mut dst[pad..pad + nx], ytaps, at);
            for p in 0..pad {
                dst[pad - 1 - p] = dst[pad + border.index(-1 - p as isize, nx)];
                dst[pad + nx + p] = dst[pad + border.index((nx + p) as isize, nx)];
            }
        };
        ypass(&mut c[C00], 0, &st.y.d0);
        if n.grad || n.hessian {
            ypass(&mut c[C01], 0, &st.y.d1);
            ypass(&mut c[C10], 1, &st.y.d0);
        }
        if n.hessian {
            ypass(&mut c[C02], 0, &st.y.d2);
            ypass(&mut c[C20], 2, &st.y.d0);
            ypass(&mut c[C11], 1, &st.y.d1);
        }
        // x pass: shifted reads of the padded rows.
        let xpass = |dst: &mut [f32], src: &[f32], xtaps: &Taps| {
            combine(dst, xtaps, |o| &src[(pad as isize + o) as usize..]);
        };
        if n.value {
            xpass(&mut rows.value, &c[C00], &st.x.d0);
        }
        if n.grad || n.hessian {
            if n.grad {
                xpass(&mut rows.gx, &c[C00], &st.x.d1);
                xpass(&mut rows.gy, &c[C01], &st.x.d0);
                xpass(&mut rows.gz, &c[C10], &st.x.d0);
                for (((g, x), y), zz) in rows.g.iter_mut().zip(&rows.gx).zip(&rows.gy).zip(&rows.gz) {
                    *g = (x * x + y * y + zz * zz).sqrt();
                }
            }
            if n.hessian {
                xpass(&mut rows.hxx, &c[C00], &st.x.d2);
                xpass(&mut rows.hxy, &c[C01], &st.x.d1);
                xpass(&mut rows.hxz, &c[C10], &st.x.d1);
                xpass(&mut rows.hyy, &c[C02], &st.x.d0);
                xpass(&mut rows.hzz, &c[C20], &st.x.d0);
                xpass(&mut rows.hyz, &c[C11], &st.x.d0);
            }
        }
    }
}
