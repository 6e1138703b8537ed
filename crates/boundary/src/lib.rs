//! Distance-to-boundary stage of mdtf (Lee et al.'s distance-based
//! transfer functions, sections 2-4; DESIGN.md "Distance to boundary").
//!
//! The paper traces two rays from each voxel, along +grad f and -grad f,
//! and keeps the one along which g increases. This stage traces that one
//! ray only and picks it before stepping: f'' = n^T H n (n = grad f / g) is
//! the derivative of g along n, so g increases along +n where f'' > 0 and
//! along -n where f'' < 0. The result is the paper's; half the rays are not
//! traced. From every voxel whose g is at least `g_min` the ray steps by
//! L_min/5 up to d_max = 15 L_min (the paper's values), sampling f'' by
//! trilinear interpolation, and at the first sign change of f'' refines the
//! zero crossing (Illinois regula falsi where the paper bisects; tolerance
//! 1e-3 voxel by default; along a ray the trilinear f'' is one cubic per
//! cell, so steps and refinement evaluate a polynomial and read memory once
//! per cell). g is read only at the crossing, by tricubic (Catmull-Rom)
//! interpolation, since trilinear interpolation flattens g's peak by up to
//! 4 % at sigma = 3 voxels; crossings whose g is below `g_hit_min` are
//! rejected.
//!
//! **Thresholds.** The paper's g = 5 at the voxel and g = 20 at the
//! boundary (8-bit data) clean the statistics of its Fig. 2 only; its
//! Fig. 3 has distances everywhere. Applied to the outputs they cut real
//! boundaries (the `shells` phantom's dentin-pulp boundary peaks at
//! g = 16 < 20 x 210 / 255). So the defaults come from the data: the noise
//! floor is `max(2 x median g, 1e-3 x value range / L_min)` (the median g of
//! a scan is the noise's, since most voxels lie inside materials; the
//! second term keeps rounding noise of clean phantoms out), `g_min` is the
//! floor and `g_hit_min` twice it, or, when the boundaries found in the (v,
//! g) histogram before the tracing are given ([`Detected`]), at most half
//! the least peak g among them (not below the floor): a boundary found
//! keeps its crossings even where the median g of a scan's noise is high.
//! The Fig. 2 thresholds (scaled by the value range / 255, the range being
//! the span of the boundaries' materials when given: noise stretches the
//! min-max range) filter the report only. Voxels at or above the floor
//! are traced even when larger thresholds are given, and a boundary whose
//! crossings all fall below them is reported in
//! [`BoundaryOutput::warnings`] (see [`LostBoundary`]).
//!
//! Outputs (input geometry): `distance` (world units; [`NO_BOUNDARY`] = -1
//! where no boundary was kept), `g_hit` (0 where no zero crossing was
//! found), `hit` ([`HitCode`]: 0 not traced, 1 hit, 2 no crossing, 3 rejected),
//! `dot` (n at the voxel . n at the hit, 0 without a hit), optionally
//! `flipped` (d_max - d, 0 without a hit) and alpha maps of distance
//! (eqs. 9-11, 0 without a hit). Every voxel is traced independently, so the
//! output is bit-identical for any thread count.

mod alpha;
mod exact_sum;
mod lost;
mod report;
mod sample;
mod trace;

pub use alpha::AlphaMap;
pub use lost::{LOST_MIN_SHARE, LostBoundary};
pub use report::{Report, ReportAccumulator, ReportBin, ReportInput, ReportThresholds};
pub use trace::HitCode;

use mdtf_volume::{Geometry, MultiField, Volume};
use ndarray::Array3;
use rayon::prelude::*;
use sample::Grid;
use serde::{Deserialize, Serialize};
use trace::{Fields, TraceSettings, trace_plane};

