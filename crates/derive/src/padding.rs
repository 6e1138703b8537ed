//! Scanner padding left out of the derivatives: a sample whose value lies
//! in the padding range (DICOM's PixelPaddingValue outside a CT's circular
//! field of view) is no data, so every derived sample whose kernel reads one
//! (within the kernel's radius along each axis, a box) is NaN: the stages
//! after derive leave NaN out (histograms, the noise floor's median, the
//! tracing), and the hard edge at the padding's rim makes no gradient.

/// The samples of the first field and the padding range, with the kernel's
/// radius per axis: what [`PaddingMask::apply`] needs per z-slice.
pub(crate) struct PaddingMask<'a> {
    samples: &'a [f32],
    dims: [usize; 3],
    range: [f32; 2],
    radius: [usize; 3],
}

impl<'a> PaddingMask<'a> {
    /// The mask of `samples` (x fastest, `dims`) for values in `range`
    /// (inclusive) read by a kernel of `radius` samples per axis.
    pub(crate) fn new(samples: &'a [f32], dims: [usize; 3], range: [f32; 2], radius: [usize; 3]) -> Self {
        PaddingMask { samples, dims, range, radius }
    }

    fn is_padding(&self, v: f32) -> bool {
        v >= self.range[0] && v <= self.range[1]
    }

    /// Sets to NaN, in every output slice `outs` of z-slice `k`, the samples
    /// whose kernel box reaches a padding sample.
    pub(crate) fn apply(&self, k: usize, outs: &mut [&mut [f32]]) {
        let [nx, ny, nz] = self.dims;
        let [rx, ry, rz] = self.radius;
        let plane = nx * ny;
        // padding anywhere in the z window, per (i, j)
        let mut hit = vec![false; plane];
        for z in k.saturating_sub(rz)..(k + rz + 1).min(nz) {
            let samples = &self.samples[z * plane..(z + 1) * plane];
            for (h, &v) in hit.iter_mut().zip(samples) {
                *h |= self.is_padding(v);
            }
        }
        if !hit.iter().any(|&h| h) {
            return;
        }
        // grown along y, then along x
        let mut grown_y = vec![false; plane];
        for j in 0..ny {
            for y in j.saturating_sub(ry)..(j + ry + 1).min(ny) {
                for i in 0..nx {
                    grown_y[j * nx + i] |= hit[y * nx + i];
                }
            }
        }
        for j in 0..ny {
            let row = &grown_y[j * nx..(j + 1) * nx];
            for i in 0..nx {
                if row[i.saturating_sub(rx)..(i + rx + 1).min(nx)].iter().any(|&h| h) {
                    for out in outs.iter_mut() {
                        out[j * nx + i] = f32::NAN;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_sample_within_the_kernel_box_of_padding_is_nan() {
        // 7 x 6 x 5, padding at (1, 2, 3) only; radius (2, 1, 1)
        let dims = [7, 6, 5];
        let mut samples = vec![0.0f32; 7 * 6 * 5];
        samples[(3 * 6 + 2) * 7 + 1] = -2000.0;
        let mask = PaddingMask::new(&samples, dims, [-2000.0, -1500.0], [2, 1, 1]);
        for k in 0usize..5 {
            let mut out = [1.0f32; 42];
            mask.apply(k, &mut [&mut out[..]]);
            for j in 0usize..6 {
                for i in 0usize..7 {
                    let near = i <= 3 && j.abs_diff(2) <= 1 && k.abs_diff(3) <= 1;
                    assert_eq!(out[j * 7 + i].is_nan(), near, "({i}, {j}, {k})");
                }
            }
        }
    }
}
