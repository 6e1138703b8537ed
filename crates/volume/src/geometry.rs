//! Grid geometry: dimensions, spacing, origin and axis directions.
//!
//! Voxel (i, j, k) is the sample at world position
//! `origin + i sx d0 + j sy d1 + k sz d2`, where d0, d1, d2 are the unit axis
//! directions (node-centred samples, the NIfTI/NRRD convention). World space
//! is RAS (NIfTI's); NRRD files in LPS are converted on read.

/// Geometry of a regular 3D grid.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Geometry {
    /// Number of samples along x, y, z.
    pub dims: [usize; 3],
    /// Distance between samples along x, y, z, in world units (mm for medical data). Positive.
    pub spacing: [f64; 3],
    /// World position of voxel (0, 0, 0), in world units.
    pub origin: [f64; 3],
    /// Unit world direction of each grid axis: `directions[a]` is axis a (x, y, z).
    pub directions: [[f64; 3]; 3],
}

impl Geometry {
    /// Axis-aligned grid with the given dims and spacing, origin at 0.
    pub fn new(dims: [usize; 3], spacing: [f64; 3]) -> Geometry {
        Geometry { dims, spacing, origin: [0.0; 3], directions: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] }
    }

    /// Same geometry with another origin.
    pub fn with_origin(mut self, origin: [f64; 3]) -> Geometry {
        self.origin = origin;
        self
    }

    /// The grid of planes `z` (clamped to the grid) where they lie in this
    /// one: the geometry of a z-slab of a slab-by-slab run.
    pub fn z_slab(&self, z: std::ops::Range<usize>) -> Geometry {
        self.part(2, z)
    }

    /// The grid of rows `y` (clamped to the grid) of every plane, where they
    /// lie in this one: the geometry of a strip of rows of a blocked run.
    pub fn y_rows(&self, y: std::ops::Range<usize>) -> Geometry {
        self.part(1, y)
    }

    /// The grid of indices `r` (clamped to the grid) along `axis` (0 = x,
    /// 1 = y, 2 = z), where they lie in this one.
    pub(crate) fn part(&self, axis: usize, r: std::ops::Range<usize>) -> Geometry {
        let n = self.dims[axis];
        let (a, b) = (r.start.min(n), r.end.min(n).max(r.start.min(n)));
        let mut geometry = self.clone();
        geometry.dims[axis] = b - a;
        let shift = a as f64 * geometry.spacing[axis];
        for c in 0..3 {
            geometry.origin[c] += shift * geometry.directions[axis][c];
        }
        geometry
    }

    /// Number of voxels.
    pub fn voxel_count(&self) -> usize {
        self.dims.iter().product()
    }

    /// ndarray shape (nz, ny, nx) of this grid.
    pub fn shape(&self) -> (usize, usize, usize) {
        (self.dims[2], self.dims[1], self.dims[0])
    }

    /// Smallest spacing, L_min, in world units.
    pub fn min_spacing(&self) -> f64 {
        self.spacing.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// The 4x4 affine mapping voxel indices (i, j, k, 1) to world coordinates.
    pub fn world_from_voxel(&self) -> [[f64; 4]; 4] {
        let mut m = [[0.0; 4]; 4];
        for row in 0..3 {
            for axis in 0..3 {
                m[row][axis] = self.directions[axis][row] * self.spacing[axis];
            }
            m[row][3] = self.origin[row];
        }
        m[3][3] = 1.0;
        m
    }

    /// Builds a geometry from a voxel-to-world affine (3 rows of 4), splitting
    /// each column into a spacing (its length) and a unit direction. Returns
    /// `None` if a column has zero or non-finite length.
    pub fn from_affine(dims: [usize; 3], affine: [[f64; 4]; 3]) -> Option<Geometry> {
        let mut spacing = [0.0; 3];
        let mut directions = [[0.0; 3]; 3];
        for axis in 0..3 {
            let col = [affine[0][axis], affine[1][axis], affine[2][axis]];
            let len = (col[0] * col[0] + col[1] * col[1] + col[2] * col[2]).sqrt();
            if !(len.is_finite() && len > 0.0) {
                return None;
            }
            spacing[axis] = len;
            directions[axis] = [col[0] / len, col[1] / len, col[2] / len];
        }
        let origin = [affine[0][3], affine[1][3], affine[2][3]];
        if origin.iter().any(|o| !o.is_finite()) {
            return None;
        }
        Some(Geometry { dims, spacing, origin, directions })
    }

    /// True if both grids have the same dims and (to 1e-6 relative) the same placement.
    pub fn same_grid(&self, other: &Geometry) -> bool {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * (1.0 + a.abs().max(b.abs()));
        self.dims == other.dims
            && (0..3).all(|a| close(self.spacing[a], other.spacing[a]))
            && (0..3).all(|a| close(self.origin[a], other.origin[a]))
            && (0..3).all(|a| (0..3).all(|r| close(self.directions[a][r], other.directions[a][r])))
    }

    /// "NXxNYxNZ" for messages.
    pub fn dims_string(&self) -> String {
        format!("{}x{}x{}", self.dims[0], self.dims[1], self.dims[2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn affine_round_trip_keeps_spacing_origin_and_directions() {
        let g = Geometry {
            dims: [4, 5, 6],
            spacing: [0.5, 0.75, 2.0],
            origin: [-10.0, 3.0, 7.5],
            directions: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        };
        let m = g.world_from_voxel();
        // voxel (1, 0, 0) lies one x-spacing along the first direction
        assert_eq!(m[0][0] + m[0][3], -10.0);
        assert_eq!(m[1][0] + m[1][3], 3.5);
        let back = Geometry::from_affine(g.dims, [m[0], m[1], m[2]]).unwrap();
        assert!(back.same_grid(&g));
        assert_eq!(back.spacing, g.spacing);
    }

    #[test]
    fn degenerate_affine_is_refused() {
        let a = [[0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        assert!(Geometry::from_affine([2, 2, 2], a).is_none());
    }
}