/// The distance written where no boundary was kept.
pub const NO_BOUNDARY: f32 = -1.0;
/// The Fig. 2 report's g threshold at the voxel on 8-bit data (the paper's 5.0), scaled by value range / 255.
pub const FIG2_G_MIN_8BIT: f64 = 5.0;
/// The Fig. 2 report's g threshold at the boundary on 8-bit data (the paper's 20.0), scaled by value range / 255.
pub const FIG2_G_HIT_MIN_8BIT: f64 = 20.0;
/// The noise floor is at least this many times the median g.
pub const NOISE_FLOOR_MEDIANS: f64 = 2.0;
/// The noise floor is at least this fraction of the value range per L_min.
pub const NOISE_FLOOR_RANGE_FRACTION: f64 = 1e-3;
/// The default g_hit_min is this many noise floors.
pub const G_HIT_MIN_FLOORS: f64 = 2.0;
/// With boundaries found before the tracing, the default g_hit_min is at
/// most this share of the least peak g among them.
pub const G_HIT_MIN_PEAK_SHARE: f64 = 0.5;

/// What boundary detection in the (v, g) histogram found before the
/// tracing, for the tracing's defaults (see the crate docs).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Detected {
    /// The least peak gradient G of the boundaries found, value units per
    /// world unit (None: none found).
    pub least_g_peak: Option<f64>,
    /// The values of the lowest and the highest material of the boundaries
    /// found, value units (None: none found).
    pub material_range: Option<[f64; 2]>,
}

/// Parameters of the boundary stage (shared by `mdtf boundary` and pipeline files).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoundaryParams {
    /// Trace only voxels with g at least this (value units per world unit).
    /// Default: the noise floor, max(2 x median g, 1e-3 x value range / L_min).
    pub g_min: Option<f64>,
    /// Keep only hits whose g is at least this. Default: twice the noise floor.
    pub g_hit_min: Option<f64>,
    /// Step along the ray, world units. Default: L_min / 5.
    pub step: Option<f64>,
    /// Longest distance traced, world units. Default: 15 L_min (the paper's).
    pub d_max: Option<f64>,
    /// Zero-crossing tolerance in voxels (of L_min). Default 1e-3.
    pub tolerance: f64,
    /// Also write the display image d_max - d.
    pub flipped: bool,
    /// Alpha maps of distance to write.
    pub alpha: Vec<AlphaMap>,
}

impl Default for BoundaryParams {
    fn default() -> Self {
        BoundaryParams {
            g_min: None,
            g_hit_min: None,
            step: None,
            d_max: None,
            tolerance: 1e-3,
            flipped: false,
            alpha: vec![],
        }
    }
}

/// The volumes the stage reads: g, f'' and the unit normal (3 fields), on one grid.
#[derive(Debug, Clone, Copy)]
pub struct BoundaryInput<'a> {
    /// Gradient magnitude.
    pub g: &'a Volume,
    /// Second directional derivative along the gradient.
    pub f2: &'a Volume,
    /// Unit normal (nx, ny, nz) along the grid axes.
    pub normal: &'a MultiField,
    /// Value range (max - min) of the data g and f'' came from; scales the
    /// noise floor's lower bound and the Fig. 2 thresholds.
    pub value_range: f64,
}

/// Errors of the boundary stage.
#[derive(Debug, thiserror::Error)]
pub enum BoundaryError {
    /// g, f'' and normal are not on one grid, or normal lacks 3 fields.
    #[error("{0}")]
    Geometry(String),
    /// A parameter is out of range.
    #[error("{0}")]
    BadParameter(String),
}

/// Counts of the hit codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TraceCounts {
    /// Voxels below g_min (or without a gradient direction).
    pub not_traced: u64,
    /// Voxels with a kept boundary.
    pub hits: u64,
    /// Traced voxels without a zero crossing within d_max.
    pub no_crossing: u64,
    /// Traced voxels whose zero crossing had g below g_hit_min.
    pub rejected: u64,
}

impl std::ops::AddAssign for TraceCounts {
    fn add_assign(&mut self, o: TraceCounts) {
        self.not_traced += o.not_traced;
        self.hits += o.hits;
        self.no_crossing += o.no_crossing;
        self.rejected += o.rejected;
    }
}

impl TraceCounts {
    /// Voxels traced (all but the not-traced ones).
    pub fn traced(&self) -> u64 {
        self.hits + self.no_crossing + self.rejected
    }
}

