//! Preview of an mdtf pack: decode it from its manifest alone and ray-cast
//! it the way its renderer family would (3D or 2D TF LUT for slicer-3dtf,
//! alpha_u(v, g_hit) x alpha_d(d) for distance-tf, Gaussian primitives with
//! a Riemann sum or the analytic segment integral for gaussian-tf and for a
//! projected-tetrahedra mesh resampled onto a grid; a product TF's factor
//! tables, whatever the profile), with Blinn-Phong shading from the normals
//! where the profile packs them, else from the value's gradient. A check
//! that the pack is complete, and a picture to look at before loading it
//! into the real renderer.

mod empty_space;
mod load;
mod mesh;
mod render;
mod samples;
mod tables;

use load::pack_geometry;
pub use load::{LoadedPack, Table, decode_channels, load, load_channels};
pub use mesh::{MESH_GRID_MAX, mesh_channels, resample};
pub use render::{Camera, Classifier, channels_read, render, render_samples, render_without_skipping};
pub use samples::{PackTextures, Samples};

use mdtf_volume::VolumeError;
use std::path::Path;

/// Errors of the preview.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    /// The pack is incomplete or inconsistent.
    #[error("{0}")]
    Pack(String),
    /// The camera is out of range (see [`Camera::check`]).
    #[error("{0}")]
    BadView(String),
    /// The profile has no preview yet.
    #[error("no preview for profile {0} yet")]
    Unsupported(String),
    /// Writing the image failed.
    #[error(transparent)]
    Io(#[from] VolumeError),
}

/// The classifier a pack's profile implies, from its lookup tables (and for
/// gaussian-tf its primitives). `analytic` selects the between-sample mode:
/// the analytic segment integral for gaussian-tf, peak finding for
/// peak-finding; otherwise both classify at the samples.
pub fn classifier(pack: &LoadedPack, analytic: bool) -> Result<Classifier, PreviewError> {
    let table = |n: &str| pack.tables.get(n).cloned();
    // a product TF (product_0, product_1, ...) classifies whatever the profile
    let factors: Vec<Table> = (0..).map_while(|k| table(&format!("product_{k}"))).collect();
    if !factors.is_empty() {
        return Ok(Classifier::Product {
            factors,
            cells_per_sample: 2.0,
            find_peaks: analytic && pack.manifest.profile == "peak-finding",
        });
    }
    match pack.manifest.profile.as_str() {
        "slicer-3dtf" => table("tf3d")
            .or_else(|| table("tf2d_default"))
            .or_else(|| table("tf2d"))
            .map(Classifier::Lut)
            .ok_or_else(|| PreviewError::Pack("slicer-3dtf pack without tf3d, tf2d or tf2d_default".into())),
        "distance-tf" => Ok(Classifier::Distance {
            alpha_u: table("alpha_u"),
            alpha_d: table("alpha_d").ok_or_else(|| PreviewError::Pack("distance-tf pack without alpha_d".into()))?,
        }),
        "gaussian-tf" | "projected-tetrahedra" => {
            let primitives = pack.gaussians.clone().filter(|g| !g.is_empty()).ok_or_else(|| {
                PreviewError::Pack(format!(
                    "{} pack without gaussians.json (mdtf run writes it)",
                    pack.manifest.profile
                ))
            })?;
            let m = primitives.iter().map(|p| p.fields()).max().unwrap_or(0);
            // the TF axes are the packed fields in texture order; the gradient
            // channel (g for scalar data, gnorm otherwise) follows them for
            // triangular GTFs. A mesh's TF is over its scalar s (read as v) and g.
            let is_gradient = |c: &str| c == "gnorm" || c == "g";
            let mut fields: Vec<String> = Vec::new();
            let mut gradient = None;
            if pack.manifest.mesh.is_some() {
                fields.push("v".into());
                gradient = Some("g".to_string());
            }
            for t in &pack.manifest.textures {
                for c in t.component_order.iter().flatten() {
                    if is_gradient(c) {
                        gradient = Some(c.clone());
                    } else if !fields.contains(c) {
                        fields.push(c.clone());
                    }
                }
            }
            let triangular = primitives.iter().any(|p| p.triangular);
            // plain primitives over (fields, gradient), such as a 2D GTF over (v, g)
            if !triangular
                && fields.len() + 1 == m
                && let Some(g) = &gradient
            {
                fields.push(g.clone());
            }
            if fields.len() < m {
                return Err(PreviewError::Pack(format!(
                    "the primitives have {m} dimensions, the pack {} fields",
                    fields.len()
                )));
            }
            fields.truncate(m);
            let mut sqrt_last = false;
            if triangular {
                if primitives.iter().any(|p| p.fields() != m) {
                    return Err(PreviewError::Pack("triangular GTFs need every primitive over the same fields".into()));
                }
                let g = gradient.ok_or_else(|| {
                    PreviewError::Pack("a triangular GTF needs the pack's gradient channel (g or gnorm)".into())
                })?;
                sqrt_last = g == "gnorm";
                fields.push(g);
            }
            Ok(Classifier::Gaussian { primitives, channels: fields, analytic, sqrt_last })
        }
        // a 2D TF over (v, 1/g): multidimensional peak finding along chords in TF space
        "peak-finding" if pack.tables.contains_key("tf2d") => Ok(Classifier::Chord {
            tf: table("tf2d").ok_or_else(|| PreviewError::Pack("tf2d vanished".into()))?,
            cells_per_sample: 2.0,
            find_peaks: analytic,
        }),
        "peak-finding" => Ok(Classifier::Peak {
            peak_table: table("peak_table").ok_or_else(|| {
                PreviewError::Pack("peak-finding pack without peak_table (pack it with a TF that has tf1d)".into())
            })?,
            preintegration: table("preintegration")
                .ok_or_else(|| PreviewError::Pack("peak-finding pack without preintegration".into()))?,
            find_peaks: analytic,
        }),
        other => Err(PreviewError::Unsupported(other.into())),
    }
}

