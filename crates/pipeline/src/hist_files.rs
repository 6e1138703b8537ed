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
    /// Voxels without a finite g (scanner padding and the voxels within the
    /// kernel's reach of it): in no histogram, by design.
    pub without_g: u64,
    /// The histogram volume, when asked for.
    pub hvol: Option<HistogramVolume>,
    /// The (v, g) histogram.
    pub joint: Option<Histogram>,
    /// The (value, 1/g) histogram, named by its value axis.
    pub inv_g: Option<Histogram>,
    /// The (v, g) and (v, g_hit) histograms of the traced voxels.
    pub stretched: Option<(Histogram, Histogram)>,
}

impl Counted {
    /// Gives every histogram's axes the units of their channels in the input's `units`.
    pub fn set_units(&mut self, units: &mdtf_volume::Units) {
        if let Some(h) = &mut self.hvol {
            h.set_units(units);
        }
        let stretched = self.stretched.iter_mut().flat_map(|(a, b)| [a, b]);
        for h in self.joint.iter_mut().chain(self.inv_g.iter_mut()).chain(stretched) {
            h.set_units(units);
        }
    }
}

/// The warning of a run whose histogram volume shows no boundary.
pub const NO_BOUNDARY_WARNING: &str = "detection: no boundary found in the (v, g) histogram (no pair of materials \
     with an arch between them standing out of the noise; see histogram/hvol.json for the materials found). \
     The default TFs show one fallback boundary placed by percentiles (from the background value to the 99th \
     percentile of v) at opacity 0.5. To do better: a smoothing kernel for noisy data (--set derive.kernel=gauss:1.5), \
     or your own TF (--set pack.tf=my-tf.json; widgets over the (v, g) histogram figure)";

/// Least share of a boundary's core voxels the tracing must keep (hit) before
/// [`tracing_losses`] warns.
pub const TRACED_MIN_SHARE: f64 = 0.5;

/// One warning per boundary of `boundaries` fewer than [`TRACED_MIN_SHARE`]
/// of whose core voxels (in the (v, g) histogram `all`) the tracing kept
/// (in `traced`, the histogram of the voxels with a hit): on a noisy scan
/// f'' crosses zero at noise, and the crossings' g fall below g_hit_min.
pub fn tracing_losses(boundaries: &[DetectedBoundary], all: &Histogram, traced: &Histogram) -> Vec<String> {
    boundaries
        .iter()
        .filter_map(|b| {
            let (n, kept) = (b.core_count(all), b.core_count(traced));
            let share = kept as f64 / n.max(1) as f64;
            (n > 0 && share < TRACED_MIN_SHARE).then(|| {
                format!(
                    "tracing: the boundary {:.4} | {:.4} (peak g {:.4}) kept {:.1} % of the {n} voxels on its arch: \
                     the others found no zero crossing of f'' or one with g below boundary.g_hit_min, so distance \
                     and g_hit miss them. Pre-filter g and f'' ([prefilter], as the shipped distance-tf does) \
                     with a smoothing kernel (derive.kernel = \"gauss:1\"), or lower boundary.g_hit_min",
                    b.v_low,
                    b.v_high,
                    b.g_peak,
                    100.0 * share
                )
            })
        })
        .collect()
}

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
/// titled by `input_name`, with the boundaries found in its histogram
/// volume, else in `default_hvol` (the default TF's, not an output); a
/// warning for voxels outside the (v, g) histogram beyond its g axis's
/// designed clip, and one for each
/// boundary the tracing kept too few voxels of (see [`tracing_losses`]).
pub fn write(
    hdir: &Path,
    c: Counted,
    default_hvol: Option<&HistogramVolume>,
    input_name: &str,
    warnings: &mut Vec<String>,
) -> Result<Written, String> {
    let err = |e: mdtf_volume::VolumeError| e.to_string();
    let mut w = Written::default();
    if let Some(hv) = c.hvol.as_ref().or(default_hvol) {
        w.boundaries = mdtf_histogram::detect_boundaries(hv);
        if w.boundaries.is_empty() {
            warnings.push(NO_BOUNDARY_WARNING.into());
        }
        w.arches = crate::figures::boundary_arches(&w.boundaries);
    }
    if let (Some(all), Some((traced, _))) = (&c.joint, &c.stretched) {
        warnings.extend(tracing_losses(&w.boundaries, all, traced));
    }
    if let Some(hv) = c.hvol {
        write_hvol(hdir, &hv, input_name, &w.arches).map_err(err)?;
        w.outputs.push("histogram/opacity.png".into());
        // the pack needs only the 2D opacity: free the 3D counts (64 MiB at 256^3) now
        let mut hv = hv;
        hv.hist.counts = Vec::new();
        w.hvol = Some(hv);
    }
    if let Some(hist) = c.joint {
        let (low_clip, g_clip) = AxisSpec::qbert("g").clip_percent;
        let outside = c.voxels as u64 - hist.total();
        let note = crate::figures::clip_note(&hist.axes[1], g_clip, outside, c.without_g);
        write_histogram_marked(hdir, &hist, Scale::Log, input_name, Some(&note), &w.arches).map_err(err)?;
        w.outputs.push("histogram/hist_v_g.png".into());
        // the clip leaves out at most floor(clip % of the finite g) at each end by design (the
        // figure's note says so), the padding its voxels; more is worth a warning (v outside its axis)
        let finite = (c.voxels as u64).saturating_sub(c.without_g) as f64;
        let clip = |percent: f64| (percent / 100.0 * finite).floor() as u64;
        let clipped_by_design = clip(low_clip) + clip(g_clip) + c.without_g;
        if outside > clipped_by_design {
            warnings.push(format!(
                "histogram: {outside} of {} voxels lie outside the (v, g) histogram and are not counted \
                 (its g axis {:.4} to {:.4}, {g_clip} % of g clipped at each end as Teem's qbert does; {} voxels \
                 without g, the scanner padding's; NaN values are never counted)",
                c.voxels, hist.axes[1].min, hist.axes[1].max, c.without_g
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
