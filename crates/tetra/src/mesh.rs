//! The tetrahedral mesh type and its checks.

use crate::TetraError;
use std::collections::BTreeMap;

/// A point array carried with the mesh (read from the file, or added by mdtf).
#[derive(Debug, Clone, PartialEq)]
pub struct PointArray {
    /// Array name.
    pub name: String,
    /// Components per point.
    pub components: usize,
    /// Values, components fastest.
    pub values: Vec<f64>,
}

/// A tetrahedral mesh with one scalar per point.
#[derive(Debug, Clone, PartialEq)]
pub struct TetMesh {
    /// Point positions, world units.
    pub points: Vec<[f64; 3]>,
    /// Tetrahedra as four point indices each.
    pub tets: Vec<[u32; 4]>,
    /// Name of the scalar s.
    pub scalar_name: String,
    /// The scalar s per point.
    pub scalar: Vec<f32>,
    /// The point arrays of the input at full precision (s among them), written
    /// back with the added ones; empty for a meshed volume.
    pub arrays: Vec<PointArray>,
}

/// What happened to the cells of an input mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MeshReport {
    /// Cells that are not tetrahedra, skipped, by VTK cell type name.
    pub skipped_cells: BTreeMap<String, usize>,
    /// Tetrahedra of (numerically) zero volume, skipped.
    pub degenerate_tets: usize,
    /// The cell array the scalar s was made from, when the mesh has no
    /// point scalar (see [`crate::cell_to_points`]).
    pub scalar_from_cells: Option<String>,
}

impl MeshReport {
    /// One line for the user: how many cells were skipped and why ("" when none).
    pub fn summary(&self) -> String {
        let mut parts: Vec<String> =
            self.skipped_cells.iter().map(|(kind, n)| format!("{n} {kind} cell(s) skipped (not tetrahedra)")).collect();
        if self.degenerate_tets > 0 {
            parts.push(format!("{} zero-volume tetrahedra skipped", self.degenerate_tets));
        }
        if let Some(name) = &self.scalar_from_cells {
            parts.push(format!(
                "no point scalar: s is the cell array '{name}' carried to the points (at each point, the mean over \
                 the tetrahedra around it weighted by their volumes)"
            ));
        }
        parts.join("; ")
    }
}

/// A value per tetrahedron (`values[t]` of `tets[t]`) carried to the
/// points: at each point the mean over the tetrahedra around it weighted by
/// their volumes (the integral of the piecewise-constant field over the
/// point's star over its volume, as VTK's CellDataToPointData does with
/// volume weights); the plain mean where they all have zero volume, 0 at a
/// point no tetrahedron uses. Corner numbers outside `points` are left out
/// (the mesh check refuses them later).
pub fn cell_to_points(points: &[[f64; 3]], tets: &[[u64; 4]], values: &[f64]) -> Vec<f64> {
    let (mut sum, mut weight, mut plain, mut count) =
        (vec![0f64; points.len()], vec![0f64; points.len()], vec![0f64; points.len()], vec![0u32; points.len()]);
    for (t, &value) in tets.iter().zip(values) {
        let corner = |c: usize| points.get(t[c] as usize).copied();
        let (Some(a), Some(b), Some(c), Some(d)) = (corner(0), corner(1), corner(2), corner(3)) else { continue };
        let volume = six_volume(a, b, c, d).abs() / 6.0;
        for &p in t {
            let p = p as usize;
            sum[p] += volume * value;
            weight[p] += volume;
            plain[p] += value;
            count[p] += 1;
        }
    }
    (0..points.len())
        .map(|p| if weight[p] > 0.0 { sum[p] / weight[p] } else { plain[p] / count[p].max(1) as f64 })
        .collect()
}

/// 6 x the signed volume of the tetrahedron (a, b, c, d).
pub fn six_volume(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> f64 {
    let u = sub(b, a);
    let v = sub(c, a);
    let w = sub(d, a);
    u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0])
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(a, b);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// Longest of the six edges of tetrahedron `t`.
pub fn max_edge(points: &[[f64; 3]], t: &[u32; 4]) -> f64 {
    let p = t.map(|i| points[i as usize]);
    let mut m = 0.0f64;
    for a in 0..4 {
        for b in a + 1..4 {
            m = m.max(dist(p[a], p[b]));
        }
    }
    m
}

/// A tetrahedron is degenerate when |6 V| <= this times its longest edge cubed
/// (a regular tetrahedron has 6 V / L^3 = 0.71; a cube's Kuhn tetrahedra 0.19).
pub const DEGENERATE_RATIO: f64 = 1e-9;

impl TetMesh {
    /// Builds a mesh from raw parts: checks every index against the point
    /// count and every coordinate and scalar for finiteness, and drops
    /// zero-volume tetrahedra (returned as a count). `what` names the source in errors.
    pub fn from_parts(
        what: &str,
        points: Vec<[f64; 3]>,
        raw_tets: Vec<[u64; 4]>,
        scalar_name: String,
        scalar: Vec<f32>,
        arrays: Vec<PointArray>,
    ) -> Result<(TetMesh, usize), TetraError> {
        let n = points.len();
        if scalar.len() != n {
            return Err(TetraError::Invalid(format!(
                "{what}: scalar '{scalar_name}' has {} values for {n} points",
                scalar.len()
            )));
        }
        if n > u32::MAX as usize {
            return Err(TetraError::Invalid(format!("{what}: {n} points is more than 2^32 - 1")));
        }
        if let Some(i) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(TetraError::Invalid(format!("{what}: point {i} has a non-finite coordinate {:?}", points[i])));
        }
        if let Some(i) = scalar.iter().position(|s| !s.is_finite()) {
            return Err(TetraError::Invalid(format!("{what}: scalar '{scalar_name}' is {} at point {i}", scalar[i])));
        }
        let mut tets = Vec::with_capacity(raw_tets.len());
        let mut degenerate = 0;
        for (c, t) in raw_tets.iter().enumerate() {
            if let Some(&bad) = t.iter().find(|&&i| i as usize >= n || i > u32::MAX as u64) {
                return Err(TetraError::IndexOutOfRange { what: what.into(), cell: c, index: bad, points: n });
            }
            let t = t.map(|i| i as u32);
            let p = t.map(|i| points[i as usize]);
            let l = max_edge(&points, &t);
            if six_volume(p[0], p[1], p[2], p[3]).abs() <= DEGENERATE_RATIO * l * l * l {
                degenerate += 1;
                continue;
            }
            tets.push(t);
        }
        if tets.is_empty() {
            return Err(TetraError::NoTetrahedra {
                what: what.into(),
                detail: if raw_tets.is_empty() {
                    "the file has no tetrahedral cells".into()
                } else {
                    format!("all {} tetrahedra have zero volume", raw_tets.len())
                },
            });
        }
        Ok((TetMesh { points, tets, scalar_name, scalar, arrays }, degenerate))
    }

    /// Longest edge over all tetrahedra (world units).
    pub fn max_edge_length(&self) -> f64 {
        self.tets.iter().map(|t| max_edge(&self.points, t)).fold(0.0, f64::max)
    }

    /// Axis-aligned bounding box (min, max) of the points.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.points {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    }
}
