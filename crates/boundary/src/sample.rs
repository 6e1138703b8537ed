//! Interpolation of a volume at continuous voxel positions.

/// A scalar grid to sample: samples x-fastest, dims (nx, ny, nz).
#[derive(Clone, Copy)]
pub(crate) struct Grid<'a> {
    pub data: &'a [f32],
    pub dims: [usize; 3],
}

impl Grid<'_> {
    /// Cell origin (lower corner, so that corner + 1 is inside the grid along
    /// every axis longer than 1) and fractions of position p, clamped to the grid.
    #[inline(always)]
    fn cell(&self, p: [f32; 3]) -> ([usize; 3], [f32; 3]) {
        let mut i0 = [0usize; 3];
        let mut t = [0f32; 3];
        for a in 0..3 {
            let top = (self.dims[a] - 1) as f32;
            let x = if p[a] > 0.0 { if p[a] < top { p[a] } else { top } } else { 0.0 };
            // x >= 0, so truncation is floor
            let f = (x as usize).min(self.dims[a].saturating_sub(2));
            i0[a] = f;
            t[a] = x - f as f32;
        }
        (i0, t)
    }

    /// Linear index of cell origin `i0`.
    #[inline(always)]
    fn base(&self, i0: [usize; 3]) -> usize {
        (i0[2] * self.dims[1] + i0[1]) * self.dims[0] + i0[0]
    }

    /// The 8 corner values of the cell at linear index `b` (x fastest: 000, 100, 010, 110, 001, ...).
    #[inline(always)]
    fn corners(&self, b: usize) -> [f32; 8] {
        let [nx, ny, _] = self.dims;
        let dx = usize::from(nx > 1);
        let dy = if ny > 1 { nx } else { 0 };
        let dz = if self.dims[2] > 1 { nx * ny } else { 0 };
        let d = self.data;
        [d[b], d[b + dx], d[b + dy], d[b + dy + dx], d[b + dz], d[b + dz + dx], d[b + dz + dy], d[b + dz + dy + dx]]
    }

    /// Trilinear interpolation at voxel position p (clamped to the grid).
    #[cfg(test)]
    pub fn trilinear(&self, p: [f32; 3]) -> f32 {
        let (i0, t) = self.cell(p);
        lerp_cell(&self.corners(self.base(i0)), t)
    }

    /// Trilinear interpolation of three grids of the same dims at p (one cell lookup).
    #[inline]
    pub fn trilinear3(grids: &[Grid; 3], p: [f32; 3]) -> [f32; 3] {
        let (i0, t) = grids[0].cell(p);
        let b = grids[0].base(i0);
        [0, 1, 2].map(|c| lerp_cell(&grids[c].corners(b), t))
    }

    /// Tricubic Catmull-Rom interpolation at voxel position p (indices clamped).
    /// Exact on quadratics, so a smooth peak is not flattened the way
    /// trilinear interpolation flattens it.
    pub fn tricubic(&self, p: [f32; 3]) -> f32 {
        let mut w = [[0f32; 4]; 3];
        let mut idx = [[0usize; 4]; 3];
        for a in 0..3 {
            let top = (self.dims[a] - 1) as f32;
            let x = if p[a] > 0.0 { if p[a] < top { p[a] } else { top } } else { 0.0 };
            let f = x as usize; // x >= 0: truncation is floor
            w[a] = catmull_rom_weights(x - f as f32);
            for o in 0..4 {
                idx[a][o] = (f + o).saturating_sub(1).min(self.dims[a] - 1);
            }
        }
        let [nx, ny, _] = self.dims;
        let mut sum = 0.0;
        for (wz, &k) in w[2].iter().zip(&idx[2]) {
            let mut plane = 0.0;
            for (wy, &j) in w[1].iter().zip(&idx[1]) {
                let row = &self.data[(k * ny + j) * nx..(k * ny + j + 1) * nx];
                let r: f32 = w[0].iter().zip(&idx[0]).map(|(wx, &i)| wx * row[i]).sum();
                plane += wy * r;
            }
            sum += wz * plane;
        }
        sum
    }
}

/// Trilinear interpolation inside one cell from its 8 corners.
#[inline(always)]
fn lerp_cell(c: &[f32; 8], t: [f32; 3]) -> f32 {
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let c00 = lerp(c[0], c[1], t[0]);
    let c10 = lerp(c[2], c[3], t[0]);
    let c01 = lerp(c[4], c[5], t[0]);
    let c11 = lerp(c[6], c[7], t[0]);
    lerp(lerp(c00, c10, t[1]), lerp(c01, c11, t[1]), t[2])
}

/// Trilinear sampling along a ray that keeps the current cell's corners,
/// so consecutive samples in one cell (steps are a fifth of a voxel) read
/// memory once.
pub(crate) struct CellCache<'a> {
    grid: Grid<'a>,
    cell: usize,
    corners: [f32; 8],
}

impl<'a> CellCache<'a> {
    /// A cache over `grid`, empty.
    pub fn new(grid: Grid<'a>) -> CellCache<'a> {
        CellCache { grid, cell: usize::MAX, corners: [0.0; 8] }
    }

    /// Trilinear interpolation at p; the same value as [`Grid::trilinear`].
    #[inline(always)]
    pub fn sample(&mut self, p: [f32; 3]) -> f32 {
        let (i0, t) = self.grid.cell(p);
        let b = self.grid.base(i0);
        if b != self.cell {
            self.cell = b;
            self.corners = self.grid.corners(b);
        }
        lerp_cell(&self.corners, t)
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
