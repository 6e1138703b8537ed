//! A volume meshed within a tetrahedra budget: every voxel is a mesh point
//! and every cell 5 or 6 tetrahedra, so a CT of 256 x 256 x 108 makes 42
//! million tetrahedra (gigabytes of mesh for a renderer that sorts them per
//! frame). Above the budget the volume is first averaged over blocks of
//! k x k x k voxels (the smallest k that meets it), as a coarser scan of
//! the same object would sample it: box filtering keeps the mean value of
//! each block, so materials keep their values and boundaries blur by the
//! block size.

use crate::from_volume::TetScheme;
use mdtf_volume::{Geometry, Volume};
use rayon::prelude::*;

/// Default most tetrahedra a volume is meshed into (about 1.2 GB of mesh files).
pub const DEFAULT_MAX_TETRAHEDRA: u64 = 16_000_000;

/// Tetrahedra a grid of `dims` samples gives when each cell is cut by `scheme`.
pub fn tetrahedra_of(dims: [usize; 3], scheme: TetScheme) -> u64 {
    let per_cell = match scheme {
        TetScheme::Five => 5,
        TetScheme::Six => 6,
    };
    dims.iter().map(|&n| n.saturating_sub(1) as u64).product::<u64>() * per_cell
}

/// The block size k (1: none) whose averaging brings `dims` within
/// `max_tetrahedra` (0: no limit), and the coarse grid's dims; k stops
/// where an axis would keep fewer than 2 samples.
pub fn coarsening(dims: [usize; 3], scheme: TetScheme, max_tetrahedra: u64) -> (usize, [usize; 3]) {
    let coarse = |k: usize| dims.map(|n| n.div_ceil(k));
    let mut k = 1;
    while max_tetrahedra > 0
        && tetrahedra_of(coarse(k), scheme) > max_tetrahedra
        && coarse(k + 1).iter().all(|&n| n >= 2)
    {
        k += 1;
    }
    (k, coarse(k))
}

/// `volume` averaged over blocks of `k` x `k` x `k` voxels (the last block
/// of an axis holds what is left), on the grid of the blocks' centres (its
/// axes as the input's, spacing k times, origin at the first block's
/// centre). `k` = 1 gives a copy.
pub fn block_average(volume: &Volume, k: usize) -> Result<Volume, crate::TetraError> {
    let g = &volume.geometry;
    let k = k.max(1);
    let dims = g.dims.map(|n| n.div_ceil(k));
    let [nx, ny, nz] = g.dims;
    let mut data = vec![0f32; dims.iter().product()];
    let samples = volume.samples();
    data.par_iter_mut().enumerate().for_each(|(c, out)| {
        let (bi, bj, bk) = (c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1]));
        let (mut sum, mut n) = (0f64, 0u32);
        for z in bk * k..((bk + 1) * k).min(nz) {
            for y in bj * k..((bj + 1) * k).min(ny) {
                let row = (z * ny + y) * nx;
                for x in bi * k..((bi + 1) * k).min(nx) {
                    sum += samples[row + x] as f64;
                    n += 1;
                }
            }
        }
        *out = (sum / n as f64) as f32;
    });
    // the first block's centre, along the input's own axes
    let shift = (k as f64 - 1.0) / 2.0;
    let mut origin = g.origin;
    for (a, dir) in g.directions.iter().enumerate() {
        let step = shift.min((g.dims[a] as f64 - 1.0) / 2.0) * g.spacing[a];
        origin.iter_mut().zip(dir).for_each(|(o, d)| *o += step * d);
    }
    let geometry = Geometry { dims, spacing: g.spacing.map(|s| s * k as f64), origin, directions: g.directions };
    Volume::from_samples(geometry, data).map_err(|e| crate::TetraError::Invalid(e.to_string()))
}

/// How a volume was coarsened to be meshed within the budget.
#[derive(Debug, Clone, PartialEq)]
pub struct Coarsened {
    /// Voxels per block edge.
    pub block: usize,
    /// The input's dims.
    pub from: [usize; 3],
    /// The mesh grid's dims.
    pub to: [usize; 3],
    /// Tetrahedra the input's own grid would have made.
    pub full_tetrahedra: u64,
    /// Tetrahedra of the mesh.
    pub tetrahedra: u64,
    /// The budget met.
    pub max_tetrahedra: u64,
}