/// Writes RGB8 pixels as a PNG. Atomic.
pub fn write_png(path: &Path, size: usize, rgb: &[u8], description: &str) -> Result<(), PreviewError> {
    mdtf_volume::write_png(path, size, size, mdtf_volume::PngColour::Rgb, rgb, description)?;
    Ok(())
}

/// Loads the pack in `dir`, renders it and writes `out` (Gaussian TFs integrated analytically when `analytic`).
pub fn preview(dir: &Path, out: &Path, cam: &Camera, analytic: bool) -> Result<(), PreviewError> {
    preview_named(dir, out, cam, analytic, dir)
}

/// [`preview`], naming the pack `shown_as` in the PNG's description (a pack
/// rendered in a staging folder is described by its final path).
pub fn preview_named(
    dir: &Path,
    out: &Path,
    cam: &Camera,
    analytic: bool,
    shown_as: &Path,
) -> Result<(), PreviewError> {
    cam.check().map_err(PreviewError::BadView)?;
    mdtf_volume::Inputs::of(&[dir]).refuse_target(out)?;
    // the classifier comes from the tables; then only the channels it and the shading read are decoded
    let pack = load_channels(dir, &|_| false)?;
    let c = classifier(&pack, analytic)?;
    let read = channels_read(&c);
    let img = if pack.manifest.mesh.is_some() {
        render(&mesh_channels(dir, &pack.manifest, MESH_GRID_MAX)?, &c, cam)
    } else {
        // the textures read in place: the same pixels as decoding them, at a fraction of the memory
        let g = pack_geometry(&pack.manifest)?;
        let textures = PackTextures::read(dir, &pack.manifest, g.voxel_count(), &|n| read.iter().any(|r| r == n))?;
        render_samples(&textures.samples(), &g, &c, cam)
    };
    let text = format!(
        "mdtf preview of {} ({}), azimuth {} elevation {}, step {} voxel",
        shown_as.display(),
        pack.manifest.profile,
        cam.azimuth,
        cam.elevation,
        cam.step
    );
    write_png(out, cam.size, &img, &text)
}

