//! The `projected-tetrahedra` pack: the mesh (as `.vtu` and as raw arrays),
//! per-vertex (s, g), per-cell boxes, the visible-cell mask of a TF, and the
//! pre-integration tables, with a
//! manifest of the pack schema.

use crate::mesh::{MeshReport, TetMesh};
use crate::{TetraError, TetraOutput, write_mesh};
use mdtf_pack::{Manifest, ManifestGeometry, MeshArrayEntry, MeshEntry, Profile, Provenance, SCHEMA_ID};
use mdtf_volume::Geometry;
use mdtf_volume::nrrd::{TableAxis, write_table_bytes};
use std::path::Path;

/// One array to write: name, meaning, units, association, components, and its little-endian bytes.
struct ArrayOut<'a> {
    name: &'a str,
    meaning: &'a str,
    units: &'a str,
    association: &'a str,
    components: usize,
    dtype: &'a str,
    /// Makes the bytes when the array is written, so only one array's bytes exist at a time.
    bytes: Box<dyn Fn() -> Vec<u8> + 'a>,
}

fn f32_bytes(values: impl Iterator<Item = f32>) -> Vec<u8> {
    values.flat_map(|v| v.to_le_bytes()).collect()
}

/// Writes the pack into `dir` (which must exist) and returns its manifest.
/// `grid` is the volume the mesh was made from, if any; otherwise the
/// manifest's geometry is the mesh's bounding box as a 2 x 2 x 2 grid.
pub fn write_pack(
    dir: &Path,
    mesh: &TetMesh,
    report: &MeshReport,
    out: &TetraOutput,
    grid: Option<&Geometry>,
    provenance: Provenance,
) -> Result<Manifest, TetraError> {
    let vtu = "mesh.vtu";
    let gradients: Vec<f32> = out.gradients.iter().flatten().copied().collect();
    write_mesh(&dir.join(vtu), mesh, &[], &[("g", 1, &out.g), ("gradient", 3, &gradients)])?;
    drop(gradients);
    let arrays = [
        ArrayOut {
            name: "points",
            meaning: "x, y, z of every point",
            units: "world units",
            association: "point",
            components: 3,
            dtype: "f32",
            bytes: Box::new(|| f32_bytes(mesh.points.iter().flatten().map(|&x| x as f32))),
        },
        ArrayOut {
            name: "s_g",
            meaning: "s (the scalar) and g = |grad s| per point",
            units: "s units; s units per world unit",
            association: "point",
            components: 2,
            dtype: "f32",
            bytes: Box::new(|| f32_bytes(mesh.scalar.iter().zip(&out.g).flat_map(|(&s, &g)| [s, g]))),
        },
        ArrayOut {
            name: "gradient",
            meaning: "grad s per point",
            units: "s units per world unit",
            association: "point",
            components: 3,
            dtype: "f32",
            bytes: Box::new(|| f32_bytes(out.gradients.iter().flatten().copied())),
        },
        ArrayOut {
            name: "tets",
            meaning: "point indices of every tetrahedron",
            units: "index",
            association: "cell",
            components: 4,
            dtype: "u32",
            bytes: Box::new(|| mesh.tets.iter().flatten().flat_map(|i| i.to_le_bytes()).collect()),
        },
        ArrayOut {
            name: "cell_box",
            meaning: "s_min, s_max, g_min, g_max over the cell's vertices (conservative culling box)",
            units: "s units; s units per world unit",
            association: "cell",
            components: 4,
            dtype: "f32",
            bytes: Box::new(|| {
                f32_bytes(out.cells.iter().flat_map(|c| [c.s_range[0], c.s_range[1], c.g_range[0], c.g_range[1]]))
            }),
        },
        ArrayOut {
            name: "cell_edges",
            meaning: "longest edge, and smallest |s_i - s_j| over the edges (banded-TF frequency bound)",
            units: "world units; s units",
            association: "cell",
            components: 2,
            dtype: "f32",
            bytes: Box::new(|| f32_bytes(out.cells.iter().flat_map(|c| [c.max_edge, c.s_min_diff]))),
        },
    ];
    let visible = out.visible.as_ref().map(|mask| ArrayOut {
        name: "cell_visible",
        meaning: "1 where the cell's (s, g) box meets a widget of the TF (Gaussians: +-3 sigma), 0 where the \
                  renderer may skip it (conservative culling, section 3.1)",
        units: "flag",
        association: "cell",
        components: 1,
        dtype: "u8",
        bytes: Box::new(move || mask.clone()),
    });
    let mut entries = Vec::new();
    for a in arrays.into_iter().chain(visible) {
        let bytes = (a.bytes)();
        let width = if a.dtype == "u8" { 1 } else { 4 };
        let count = bytes.len() / (width * a.components);
        let file = format!("{}.nrrd", a.name);
        let axes = [
            TableAxis { label: "component".into(), size: a.components, min: 0.0, max: a.components as f64 },
            TableAxis { label: a.association.into(), size: count, min: 0.0, max: count as f64 },
        ];
        let type_name = match a.dtype {
            "u32" => "uint32",
            "u8" => "uint8",
            _ => "float",
        };
        write_table_bytes(&dir.join(&file), &axes, type_name, &bytes)?;
        drop(bytes);
        entries.push(MeshArrayEntry {
            name: a.name.into(),
            meaning: a.meaning.into(),
            units: a.units.into(),
            association: a.association.into(),
            components: a.components,
            dtype: a.dtype.into(),
            file,
        });
    }
    let geometry = match grid {
        Some(g) => ManifestGeometry {
            dims: g.dims,
            spacing: g.spacing,
            origin: g.origin,
            world_from_voxel: g.world_from_voxel(),
        },
        None => {
            let (lo, hi) = mesh.bounds();
            let spacing = [0, 1, 2].map(|a| (hi[a] - lo[a]).max(f64::MIN_POSITIVE));
            let g = Geometry::new([2, 2, 2], spacing).with_origin(lo);
            ManifestGeometry { dims: g.dims, spacing, origin: lo, world_from_voxel: g.world_from_voxel() }
        }
    };
    let manifest = Manifest {
        schema: SCHEMA_ID.into(),
        profile: Profile::ProjectedTetrahedra.to_string(),
        geometry,
        textures: Vec::new(),
        channels: Vec::new(),
        luts: out.luts.iter().map(|l| l.write(dir)).collect::<Result<_, _>>()?,
        mesh: Some(MeshEntry {
            points: mesh.points.len(),
            tetrahedra: mesh.tets.len(),
            skipped_cells: report.skipped_cells.clone(),
            degenerate_tetrahedra: report.degenerate_tets,
            max_edge_length: out.max_edge_length,
            gradient_method: out.gradient.describe().into(),
            vtu: vtu.into(),
            arrays: entries,
        }),
        provenance,
    };
    let json = serde_json::to_string_pretty(&manifest)
        .map_err(|e| TetraError::Invalid(format!("cannot serialise the manifest: {e}")))?;
    mdtf_volume::write_file_atomically(&dir.join("manifest.json"), |w| w.write_all(json.as_bytes()))?;
    Ok(manifest)
}
