//! Per-vertex gradients, two ways, both exact for linear fields:
//!
//! * least squares (the default): the linear function through the vertex
//!   that best fits its edge neighbours, weighted by 1 / |d|^4 so that short
//!   edges dominate (on a grid mesh the axis neighbours, as in central
//!   differences);
//! * volume average: the volume-weighted mean of the constant gradients of
//!   the linear interpolant on the tetrahedra around the vertex.
//!
//! On the meshed erf sphere (64^3, sigma 3, |x| < 2 sigma) the mean relative
//! g error is 1.50 % / 1.82 % (least squares / average, 6 tetrahedra per
//! cell) and 2.6 % / 3.6 % with voxels of (1, 1, 2); central differences on
//! the grid itself are at 1.9 % at the boundary, so both are sampling-limited
//! there. Least squares costs a neighbour list per vertex.

use crate::mesh::{TetMesh, six_volume, sub};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Gradient of the linear interpolant of `s` on one tetrahedron, and its volume.
pub fn tet_gradient(p: [[f64; 3]; 4], s: [f64; 4]) -> ([f64; 3], f64) {
    let e1 = sub(p[1], p[0]);
    let e2 = sub(p[2], p[0]);
    let e3 = sub(p[3], p[0]);
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let (c23, c31, c12) = (cross(e2, e3), cross(e3, e1), cross(e1, e2));
    let det = six_volume(p[0], p[1], p[2], p[3]);
    let (d1, d2, d3) = (s[1] - s[0], s[2] - s[0], s[3] - s[0]);
    let grad = [0, 1, 2].map(|a| (d1 * c23[a] + d2 * c31[a] + d3 * c12[a]) / det);
    (grad, det.abs() / 6.0)
}

/// Tetrahedra around every vertex, in increasing tetrahedron order (CSR):
/// the tetrahedra of vertex v are `tets[start[v]..start[v + 1]]`.
pub struct VertexStars {
    /// Offsets into `tets`, one more than the vertex count.
    pub start: Vec<usize>,
    /// Tetrahedron indices.
    pub tets: Vec<u32>,
}

impl VertexStars {
    /// Builds the stars by a counting sort of the cells' vertex references.
    pub fn new(mesh: &TetMesh) -> VertexStars {
        let n = mesh.points.len();
        let mut start = vec![0usize; n + 1];
        for t in &mesh.tets {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for v in 0..n {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut tets = vec![0u32; start[n]];
        for (c, t) in mesh.tets.iter().enumerate() {
            for &v in t {
                tets[fill[v as usize]] = c as u32;
                fill[v as usize] += 1;
            }
        }
        VertexStars { start, tets }
    }
}

/// How per-vertex gradients are estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GradientMethod {
    /// Weighted least-squares fit of a linear function over the edge
    /// neighbours (weights 1 / |d|^4): the default, the most accurate on the erf sphere.
    LeastSquares,
    /// Volume-weighted average of the per-tetrahedron gradients around the vertex.
    VolumeAverage,
}

impl GradientMethod {
    /// One line for the manifest.
    pub fn describe(self) -> &'static str {
        match self {
            GradientMethod::LeastSquares => {
                "least-squares linear fit over the edge neighbours, weights 1/|d|^4 (volume average where singular)"
            }
            GradientMethod::VolumeAverage => {
                "volume-weighted average of the constant per-tetrahedron gradients of the linear interpolant"
            }
        }
    }
}

impl std::str::FromStr for GradientMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "least-squares" => Ok(GradientMethod::LeastSquares),
            "volume-average" => Ok(GradientMethod::VolumeAverage),
            _ => Err(format!("unknown gradient method '{s}' (least-squares, volume-average)")),
        }
    }
}

/// Per-vertex gradient of the mesh's scalar (scalar units per world unit).
/// Vertices in no tetrahedron get 0. Deterministic whatever the thread count.
pub fn vertex_gradients(mesh: &TetMesh, method: GradientMethod) -> Vec<[f32; 3]> {
    let stars = VertexStars::new(mesh);
    (0..mesh.points.len())
        .into_par_iter()
        .map_init(Vec::new, |neighbours: &mut Vec<u32>, v| {
            let star = &stars.tets[stars.start[v]..stars.start[v + 1]];
            let fit = match method {
                GradientMethod::LeastSquares => least_squares(mesh, star, v, neighbours),
                GradientMethod::VolumeAverage => None,
            };
            fit.unwrap_or_else(|| volume_average(mesh, star)).map(|x| x as f32)
        })
        .collect()
}

/// Volume-weighted mean of the per-tetrahedron gradients of `star`.
fn volume_average(mesh: &TetMesh, star: &[u32]) -> [f64; 3] {
    let (mut sum, mut weight) = ([0.0f64; 3], 0.0f64);
    for &c in star {
        let t = mesh.tets[c as usize];
        let (g, vol) = tet_gradient(t.map(|i| mesh.points[i as usize]), t.map(|i| mesh.scalar[i as usize] as f64));
        for a in 0..3 {
            sum[a] += vol * g[a];
        }
        weight += vol;
    }
    if weight > 0.0 { sum.map(|x| x / weight) } else { [0.0; 3] }
}

/// The weighted least-squares gradient at `v` over the edge neighbours in
/// its `star`; None where the fit is singular (fewer than three independent edges).
fn least_squares(mesh: &TetMesh, star: &[u32], v: usize, neighbours: &mut Vec<u32>) -> Option<[f64; 3]> {
    neighbours.clear();
    for &c in star {
        neighbours.extend(mesh.tets[c as usize].iter().copied().filter(|&u| u as usize != v));
    }
    neighbours.sort_unstable();
    neighbours.dedup();
    let p = mesh.points[v];
    let s = mesh.scalar[v] as f64;
    let (mut m, mut r) = ([[0.0f64; 3]; 3], [0.0f64; 3]);
    for &u in neighbours.iter() {
        let d = sub(mesh.points[u as usize], p);
        let q = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        // 1/|d|^4 favours the short edges: on a grid the axis neighbours, as central differences do
        let w = 1.0 / (q * q);
        let df = mesh.scalar[u as usize] as f64 - s;
        for a in 0..3 {
            r[a] += w * d[a] * df;
            for b in 0..3 {
                m[a][b] += w * d[a] * d[b];
            }
        }
    }
    solve3(m, r)
}

/// Solves m x = r by Cramer's rule; None when m is (nearly) singular.
fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> Option<[f64; 3]> {
    let det3 = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let det = det3(m);
    let scale = m[0][0] * m[1][1] * m[2][2];
    if det.is_nan() || det.abs() <= 1e-12 * scale.abs() {
        return None;
    }
    Some([0, 1, 2].map(|c| {
        let mut a = m;
        for row in 0..3 {
            a[row][c] = r[row];
        }
        det3(a) / det
    }))
}

/// |gradient| per vertex.
pub fn magnitudes(gradients: &[[f32; 3]]) -> Vec<f32> {
    gradients.par_iter().map(|g| (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt()).collect()
}