impl Coarsened {
    /// One sentence for stderr and the run report.
    pub fn note(&self) -> String {
        let [a, b, c] = self.from;
        let [x, y, z] = self.to;
        let k = self.block;
        format!(
            "the {a} x {b} x {c} grid would make {} tetrahedra, over the budget of {}: meshed the volume \
             averaged over {k} x {k} x {k} blocks ({x} x {y} x {z} points, {} tetrahedra)",
            self.full_tetrahedra, self.max_tetrahedra, self.tetrahedra
        )
    }
}

/// `volume` meshed by `scheme` within `max_tetrahedra` (0: no limit): as
/// it is when it fits, else averaged over the blocks [`coarsening`] picks
/// (and how, to say so). The mesh's grid is the second value.
pub fn tetrahedralise_within(
    volume: &Volume,
    scheme: TetScheme,
    max_tetrahedra: u64,
    scalar_name: &str,
) -> Result<(crate::TetMesh, Geometry, Option<Coarsened>), crate::TetraError> {
    let (block, to) = coarsening(volume.geometry.dims, scheme, max_tetrahedra);
    if block == 1 {
        let mesh = crate::tetrahedralise(volume, scheme, scalar_name)?;
        return Ok((mesh, volume.geometry.clone(), None));
    }
    let coarse = block_average(volume, block)?;
    let mesh = crate::tetrahedralise(&coarse, scheme, scalar_name)?;
    let how = Coarsened {
        block,
        from: volume.geometry.dims,
        to,
        full_tetrahedra: tetrahedra_of(volume.geometry.dims, scheme),
        tetrahedra: tetrahedra_of(to, scheme),
        max_tetrahedra,
    };
    Ok((mesh, coarse.geometry, Some(how)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_block_size_is_the_least_that_meets_the_budget() {
        // 256 x 256 x 108 at 6 per cell: 42.5 million; halving each axis: 5.3 million
        let dims = [256, 256, 108];
        assert_eq!(tetrahedra_of(dims, TetScheme::Six), 255 * 255 * 107 * 6);
        assert_eq!(coarsening(dims, TetScheme::Six, DEFAULT_MAX_TETRAHEDRA), (2, [128, 128, 54]));
        assert_eq!(coarsening(dims, TetScheme::Six, 0), (1, dims));
        assert_eq!(coarsening([48; 3], TetScheme::Six, DEFAULT_MAX_TETRAHEDRA), (1, [48; 3]));
        // never below 2 samples on an axis
        assert_eq!(coarsening([4, 4, 3], TetScheme::Six, 1).1[2], 2);
    }

    #[test]
    fn blocks_average_their_voxels_and_sit_at_their_centres() {
        // v = x + 10 y + 100 z on 5 x 4 x 3, spacing (1, 2, 3), origin (10, 20, 30)
        let g = Geometry::new([5, 4, 3], [1.0, 2.0, 3.0]).with_origin([10.0, 20.0, 30.0]);
        let data: Vec<f32> = (0..60).map(|i| ((i % 5) + 10 * ((i / 5) % 4) + 100 * (i / 20)) as f32).collect();
        let v = Volume::from_samples(g, data).unwrap();
        let c = block_average(&v, 2).unwrap();
        assert_eq!(c.geometry.dims, [3, 2, 2]);
        assert_eq!(c.geometry.spacing, [2.0, 4.0, 6.0]);
        assert_eq!(c.geometry.origin, [10.5, 21.0, 31.5]);
        // block (0, 0, 0): x 0..2, y 0..2, z 0..2 -> mean 0.5 + 5 + 50; block (2, 1, 1): x 4, y 2..4, z 2
        assert_eq!(c.samples()[0], 55.5);
        assert_eq!(c.samples()[11], 4.0 + 25.0 + 200.0);
    }
}