/// One image of a contact sheet, as 8-bit RGB.
fn decode_png(path: &Path) -> Result<(usize, usize, Vec<u8>), PreviewError> {
    let bad = |e: String| PreviewError::Pack(format!("{}: {e}", path.display()));
    let file = std::fs::File::open(path).map_err(|e| bad(e.to_string()))?;
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().map_err(|e| bad(e.to_string()))?;
    let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| bad("image too large".into()))?];
    let info = reader.next_frame(&mut buf).map_err(|e| bad(e.to_string()))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let channels = info.color_type.samples();
    if info.bit_depth != png::BitDepth::Eight {
        return Err(bad("only 8-bit images go on a contact sheet".into()));
    }
    let mut rgb = Vec::with_capacity(w * h * 3);
    for px in buf[..w * h * channels].chunks_exact(channels) {
        match channels {
            1 | 2 => rgb.extend([px[0]; 3]),
            _ => rgb.extend(&px[..3]),
        }
    }
    Ok((w, h, rgb))
}

/// Height of the caption strip under each picture of a contact sheet, pixels.
pub const CAPTION_HEIGHT: usize = 26;

/// Tiles PNG images left to right in rows of `columns`, each scaled to fit a
/// `cell` x (`cell` - [`CAPTION_HEIGHT`]) box (nearest neighbour) above its
/// caption, on a dark grey background. The captions (e.g. what the picture
/// is and its file in the output folder) also make up the PNG's description.
pub fn contact_sheet(images: &[(&Path, &str)], columns: usize, cell: usize, out: &Path) -> Result<(), PreviewError> {
    let columns = columns.max(1);
    let rows = images.len().div_ceil(columns).max(1);
    let (w, h) = (columns * cell, rows * cell);
    let picture = cell.saturating_sub(CAPTION_HEIGHT).max(1);
    let mut sheet = vec![40u8; w * h * 3];
    for (n, (path, _)) in images.iter().enumerate() {
        let (iw, ih, rgb) = decode_png(path)?;
        let scale = (picture as f64 / iw.max(ih) as f64).min(4.0);
        let (ox, oy) = ((n % columns) * cell, (n / columns) * cell);
        for y in 0..picture {
            for x in 0..cell {
                let (sx, sy) = ((x as f64 / scale) as usize, (y as f64 / scale) as usize);
                if sx < iw && sy < ih {
                    let src = (sy * iw + sx) * 3;
                    let dst = ((oy + y) * w + ox + x) * 3;
                    sheet[dst..dst + 3].copy_from_slice(&rgb[src..src + 3]);
                }
            }
        }
    }
    draw_captions(&mut sheet, (w, h), images, columns, cell)?;
    let captions: Vec<&str> = images.iter().map(|(_, c)| *c).collect();
    let text = format!("mdtf contact sheet: {}", captions.join("; "));
    mdtf_volume::write_png(out, w, h, mdtf_volume::PngColour::Rgb, &sheet, &text)?;
    Ok(())
}

/// Writes each image's caption in the strip under it (DejaVu Sans, bundled).
fn draw_captions(
    sheet: &mut [u8],
    (w, h): (usize, usize),
    images: &[(&Path, &str)],
    columns: usize,
    cell: usize,
) -> Result<(), PreviewError> {
    use plotters::prelude::*;
    mdtf_volume::register_figure_font();
    let fail = |e: &dyn std::fmt::Debug| PreviewError::Pack(format!("drawing the contact sheet's captions: {e:?}"));
    let root = BitMapBackend::with_buffer(sheet, (w as u32, h as u32)).into_drawing_area();
    let style = ("sans-serif", 14).into_font().color(&RGBColor(230, 230, 230));
    for (n, (_, caption)) in images.iter().enumerate() {
        let (ox, oy) = ((n % columns) * cell, (n / columns) * cell);
        let at = ((ox + 6) as i32, (oy + cell - CAPTION_HEIGHT + 5) as i32);
        root.draw(&Text::new(caption.to_string(), at, style.clone())).map_err(|e| fail(&e))?;
    }
    root.present().map_err(|e| fail(&e))
}
