//! Interpolation of a volume at continuous voxel positions.

/// A scalar grid to sample: samples x-fastest, dims (nx, ny, nz).
#[derive(Clone, Copy)]
pub(crate) struct Grid<'a> {
    pub data: &'a [f32],
    pub dims: [usize; 3],
}

impl Grid<'_> {
    #[inline(always)]
    fn at(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[(k * self.dims[1] + j) * self.dims[0] + i]
    }

    /// Trilinear interpolation at voxel position p (clamped to the grid).
    #[inline]
    pub fn trilinear(&self, p: [f32; 3]) -> f32 {
        let mut i0 = [0usize; 3];
        let mut t = [0f32; 3];
        for a in 0..3 {
            let n = self.dims[a];
            let x = p[a].clamp(0.0, (n - 1) as f32);
            let f = (x.floor() as usize).min(n.saturating_sub(2));
            i0[a] = f;
            t[a] = if n > 1 { x - f as f32 } else { 0.0 };
        }
        let i1 = [0, 1, 2].map(|a| (i0[a] + 1).min(self.dims[a] - 1));
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(self.at(i0[0], i0[1], i0[2]), self.at(i1[0], i0[1], i0[2]), t[0]);
        let c10 = lerp(self.at(i0[0], i1[1], i0[2]), self.at(i1[0], i1[1], i0[2]), t[0]);
        let c01 = lerp(self.at(i0[0], i0[1], i1[2]), self.at(i1[0], i0[1], i1[2]), t[0]);
        let c11 = lerp(self.at(i0[0], i1[1], i1[2]), self.at(i1[0], i1[1], i1[2]), t[0]);
        lerp(lerp(c00, c10, t[1]), lerp(c01, c11, t[1]), t[2])
    }

    /// Tricubic Catmull-Rom interpolation at voxel position p (indices clamped).
    /// Exact on quadratics, so a smooth peak is not flattened the way
    /// trilinear interpolation flattens it.
    pub fn tricubic(&self, p: [f32; 3]) -> f32 {
        let mut base = [0isize; 3];
        let mut w = [[0f32; 4]; 3];
        for a in 0..3 {
            let x = p[a].clamp(0.0, (self.dims[a] - 1) as f32);
            let f = x.floor();
            base[a] = f as isize - 1;
            w[a] = catmull_rom_weights(x - f);
        }
        let idx = |a: usize, o: isize| (base[a] + o).clamp(0, self.dims[a] as isize - 1) as usize;
        let mut sum = 0.0;
        for (oz, wz) in w[2].iter().enumerate() {
            let k = idx(2, oz as isize);
            for (oy, wy) in w[1].iter().enumerate() {
                let j = idx(1, oy as isize);
                let mut row = 0.0;
                for (ox, wx) in w[0].iter().enumerate() {
                    row += wx * self.at(idx(0, ox as isize), j, k);
                }
                sum += wz * wy * row;
            }
        }
        sum
    }
}

/// Catmull-Rom weights of the four samples at offsets -1, 0, 1, 2 for fraction t in [0, 1).
fn catmull_rom_weights(t: f32) -> [f32; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_of(f: impl Fn(f32, f32, f32) -> f32) -> Vec<f32> {
        let mut v = Vec::new();
        for k in 0..6 {
            for j in 0..5 {
                for i in 0..4 {
                    v.push(f(i as f32, j as f32, k as f32));
                }
            }
        }
        v
    }

    #[test]
    fn trilinear_is_exact_on_trilinear_functions_and_tricubic_on_quadratics() {
        let lin = grid_of(|x, y, z| 1.0 + 2.0 * x - y + 0.5 * z + 0.25 * x * y * z);
        let g = Grid { data: &lin, dims: [4, 5, 6] };
        let (x, y, z) = (1.3f32, 2.7f32, 3.1f32);
        assert!((g.trilinear([x, y, z]) - (1.0 + 2.0 * x - y + 0.5 * z + 0.25 * x * y * z)).abs() < 1e-5);
        let quad = grid_of(|x, y, z| x * x - 0.5 * y * y + x * z + 3.0);
        let g = Grid { data: &quad, dims: [4, 5, 6] };
        let (x, y, z) = (1.4f32, 2.2f32, 2.6f32);
        assert!((g.tricubic([x, y, z]) - (x * x - 0.5 * y * y + x * z + 3.0)).abs() < 1e-4);
        // at the nodes both interpolate
        assert_eq!(g.trilinear([2.0, 3.0, 4.0]), quad[(4 * 5 + 3) * 4 + 2]);
        assert!((g.tricubic([2.0, 3.0, 4.0]) - quad[(4 * 5 + 3) * 4 + 2]).abs() < 1e-5);
    }
}
