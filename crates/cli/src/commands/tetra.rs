//! `mdtf tetra`: tetrahedral meshes to projected-tetrahedra packs.

use crate::args::TetraArgs;
use crate::input::{parse_size, read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_pipeline::stages::pack::{Provenance, TetTable, parse_tf, sha256_file};
use mdtf_pipeline::stages::tetra::{MeshReport, TetMesh, TetraParams, read_mesh, tetrahedralise, write_pack};
use mdtf_volume::{Inputs, OutputFolder};

/// Reads or meshes the input, computes everything, writes the pack folder atomically.
pub fn run(args: &TetraArgs, progress: &Progress) -> Result<()> {
    let mut params = TetraParams {
        scalar: args.scalar.clone(),
        tets: args.tets.parse().map_err(|e: String| anyhow::anyhow!("--tets: {e}"))?,
        gradient: args.gradient.parse().map_err(|e: String| anyhow::anyhow!("--gradient: {e}"))?,
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
    let tf = match &args.tf {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
            Some(parse_tf(&text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?)
        }
        None => None,
    };

    let inputs = Inputs::of(
        &[args.input.as_deref(), args.from_volume.as_deref(), args.tf.as_deref()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>(),
    );
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    let (mesh, report, grid, source): (TetMesh, MeshReport, _, _) = match (&args.input, &args.from_volume) {
        (Some(path), _) => {
            let (mesh, report) = progress.step("reading the mesh", || read_mesh(path, args.scalar.as_deref()))?;
            (mesh, report, None, path.clone())
        }
        (None, Some(path)) => {
            let (mf, _) = read_input(path, &args.read, &read_options(&args.read))?;
            let volume = mf.into_scalar().context("--from-volume takes a one-field volume")?;
            let name = args.scalar.clone().unwrap_or_else(|| "v".into());
            let mesh = progress.step("meshing", || tetrahedralise(&volume, params.tets, &name))?;
            (mesh, MeshReport::default(), Some(volume.geometry), path.clone())
        }
        (None, None) => anyhow::bail!("give a mesh (.vtu/.vtk) or --from-volume VOLUME"),
    };
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
    };
    progress.step("writing the pack", || write_pack(folder.path(), &mesh, &report, &out, grid.as_ref(), provenance))?;
    folder.publish(&inputs)?;
    for n in &out.notes {
        progress.note(&format!("note: {n}"));
    }
    let g_max = out.g.iter().copied().fold(0.0f32, f32::max);
    let visible = out.visible.as_ref().map_or(String::new(), |mask| {
        let shown = mask.iter().filter(|&&m| m == 1).count();
        format!("; {shown} cells ({:.1} %) visible under the TF", 100.0 * shown as f64 / mask.len().max(1) as f64)
    });
    progress.note(&format!(
        "{} points, {} tetrahedra (longest edge {:.4}), g up to {g_max:.4}; tables: {}{visible}; pack in {}",
        mesh.points.len(),
        mesh.tets.len(),
        out.max_edge_length,
        out.luts.iter().map(|l| l.name.as_str()).collect::<Vec<_>>().join(", "),
        args.output.display()
    ));
    Ok(())
}
