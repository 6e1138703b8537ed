//! Conforming tetrahedral meshes of regular volumes: every grid cell is cut
//! into 5 or 6 tetrahedra whose faces match across neighbouring cells.

use crate::mesh::TetMesh;
use mdtf_volume::Volume;
use serde::{Deserialize, Serialize};

/// How each grid cell is cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TetScheme {
    /// Five tetrahedra (four corners and a central one), the orientation
    /// alternating with the parity of i + j + k so that face diagonals match.
    #[serde(rename = "5")]
    Five,
    /// Six tetrahedra around the cell's main diagonal (Kuhn/Freudenthal):
    /// the same cut in every cell, conforming, and centrally symmetric
    /// around every vertex.
    #[serde(rename = "6")]
    Six,
}

impl std::str::FromStr for TetScheme {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "5" => Ok(TetScheme::Five),
            "6" => Ok(TetScheme::Six),
            _ => Err(format!("'{s}': tetrahedra per cell must be 5 or 6")),
        }
    }
}

/// Corner c of a cell is at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).
const KUHN: [[usize; 4]; 6] = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]];
const FIVE_EVEN: [[usize; 4]; 5] = [[1, 2, 4, 7], [0, 1, 2, 4], [3, 1, 2, 7], [5, 1, 4, 7], [6, 2, 4, 7]];
const FIVE_ODD: [[usize; 4]; 5] = [[0, 3, 5, 6], [1, 0, 3, 5], [2, 0, 3, 6], [4, 0, 5, 6], [7, 3, 5, 6]];

/// Meshes `volume`: one point per voxel at its world position (directions
/// and origin applied), the voxel value as the scalar `scalar_name`.
/// Volumes with fewer than 2 samples along an axis have no cells and are refused.
pub fn tetrahedralise(volume: &Volume, scheme: TetScheme, scalar_name: &str) -> Result<TetMesh, crate::TetraError> {
    let g = &volume.geometry;
    let [nx, ny, nz] = g.dims;
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(crate::TetraError::Invalid(format!(
            "a {nx} x {ny} x {nz} volume has no cells to cut into tetrahedra (need at least 2 samples per axis)"
        )));
    }
    let per_cell = match scheme {
        TetScheme::Five => 5,
        TetScheme::Six => 6,
    };
    let cells = (nx - 1) as u128 * (ny - 1) as u128 * (nz - 1) as u128;
    let points = (nx * ny * nz) as u128;
    if points > u32::MAX as u128 {
        return Err(crate::TetraError::Invalid(format!("{nx} x {ny} x {nz} = {points} points: more than 2^32 - 1")));
    }
    // what the stage holds at its peak: connectivity and vertex stars (16 + 16 bytes a
    // tetrahedron), cell boxes (24) and one array being written (16); per point the
    // position, scalar, gradient, g and star offset (52)
    let needed = cells * per_cell * 72 + points * 52;
    let available = mdtf_volume::available_memory() as u128;
    if needed > available {
        return Err(crate::TetraError::Invalid(format!(
            "meshing {nx} x {ny} x {nz} voxels gives {} tetrahedra needing about {} of memory, more than the {} \
             available; resample the volume first (or set tetra.tets to 5)",
            cells * per_cell,
            mdtf_volume::human_bytes(needed),
            mdtf_volume::human_bytes(available)
        )));
    }
    let m = g.world_from_voxel();
    let mut points = Vec::with_capacity(nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let v = [i as f64, j as f64, k as f64];
                points.push([0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2] + m[r][3]));
            }
        }
    }
    let mut tets = Vec::with_capacity(cells as usize * per_cell as usize);
    let index = |i: usize, j: usize, k: usize| (i + nx * (j + ny * k)) as u32;
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let corner = |c: usize| index(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                let cut: &[[usize; 4]] = match scheme {
                    TetScheme::Six => &KUHN,
                    TetScheme::Five if (i + j + k) % 2 == 0 => &FIVE_EVEN,
                    TetScheme::Five => &FIVE_ODD,
                };
                tets.extend(cut.iter().map(|t| t.map(corner)));
            }
        }
    }
    Ok(TetMesh { points, tets, scalar_name: scalar_name.into(), scalar: volume.samples().to_vec(), arrays: Vec::new() })
}
