//! `mdtf export`: a pack for VTK/ParaView and 3D Slicer.

use crate::progress::Progress;
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use mdtf_pipeline::stages::export::{Target, export};
use std::path::PathBuf;

/// `mdtf export`.
#[derive(Debug, Args)]
#[command(after_help = "Reads the pack through its manifest, as a renderer would, and writes into DIR:\n\
  vtk, paraview: volume.vti (VTK XML image data, zlib-compressed: every decoded channel as a\n\
    point array in its units, the normal as one 3-component array; origin, spacing and\n\
    direction of the pack's grid), tf2d.vti (the transfer function as an RGBA image over its\n\
    two channels, in their units), mdtf_vtk_tf.py, and render_vtk.py (vtk) or\n\
    open_in_paraview.py (pvpython, pvbatch, ParaView's Python shell);\n\
  slicer: v.nrrd and volume_property.vp (the separable part of a (v, g) TF: scalar opacity,\n\
    gradient opacity, colour);\n\
  export.json (what was written, with the TF's axes and ranges) and README.md (how to open each).\n\n\
The TF is the pack's 2D table: slicer-3dtf's tf2d (its f'' emphasis left out) or the histogram\n\
volume's tf2d_default, distance-tf's alpha_u over (v, g_hit) (alpha_d left out) or alpha_d\n\
alone, peak-finding's tf2d over (v, inv_g); a 3D table alone is reduced by its most opaque f''\n\
cell. What is left out is printed and kept in export.json. VTK's 2D mode reads the table at\n\
each array's value normalised by that array's data range, with no opacity correction; the\n\
scripts resample the table onto the arrays' ranges and correct the opacity for their step, so\n\
VTK shows what mdtf preview shows. Both render in the grid's own frame (VTK's ray caster\n\
misshades images with rotated axes); open_in_paraview.py --world places the volume in the world.\n\n\
Examples:\n  mdtf export out/pack -o out/vtk\n  mdtf export out/pack --to slicer -o out/slicer\n  \
cd out/vtk && VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow python render_vtk.py -o render.png\n  \
cd out/vtk && xvfb-run -a pvbatch open_in_paraview.py --screenshot shot.png")]
pub struct ExportArgs {
    /// Pack folder (with manifest.json).
    pub pack: PathBuf,
    /// Output folder (new, or one mdtf made).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Tools to export for, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "vtk,paraview,slicer")]
    pub to: Vec<TargetArg>,
}

/// `--to` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TargetArg {
    /// volume.vti, tf2d.vti and render_vtk.py.
    Vtk,
    /// volume.vti, tf2d.vti and open_in_paraview.py.
    Paraview,
    /// v.nrrd and volume_property.vp.
    Slicer,
}

/// Exports the pack.
pub fn run(args: &ExportArgs, progress: &Progress) -> Result<()> {
    let targets: Vec<Target> = args
        .to
        .iter()
        .map(|t| match t {
            TargetArg::Vtk => Target::Vtk,
            TargetArg::Paraview => Target::Paraview,
            TargetArg::Slicer => Target::Slicer,
        })
        .collect();
    let manifest = progress
        .step("exporting", || export(&args.pack, &args.output, &targets))
        .with_context(|| format!("exporting {}", args.pack.display()))?;
    for note in &manifest.notes {
        progress.note(&format!("note: {note}"));
    }
    progress.note(&format!("wrote {} (see its README.md)", args.output.display()));
    Ok(())
}
