//! Interpolating an irregular or tilted stack of slices onto a regular grid.
//!
//! Output slice k lies at `along_0 + k * spacing` on the slice normal. It is
//! the linear blend of the two input slices around it; each input slice is
//! first shifted in-plane by its own offset from the first slice (bilinear),
//! which undoes a gantry tilt (a shear of the stack). Together that is
//! trilinear interpolation on the sheared input grid. Where a shifted slice
//! does not cover the output, the smallest value of the series (air, in CT)
//! fills in, so no false boundary appears at the edge.

use super::series::{Resampling, SliceRef};
use rayon::prelude::*;

/// Interpolates `stack` (one cols x rows plane per slice of `slices`, in
/// order along the normal) onto the regular grid of `plan`.
pub fn resample(stack: &[f32], cols: usize, rows: usize, slices: &[SliceRef], plan: &Resampling) -> Vec<f32> {
    let plane = cols * rows;
    let fill = stack.iter().copied().fold(f32::INFINITY, f32::min);
    let along: Vec<f64> = slices.iter().map(|s| s.along).collect();
    let mut out = vec![0.0f32; plane * plan.nz];
    out.par_chunks_mut(plane).enumerate().for_each(|(k, dst)| {
        let t = along[0] + k as f64 * plan.spacing;
        let b = along.partition_point(|&a| a <= t).clamp(1, along.len() - 1);
        let a = b - 1;
        let w = ((t - along[a]) / (along[b] - along[a])).clamp(0.0, 1.0);
        let slice = |s: usize| Shifted::new(&stack[s * plane..(s + 1) * plane], cols, rows, plan.offsets[s], fill);
        let (below, above) = (slice(a), slice(b));
        for j in 0..rows {
            for i in 0..cols {
                let va = below.at(i, j);
                let vb = if w > 0.0 { above.at(i, j) } else { va };
                dst[j * cols + i] = ((1.0 - w) * va as f64 + w * vb as f64) as f32;
            }
        }
    });
    out
}

/// One input slice seen from the output grid: it lies `offset` pixels (x, y)
/// from the first slice, so output pixel (i, j) reads it bilinearly at
/// (i - ox, j - oy). The whole-pixel shift and the fraction are the same for
/// every pixel of the slice, so they are split once here.
struct Shifted<'a> {
    src: &'a [f32],
    cols: usize,
    rows: usize,
    shift: [isize; 2],
    frac: [f64; 2],
    fill: f32,
}

impl<'a> Shifted<'a> {
    fn new(src: &'a [f32], cols: usize, rows: usize, offset: [f64; 2], fill: f32) -> Shifted<'a> {
        let (x, y) = (-offset[0], -offset[1]);
        let (x0, y0) = (x.floor(), y.floor());
        Shifted { src, cols, rows, shift: [x0 as isize, y0 as isize], frac: [x - x0, y - y0], fill }
    }

    fn pixel(&self, x: isize, y: isize) -> f64 {
        if x < 0 || y < 0 || x >= self.cols as isize || y >= self.rows as isize {
            f64::from(self.fill)
        } else {
            f64::from(self.src[y as usize * self.cols + x as usize])
        }
    }

    fn at(&self, i: usize, j: usize) -> f32 {
        let (x, y) = (i as isize + self.shift[0], j as isize + self.shift[1]);
        let [fx, fy] = self.frac;
        if fx == 0.0 && fy == 0.0 {
            return self.pixel(x, y) as f32;
        }
        let top = self.pixel(x, y) * (1.0 - fx) + self.pixel(x + 1, y) * fx;
        let bottom = self.pixel(x, y + 1) * (1.0 - fx) + self.pixel(x + 1, y + 1) * fx;
        (top * (1.0 - fy) + bottom * fy) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slice(along: f64) -> SliceRef {
        SliceRef { file: 0, frame: 0, position: [0.0, 0.0, along], along, rescale: (1.0, 0.0) }
    }

    #[test]
    fn a_missing_slice_is_filled_linearly_and_shifts_are_bilinear() {
        // slices at z = 0, 1, 3 with values z (a linear ramp) on 3x2 pixels
        let slices = [slice(0.0), slice(1.0), slice(3.0)];
        let stack: Vec<f32> = [0.0f32, 1.0, 3.0].iter().flat_map(|&v| [v; 6]).collect();
        let plan = Resampling { nz: 4, spacing: 1.0, offsets: vec![[0.0; 2]; 3] };
        let out = resample(&stack, 3, 2, &slices, &plan);
        for k in 0..4 {
            assert!(
                out[k * 6..(k + 1) * 6].iter().all(|&v| v == k as f32),
                "slice {k}: {:?}",
                &out[k * 6..(k + 1) * 6]
            );
        }
        // a slice shifted half a pixel along x reads halfway between columns
        let ramp = [0.0f32, 10.0, 20.0, 0.0, 10.0, 20.0];
        assert_eq!(Shifted::new(&ramp, 3, 2, [0.5, 0.0], -1.0).at(1, 0), 5.0);
        assert_eq!(Shifted::new(&ramp, 3, 2, [0.5, 0.0], -1.0).at(0, 1), -0.5);
    }
}
