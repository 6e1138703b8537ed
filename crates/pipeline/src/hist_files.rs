//! The histogram step's files and figures from its counts, however they were
//! counted (over the whole volume, or slab by slab): the histogram volume
//! first (its boundaries are drawn on the others), then the (v, g), (v, 1/g)
//! and stretched histograms.

use mdtf_histogram::{
    AxisSpec, DetectedBoundary, Histogram, HistogramVolume, Scale, write_histogram, write_histogram_marked, write_hvol,
    write_stretched,
};
use std::path::Path;

/// What the histogram step counted.
#[derive(Default)]
pub struct Counted {
    /// Voxels of the input grid.
    pub voxels: usize,
    /// The histogram volume, when asked for.
    pub hvol: Option<HistogramVolume>,
    /// The (v, g) histogram.
    pub joint: Option<Histogram>,
    /// The (value, 1/g) histogram, named by its value axis.
    pub inv_g: Option<Histogram>,
    /// The (v, g) and (v, g_hit) histograms of the traced voxels.
    pub stretched: Option<(Histogram, Histogram)>,
}

/// The warning of a run whose histogram volume shows no boundary.
pub const NO_BOUNDARY_WARNING: &str = "detection: no boundary found in the (v, g) histogram (no pair of materials \
     with an arch between them standing out of the noise; see histogram/hvol.json for the materials found). \
     The default TFs show one fallback boundary placed by percentiles (from the background value to the 99th \
     percentile of v) at opacity 0.5. To do better: a smoothing kernel for noisy data (--set derive.kernel=gauss:1.5), \
     or your own TF (--set pack.tf=my-tf.json; widgets over the (v, g) histogram figure)";

/// What the files written leave for the later steps.
#[derive(Default)]
pub struct Written {
    /// Files written, relative to the output folder.
    pub outputs: Vec<String>,
    /// The boundaries found in the histogram volume.
    pub boundaries: Vec<DetectedBoundary>,
    /// Their marks on the figures.
    pub arches: Vec<mdtf_histogram::ArchMark>,
    /// The 2D histograms the pack's TFs are drawn over.
    pub figure_hists: Vec<Histogram>,
    /// The histogram volume without its 3D counts (the pack's default opacity reads the rest).
    pub hvol: Option<HistogramVolume>,
}

/// Writes the files of `c` into `hdir` (the output folder's `histogram/`),
/// titled by `input_name`; a warning for voxels outside the (v, g) histogram.
pub fn write(hdir: &Path, c: Counted, input_name: &str, warnings: &mut Vec<String>) -> Result<Written, String> {
    let err = |e: mdtf_volume::VolumeError| e.to_string();
    let mut w = Written::default();
    if let Some(hv) = c.hvol {
        w.boundaries = mdtf_histogram::detect_boundaries(&hv);
        if w.boundaries.is_empty() {
            warnings.push(NO_BOUNDARY_WARNING.into());
        }
        w.arches = crate::figures::boundary_arches(&w.boundaries);
        write_hvol(hdir, &hv, input_name, &w.arches).map_err(err)?;
        w.outputs.push("histogram/opacity.png".into());
        // the pack needs only the 2D opacity: free the 3D counts (64 MiB at 256^3) now
        let mut hv = hv;
        hv.hist.counts = Vec::new();
        w.hvol = Some(hv);
    }
    if let Some(hist) = c.joint {
        let g_clip = AxisSpec::qbert("g").clip_percent.1;
        let outside = c.voxels as u64 - hist.total();
        let note = crate::figures::clip_note(&hist.axes[1], g_clip, outside);
        write_histogram_marked(hdir, &hist, Scale::Log, input_name, Some(&note), &w.arches).map_err(err)?;
        w.outputs.push("histogram/hist_v_g.png".into());
        if outside > 0 {
            warnings.push(format!(
                "histogram: {outside} of {} voxels lie outside the (v, g) histogram and are not counted \
                 (its g axis stops at {:.4}, the top {g_clip} % of g clipped as Teem's qbert does; NaN values \
                 are never counted)",
                c.voxels, hist.axes[1].max
            ));
        }
        w.figure_hists.push(hist);
    }
    if let Some(hist) = c.inv_g {
        write_histogram(hdir, &hist, Scale::Log, input_name).map_err(err)?;
        w.outputs.push(format!("histogram/hist_{}_inv_g.png", hist.axes[0].name));
        w.figure_hists.push(hist);
    }
    if let Some((normal, stretched)) = c.stretched {
        write_stretched(hdir, &normal, &stretched, Scale::Log, input_name, &w.arches).map_err(err)?;
        w.outputs.push("histogram/normal_vs_stretched.png".into());
        w.figure_hists.push(stretched);
    }
    Ok(w)
}
