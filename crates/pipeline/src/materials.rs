//! Where the materials of a multi-field volume lie: how many voxels and
//! faces each has, which one is the background, and how deep each lies
//! below the outside, the facts the default Gaussian TF's opacities read
//! (see [`crate::gaussians::material_gaussians`]).

use mdtf_histogram::{CLUSTER_MASK, NO_CLUSTER};
use rayon::prelude::*;

/// Least share of a material's faces it must share with another region to
/// count as lying against it (a few voxels that noise put in the wrong
/// cluster do not make two materials neighbours).
pub const TOUCH_SHARE: f64 = 0.05;

/// The materials' shapes on the grid.
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialShapes {
    /// Voxels of each material.
    pub voxels: Vec<u64>,
    /// Faces of each material's voxels that border another region or the
    /// volume's edge (its surface, in voxel faces).
    pub faces: Vec<u64>,
    /// The material holding more than half of the voxels on the volume's
    /// six faces (the air around a head), if one does.
    pub background: Option<usize>,
    /// Each material's layer below the outside (the background and the
    /// volume's edge): 1 when it lies against the outside, k + 1 when it
    /// lies against a material of layer k, None when it is not reached so
    /// (and for the background itself).
    pub depth: Vec<Option<usize>>,
}

impl MaterialShapes {
    /// The shapes of the `count` materials of `labels` (as
    /// [`mdtf_histogram::JointClusters::labels`] gives them) on a grid of
    /// `dims` (x fastest).
    pub fn of(labels: &[u8], dims: [usize; 3], count: usize) -> MaterialShapes {
        let [nx, ny, nz] = dims;
        // regions: the materials, then the voxels of no cluster, then the volume's edge
        let (unlabelled, edge) = (count, count + 1);
        let regions = count + 2;
        let region = |l: u8| if l == NO_CLUSTER { unlabelled } else { (l & CLUSTER_MASK) as usize };
        // per z-plane: voxels and border voxels of each material, and the faces between regions
        let planes: Vec<(Vec<u64>, Vec<u64>, Vec<u64>)> = (0..nz)
            .into_par_iter()
            .map(|z| {
                let (mut voxels, mut border, mut touch) =
                    (vec![0u64; count], vec![0u64; count], vec![0u64; regions * regions]);
                for y in 0..ny {
                    for x in 0..nx {
                        let i = x + nx * (y + ny * z);
                        let k = region(labels[i]);
                        if k >= count {
                            continue;
                        }
                        voxels[k] += 1;
                        let neighbours = [
                            (x > 0).then(|| i - 1),
                            (x + 1 < nx).then(|| i + 1),
                            (y > 0).then(|| i - nx),
                            (y + 1 < ny).then(|| i + nx),
                            (z > 0).then(|| i - nx * ny),
                            (z + 1 < nz).then(|| i + nx * ny),
                        ];
                        let edges = neighbours.iter().filter(|j| j.is_none()).count() as u64;
                        border[k] += u64::from(edges > 0);
                        touch[k * regions + edge] += edges;
                        for j in neighbours.iter().flatten() {
                            let r = region(labels[*j]);
                            if r != k {
                                touch[k * regions + r] += 1;
                            }
                        }
                    }
                }
                (voxels, border, touch)
            })
            .collect();
        let (mut voxels, mut border, mut touch) = (vec![0u64; count], vec![0u64; count], vec![0u64; regions * regions]);
        for (v, b, t) in planes {
            voxels.iter_mut().zip(v).for_each(|(a, x)| *a += x);
            border.iter_mut().zip(b).for_each(|(a, x)| *a += x);
            touch.iter_mut().zip(t).for_each(|(a, x)| *a += x);
        }
        let faces: Vec<u64> = (0..count).map(|k| touch[k * regions..(k + 1) * regions].iter().sum()).collect();
        let inner = |n: usize| n.saturating_sub(2) as u64;
        let border_voxels = (nx * ny * nz) as u64 - inner(nx) * inner(ny) * inner(nz);
        let background = (0..count).find(|&k| 2 * border[k] > border_voxels);

        // layers, outside in: a material lies against a region when they share TOUCH_SHARE of its faces
        let against = |k: usize, r: usize| touch[k * regions + r] as f64 >= TOUCH_SHARE * faces[k].max(1) as f64;
        let mut depth: Vec<Option<usize>> = vec![None; count];
        let mut layer: Vec<usize> = std::iter::once(edge).chain(background).collect();
        let mut d = 1;
        while !layer.is_empty() {
            let next: Vec<usize> = (0..count)
                .filter(|&k| Some(k) != background && depth[k].is_none() && layer.iter().any(|&r| against(k, r)))
                .collect();
            next.iter().for_each(|&k| depth[k] = Some(d));
            layer = next;
            d += 1;
        }
        MaterialShapes { voxels, faces, background, depth }
    }

