//! Export of an mdtf pack for the tools users already have: VTK and
//! ParaView (a `.vti` of the decoded channels, the transfer function as a
//! 2D RGBA image, and Python scripts that render with VTK's 2D
//! transfer-function mode) and 3D Slicer (an NRRD of v and a `.vp` volume
//! property with the separable part of the TF).
//!
//! The exporter reads the pack as any renderer would, through its manifest
//! (`mdtf_preview::load`), and moves no algorithm: the channels are the
//! pack's decoded codes, the TF is the pack's table.
//!
//! VTK's 2D mode looks the table up at each array's value normalised by
//! that array's own data range, on X the scalar array and on Y the array
//! named by `SetTransfer2DYAxisArray`; it applies no opacity correction for
//! the sample distance. The table is therefore written in its own units (its
//! `.vti` origin and spacing are the cell centres and widths in channel
//! units), and the scripts resample it onto the arrays' ranges and correct
//! its opacity for their sample distance before handing it to VTK.

mod slicer;
mod tf2d;
mod vti;

pub use slicer::{AMBIENT, DIFFUSE, SPECULAR, SPECULAR_POWER, volume_property};
pub use tf2d::{Marginals, Tf2d, TfAxis, marginals, pack_tf2d};
pub use vti::{PointArray, write_vti};

use mdtf_pack::ManifestGeometry;
use mdtf_preview::{LoadedPack, PreviewError};
use mdtf_volume::{Geometry, Inputs, OutputFolder, Volume, VolumeError, WriteOptions};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema identifier of `export.json`.
pub const EXPORT_SCHEMA: &str = "mdtf-export/1";

/// A tool to export for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Target {
    /// `volume.vti`, `tf2d.vti` and `render_vtk.py` for the `vtk` Python package.
    Vtk,
    /// `volume.vti`, `tf2d.vti` and `open_in_paraview.py` for pvpython, pvbatch or ParaView's Python shell.
    Paraview,
    /// `v.nrrd` and `volume_property.vp` for 3D Slicer.
    Slicer,
}

/// Errors of the export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The pack could not be read.
    #[error("{0}")]
    Pack(#[from] PreviewError),
    /// Writing failed, or the output folder may not be written.
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// Writing a file of the export failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// The pack has nothing these targets can show.
    #[error("{0}")]
    Unsupported(String),
}

/// An exported array, as `export.json` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportedArray {
    /// Point-array name in `volume.vti`.
    pub name: String,
    /// Values per point.
    pub components: usize,
    /// The pack channels it holds, in component order.
    pub channels: Vec<String>,
    /// Units, from the manifest.
    pub units: String,
    /// What it measures, from the manifest.
    pub meaning: String,
}

/// The exported transfer function, as `export.json` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportedTf {
    /// The `.vti` of the table: 4-component float RGBA, x fastest, origin and
    /// spacing the cell centres and widths in channel units.
    pub file: String,
    /// The pack table it comes from.
    pub source: String,
    /// Channel of the X axis (VTK's scalar array).
    pub x: String,
    /// Channel of the Y axis (VTK's `SetTransfer2DYAxisArray`).
    pub y: String,
    /// [min, max] covered by the X cells, channel units.
    pub x_range: [f64; 2],
    /// [min, max] covered by the Y cells, channel units.
    pub y_range: [f64; 2],
    /// Cells along X and Y.
    pub cells: [usize; 2],
    /// The path length the opacities are per (L_min, world units).
    pub opacity_unit: f64,
    /// What the table leaves out of the pack's classification, if anything.
    pub approximation: Option<String>,
}

/// The Slicer files, as `export.json` lists them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportedSlicer {
    /// NRRD of v.
    pub volume: String,
    /// Volume property, when the TF is over (v, g).
    pub property: Option<String>,
}

/// `export.json`: what the export holds, read by its scripts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportManifest {
    /// Always [`EXPORT_SCHEMA`].
    pub schema: String,
    /// The pack's profile.
    pub profile: String,
    /// The pack's grid.
    pub geometry: ManifestGeometry,
    /// `volume.vti`, when VTK or ParaView was a target.
    pub volume: Option<String>,
    /// Its point arrays.
    pub arrays: Vec<ExportedArray>,
    /// The transfer function, when the pack has a 2D (or 3D) table.
    pub tf: Option<ExportedTf>,
    /// Whether the pack has normals (the scripts shade then).
    pub shade: bool,
    /// Ambient, diffuse, specular and specular power of the shading.
    pub lighting: [f64; 4],
    /// The Slicer files, when Slicer was a target.
    pub slicer: Option<ExportedSlicer>,
    /// What was not exported, and why.
    pub notes: Vec<String>,
}

