//! Figures that join two stages' results or several channels: the
//! boundaries found in the histogram volume drawn on the (v, g) histograms,
//! the pack's 2D transfer functions drawn over the histograms of their two
//! channels, and the joint histograms of a multi-field input's fields.

use mdtf_histogram::{
    ArchMark, Axis, AxisSpec, DetectedBoundary, Histogram, Labels, Overlay, Scale, count, write_histogram,
    write_overlay_figure,
};
use mdtf_pack::Lut;
use mdtf_volume::{Volume, VolumeError};
use std::collections::BTreeMap;
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
pub fn clip_note(axis: &mdtf_histogram::Axis, percent: f64, outside: u64, without: u64) -> String {
    let padding = if without > 0 { format!(", {without} of them without g (scanner padding)") } else { String::new() };
    format!(
        "{} axis {:.4} to {:.4}: {percent} % clipped at each end (as Teem's qbert does); {outside} voxels not drawn{padding}",
        axis.name, axis.min, axis.max
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

/// Fields whose pairs get joint histograms (the first ones of the input).
pub const MAX_PAIRED_FIELDS: usize = 4;

/// The joint histograms of a multi-field input: every pair of its first
/// [`MAX_PAIRED_FIELDS`] fields, and each of them against ||G|| when it was
/// derived (the gaussian-tf pack's gradient), written into `hdir`; returns
/// the figures written, relative to the run's folder, and the histograms
/// of the field pairs (for [`write_gaussian_figures`]).
pub fn write_field_pair_histograms(
    fields: &[String],
    chans: &BTreeMap<crate::channel::Channel, Volume>,
    hdir: &Path,
    title: &str,
) -> Result<(Vec<String>, Vec<Histogram>), String> {
    let named: Vec<(&str, &Volume)> = fields
        .iter()
        .take(MAX_PAIRED_FIELDS)
        .enumerate()
        .filter_map(|(k, f)| chans.get(&crate::channel::Channel::Field(k)).map(|v| (f.as_str(), v)))
        .collect();
    let axis = |name: &str, v: &Volume, spec: AxisSpec| spec.resolve(name, v.samples()).map_err(|e| e.to_string());
    let axes: Vec<Axis> = named.iter().map(|(f, v)| axis(f, v, AxisSpec::qbert(f))).collect::<Result<_, _>>()?;
    // (the first field's index, the second channel and its axis)
    let mut pairs: Vec<(usize, &Volume, Axis)> = Vec::new();
    for a in 0..named.len() {
        pairs.extend((a + 1..named.len()).map(|b| (a, named[b].1, axes[b].clone())));
    }
    if let Some(gnorm) = chans.get(&crate::channel::Channel::Gnorm) {
        // ||G|| has g's long tail: clipped as g is
        let spec = AxisSpec { clip_percent: AxisSpec::qbert("g").clip_percent, ..AxisSpec::qbert("gnorm") };
        let gnorm_axis = axis("gnorm", gnorm, spec)?;
        pairs.extend((0..named.len()).map(|a| (a, gnorm, gnorm_axis.clone())));
    }
    let mut written = Vec::new();
    let mut field_pairs = Vec::new();
    for (a, second, second_axis) in pairs {
        let file = format!("histogram/hist_{}_{}.png", axes[a].name, second_axis.name);
        let hist = count(&[named[a].1.samples(), second.samples()], vec![axes[a].clone(), second_axis], None)
            .map_err(|e| e.to_string())?;
        write_histogram(hdir, &hist, Scale::Log, title).map_err(|e| e.to_string())?;
        written.push(file);
        if hist.axes[1].name != "gnorm" {
            field_pairs.push(hist);
        }
    }
    Ok((written, field_pairs))
}

/// Cells per axis of the Gaussian TF drawn over a field-pair histogram.
const GAUSSIAN_FIGURE_CELLS: usize = 256;

/// Writes `tf_gaussians_<a>_<b>.png` into `dir` for every field-pair
/// histogram of `hists` (fields named as in `fields`): the full Gaussians
/// of `gaussians` over the pair's plane, the other fields at each
/// primitive's centre, drawn over the counts (colour by each primitive's
/// share of the extinction sum alpha_max rho, opacity 1 - exp(-sum)).
/// Triangular primitives, which need the gradient, are left out. On scalar
/// data (`fields` empty), `tf_gaussians_v_g.png` over the (v, g) histogram
/// of `hists` instead, with every primitive (a triangular one widening with
/// g). Returns the files written, relative to `dir`.
pub fn write_gaussian_figures(
    dir: &Path,
    gaussians: &[mdtf_pack::GaussianPrimitive],
    hists: &[Histogram],
    fields: &[String],
    title: &str,
) -> Result<Vec<String>, VolumeError> {
    if fields.is_empty() {
        let plane = hists.iter().find(|h| h.axes.len() == 2 && h.axes[0].name == "v" && h.axes[1].name == "g");
        let scalar: Vec<&mdtf_pack::GaussianPrimitive> = gaussians.iter().filter(|g| g.fields() == 1).collect();
        return match plane {
            Some(h) if !scalar.is_empty() => {
                // (v, g): a full Gaussian reads v alone, a triangular one v and g
                let note = "the Gaussians' colour mixed in by the square root of their opacity relative to the \
                            largest; a triangular one widens with g";
                Ok(vec![gaussian_figure(dir, h, &scalar, title, note, |_, xv, yv| vec![xv, yv])?])
            }
            _ => Ok(Vec::new()),
        };
    }
    let full: Vec<&mdtf_pack::GaussianPrimitive> =
        gaussians.iter().filter(|g| !g.triangular && g.fields() == fields.len()).collect();
    let mut written = Vec::new();
    if full.is_empty() {
        return Ok(written);
    }
    for h in hists.iter().filter(|h| h.axes.len() == 2) {
        let index = |name: &str| fields.iter().position(|f| f == name);
        let (Some(a), Some(b)) = (index(&h.axes[0].name), index(&h.axes[1].name)) else { continue };
        let note = "the Gaussians' colour mixed in by the square root of their opacity relative to the largest; \
                    other fields at each Gaussian's centre";
        let at = |g: &mdtf_pack::GaussianPrimitive, xv: f64, yv: f64| {
            let mut v = g.centre.clone();
            (v[a], v[b]) = (xv, yv);
            v
        };
        written.push(gaussian_figure(dir, h, &full, title, note, at)?);
    }
    Ok(written)
}

/// Draws the primitives `gs` over the 2D histogram `h` into
/// `tf_gaussians_<x>_<y>.png` in `dir`: each evaluated at `at(primitive,
/// x, y)` on a grid of [`GAUSSIAN_FIGURE_CELLS`] per axis, coloured by its
/// share of the extinction sum alpha_max rho, opacity 1 - exp(-sum); the file's name.
fn gaussian_figure(
    dir: &Path,
    h: &Histogram,
    gs: &[&mdtf_pack::GaussianPrimitive],
    title: &str,
    note: &str,
    at: impl Fn(&mdtf_pack::GaussianPrimitive, f64, f64) -> Vec<f64>,
) -> Result<String, VolumeError> {
    let n = GAUSSIAN_FIGURE_CELLS;
    let (x, y) = (&h.axes[0], &h.axes[1]);
    let centre = |axis: &Axis, i: usize| axis.min + (i as f64 + 0.5) * (axis.max - axis.min) / n as f64;
    let mut rgba = vec![0f32; 4 * n * n];
    for (cell, out) in rgba.chunks_exact_mut(4).enumerate() {
        let (xv, yv) = (centre(x, cell % n), centre(y, cell / n));
        let (mut depth, mut colour) = (0.0, [0.0f64; 3]);
        for g in gs {
            let e = g.alpha_max * g.density(&at(g, xv, yv));
            depth += e;
            colour.iter_mut().zip(g.colour).for_each(|(c, gc)| *c += e * gc);
        }
        if depth > 0.0 {
            out[..3].iter_mut().zip(colour).for_each(|(o, c)| *o = (c / depth) as f32);
            out[3] = (1.0 - (-depth).exp()) as f32;
        }
    }
    let mut labels = Labels::of(h, &format!("Gaussian TF over the ({}, {}) histogram of {title}", x.name, y.name));
    labels.note = Some(note.into());
    let overlay = Overlay { x: (x.min, x.max, n), y: (y.min, y.max, n), rgba: &rgba };
    let file = format!("tf_gaussians_{}_{}.png", x.name, y.name);
    write_overlay_figure(&dir.join(&file), h, Scale::Log, &labels, &overlay)?;
    Ok(file)
}