/// The outputs, each on the input grid.
#[derive(Debug, Clone)]
pub struct BoundaryOutput {
    /// Distance to the boundary (world units), [`NO_BOUNDARY`] where none was kept.
    pub distance: Volume,
    /// g at the zero crossing (0 where none was found).
    pub g_hit: Volume,
    /// [`HitCode`] as a number.
    pub hit: Volume,
    /// Dot product of the unit gradients at the voxel and at the hit.
    pub dot: Volume,
    /// d_max - d where a boundary was kept, else 0 (if asked for).
    pub flipped: Option<Volume>,
    /// (file name, alpha volume) per requested alpha map.
    pub alpha: Vec<(String, Volume)>,
    /// How many voxels got each code.
    pub counts: TraceCounts,
    /// The thresholds and sampling actually used (defaults resolved).
    pub resolved: ResolvedParams,
    /// Boundaries the thresholds took out of the outputs.
    pub lost: Vec<LostBoundary>,
    /// One sentence per lost boundary, for stderr and run reports.
    pub warnings: Vec<String>,
}

/// Parameters after defaults are applied.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ResolvedParams {
    /// The noise floor, value units per world unit: voxels with g at or above it are traced.
    pub noise_floor: f64,
    /// g_min used.
    pub g_min: f64,
    /// g_hit_min used.
    pub g_hit_min: f64,
    /// The Fig. 2 report's threshold at the voxel (5 x value range / 255).
    pub fig2_g_min: f64,
    /// The Fig. 2 report's threshold at the boundary (20 x value range / 255).
    pub fig2_g_hit_min: f64,
    /// The value range the Fig. 2 thresholds scale by: the span of the
    /// materials of the boundaries found, or else the data's min-max range.
    pub fig2_range: f64,
    /// `fig2_range` is the span of the boundaries' materials.
    pub fig2_range_of_boundaries: bool,
    /// The default g_hit_min was lowered to keep the boundaries found
    /// (half the least peak g among them).
    pub g_hit_min_of_boundaries: bool,
    /// Step, world units.
    pub step: f64,
    /// d_max, world units.
    pub d_max: f64,
    /// Tolerance, world units.
    pub tolerance: f64,
}

impl BoundaryOutput {
    /// The Fig. 2 report, with mean g taken from `g` (the gradient magnitude
    /// at the voxels), over the hits that pass the Fig. 2 thresholds.
    pub fn report(&self, g: &Volume) -> Report {
        let input = ReportInput {
            hit: self.hit.samples(),
            dot: self.dot.samples(),
            distance: self.distance.samples(),
            g: g.samples(),
            g_hit: self.g_hit.samples(),
        };
        Report::new(input, self.resolved.report_thresholds())
    }
}

impl ResolvedParams {
    /// The Fig. 2 report's thresholds.
    pub fn report_thresholds(&self) -> ReportThresholds {
        ReportThresholds { g_min: self.fig2_g_min, g_hit_min: self.fig2_g_hit_min }
    }
}

/// The noise floor of a g volume: max(2 x median g, 1e-3 x value range /
/// L_min), value units per world unit. With no finite g, the second term.
pub fn noise_floor(g: &[f32], value_range: f64, l_min: f64) -> f64 {
    noise_floor_of_median(mdtf_volume::median(g), value_range, l_min)
}

/// [`noise_floor`] from the median of g (None: no finite g), for runs that
/// find the median over blocks.
pub fn noise_floor_of_median(median: Option<f32>, value_range: f64, l_min: f64) -> f64 {
    let median = median.unwrap_or(0.0) as f64;
    (NOISE_FLOOR_MEDIANS * median).max(NOISE_FLOOR_RANGE_FRACTION * value_range / l_min.max(f64::MIN_POSITIVE))
}

/// The paper's d_max, 15 L_min (world units).
pub fn default_d_max(geometry: &Geometry) -> f64 {
    15.0 * geometry.min_spacing()
}

/// Resolves defaults and checks every parameter against the grid.
/// `noise_floor` is [`noise_floor`] of the g volume; to check the
/// parameters before g exists, pass [`noise_floor`] of an empty slice.
pub fn resolve(
    params: &BoundaryParams,
    geometry: &Geometry,
    value_range: f64,
    noise_floor: f64,
) -> Result<ResolvedParams, BoundaryError> {
    resolve_detected(params, geometry, value_range, noise_floor, &Detected::default())
}