/// Name of the exported files.
const VOLUME_VTI: &str = "volume.vti";
const TF_VTI: &str = "tf2d.vti";
const SLICER_NRRD: &str = "v.nrrd";
const SLICER_VP: &str = "volume_property.vp";
const MANIFEST: &str = "export.json";

/// The scripts, shipped beside the data.
const HELPER_PY: (&str, &str) = ("mdtf_vtk_tf.py", include_str!("../scripts/mdtf_vtk_tf.py"));
const RENDER_VTK_PY: (&str, &str) = ("render_vtk.py", include_str!("../scripts/render_vtk.py"));
const PARAVIEW_PY: (&str, &str) = ("open_in_paraview.py", include_str!("../scripts/open_in_paraview.py"));

/// The normal components, exported as one 3-component array.
const NORMAL: [&str; 3] = ["nx", "ny", "nz"];

/// Exports the pack in `pack_dir` for `targets` into the folder `out`
/// (built beside it and published in one step; never over the pack).
pub fn export(pack_dir: &Path, out: &Path, targets: &[Target]) -> Result<ExportManifest, ExportError> {
    let inputs = Inputs::of(&[pack_dir]);
    let folder = OutputFolder::begin(out, &inputs)?;
    let pack = mdtf_preview::load(pack_dir)?;
    if pack.manifest.mesh.is_some() {
        return Err(ExportError::Unsupported(format!(
            "{} is a projected-tetrahedra pack: its mesh.vtu (with s, g and the gradient) opens in ParaView as it is",
            pack_dir.display()
        )));
    }
    let manifest = write_export(&pack, folder.path(), targets)?;
    folder.publish(&inputs)?;
    Ok(manifest)
}

/// Writes the export of `pack` into the folder `dir`.
fn write_export(pack: &LoadedPack, dir: &Path, targets: &[Target]) -> Result<ExportManifest, ExportError> {
    let geometry = pack
        .channels
        .values()
        .next()
        .map(|v| v.geometry.clone())
        .ok_or_else(|| ExportError::Unsupported("the pack has no channel to export".into()))?;
    let vtk_like = targets.iter().any(|t| matches!(t, Target::Vtk | Target::Paraview));
    let shade = NORMAL.iter().all(|n| pack.channels.contains_key(*n));
    let tf = pack_tf2d(pack);
    let mut notes = Vec::new();
    match &tf {
        Some(t) => notes.extend(t.approximation.clone()),
        None => notes.push(format!(
            "the {} pack has no 2D or 3D transfer-function table: only the data is exported",
            pack.manifest.profile
        )),
    }
    let mut manifest = ExportManifest {
        schema: EXPORT_SCHEMA.into(),
        profile: pack.manifest.profile.clone(),
        geometry: pack.manifest.geometry.clone(),
        volume: None,
        arrays: Vec::new(),
        tf: None,
        shade,
        lighting: [AMBIENT, DIFFUSE, SPECULAR, SPECULAR_POWER],
        slicer: None,
        notes: Vec::new(),
    };
    if vtk_like {
        let (arrays, listed) = point_arrays(pack, shade);
        let active = tf.as_ref().map(|t| t.x.channel.clone()).or_else(|| listed.first().map(|a| a.name.clone()));
        write_file(dir, VOLUME_VTI, |w| write_vti(w, &geometry, &arrays, active.as_deref()))?;
        manifest.volume = Some(VOLUME_VTI.into());
        manifest.arrays = listed;
        if let Some(t) = &tf {
            write_file(dir, TF_VTI, |w| write_vti(w, &tf_image_geometry(t), &[tf_array(t)], Some("rgba")))?;
            manifest.tf = Some(ExportedTf {
                file: TF_VTI.into(),
                source: t.source.clone(),
                x: t.x.channel.clone(),
                y: t.y.channel.clone(),
                x_range: [t.x.min, t.x.max],
                y_range: [t.y.min, t.y.max],
                cells: [t.x.cells, t.y.cells],
                opacity_unit: geometry.min_spacing(),
                approximation: t.approximation.clone(),
            });
            let scripts =
                [(None, HELPER_PY), (Some(Target::Vtk), RENDER_VTK_PY), (Some(Target::Paraview), PARAVIEW_PY)];
            for (for_target, (name, text)) in scripts {
                if for_target.is_none_or(|t| targets.contains(&t)) {
                    write_file(dir, name, |w| w.write_all(text.as_bytes()))?;
                }
            }
        }
    }
    if targets.contains(&Target::Slicer) {
        manifest.slicer = Some(write_slicer(pack, dir, tf.as_ref(), shade, &mut notes)?);
    }
    manifest.notes = notes;
    let json = serde_json::to_string_pretty(&manifest)
        .map_err(|e| ExportError::Unsupported(format!("export.json could not be written: {e}")))?;
    write_file(dir, MANIFEST, |w| w.write_all(json.as_bytes()))?;
    let readme = readme(&manifest, targets);
    write_file(dir, "README.md", |w| w.write_all(readme.as_bytes()))?;
    Ok(manifest)
}