    /// Material k's mean chord in voxels: Cauchy's 4 V / S for a body of
    /// volume V and surface S, with S counted in voxel faces, which
    /// overstate a smooth surface by 3/2 on average: 6 V / faces.
    pub fn mean_chord(&self, k: usize) -> f64 {
        6.0 * self.voxels[k] as f64 / self.faces[k].max(1) as f64
    }

    /// Whether material k lies in the deepest layer (or in none the outside reaches).
    pub fn innermost(&self, k: usize) -> bool {
        let deepest = self.depth.iter().enumerate().filter(|(j, _)| Some(*j) != self.background).map(|(_, d)| *d);
        match self.depth[k] {
            None => true,
            Some(d) => deepest.flatten().all(|other| other <= d),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Labels of nested balls of materials 0 (outermost, filling the grid) to
    /// `radii.len() - 1` on an n^3 grid, ball k of radius radii[k] voxels.
    fn nested(n: usize, radii: &[f64]) -> Vec<u8> {
        let c = n as f64 / 2.0;
        let mut labels = vec![0u8; n * n * n];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let r =
                        ((x as f64 + 0.5 - c).powi(2) + (y as f64 + 0.5 - c).powi(2) + (z as f64 + 0.5 - c).powi(2))
                            .sqrt();
                    labels[x + n * (y + n * z)] = radii.iter().rposition(|&rk| r < rk).map_or(0, |k| k as u8);
                }
            }
        }
        labels
    }

    #[test]
    fn nested_balls_are_layers_below_the_background() {
        let n = 40;
        let labels = nested(n, &[f64::INFINITY, 16.0, 12.0, 8.0]);
        let s = MaterialShapes::of(&labels, [n; 3], 4);
        assert_eq!(s.background, Some(0));
        assert_eq!(s.depth, vec![None, Some(1), Some(2), Some(3)]);
        assert!(s.innermost(3) && !s.innermost(2) && !s.innermost(1));
        // a ball of radius 8: V = 2145 voxels (4/3 pi 8^3 = 2145), its mean chord 4/3 r = 10.7
        let chord = s.mean_chord(3);
        assert!((chord - 4.0 / 3.0 * 8.0).abs() < 1.5, "{chord}");
        assert_eq!(s.voxels.iter().sum::<u64>(), (n * n * n) as u64);
        // the outer shell: V = 4/3 pi (16^3 - 12^3), S = 4 pi (16^2 + 12^2): chord 4 V / S = 3.1
        let shell = s.mean_chord(2);
        assert!((shell - 4.0 * (16f64.powi(3) - 12f64.powi(3)) / 3.0 / (16f64.powi(2) + 12f64.powi(2))).abs() < 1.0);
    }

    #[test]
    fn without_a_background_the_volume_edge_is_the_outside() {
        // two halves along x: neither holds more than half of the border voxels
        let n = 10;
        let labels: Vec<u8> = (0..n * n * n).map(|i| u8::from(i % n >= n / 2)).collect();
        let s = MaterialShapes::of(&labels, [n; 3], 2);
        assert_eq!(s.background, None);
        assert_eq!(s.depth, vec![Some(1), Some(1)]);
        assert!(s.innermost(0) && s.innermost(1));
    }
}
