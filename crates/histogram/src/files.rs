//! Writing histograms and the histogram volume as files: PNG pictures,
//! NRRD counts and tables, EXR counts, JSON and CSV sidecars.

use crate::axis::Axis;
use crate::count::Histogram;
use crate::figure::{ArchMark, Labels, Overlay};
use crate::hvol::HistogramVolume;
use crate::image::{Scale, side_by_side, write_exr, write_png};
use mdtf_volume::nrrd::{TableAxis, write_counts_nrrd, write_table_nrrd};
use mdtf_volume::{VolumeError, write_file_atomically};
use std::path::Path;

fn table_axes(axes: &[Axis]) -> Vec<TableAxis> {
    axes.iter().map(|a| TableAxis { label: a.name.clone(), size: a.bins, min: a.min, max: a.max }).collect()
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), VolumeError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| VolumeError::Fields(e.to_string()))?;
    write_file_atomically(path, |w| w.write_all(text.as_bytes()))
}

/// Writes `hist_<axes>.{nrrd,json}` and, for 1D/2D, the figure `.png` (axes
/// in data units, a colour bar; titled `title`, e.g. the input's name) and
/// for 2D the exact counts as `.exr`; for 3D the colour-volume picture
/// `_rgb.png` of the three primary-plane projections, into `dir`.
pub fn write_histogram(dir: &Path, h: &Histogram, scale: Scale, title: &str) -> Result<(), VolumeError> {
    write_histogram_marked(dir, h, scale, title, None, &[])
}

/// [`write_histogram`] with a note below the 2D or 1D figure (e.g. how an
/// axis was clipped) and boundaries drawn on a (v, g) figure.
pub fn write_histogram_marked(
    dir: &Path,
    h: &Histogram,
    scale: Scale,
    title: &str,
    note: Option<&str>,
    arches: &[ArchMark],
) -> Result<(), VolumeError> {
    let stem: Vec<&str> = h.axes.iter().map(|a| a.name.as_str()).collect();
    let stem = format!("hist_{}", stem.join("_"));
    write_counts_nrrd(&dir.join(format!("{stem}.nrrd")), &table_axes(&h.axes), &h.counts)?;
    write_json(
        &dir.join(format!("{stem}.json")),
        &serde_json::json!({ "axes": h.axes, "total": h.total(), "max": h.max(), "scale": format!("{scale:?}"),
            "png": "first axis to the right, second axis upward" }),
    )?;
    if h.axes.len() <= 2 {
        let mut labels = Labels::of(h, &format!("{stem} of {title}"));
        labels.note = note.map(String::from);
        labels.arches = arches.to_vec();
        let figure = h.figure(scale, &labels).map_err(VolumeError::Fields)?;
        if let Some(f) = figure {
            let text = format!("{}; axes: {}; {}", labels.title, labels.axes.join(" | "), h.describe(scale));
            crate::rgb::write_rgb_png(&dir.join(format!("{stem}.png")), &f, &text)?;
        }
    }
    if h.axes.len() == 2 {
        write_exr(&dir.join(format!("{stem}.exr")), h)?;
    }
    if let Some(rgb) = h
        .projections_figure(scale, &format!("{stem} of {title}: primary-plane projections"))
        .map_err(VolumeError::Fields)?
    {
        let text = format!(
            "primary-plane projections ({0}, {1}) | ({0}, {2}) | ({1}, {2}); {0} red, {1} green, {2} blue; {3}",
            h.axes[0].name,
            h.axes[1].name,
            h.axes[2].name,
            h.describe(scale)
        );
        crate::rgb::write_rgb_png(&dir.join(format!("{stem}_rgb.png")), &rgb, &text)?;
    }
    Ok(())
}

/// Writes the stretched histogram's files and `normal_vs_stretched.png` (the distance paper's Fig. 5),
/// with the detected boundaries `arches` drawn as arches on the normal (v, g) panel and as the
/// lines they collapse to (g_hit = their peak g) on the stretched one and its own figure.
pub fn write_stretched(
    dir: &Path,
    normal: &Histogram,
    stretched: &Histogram,
    scale: Scale,
    title: &str,
    arches: &[ArchMark],
) -> Result<(), VolumeError> {
    let collapsed: Vec<ArchMark> = arches.iter().map(ArchMark::collapsed).collect();
    write_histogram_marked(dir, stretched, scale, title, None, &collapsed)?;
    // short panel titles (two long ones would run into each other); the input is named below
    let mut left = Labels::of(normal, "normal (v, g) of the traced voxels");
    left.arches = arches.to_vec();
    left.note = Some(format!("input: {title}"));
    let mut right = Labels::of(stretched, "stretched (v, g_hit)");
    right.arches = collapsed;
    let text = format!("left: normal (v, g) of traced voxels; right: stretched (v, g_hit); {}", normal.describe(scale));
    match normal.figure_beside(stretched, scale, [&left, &right]).map_err(VolumeError::Fields)? {
        Some(both) => crate::rgb::write_rgb_png(&dir.join("normal_vs_stretched.png"), &both, &text),
        None => write_png(
            &dir.join("normal_vs_stretched.png"),
            &side_by_side(&normal.image(scale), &stretched.image(scale)),
            &text,
        ),
    }
}

