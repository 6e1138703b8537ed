//! Interpolation of a volume at continuous voxel positions.

/// A scalar grid to sample: samples x-fastest, dims (nx, ny, nz).
#[derive(Clone, Copy)]
pub(crate) struct Grid<'a> {
    pub data: &'a [f32],
    pub dims: [usize; 3],
    /// Position of the grid's first sample per axis: 0 for a whole volume,
    /// the block's first plane for a block. Positions are in the whole
    /// volume's voxel coordinates, so a block computes them with the same bits.
    low: [f32; 3],
    /// low + dims - 1 per axis: the largest position inside the grid.
    top: [f32; 3],
    /// The largest cell origin per axis (low + dims - 2, or low for an axis of one sample).
    last_cell: [f32; 3],
}

impl<'a> Grid<'a> {
    /// The grid of `data` (x fastest) with `dims`, its first sample at position 0.
    #[cfg(test)]
    pub fn new(data: &'a [f32], dims: [usize; 3]) -> Grid<'a> {
        Grid::at(data, dims, [0; 3])
    }

    /// The grid of `data` (x fastest) with `dims`, its first sample at
    /// position `first` (voxels) of the whole volume.
    pub fn at(data: &'a [f32], dims: [usize; 3], first: [usize; 3]) -> Grid<'a> {
        let low = first.map(|f| f as f32);
        let top = [0, 1, 2].map(|a| (first[a] + dims[a].saturating_sub(1)) as f32);
        let last_cell = [0, 1, 2].map(|a| (first[a] + dims[a].saturating_sub(2)) as f32);
        Grid { data, dims, low, top, last_cell }
    }
}

impl Grid<'_> {
    /// The largest position inside the grid along `axis`.
    #[inline(always)]
    pub fn top(&self, axis: usize) -> f32 {
        self.top[axis]
    }

    /// The smallest position inside the grid along `axis`.
    #[inline(always)]
    pub fn low(&self, axis: usize) -> f32 {
        self.low[axis]
    }

    /// Cell origin (lower corner, so that corner + 1 is inside the grid along
    /// every axis longer than 1), the same as floats, and the fractions of
    /// position p, clamped to the grid (NaN clamps to 0).
    #[inline(always)]
    fn cell(&self, p: [f32; 3]) -> ([usize; 3], [f32; 3], [f32; 3]) {
        let mut i0 = [0usize; 3];
        let mut origin = [0f32; 3];
        let mut t = [0f32; 3];
        for a in 0..3 {
            let x = p[a].max(self.low[a]).min(self.top[a]);
            let f = x.floor().min(self.last_cell[a]);
            // 0 <= f - low < 2^24: exact as an integer
            i0[a] = (f - self.low[a]) as u32 as usize;
            origin[a] = f;
            t[a] = x - f;
        }
        (i0, origin, t)
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
        let (i0, _, t) = self.cell(p);
        lerp_cell(&self.corners(self.base(i0)), t)
    }

    /// Trilinear interpolation of three grids of the same dims at p (one cell lookup).
    #[inline(always)]
    pub fn trilinear3(grids: &[Grid; 3], p: [f32; 3]) -> [f32; 3] {
        let (i0, _, t) = grids[0].cell(p);
        let b = grids[0].base(i0);
        [lerp_cell(&grids[0].corners(b), t), lerp_cell(&grids[1].corners(b), t), lerp_cell(&grids[2].corners(b), t)]
    }

    /// Tricubic Catmull-Rom interpolation at voxel position p (indices clamped).
    /// Exact on quadratics, so a smooth peak is not flattened the way
    /// trilinear interpolation flattens it.
    #[inline(always)]
    pub fn tricubic(&self, p: [f32; 3]) -> f32 {
        let [nx, ny, _] = self.dims;
        let mut w = [[0f32; 4]; 3];
        // index of the first of the four samples (f - 1), possibly -1
        let mut first = [0isize; 3];
        let mut interior = true;
        for a in 0..3 {
            let x = p[a].max(self.low[a]).min(self.top[a]);
            let f = x.floor();
            w[a] = catmull_rom_weights(x - f);
            let f = (f - self.low[a]) as u32 as usize;
            // the four samples f - 1 ..= f + 2 inside the grid: no clamping needed
            interior &= f >= 1 && f + 2 < self.dims[a];
            first[a] = f as isize - 1;
        }
        let row_sum = |row: [f32; 4]| w[0][0] * row[0] + w[0][1] * row[1] + w[0][2] * row[2] + w[0][3] * row[3];
        let mut sum = 0.0;
        for (dz, wz) in w[2].iter().enumerate() {
            let mut plane = 0.0;
            for (dy, wy) in w[1].iter().enumerate() {
                let row = if interior {
                    let start = ((first[2] as usize + dz) * ny + first[1] as usize + dy) * nx + first[0] as usize;
                    match self.data.get(start..start + 4) {
                        Some(r) => [r[0], r[1], r[2], r[3]],
                        None => [0.0; 4],
                    }
                } else {
                    // indices clamped to the grid (the border policy of clamp to edge)
                    let clamp =
                        |a: usize, o: usize| (first[a] + o as isize).clamp(0, self.dims[a] as isize - 1) as usize;
                    let start = (clamp(2, dz) * ny + clamp(1, dy)) * nx;
                    let at = |o: usize| self.data.get(start + clamp(0, o)).copied().unwrap_or(0.0);
                    [at(0), at(1), at(2), at(3)]
                };
                plane += wy * row_sum(row);
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

/// Trilinear samples of a grid along one ray p(t) = o + t d (voxel
/// coordinates; t in world units when d is in voxels per world unit), cell
/// by cell. Along a line inside one cell the trilinear interpolant is a
/// cubic in t, so a sample costs one Horner evaluation; the corners and the
/// cubic are computed when the ray enters a cell. At the first sample of a
/// cell the value has the bits of [`Grid::trilinear`] (the cubic is the
/// same x, y, z lerps, expanded in t).
pub(crate) struct RayCells<'a> {
    grid: Grid<'a>,
    o: [f32; 3],
    d: [f32; 3],
    /// 1 / d per axis (0 where d is 0: that axis never bounds the cell's t range).
    inv_d: [f32; 3],
    /// The t range the current cell covers (an empty range before the first sample).
    t_enter: f32,
    t_exit: f32,
    /// t where s = t - t0 = 0 (the sample that entered the cell).
    t0: f32,
    /// c0 + s (c1 + s (c2 + s c3)).
    c: [f32; 4],
}

impl<'a> RayCells<'a> {
    /// The ray from `o` along `d` through `grid`.
    pub fn new(grid: Grid<'a>, o: [f32; 3], d: [f32; 3]) -> RayCells<'a> {
        let inv = |x: f32| if x != 0.0 { 1.0 / x } else { 0.0 };
        let inv_d = [inv(d[0]), inv(d[1]), inv(d[2])];
        RayCells { grid, o, d, inv_d, t_enter: f32::INFINITY, t_exit: f32::NEG_INFINITY, t0: 0.0, c: [0.0; 4] }
    }

    /// Where the current cell's t range starts (the ray enters it there).
    pub fn cell_start(&self) -> f32 {
        self.t_enter
    }

    /// The trilinear interpolant at p(t) (clamped to the grid, as [`Grid::trilinear`]).
    #[inline(always)]
    pub fn sample(&mut self, t: f32) -> f32 {
        if !(t >= self.t_enter && t <= self.t_exit) {
            self.enter(t);
        }
        let s = t - self.t0;
        self.c[0] + s * (self.c[1] + s * (self.c[2] + s * self.c[3]))
    }

    /// Makes the cell holding p(t) current: its t range and its cubic in s = t - t0, t0 = t.
    #[inline(always)]
    fn enter(&mut self, t: f32) {
        let (o, d) = (self.o, self.d);
        let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
        let (i0, cell, u) = self.grid.cell(p);
        let k = self.grid.corners(self.grid.base(i0));
        let (mut lo, mut hi) = (f32::NEG_INFINITY, f32::INFINITY);
        for a in 0..3 {
            if d[a] != 0.0 {
                let inv = self.inv_d[a];
                let (t_low, t_high) = ((cell[a] - o[a]) * inv, (cell[a] + 1.0 - o[a]) * inv);
                lo = lo.max(t_low.min(t_high));
                hi = hi.min(t_low.max(t_high));
            }
        }
        // Outside the grid the interpolant is clamped, not a cubic in t: such
        // a sample covers only itself.
        let outside = (0..3).any(|a| !(p[a] >= self.grid.low[a] && p[a] <= self.grid.top[a]));
        (self.t_enter, self.t_exit) = if outside { (t, t) } else { (lo.min(t), hi.max(t)) };
        self.t0 = t;
        // x lerps: linear in s, A + B s, for the four (y, z) corner pairs
        let line = |a: f32, b: f32| (a + (b - a) * u[0], (b - a) * d[0]);
        let e = [line(k[0], k[1]), line(k[2], k[3]), line(k[4], k[5]), line(k[6], k[7])];
        // y lerps: quadratics in s
        let quad = |p0: (f32, f32), p1: (f32, f32)| {
            let (da, db) = (p1.0 - p0.0, p1.1 - p0.1);
            [p0.0 + da * u[1], p0.1 + db * u[1] + da * d[1], db * d[1]]
        };
        let (q0, q1) = (quad(e[0], e[1]), quad(e[2], e[3]));
        // z lerp: the cubic
        let dq = [q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2]];
        self.c = [
            q0[0] + dq[0] * u[2],
            q0[1] + dq[1] * u[2] + dq[0] * d[2],
            q0[2] + dq[2] * u[2] + dq[1] * d[2],
            dq[2] * d[2],
        ];
    }
}

/// Catmull-Rom weights of the four samples at offsets -1, 0, 1, 2 for fraction t in [0, 1).
#[inline(always)]
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
    fn samples_along_a_ray_equal_trilinear_interpolation() {
        let v = grid_of(|x, y, z| (x * 1.3 + y * y * 0.7 - z * x * 0.4 + 0.1 * x * y * z).sin());
        let g = Grid::new(&v, [4, 5, 6]);
        for (o, d) in [
            ([0.3f32, 1.7, 4.9], [0.61f32, 0.55, -0.57]),
            ([3.0, 0.0, 2.5], [-0.8, 0.6, 0.0]),
            ([1.0, 2.0, 3.0], [0.0, 0.0, 1.0]),
        ] {
            let mut ray = RayCells::new(g, o, d);
            // forward in steps of 0.2, then backwards (refinement jumps back and forth)
            let ts: Vec<f32> =
                (0..12).map(|i| i as f32 * 0.2).chain((0..12).rev().map(|i| i as f32 * 0.2 + 0.05)).collect();
            for t in ts {
                let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
                let (want, got) = (g.trilinear(p), ray.sample(t));
                assert!((want - got).abs() <= 1e-5, "o {o:?} d {d:?} t {t}: {want} vs {got}");
            }
        }
        // at a cell's first sample, the very bits of trilinear interpolation
        let mut ray = RayCells::new(g, [0.3, 1.7, 2.2], [0.5, 0.5, 0.5]);
        assert_eq!(ray.sample(0.0).to_bits(), g.trilinear([0.3, 1.7, 2.2]).to_bits());
    }

    #[test]
    fn trilinear_is_exact_on_trilinear_functions_and_tricubic_on_quadratics() {
        let lin = grid_of(|x, y, z| 1.0 + 2.0 * x - y + 0.5 * z + 0.25 * x * y * z);
        let g = Grid::new(&lin, [4, 5, 6]);
        let (x, y, z) = (1.3f32, 2.7f32, 3.1f32);
        assert!((g.trilinear([x, y, z]) - (1.0 + 2.0 * x - y + 0.5 * z + 0.25 * x * y * z)).abs() < 1e-5);
        let quad = grid_of(|x, y, z| x * x - 0.5 * y * y + x * z + 3.0);
        let g = Grid::new(&quad, [4, 5, 6]);
        let (x, y, z) = (1.4f32, 2.2f32, 2.6f32);
        assert!((g.tricubic([x, y, z]) - (x * x - 0.5 * y * y + x * z + 3.0)).abs() < 1e-4);
        // near and at the faces the samples are clamped to the grid (clamp to edge): the
        // separable Catmull-Rom sum written out with clamped indices
        let reference = |p: [f32; 3]| {
            let mut sum = 0.0f64;
            let idx = |a: usize, o: i32| (p[a].floor() as i32 - 1 + o).clamp(0, [4, 5, 6][a] - 1) as usize;
            let w = |a: usize, o: usize| catmull_rom_weights(p[a] - p[a].floor())[o] as f64;
            for (c, wz) in (0..4).map(|c| (c, w(2, c))) {
                for (b, wy) in (0..4).map(|b| (b, w(1, b))) {
                    for (a, wx) in (0..4).map(|a| (a, w(0, a))) {
                        let i = (idx(2, c as i32) * 5 + idx(1, b as i32)) * 4 + idx(0, a as i32);
                        sum += wz * wy * wx * quad[i] as f64;
                    }
                }
            }
            sum
        };
        for p in [[0.3f32, 0.0, 4.6], [2.9, 3.99, 0.2], [0.0, 4.0, 5.0], [1.5, 2.5, 3.5]] {
            assert!((g.tricubic(p) as f64 - reference(p)).abs() < 1e-4, "{p:?}: {} vs {}", g.tricubic(p), reference(p));
        }
        // at the nodes both interpolate
        assert_eq!(g.trilinear([2.0, 3.0, 4.0]), quad[(4 * 5 + 3) * 4 + 2]);
        assert!((g.tricubic([2.0, 3.0, 4.0]) - quad[(4 * 5 + 3) * 4 + 2]).abs() < 1e-5);
    }
}