/// [`resolve`] with the boundaries found before the tracing (see the crate docs).
pub fn resolve_detected(
    params: &BoundaryParams,
    geometry: &Geometry,
    value_range: f64,
    noise_floor: f64,
    detected: &Detected,
) -> Result<ResolvedParams, BoundaryError> {
    let l_min = geometry.min_spacing();
    let of_boundaries = detected.material_range.map(|[lo, hi]| hi - lo).filter(|&s| s > 0.0 && s <= value_range);
    let fig2_range = of_boundaries.unwrap_or(value_range);
    let scale = fig2_range / 255.0;
    let of_floor = G_HIT_MIN_FLOORS * noise_floor;
    let of_peaks = detected.least_g_peak.map(|g| (G_HIT_MIN_PEAK_SHARE * g).max(noise_floor));
    let lowered = params.g_hit_min.is_none() && of_peaks.is_some_and(|g| g < of_floor);
    let r = ResolvedParams {
        noise_floor,
        g_min: params.g_min.unwrap_or(noise_floor),
        g_hit_min: params.g_hit_min.unwrap_or(of_peaks.map_or(of_floor, |g| g.min(of_floor))),
        fig2_g_min: FIG2_G_MIN_8BIT * scale,
        fig2_g_hit_min: FIG2_G_HIT_MIN_8BIT * scale,
        fig2_range,
        fig2_range_of_boundaries: of_boundaries.is_some(),
        g_hit_min_of_boundaries: lowered,
        step: params.step.unwrap_or(l_min / 5.0),
        d_max: params.d_max.unwrap_or(default_d_max(geometry)),
        tolerance: params.tolerance * l_min,
    };
    let bad = |m: String| Err(BoundaryError::BadParameter(m));
    if !(r.step.is_finite() && r.step > 0.0) {
        return bad(format!("boundary.step must be positive (world units), got {}", r.step));
    }
    if !(r.d_max.is_finite() && r.d_max > 0.0) {
        return bad(format!("boundary.d_max must be positive (world units), got {}", r.d_max));
    }
    let extent = (0..3).map(|a| (geometry.dims[a] as f64 - 1.0) * geometry.spacing[a]).fold(0.0, f64::max);
    if r.d_max > extent {
        return bad(format!(
            "boundary.d_max {} is larger than the volume (its longest extent is {extent} world units)",
            r.d_max
        ));
    }
    if r.step > r.d_max {
        return bad(format!("boundary.step {} is larger than boundary.d_max {}", r.step, r.d_max));
    }
    if !(params.tolerance.is_finite() && params.tolerance > 0.0) {
        return bad(format!("boundary.tolerance must be positive (voxels), got {}", params.tolerance));
    }
    for (name, v) in [("boundary.g_min", r.g_min), ("boundary.g_hit_min", r.g_hit_min)] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("{name} must be a non-negative number, got {v}"));
        }
    }
    for a in &params.alpha {
        a.validate().map_err(BoundaryError::BadParameter)?;
        a.check_within(r.d_max).map_err(BoundaryError::BadParameter)?;
    }
    Ok(r)
}

/// Traces every voxel.
pub fn run(input: &BoundaryInput, params: &BoundaryParams) -> Result<BoundaryOutput, BoundaryError> {
    run_block(input, params, 0)
}

/// [`run`] with the boundaries found before the tracing (see the crate docs).
pub fn run_detected(
    input: &BoundaryInput,
    params: &BoundaryParams,
    detected: &Detected,
) -> Result<BoundaryOutput, BoundaryError> {
    let stats = VolumeStats { detected: *detected, ..VolumeStats::of(input.g, input.value_range) };
    trace_whole(input, params, 0, &stats)
}

/// What the tracing of a block takes from the whole volume (reductions of a
/// first pass), so that a slab-by-slab run gives the whole-volume run's bits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VolumeStats {
    /// Value range (max - min) of the data g and f'' came from.
    pub value_range: f64,
    /// [`noise_floor`] of the whole g volume, value units per world unit.
    pub noise_floor: f64,
    /// Largest finite g of the whole volume (0 without one): the axis of the crossings' histogram.
    pub g_max: f32,
    /// The boundaries found before the tracing (none: the defaults of the noise floor alone).
    #[serde(default)]
    pub detected: Detected,
}