/// Writes `dir/name` with `fill`.
fn write_file(
    dir: &Path,
    name: &str,
    fill: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<(), ExportError> {
    let path = dir.join(name);
    let written = std::fs::File::create(&path).and_then(|file| {
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w).and_then(|()| std::io::Write::flush(&mut w))
    });
    written.map_err(|source| ExportError::Io { path, source })
}

/// The pack's channels as point arrays, the normal components as one
/// 3-component "normal" when the pack `has_normals` (all three); and their
/// descriptions from the manifest.
fn point_arrays(pack: &LoadedPack, has_normals: bool) -> (Vec<PointArray<'_>>, Vec<ExportedArray>) {
    let entry = |name: &str| pack.manifest.channels.iter().find(|c| c.name == name);
    let describe = |name: &str, channels: Vec<String>, components: usize| ExportedArray {
        name: name.into(),
        components,
        units: entry(&channels[0]).map(|c| c.units.clone()).unwrap_or_default(),
        meaning: entry(&channels[0]).map(|c| c.meaning.clone()).unwrap_or_default(),
        channels,
    };
    let mut arrays = Vec::new();
    let mut listed = Vec::new();
    for (name, volume) in &pack.channels {
        if has_normals && NORMAL.contains(&name.as_str()) {
            continue;
        }
        arrays.push(PointArray { name: name.clone(), components: 1, values: volume.samples().into() });
        listed.push(describe(name, vec![name.clone()], 1));
    }
    let normals: Option<Vec<&Volume>> = NORMAL.iter().map(|n| pack.channels.get(*n)).collect();
    if let Some(n) = normals {
        let (x, y, z) = (n[0].samples(), n[1].samples(), n[2].samples());
        let values: Vec<f32> = x.iter().zip(y).zip(z).flat_map(|((a, b), c)| [*a, *b, *c]).collect();
        arrays.push(PointArray { name: "normal".into(), components: 3, values: values.into() });
        let mut d = describe("normal", NORMAL.iter().map(|s| s.to_string()).collect(), 3);
        d.meaning = "unit normal (nx, ny, nz)".into();
        listed.push(d);
    }
    (arrays, listed)
}

/// The table's grid: one point per cell at its centre, in channel units.
fn tf_image_geometry(t: &Tf2d) -> Geometry {
    Geometry::new([t.x.cells, t.y.cells, 1], [t.x.cell_width(), t.y.cell_width(), 1.0]).with_origin([
        t.x.centre(0),
        t.y.centre(0),
        0.0,
    ])
}

fn tf_array(t: &Tf2d) -> PointArray<'static> {
    PointArray {
        name: "rgba".into(),
        components: 4,
        values: t.rgba.iter().flatten().copied().collect::<Vec<f32>>().into(),
    }
}

