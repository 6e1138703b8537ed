//! `mdtf tetra`: tetrahedral meshes to projected-tetrahedra packs.

use crate::args::TetraArgs;
use crate::input::{parse_size, read_input, read_options, read_tf};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_pipeline::stages::pack::{Provenance, TetTable, sha256_file};
use mdtf_pipeline::stages::tetra::{
    MeshReport, TetMesh, TetraOutput, TetraParams, read_mesh, tetrahedralise_within, write_pack,
};
use mdtf_volume::{Geometry, Inputs, OutputFolder};
use std::path::{Path, PathBuf};

/// Reads or meshes the input, computes everything, writes the pack folder atomically.
pub fn run(args: &TetraArgs, progress: &Progress) -> Result<()> {
    let params = params(args)?;
    let tf = read_tf(args.tf.as_deref())?;
    let inputs = Inputs::of(
        &[args.input.as_deref(), args.from_volume.as_deref(), args.tf.as_deref()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>(),
    );
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    let Meshed { mesh, report, grid, source } = mesh_of(args, &params, progress)?;
    let summary = report.summary();
    if !summary.is_empty() {
        progress.note(&format!("{}: {summary}", source.display()));
    }
    let out = progress.step("gradients, cells and tables", || {
        mdtf_pipeline::stages::tetra::run_with_progress(&mesh, &params, tf.as_ref(), &|step| progress.message(step))
    })?;
    let provenance = Provenance {
        mdtf_version: env!("CARGO_PKG_VERSION").into(),
        input: Some(source.display().to_string()),
        input_sha256: sha256_file(&source).ok(),
        stages: serde_json::json!({ "tetra": params }),
        ..Default::default()
    };
    progress.step("writing the pack", || write_pack(folder.path(), &mesh, &report, &out, grid.as_ref(), provenance))?;
    // the (s, g) TF a renderer and `mdtf preview` start from
    let spacing = grid.as_ref().map_or_else(|| typical_edge(&mesh), Geometry::min_spacing);
    let gaussians = mdtf_pipeline::gaussians::mesh_gaussians(tf.as_ref(), &mesh.scalar, &out.g, spacing);
    mdtf_pipeline::gaussians::write(folder.path(), &gaussians)?;
    folder.publish(&inputs)?;
    for n in &out.notes {
        progress.note(&format!("note: {n}"));
    }
    progress.note(&closing_note(&mesh, &out, &args.output));
    Ok(())
}

/// The edge of a cube cut into 6 tetrahedra of the mesh's mean volume:
/// the mesh's typical edge length, world units (1 for an empty mesh).
fn typical_edge(mesh: &TetMesh) -> f64 {
    let corner = |i: u32| mesh.points[i as usize];
    let total: f64 = mesh
        .tets
        .iter()
        .map(|t| mdtf_pipeline::stages::tetra::six_volume(corner(t[0]), corner(t[1]), corner(t[2]), corner(t[3])).abs())
        .sum();
    if mesh.tets.is_empty() || total <= 0.0 { 1.0 } else { (total / mesh.tets.len() as f64).cbrt() }
}

/// The meshing and tables' parameters the flags give.
fn params(args: &TetraArgs) -> Result<TetraParams> {
    let mut params = TetraParams {
        scalar: args.scalar.clone(),
        tets: args.tets.parse().map_err(|e: String| anyhow::anyhow!("--tets: {e}"))?,
        gradient: args.gradient.parse().map_err(|e: String| anyhow::anyhow!("--gradient: {e}"))?,
        max_tetrahedra: args.max_tetrahedra,
        ..Default::default()
    };
    params.tables.tables = args
        .tables
        .iter()
        .map(|t| t.trim().parse::<TetTable>())
        .collect::<Result<_, _>>()
        .map_err(anyhow::Error::msg)?;
    params.tables.fb_size = parse_size(&args.fb_size, "--fb-size")?;
    params.tables.preint_size = parse_size(&args.preint_size, "--preint-size")?;
    params.tables.tau_max = args.tau_max;
    params.tables.d_max = args.d_max;
    Ok(params)
}

/// A mesh, read or made from a volume.
struct Meshed {
    mesh: TetMesh,
    /// What reading the mesh repaired or dropped (empty for a meshed volume).
    report: MeshReport,
    /// The volume's grid, when the mesh was made from one.
    grid: Option<Geometry>,
    /// The file it came from.
    source: PathBuf,
}

/// The mesh file's mesh, or the `--from-volume` volume meshed.
fn mesh_of(args: &TetraArgs, params: &TetraParams, progress: &Progress) -> Result<Meshed> {
    match (&args.input, &args.from_volume) {
        (Some(path), _) => {
            let (mesh, report) = progress.step("reading the mesh", || read_mesh(path, args.scalar.as_deref()))?;
            Ok(Meshed { mesh, report, grid: None, source: path.clone() })
        }
        (None, Some(path)) => {
            let (mf, _) = read_input(path, &args.read, &read_options(&args.read))?;
            let volume = mf.into_scalar().context("--from-volume takes a one-field volume")?;
            let name = args.scalar.clone().unwrap_or_else(|| "v".into());
            let (mesh, grid, coarsened) = progress
                .step("meshing", || tetrahedralise_within(&volume, params.tets, params.max_tetrahedra, &name))?;
            if let Some(c) = coarsened {
                progress.note(&format!("note: {} (--max-tetrahedra 0 meshes every voxel)", c.note()));
            }
            Ok(Meshed { mesh, report: MeshReport::default(), grid: Some(grid), source: path.clone() })
        }
        (None, None) => anyhow::bail!("give a mesh (.vtu/.vtk) or --from-volume VOLUME"),
    }
}

/// The mesh, its gradients and the tables made, for the closing note.
fn closing_note(mesh: &TetMesh, out: &TetraOutput, output: &Path) -> String {
    let g_max = out.g.iter().copied().fold(0.0f32, f32::max);
    let visible = out.visible.as_ref().map_or(String::new(), |mask| {
        let shown = mask.iter().filter(|&&m| m == 1).count();
        format!("; {shown} cells ({:.1} %) visible under the TF", 100.0 * shown as f64 / mask.len().max(1) as f64)
    });
    format!(
        "{} points, {} tetrahedra (longest edge {:.4}), g up to {g_max:.4}; tables: {}{visible}; pack in {}",
        mesh.points.len(),
        mesh.tets.len(),
        out.max_edge_length,
        out.luts.iter().map(|l| l.name.as_str()).collect::<Vec<_>>().join(", "),
        output.display()
    )
}
