//! Histogram stage of mdtf: joint histograms of 1 to 3 channels (v, g, f'',
//! the stretched (v, g_hit), pairs of fields), their pictures, and the
//! histogram volume of Kindlmann and Durkin with the position function and a
//! default opacity transfer function, the boundaries it shows, and the
//! materials (clusters) of several fields' joint histogram.
//!
//! Counts are integers and parts are summed in a fixed order, so results do
//! not depend on the thread count. Bin rule: [`Axis::bin`].

mod axis;
mod boundaries;
mod clusters;
mod count;
mod figure;
mod files;
mod hvol;
mod image;
mod materials;
mod packed;
mod percentile;
mod rgb;

pub use axis::{Axis, AxisSpec, DEFAULT_BINS, MAX_INTEGER_BINS};
pub use boundaries::{
    ARCH_BAND, ARCH_SAMPLES, ARCH_T, CORE_T, DetectedBoundary, Detection, FALLBACK_G_QUANTILE, FALLBACK_HIGH_QUANTILE,
    MAX_BOUNDARIES, MIN_CONFIDENCE, MIN_CORE_SHARE, MIN_PEAK_OVER_NOISE, MIN_SIGMA_SPACINGS, background_value, detect,
    detect_boundaries, detect_in, fallback_boundary,
};
pub use clusters::{
    CLUSTER_BINS, CLUSTER_MASK, CORE_BIT, CORE_DENSITY, Cluster, JointClusters, MAX_CLUSTERS, MERGE_RATIO,
    MIN_CLUSTER_SHARE, NO_CLUSTER, TOP_BIT, TOP_DENSITY, joint_clusters,
};
pub use count::{Histogram, count, stretched_pair};
pub use figure::{
    ArchMark, FIGURE_SIZE, Labels, Overlay, PLOT_PIXELS, PROJECTIONS_SIZE, SIDE_BY_SIDE_SIZE, axis_label,
    axis_label_of, count_colour,
};
pub use files::{write_histogram, write_histogram_marked, write_hvol, write_overlay_figure, write_stretched};
pub use hvol::{
    HVOL_PARTS, HistogramVolume, HvolAccumulator, HvolAxes, HvolBySlabs, HvolParams, HvolPart, fixed_parts,
    histogram_volume, part_groups,
};
pub use image::{Grey, Scale, grey_level, side_by_side, write_exr, write_png};
pub use materials::{
    BASIN_RATIO, CLEAR_DEPTH, DIP_REACH, MIN_COLUMN_SHARE, MIN_DEPTH, MIN_MATERIAL_SHARE, MIN_NEAR_ZERO_SHARE,
    Material, column_median_g, find_materials,
};
pub use percentile::ChannelStats;
pub use rgb::{Rgb, write_rgb_png};

/// Errors of the histogram stage.
#[derive(Debug, thiserror::Error)]
pub enum HistogramError {
    /// Zero bins, an inverted, degenerate or non-finite range, or an all-NaN channel.
    #[error("{0}")]
    BadAxis(String),
    /// Channels of different sizes or geometry.
    #[error("{0}")]
    Geometry(String),
    /// The data hold nothing to measure.
    #[error("{0}")]
    Degenerate(String),
}

/// Voxels whose boundary tracing kept a hit (`hit` == 1), the mask of the stretched histogram.
pub fn hit_mask(hit: &[f32]) -> Vec<bool> {
    hit.iter().map(|&h| h == 1.0).collect()
}