/// Writes v as NRRD and, for a TF over (v, g), the `.vp` of its marginals.
fn write_slicer(
    pack: &LoadedPack,
    dir: &Path,
    tf: Option<&Tf2d>,
    shade: bool,
    notes: &mut Vec<String>,
) -> Result<ExportedSlicer, ExportError> {
    // v, or for a multi-field pack its first field
    let fields = pack.manifest.textures.iter().flat_map(|t| t.component_order.iter().flatten());
    let (name, v) = std::iter::once("v")
        .chain(fields.map(String::as_str).filter(|c| *c != "gnorm"))
        .find_map(|c| pack.channels.get(c).map(|v| (c, v)))
        .ok_or_else(|| {
            ExportError::Unsupported("the pack has no channel v (nor a field) for Slicer to render".into())
        })?;
    if name != "v" {
        notes.push(format!("{SLICER_NRRD} holds the field {name}, the pack's first (it has no v)"));
    }
    mdtf_volume::write_volume(&dir.join(SLICER_NRRD), v, &WriteOptions { gzip: true, ..WriteOptions::default() }, &[])?;
    let property = match tf {
        Some(t) if t.x.channel == "v" && t.y.channel == "g" => {
            let text = volume_property(t, &marginals(t), shade);
            write_file(dir, SLICER_VP, |w| w.write_all(text.as_bytes()))?;
            notes.push(
                "volume_property.vp is the separable approximation of the 2D TF: scalar opacity max over g, \
                 gradient opacity max over v (normalised), colour the opacity-weighted mean over g; Slicer measures \
                 the gradient magnitude itself"
                    .into(),
            );
            Some(SLICER_VP.to_string())
        }
        Some(t) => {
            notes.push(format!(
                "no volume_property.vp: the TF is over ({}, {}), and Slicer's separable functions are over v and its \
                 gradient magnitude",
                t.x.channel, t.y.channel
            ));
            None
        }
        None => None,
    };
    Ok(ExportedSlicer { volume: SLICER_NRRD.into(), property })
}

/// The folder's README: what each file is and how to open it.
fn readme(m: &ExportManifest, targets: &[Target]) -> String {
    let mut s = format!(
        "# mdtf export ({} pack)\n\nMade by `mdtf export`; `export.json` lists every file, array and range.\n\n",
        m.profile
    );
    if let Some(v) = &m.volume {
        s += &format!(
            "## VTK and ParaView\n\n`{v}` is VTK XML image data with the decoded channels as point arrays in their units \
             (origin, spacing and direction as the pack's grid): {}.\n\n",
            m.arrays.iter().map(|a| format!("`{}`", a.name)).collect::<Vec<_>>().join(", ")
        );
    }
    if let Some(tf) = &m.tf {
        s += &format!(
            "`{}` is the transfer function (from the pack's `{}`) as a {} x {} RGBA image over ({}, {}): X from {} to {}, \
             Y from {} to {}; opacity per {} world units of path.\n\n",
            tf.file,
            tf.source,
            tf.cells[0],
            tf.cells[1],
            tf.x,
            tf.y,
            tf.x_range[0],
            tf.x_range[1],
            tf.y_range[0],
            tf.y_range[1],
            tf.opacity_unit
        );
        if targets.contains(&Target::Vtk) {
            s += "Render with the `vtk` Python package (9.3 or later; offscreen on a machine without a display: \
                  `VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow` or `vtkOSOpenGLRenderWindow`):\n\n    \
                  python render_vtk.py -o render.png --view 30,20 --size 512\n    \
                  python render_vtk.py --window\n\nThe view is `mdtf preview`'s: the same azimuth and elevation about the \
                  volume's z axis, orthographic, framing the whole grid, rendered in the grid's own frame (VTK's ray caster \
                  misshades images with rotated axes).\n\n";
        }
        if targets.contains(&Target::Paraview) {
            s += "Open in ParaView (5.11 or later): `pvpython open_in_paraview.py` (or `pvbatch open_in_paraview.py \
                  --screenshot shot.png`), or in the GUI run it from View > Python Shell > Run Script. It loads the `.vti` \
                  in its grid's own frame (`--world` places it by the grid's origin and axes, which ParaView 5.11 \
                  misplaces and misshades for rotated axes), selects the 2D transfer-function mode with the Y axis \
                  array set, and installs the table.\n\n";
        }
        s += "VTK's 2D mode normalises each array by its own data range and does not correct opacity for the sample \
              distance; `mdtf_vtk_tf.py` resamples the table onto the arrays' ranges and corrects its opacity, so that \
              what VTK shows is what the pack's renderer shows.\n\n";
    }
    if let Some(sl) = &m.slicer {
        s += &format!(
            "## 3D Slicer\n\nLoad `{}` (Add Data), then in Volume Rendering load the volume property",
            sl.volume
        );
        s += &match &sl.property {
            Some(p) => format!(
                " `{p}` (the `.vp` file through Add Data, then select it as the preset's property). It holds the \
                 separable approximation of the 2D TF: scalar opacity over v, gradient opacity over g, colour over v.\n\n"
            ),
            None => ": this pack's TF has no separable form for Slicer, so none was written.\n\n".into(),
        };
    }
    if !m.notes.is_empty() {
        s += "## Notes\n\n";
        for n in &m.notes {
            s += &format!("- {n}\n");
        }
    }
    s
}