impl VolumeStats {
    /// The statistics of a whole g volume whose data span `value_range`.
    pub fn of(g: &Volume, value_range: f64) -> VolumeStats {
        let noise_floor = noise_floor(g.samples(), value_range, g.geometry.min_spacing());
        VolumeStats { value_range, noise_floor, g_max: g_max(g.samples()), detected: Detected::default() }
    }
}

/// The largest finite g of `g` (0 without one), as [`VolumeStats::g_max`] takes it.
pub fn g_max(g: &[f32]) -> f32 {
    mdtf_volume::finite_sample_range(g).map_or(0.0, |r| r.1)
}

/// The g at the zero crossings of the traced voxels, counted over
/// [0, [`VolumeStats::g_max`]]; the counts of blocks add up exactly.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Crossings(lost::CrossingHistogram);

impl Crossings {
    /// Adds another block's crossings.
    pub fn merge(&mut self, other: &Crossings) {
        self.0.merge(&other.0);
    }

    /// The boundaries the thresholds of `r` took out of the outputs, and a
    /// sentence on each for warnings.
    pub fn lost(&self, r: &ResolvedParams) -> (Vec<LostBoundary>, Vec<String>) {
        let cut = r.g_min.max(r.g_hit_min);
        let lost = lost::lost_boundaries(&self.0, G_HIT_MIN_FLOORS * r.noise_floor, cut);
        let warnings = lost.iter().map(|l| lost_warning(l, r)).collect();
        (lost, warnings)
    }
}

/// The tracing of a block's own planes.
#[derive(Debug, Clone)]
pub struct BlockTrace {
    /// Distance (world units), on the traced planes.
    pub distance: Volume,
    /// g at the zero crossing.
    pub g_hit: Volume,
    /// [`HitCode`] as a number.
    pub hit: Volume,
    /// Dot product of the unit gradients at the voxel and at the hit.
    pub dot: Volume,
    /// How many voxels got each code.
    pub counts: TraceCounts,
    /// The crossings' g, to merge and then look for lost boundaries in.
    pub crossings: Crossings,
    /// The thresholds and sampling used.
    pub resolved: ResolvedParams,
}

/// Where a block lies in the whole volume and which of its voxels to trace:
/// a box of g, f'' and normal cut from the whole grid (z-slab, strip of
/// rows, or both) whose first voxel is voxel `first` of the whole volume,
/// and the rows and planes of the block (its own coordinates) to trace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockPlace {
    /// The block's first voxel in the whole volume's (x, y, z) indices.
    pub first: [usize; 3],
    /// The block's rows (y) to trace, in the block's own indices.
    pub rows: std::ops::Range<usize>,
    /// The block's planes (z) to trace, in the block's own indices.
    pub planes: std::ops::Range<usize>,
}

impl BlockPlace {
    /// Every voxel of a block (a z-slab of full planes) whose first plane
    /// is plane `first_plane` of the whole volume, with `dims` its grid.
    pub fn z_slab(first_plane: usize, dims: [usize; 3]) -> BlockPlace {
        BlockPlace { first: [0, 0, first_plane], rows: 0..dims[1], planes: 0..dims[2] }
    }
}

/// Traces the rows and planes `place` names of a block of g, f'' and
/// normal (see [`BlockPlace`]). Ray positions are in the whole volume's
/// voxel coordinates and the defaults come from `stats`, so every traced
/// voxel whose ray stays inside the block (those at least the plan's halo
/// from its cut faces) gets the whole-volume run's bits. The outputs hold
/// the traced rows and planes only.
pub fn trace_block(
    input: &BoundaryInput,
    params: &BoundaryParams,
    place: &BlockPlace,
    stats: &VolumeStats,
) -> Result<BlockTrace, BoundaryError> {
    trace_block_into(input, params, place, stats, None)
}

