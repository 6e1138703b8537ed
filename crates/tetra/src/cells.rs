//! Per-cell quantities for the renderer: (s, g) boxes for conservative
//! culling, the longest edge (the D range of the tables) and the smallest
//! value difference between vertices (the banded-TF frequency bound).

use crate::mesh::{TetMesh, max_edge};
use mdtf_pack::TfFile;
use rayon::prelude::*;

/// What the renderer needs to know about one tetrahedron.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellInfo {
    /// [min, max] of s over the four vertices.
    pub s_range: [f32; 2],
    /// [min, max] of g over the four vertices.
    pub g_range: [f32; 2],
    /// Longest edge, world units.
    pub max_edge: f32,
    /// Smallest |s_i - s_j| over the six edges (the paper's bound on banded-TF frequency).
    pub s_min_diff: f32,
}

/// [`CellInfo`] of every tetrahedron, `g` per vertex.
pub fn cell_infos(mesh: &TetMesh, g: &[f32]) -> Vec<CellInfo> {
    mesh.tets
        .par_iter()
        .map(|t| {
            let s = t.map(|i| mesh.scalar[i as usize]);
            let gv = t.map(|i| g[i as usize]);
            let range = |x: [f32; 4]| {
                [x.iter().copied().fold(f32::INFINITY, f32::min), x.iter().copied().fold(f32::NEG_INFINITY, f32::max)]
            };
            let mut diff = f32::INFINITY;
            for a in 0..4 {
                for b in a + 1..4 {
                    diff = diff.min((s[a] - s[b]).abs());
                }
            }
            CellInfo {
                s_range: range(s),
                g_range: range(gv),
                max_edge: max_edge(&mesh.points, t) as f32,
                s_min_diff: diff,
            }
        })
        .collect()
}

/// Cells whose (s, g) box meets the widget box `s_range` x `g_range`: the
/// conservative culling of section 3.1. Since s and g are linear inside a
/// cell, every value a cell takes lies in its box, so a cell with any vertex
/// (or any interior point) inside the widget is kept.
pub fn cull(cells: &[CellInfo], s_range: [f32; 2], g_range: [f32; 2]) -> Vec<u32> {
    cells
        .iter()
        .enumerate()
        .filter(|(_, c)| {
            c.s_range[0] <= s_range[1]
                && c.s_range[1] >= s_range[0]
                && c.g_range[0] <= g_range[1]
                && c.g_range[1] >= g_range[0]
        })
        .map(|(i, _)| i as u32)
        .collect()
}

/// The visible-cell mask of section 3.1 for a transfer function: 1 for a
/// cell whose (s, g) box may meet one of `tf`'s widgets
/// ([`TfFile::supports`]; Gaussian widgets reach +-3 sigma), 0 for a cell
/// the renderer can skip.
pub fn visible_cells(cells: &[CellInfo], tf: &TfFile) -> Vec<u8> {
    let supports = tf.supports();
    let range = |r: [f32; 2]| [f64::from(r[0]), f64::from(r[1])];
    cells.par_iter().map(|c| u8::from(supports.iter().any(|s| s.meets(range(c.s_range), range(c.g_range))))).collect()
}
