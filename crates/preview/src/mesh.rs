//! A projected-tetrahedra pack seen by the ray caster: its mesh's per-point
//! s and g resampled onto a regular grid over the mesh's bounding box,
//! linearly inside each tetrahedron (the field a projected-tetrahedra
//! renderer integrates), as the channels `v` and `g`. The grid's axes are
//! those of the pack's geometry (the volume the mesh was made from, oblique
//! or flipped as it may be; the world axes for a mesh read from a file), so
//! that a volume and the mesh made from it are seen the same way.

use crate::PreviewError;
use mdtf_pack::{Manifest, MeshArrayEntry};
use mdtf_volume::{Geometry, Volume};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Grid nodes along the longest axis of the box a mesh is resampled onto, at most.
pub const MESH_GRID_MAX: usize = 192;

/// z-planes of the grid one task fills.
const SLAB: usize = 4;

/// How far outside a tetrahedron (in barycentric weight) a node still counts
/// as inside, so nodes on shared faces and vertices are never missed.
const INSIDE_TOLERANCE: f64 = 1e-7;

/// The pack's mesh as the channels `v` (its scalar s) and `g` on a regular
/// grid (see [`resample`]); `cap` nodes along the longest axis at most.
pub fn mesh_channels(dir: &Path, manifest: &Manifest, cap: usize) -> Result<BTreeMap<String, Volume>, PreviewError> {
    let mesh =
        manifest.mesh.as_ref().ok_or_else(|| PreviewError::Pack("projected-tetrahedra pack without a mesh".into()))?;
    let points = read_array(dir, &mesh.arrays, "points", 3, "f32", mesh.points)?;
    let s_g = read_array(dir, &mesh.arrays, "s_g", 2, "f32", mesh.points)?;
    let tets = read_array(dir, &mesh.arrays, "tets", 4, "u32", mesh.tetrahedra)?;
    let f32s =
        |b: &[u8]| -> Vec<f32> { b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect() };
    let points: Vec<[f64; 3]> =
        f32s(&points).chunks_exact(3).map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect();
    let s_g = f32s(&s_g);
    let (s, g): (Vec<f32>, Vec<f32>) = s_g.chunks_exact(2).map(|p| (p[0], p[1])).unzip();
    let tets: Vec<[u32; 4]> = tets
        .chunks_exact(16)
        .map(|c| [0, 1, 2, 3].map(|k| u32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]])))
        .collect();
    if let Some(bad) = tets.iter().flatten().find(|&&i| i as usize >= points.len()) {
        return Err(PreviewError::Pack(format!("tets.nrrd names point {bad} of {}", points.len())));
    }
    // the points along the pack grid's own axes, from its origin
    let frame = &manifest.geometry;
    let axes: [[f64; 3]; 3] = [0, 1, 2].map(|a| {
        let column = [0, 1, 2].map(|r| frame.world_from_voxel[r][a]);
        let length = column.iter().map(|c| c * c).sum::<f64>().sqrt();
        if length > 0.0 { column.map(|c| c / length) } else { [0, 1, 2].map(|r| f64::from(u8::from(r == a))) }
    });
    let local: Vec<[f64; 3]> =
        points.iter().map(|p| axes.map(|d| (0..3).map(|r| d[r] * (p[r] - frame.origin[r])).sum::<f64>())).collect();
    let boxed = mesh_grid(&local, cap).ok_or_else(|| PreviewError::Pack("the mesh has no finite points".into()))?;
    let [vs, vg] = resample(&local, &tets, [&s, &g], &boxed);
    // the same grid in the world: its corner along the pack's axes
    let corner = [0, 1, 2].map(|r| frame.origin[r] + (0..3).map(|a| boxed.origin[a] * axes[a][r]).sum::<f64>());
    let grid = Geometry { origin: corner, directions: axes, ..boxed };
    let volume = |samples: Vec<f32>| {
        let [nx, ny, nz] = grid.dims;
        let data = ndarray::Array3::from_shape_vec((nz, ny, nx), samples)
            .map_err(|e| PreviewError::Pack(format!("resampled mesh: {e}")))?;
        Volume::new(grid.clone(), data).map_err(PreviewError::Io)
    };
    Ok(BTreeMap::from([("v".to_string(), volume(vs)?), ("g".to_string(), volume(vg)?)]))
}