/// Writes a figure of the 2D histogram `h` with the RGBA table `overlay`
/// over its counts (see [`Overlay`]) as the PNG `path`.
pub fn write_overlay_figure(
    path: &Path,
    h: &Histogram,
    scale: Scale,
    labels: &Labels,
    overlay: &Overlay,
) -> Result<(), VolumeError> {
    let figure = h.figure_with(scale, labels, Some(overlay)).map_err(VolumeError::Fields)?;
    let Some(f) = figure else { return Err(VolumeError::Fields("an overlay needs a 2D histogram".into())) };
    let text = format!(
        "{}; axes: {}; {}; table drawn over the counts",
        labels.title,
        labels.axes.join(" | "),
        h.describe(scale)
    );
    crate::rgb::write_rgb_png(path, &f, &text)
}

/// Colour of the default opacity drawn over the histogram volume's counts in `opacity.png`.
const OPACITY_COLOUR: [f32; 3] = [1.0, 0.85, 0.3];

/// Writes `hvol.nrrd`, `position.nrrd`, `opacity.{nrrd,png}`, `hvol_per_v.csv` and `hvol.json`
/// (with the materials and boundaries [`crate::detect`] finds). `opacity.png`
/// draws the opacity over the (v, g) counts, with `arches` (e.g. the
/// boundaries found, in their colours) and the tent's width stated; `title` names the input.
pub fn write_hvol(dir: &Path, hv: &HistogramVolume, title: &str, arches: &[ArchMark]) -> Result<(), VolumeError> {
    write_counts_nrrd(&dir.join("hvol.nrrd"), &table_axes(&hv.hist.axes), &hv.hist.counts)?;
    let vg = table_axes(&hv.vg_axes);
    write_table_nrrd(&dir.join("position.nrrd"), &vg, &hv.position)?;
    write_table_nrrd(&dir.join("opacity.nrrd"), &vg, &hv.opacity)?;
    let counts = Histogram { axes: hv.vg_axes.to_vec(), counts: hv.count_vg.clone() };
    let rgba: Vec<f32> =
        hv.opacity.iter().flat_map(|&a| [OPACITY_COLOUR[0], OPACITY_COLOUR[1], OPACITY_COLOUR[2], a]).collect();
    let [av, ag] = &hv.vg_axes;
    let overlay = Overlay { x: (av.min, av.max, av.bins), y: (ag.min, ag.max, ag.bins), rgba: &rgba };
    let mut labels = Labels::of(&counts, &format!("default opacity over the (v, g) histogram of {title}"));
    labels.note = Some(format!(
        "opacity = tent of the position p(v, g), half-width {:.3} (sigma {:.3} world units); drawn at the square root of opacity",
        hv.tent_width, hv.sigma
    ));
    labels.arches = arches.to_vec();
    write_overlay_figure(&dir.join("opacity.png"), &counts, Scale::Log, &labels, &overlay)?;
    let mut csv = String::from("v,voxels,mean_g,mean_f2\n");
    for b in 0..hv.count_v.len() {
        csv += &format!("{},{},{},{}\n", hv.vg_axes[0].centre(b), hv.count_v[b], hv.mean_g_v[b], hv.mean_h_v[b]);
    }
    write_file_atomically(&dir.join("hvol_per_v.csv"), |w| w.write_all(csv.as_bytes()))?;
    let detection = crate::boundaries::detect(hv);
    write_json(
        &dir.join("hvol.json"),
        &serde_json::json!({
            "sigma": hv.sigma, "g_thresh": hv.g_thresh, "tent_width": hv.tent_width,
            "axes": hv.hist.axes, "sigma_formula": "2 max g(v) / (sqrt(e) (max h(v) - min h(v)))",
            "materials": detection.materials, "boundaries": detection.boundaries,
        }),
    )
}