/// [`trace_block`], its outputs in the memory of `spent` (a block's tracing
/// done with) when given: a caller tracing block after block saves mapping
/// fresh memory for each, which page-faults at a cost like the tracing's.
pub fn trace_block_into(
    input: &BoundaryInput,
    params: &BoundaryParams,
    place: &BlockPlace,
    stats: &VolumeStats,
    spent: Option<BlockTrace>,
) -> Result<BlockTrace, BoundaryError> {
    let geo = &input.g.geometry;
    if !input.f2.geometry.same_grid(geo) || !input.normal.geometry.same_grid(geo) {
        return Err(BoundaryError::Geometry(format!(
            "g ({} spacing {:?}), f2 ({} spacing {:?}) and normal ({} spacing {:?}) must share one grid",
            geo.dims_string(),
            geo.spacing,
            input.f2.geometry.dims_string(),
            input.f2.geometry.spacing,
            input.normal.geometry.dims_string(),
            input.normal.geometry.spacing
        )));
    }
    if input.normal.fields.len() != 3 {
        return Err(BoundaryError::Geometry(format!(
            "normal must have 3 fields, it has {}",
            input.normal.fields.len()
        )));
    }
    let BlockPlace { first, rows, planes } = place;
    for (what, r, n) in [("rows", rows, geo.dims[1]), ("planes", planes, geo.dims[2])] {
        if r.start > r.end || r.end > n {
            return Err(BoundaryError::Geometry(format!(
                "{what} {r:?} to trace are not within the block's {n} {what}"
            )));
        }
    }
    let r = resolve_detected(params, geo, stats.value_range, stats.noise_floor, &stats.detected)?;
    fn grid(v: &Array3<f32>, dims: [usize; 3], first: [usize; 3]) -> Grid<'_> {
        Grid::at(v.as_slice().unwrap_or(&[]), dims, first)
    }
    let grid = |v| grid(v, geo.dims, *first);
    let fields = Fields {
        g: grid(&input.g.data),
        f2: grid(&input.f2.data),
        n: [grid(&input.normal.fields[0].data), grid(&input.normal.fields[1].data), grid(&input.normal.fields[2].data)],
    };
    let settings = TraceSettings {
        spacing: geo.spacing.map(|s| s as f32),
        step: r.step as f32,
        steps: (r.d_max / r.step + 1e-9).floor() as usize,
        tolerance: r.tolerance as f32,
        g_min: r.g_min as f32,
        g_hit_min: r.g_hit_min as f32,
        g_probe: r.g_min.min(r.noise_floor) as f32,
    };
    let plane = geo.dims[0] * rows.len();
    let out_geo = geo.z_slab(planes.clone()).y_rows(rows.clone());
    let mut memory = spent.map(|b| [b.distance, b.g_hit, b.hit, b.dot]).into_iter().flatten();
    let mut zeros = || -> Result<Volume, BoundaryError> {
        let Some(v) = memory.next() else { return Ok(Volume::zeros(out_geo.clone())) };
        let mut samples = v.data.into_raw_vec_and_offset().0;
        samples.clear();
        samples.resize(out_geo.voxel_count(), 0.0);
        Volume::from_samples(out_geo.clone(), samples).map_err(|e| BoundaryError::Geometry(e.to_string()))
    };
    let (mut distance, mut g_hit, mut hit, mut dot) = (zeros()?, zeros()?, zeros()?, zeros()?);
    let mut counts = TraceCounts::default();
    let mut crossings = lost::CrossingHistogram::new(stats.g_max);
    {
        let d = distance.data.as_slice_mut().unwrap_or(&mut []);
        let gh = g_hit.data.as_slice_mut().unwrap_or(&mut []);
        let h = hit.data.as_slice_mut().unwrap_or(&mut []);
        let dt = dot.data.as_slice_mut().unwrap_or(&mut []);
        let per_plane: Vec<(TraceCounts, lost::CrossingHistogram)> = d
            .par_chunks_mut(plane.max(1))
            .zip(gh.par_chunks_mut(plane.max(1)))
            .zip(h.par_chunks_mut(plane.max(1)))
            .zip(dt.par_chunks_mut(plane.max(1)))
            .enumerate()
            .map(|(k, (((d, gh), h), dt))| {
                let mut hist = lost::CrossingHistogram::new(stats.g_max);
                let out = trace::PlaneOut { distance: d, g_hit: gh, hit: h, dot: dt, crossings: &mut hist };
                (trace_plane(&fields, &settings, planes.start + k, rows.clone(), out), hist)
            })
            .collect();
        for (c, h) in per_plane {
            counts += c;
            crossings.merge(&h);
        }
    }
    Ok(BlockTrace { distance, g_hit, hit, dot, counts, crossings: Crossings(crossings), resolved: r })
}

