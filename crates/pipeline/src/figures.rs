//! Figures that join two stages' results: the boundaries found in the
//! histogram volume drawn on the (v, g) histograms, and the pack's 2D
//! transfer functions drawn over the histograms of their two channels.

use mdtf_histogram::{ArchMark, DetectedBoundary, Histogram, Labels, Overlay, Scale, write_overlay_figure};
use mdtf_pack::Lut;
use mdtf_volume::VolumeError;
use std::path::Path;

/// The boundaries as arches to draw, numbered from 1 as the report lists
/// them and in the colours the default transfer functions give them.
pub fn boundary_arches(boundaries: &[DetectedBoundary]) -> Vec<ArchMark> {
    boundaries
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let c = mdtf_pack::boundary_colour(k, boundaries.len()).map(|x| (x * 255.0).round() as u8);
            b.arch(&(k + 1).to_string(), c)
        })
        .collect()
}

/// The note under a histogram figure whose second axis `axis` (g, g_hit)
/// was clipped at its top `percent` % (Teem qbert's rule), leaving `outside` voxels out.
pub fn clip_note(axis: &mdtf_histogram::Axis, percent: f64, outside: u64) -> String {
    format!(
        "{} axis up to {:.4}: its top {percent} % clipped (as Teem's qbert does), {outside} voxels above it not drawn",
        axis.name, axis.max
    )
}

/// Writes `tf_<table>.png` into `dir` for every RGBA table of two axes in
/// `luts` that some histogram of `hists` has the same two channels for:
/// the table drawn over that histogram's counts, the `arches` on it when
/// its axes are (v, g). Returns the files written, relative to `dir`.
pub fn write_tf_figures(
    dir: &Path,
    luts: &[Lut],
    hists: &[&Histogram],
    title: &str,
    arches: &[ArchMark],
) -> Result<Vec<String>, VolumeError> {
    let mut written = Vec::new();
    for lut in luts.iter().filter(|l| l.components == 4 && l.axes.len() == 2) {
        let (x, y) = (&lut.axes[0], &lut.axes[1]);
        let Some(h) =
            hists.iter().find(|h| h.axes.len() == 2 && h.axes[0].name == x.channel && h.axes[1].name == y.channel)
        else {
            continue;
        };
        let mut labels =
            Labels::of(h, &format!("{} over the ({}, {}) histogram of {title}", lut.name, x.channel, y.channel));
        labels.note =
            Some("the table's colour mixed in by the square root of its opacity relative to its largest".into());
        if x.channel == "v" && y.channel == "g" {
            labels.arches = arches.to_vec();
        }
        let overlay = Overlay { x: (x.min, x.max, x.size), y: (y.min, y.max, y.size), rgba: &lut.values };
        let file = format!("tf_{}.png", lut.name);
        write_overlay_figure(&dir.join(&file), h, Scale::Log, &labels, &overlay)?;
        written.push(file);
    }
    Ok(written)
}