/// The little-endian bytes of the mesh array `name` (the last
/// count x components x width bytes of its attached NRRD), checked against the manifest.
fn read_array(
    dir: &Path,
    arrays: &[MeshArrayEntry],
    name: &str,
    components: usize,
    dtype: &str,
    count: usize,
) -> Result<Vec<u8>, PreviewError> {
    let a = arrays
        .iter()
        .find(|a| a.name == name)
        .ok_or_else(|| PreviewError::Pack(format!("the mesh has no '{name}' array")))?;
    if a.components != components || a.dtype != dtype {
        return Err(PreviewError::Pack(format!(
            "mesh array '{name}' is {} x {}, expected {components} x {dtype}",
            a.components, a.dtype
        )));
    }
    let path = crate::load::pack_file(dir, &a.file)?;
    let bytes = std::fs::read(&path).map_err(|e| PreviewError::Pack(format!("{}: {e}", path.display())))?;
    let len = count * components * 4;
    if bytes.len() < len {
        return Err(PreviewError::Pack(format!("{}: shorter than its {count} x {components} values", a.file)));
    }
    Ok(bytes[bytes.len() - len..].to_vec())
}

/// The grid over the points' bounding box: cubic cells, `cap` nodes along
/// the longest side at most and about as many as the mesh has points
/// along it (a mesh cut from an n^3 volume gets about n^3 nodes).
fn mesh_grid(points: &[[f64; 3]], cap: usize) -> Option<Geometry> {
    let finite = points.iter().filter(|p| p.iter().all(|x| x.is_finite()));
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in finite {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    if !lo[0].is_finite() {
        return None;
    }
    let ext = [0, 1, 2].map(|a| hi[a] - lo[a]);
    let longest = ext.iter().cloned().fold(0.0, f64::max);
    if longest <= 0.0 {
        return Some(Geometry::new([2, 2, 2], [1.0; 3]).with_origin(lo));
    }
    let per_side = (points.len() as f64).cbrt().ceil() as usize + 1;
    let nodes = per_side.clamp(2, cap.max(2));
    let h = longest / (nodes - 1) as f64;
    let dims = ext.map(|e| ((e / h + 1e-9).floor() as usize + 1).max(2));
    Some(Geometry::new(dims, [h; 3]).with_origin(lo))
}

/// `values` (one per point) interpolated linearly inside each tetrahedron at
/// every node of `grid` (axis-aligned, its origin and spacing in the points'
/// units). Nodes in no tetrahedron get the values' minimum less their span
/// (outside every TF's domain) and g = 0. Deterministic for any thread count.
pub fn resample(points: &[[f64; 3]], tets: &[[u32; 4]], values: [&[f32]; 2], grid: &Geometry) -> [Vec<f32>; 2] {
    let [nx, ny, nz] = grid.dims;
    let voxel: Vec<[f64; 3]> =
        points.iter().map(|p| [0, 1, 2].map(|a| (p[a] - grid.origin[a]) / grid.spacing[a])).collect();
    // the z-nodes a tetrahedron can hold, ceil(min z) ..= floor(max z) within the grid (empty when hi < lo)
    let z_nodes = |t: u32| {
        let z = tets[t as usize].map(|i| voxel[i as usize][2]);
        let lo = z.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = z.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        ((lo - 1e-9).ceil().max(0.0) as i64, (hi + 1e-9).floor().min(nz as f64 - 1.0) as i64)
    };
    let mut order: Vec<u32> = (0..tets.len() as u32).filter(|&t| z_nodes(t).1 >= z_nodes(t).0).collect();
    order.par_sort_by_key(|&t| z_nodes(t).0);
    let span = order.par_iter().map(|&t| z_nodes(t).1 - z_nodes(t).0).max().unwrap_or(0);
    let fill = |v: &[f32]| {
        let (lo, hi) = v
            .iter()
            .filter(|x| x.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        if lo.is_finite() { lo - (hi - lo).max(1.0) } else { 0.0 }
    };
    let plane = nx * ny;
    let mut out = [vec![fill(values[0]); plane * nz], vec![0f32; plane * nz]];
    let [s_out, g_out] = &mut out;
    s_out.par_chunks_mut(plane * SLAB).zip(g_out.par_chunks_mut(plane * SLAB)).enumerate().for_each(
        |(slab, (s_slab, g_slab))| {
            let (k_lo, k_hi) = ((slab * SLAB) as i64, (slab * SLAB + SLAB).min(nz) as i64);
            let first = order.partition_point(|&t| z_nodes(t).0 + span < k_lo);
            let last = order.partition_point(|&t| z_nodes(t).0 < k_hi);
            for &t in &order[first..last] {
                let (k0, k1) = z_nodes(t);
                let (k0, k1) = (k0.max(k_lo), k1.min(k_hi - 1));
                let tet = &tets[t as usize];
                let Some(bary) = Barycentric::of(tet.map(|i| voxel[i as usize])) else { continue };
                let (lo, hi) = bary.bounds();
                let nodes = |a: usize, n: usize| {
                    let (first, last) = ((lo[a] - 1e-9).ceil().max(0.0), (hi[a] + 1e-9).floor().min(n as f64 - 1.0));
                    (first as usize)..(last + 1.0).max(first) as usize
                };
                for k in k0..=k1 {
                    for j in nodes(1, ny) {
                        for i in nodes(0, nx) {
                            if let Some(w) = bary.weights([i as f64, j as f64, k as f64]) {
                                let at = (k - k_lo) as usize * plane + j * nx + i;
                                let mix = |v: &[f32]| (0..4).map(|c| w[c] * v[tet[c] as usize] as f64).sum::<f64>();
                                s_slab[at] = mix(values[0]) as f32;
                                g_slab[at] = mix(values[1]) as f32;
                            }
                        }
                    }
                }
            }
        },
    );
    out
}

/// A tetrahedron's barycentric coordinates: its first vertex and the
/// inverse of the matrix of its edges from there.
struct Barycentric {
    corners: [[f64; 3]; 4],
    inverse: [[f64; 3]; 3],
}

impl Barycentric {
    /// None for a degenerate (flat) tetrahedron.
    fn of(corners: [[f64; 3]; 4]) -> Option<Barycentric> {
        let e = [1, 2, 3].map(|c| [0, 1, 2].map(|a| corners[c][a] - corners[0][a]));
        // columns e0, e1, e2: M = [e0 e1 e2], inverse by cofactors
        let m = |r: usize, c: usize| e[c][r];
        let det = m(0, 0) * (m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1)) - m(0, 1) * (m(1, 0) * m(2, 2) - m(1, 2) * m(2, 0))
            + m(0, 2) * (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0));
        let scale = e.iter().map(|v| v.iter().map(|x| x * x).sum::<f64>()).fold(0.0, f64::max).powf(1.5);
        if !det.is_finite() || det.abs() <= 1e-12 * scale {
            return None;
        }
        let cof = |r: usize, c: usize| {
            let (r0, r1) = ((r + 1) % 3, (r + 2) % 3);
            let (c0, c1) = ((c + 1) % 3, (c + 2) % 3);
            m(r0, c0) * m(r1, c1) - m(r0, c1) * m(r1, c0)
        };
        let inverse = [0, 1, 2].map(|r| [0, 1, 2].map(|c| cof(c, r) / det));
        Some(Barycentric { corners, inverse })
    }

    /// The bounding box of the corners.
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let lo = [0, 1, 2].map(|a| self.corners.iter().map(|c| c[a]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1, 2].map(|a| self.corners.iter().map(|c| c[a]).fold(f64::NEG_INFINITY, f64::max));
        (lo, hi)
    }

    /// The four weights of `p`, when it lies inside (or on the surface).
    fn weights(&self, p: [f64; 3]) -> Option<[f64; 4]> {
        let d = [0, 1, 2].map(|a| p[a] - self.corners[0][a]);
        let l = [0, 1, 2].map(|r| (0..3).map(|c| self.inverse[r][c] * d[c]).sum::<f64>());
        let w = [1.0 - l[0] - l[1] - l[2], l[0], l[1], l[2]];
        w.iter().all(|&x| x >= -INSIDE_TOLERANCE).then_some(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear field on a meshed cube is reproduced exactly at every node, and
    /// nodes outside the mesh get the fill value.
    #[test]
    fn a_linear_field_on_a_kuhn_cube_resamples_exactly() {
        // one unit cube cut into 6 tetrahedra around its main diagonal
        let corner = |c: u32| [(c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64];
        let points: Vec<[f64; 3]> = (0..8).map(corner).collect();
        let tets = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]];
        let f = |p: [f64; 3]| 2.0 * p[0] - 3.0 * p[1] + 0.5 * p[2] + 1.0;
        let s: Vec<f32> = points.iter().map(|&p| f(p) as f32).collect();
        let g: Vec<f32> = vec![3.64; 8];
        // a grid of 0.25 spacing that reaches 0.25 beyond the cube along x
        let grid = Geometry::new([6, 5, 5], [0.25; 3]);
        let [rs, rg] = resample(&points, &tets, [&s, &g], &grid);
        for k in 0..5 {
            for j in 0..5 {
                for i in 0..6 {
                    let at = (k * 5 + j) * 6 + i;
                    let p = [i as f64 * 0.25, j as f64 * 0.25, k as f64 * 0.25];
                    if i == 5 {
                        // s runs from -2 at (0, 1, 0) to 3.5 at (1, 0, 1): the fill is -2 - 5.5
                        assert_eq!((rs[at], rg[at]), (-7.5, 0.0), "node {p:?} is outside");
                    } else {
                        assert!((rs[at] as f64 - f(p)).abs() < 1e-5, "node {p:?}: {} vs {}", rs[at], f(p));
                        assert!((rg[at] - 3.64).abs() < 1e-5);
                    }
                }
            }
        }
    }

    #[test]
    fn the_grid_covers_the_points_with_cubic_cells_up_to_the_cap() {
        let points = [[0.0, 0.0, 0.0], [10.0, 5.0, 2.0]];
        let g = mesh_grid(&points, 11).unwrap();
        // 2 points: about 3 nodes per side
        assert_eq!(g.spacing, [5.0; 3]);
        assert_eq!(g.dims, [3, 2, 2]);
        let many: Vec<[f64; 3]> = (0..1000).map(|i| [i as f64 / 999.0 * 10.0, 0.0, 0.0]).collect();
        let g = mesh_grid(&many, 6).unwrap();
        assert_eq!((g.dims, g.spacing), ([6, 2, 2], [2.0; 3]));
    }

    #[test]
    fn flat_tetrahedra_are_skipped() {
        assert!(Barycentric::of([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]).is_none());
    }
}

#[cfg(test)]
mod grid_mesh_tests {
    use super::*;

    /// Every node of the box of a meshed grid lies in some tetrahedron, whatever the resampling grid.
    #[test]
    fn no_node_of_a_meshed_grid_is_missed() {
        let n = 9usize;
        let idx = |i: usize, j: usize, k: usize| (i + n * (j + n * k)) as u32;
        let mut points = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    points.push([i as f64 * 0.7 - 3.0, j as f64 * 0.7 + 1.0, k as f64 * 0.7]);
                }
            }
        }
        let kuhn = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]];
        let mut tets = Vec::new();
        for k in 0..n - 1 {
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let c = |c: usize| idx(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                    tets.extend(kuhn.iter().map(|t: &[usize; 4]| t.map(c)));
                }
            }
        }
        let s: Vec<f32> = points.iter().map(|p| (p[0] + 2.0 * p[1] - p[2]) as f32).collect();
        for cap in [5, 9, 10, 13, 40] {
            let grid = mesh_grid(&points, cap).unwrap();
            let [rs, _] = resample(&points, &tets, [&s, &s], &grid);
            let s_min = s.iter().cloned().fold(f32::INFINITY, f32::min);
            let missed = rs.iter().filter(|&&x| x < s_min - 1e-3).count();
            assert_eq!(missed, 0, "cap {cap}: grid {:?}", grid.dims);
        }
    }
}