/// Traces every voxel of a block (a z-slab) whose first plane is plane
/// `first_plane` of the whole volume. Ray positions are computed in the
/// whole volume's voxel coordinates, so the block's voxels whose rays stay
/// inside it (those at least the plan's halo from its cut faces) get the
/// whole-volume run's bits. The thresholds the defaults take from the data
/// (the noise floor's median of g) are the block's own: pass `g_min` and
/// `g_hit_min` from the whole volume, or use [`trace_block`] with the
/// whole volume's [`VolumeStats`], for identical results.
pub fn run_block(
    input: &BoundaryInput,
    params: &BoundaryParams,
    first_plane: usize,
) -> Result<BoundaryOutput, BoundaryError> {
    trace_whole(input, params, first_plane, &VolumeStats::of(input.g, input.value_range))
}

/// Traces every voxel of a block whose first plane is `first_plane`, with the defaults of `stats`.
fn trace_whole(
    input: &BoundaryInput,
    params: &BoundaryParams,
    first_plane: usize,
    stats: &VolumeStats,
) -> Result<BoundaryOutput, BoundaryError> {
    let place = BlockPlace::z_slab(first_plane, input.g.geometry.dims);
    let BlockTrace { distance, g_hit, hit, dot, counts, crossings, resolved: r } =
        trace_block(input, params, &place, stats)?;
    let maps = hit_maps(params, r.d_max);
    let hit_mask = |f: &HitMap| {
        let data = ndarray::Zip::from(&distance.data).and(&hit.data).map_collect(|&d, &h| f.at(d, h));
        Volume { geometry: distance.geometry.clone(), data }
    };
    let mut maps = maps.iter();
    let flipped = params.flipped.then(|| maps.next().map(hit_mask)).flatten();
    let alpha = maps.map(|m| (m.name.clone(), hit_mask(m))).collect();
    let (lost, warnings) = crossings.lost(&r);
    Ok(BoundaryOutput { distance, g_hit, hit, dot, flipped, alpha, counts, resolved: r, lost, warnings })
}

/// A map of the distance where the tracing kept a boundary (0 elsewhere):
/// the flipped distance or an alpha map, by the file name it is written to.
pub struct HitMap {
    /// The file name (without extension): `flipped`, or the alpha map's.
    pub name: String,
    /// The map's value at distance d (voxels), f32 as written.
    map: Box<dyn Fn(f32) -> f32 + Send + Sync>,
}

impl HitMap {
    /// The map at a voxel of distance `d` and hit code `hit` (0 without a kept boundary).
    pub fn at(&self, d: f32, hit: f32) -> f32 {
        if hit == 1.0 { (self.map)(d) } else { 0.0 }
    }
}

/// The maps `params` asks for (`flipped` first, then each alpha map), for a
/// tracing that resolved `d_max` (voxels): functions of a voxel's distance
/// and hit code, so a slab-by-slab run makes them slab by slab.
pub fn hit_maps(params: &BoundaryParams, d_max: f64) -> Vec<HitMap> {
    let mut maps = Vec::with_capacity(params.alpha.len() + 1);
    if params.flipped {
        let top = d_max as f32;
        maps.push(HitMap { name: "flipped".into(), map: Box::new(move |d| top - d) });
    }
    for &a in &params.alpha {
        let map = Box::new(move |d: f32| a.eval(d as f64, d_max) as f32);
        maps.push(HitMap { name: a.file_name().to_string(), map });
    }
    maps
}

fn lost_warning(l: &LostBoundary, r: &ResolvedParams) -> String {
    let which =
        if r.g_hit_min > l.g_peak { format!("g_hit_min {:.4}", r.g_hit_min) } else { format!("g_min {:.4}", r.g_min) };
    format!(
        "a boundary with peak g {:.4} ({} voxels, {:.1} % of the traced ones) is below {which}: it is missing from \
         distance and g_hit; lower the threshold (the noise floor is {:.4})",
        l.g_peak,
        l.voxels,
        100.0 * l.share,
        r.noise_floor
    )
}
