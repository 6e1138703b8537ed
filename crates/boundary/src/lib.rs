//! Distance-to-boundary stage of mdtf (Lee et al.'s distance-based
//! transfer functions, sections 2-4; DESIGN.md "Distance to boundary").
//!
//! From every voxel whose g is at least `g_min`, [`run`] steps along +n and
//! -n (n = grad f / g) with step L_min/5 up to d_max = 15 L_min, sampling g
//! and f'' by trilinear interpolation, follows the direction in which g
//! increases (the sign of f'' at the voxel: f'' = n^T H n is the derivative
//! of g along n), and at the first sign change of f'' refines the zero
//! crossing (Illinois regula falsi, tolerance 1e-3 voxel by default; along
//! a ray the trilinear f'' is one cubic per cell, so steps and refinement
//! evaluate a polynomial and read memory once per cell). g at the hit is
//! read by tricubic (Catmull-Rom) interpolation, since trilinear
//! interpolation flattens g's peak by up to 4 % at sigma = 3 voxels; hits
//! whose g is below `g_hit_min` (noise, phantom edges) are rejected.
//!
//! Outputs (input geometry): `distance` (world units; [`NO_BOUNDARY`] = -1
//! where no boundary was kept), `g_hit` (0 where no zero crossing was
//! found), `hit` ([`HitCode`]: 0 not traced, 1 hit, 2 no crossing, 3 rejected),
//! `dot` (n at the voxel . n at the hit, 0 without a hit), optionally
//! `flipped` (d_max - d, 0 without a hit) and alpha maps of distance
//! (eqs. 9-11, 0 without a hit). Every voxel is traced independently, so the
//! output is bit-identical for any thread count.

mod alpha;
mod report;
mod sample;
mod trace;

pub use alpha::AlphaMap;
pub use report::{Report, ReportBin};
pub use trace::HitCode;

use mdtf_volume::{Geometry, MultiField, Volume};
use ndarray::Array3;
use rayon::prelude::*;
use sample::Grid;
use serde::{Deserialize, Serialize};
use trace::{Fields, TraceSettings, trace_plane};

/// The distance written where no boundary was kept.
pub const NO_BOUNDARY: f32 = -1.0;
/// Default g_min for 8-bit data (the paper's 5.0), scaled by value range / 255.
pub const G_MIN_8BIT: f64 = 5.0;
/// Default g_hit_min for 8-bit data (the paper's 20.0), scaled by value range / 255.
pub const G_HIT_MIN_8BIT: f64 = 20.0;

/// Parameters of the boundary stage (shared by `mdtf boundary` and pipeline files).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoundaryParams {
    /// Trace only voxels with g at least this (value units per world unit).
    /// Default: 5.0 x value range / 255 (the paper's 5.0 on 8-bit data).
    pub g_min: Option<f64>,
    /// Keep only hits whose g is at least this. Default: 20.0 x value range / 255.
    pub g_hit_min: Option<f64>,
    /// Step along the ray, world units. Default: L_min / 5.
    pub step: Option<f64>,
    /// Longest distance traced, world units. Default: 15 L_min.
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
    /// Value range (max - min) of the data g and f'' came from; scales the default thresholds.
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct TraceCounts {
    /// Voxels below g_min.
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
}

/// Parameters after defaults are applied.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ResolvedParams {
    /// g_min used.
    pub g_min: f64,
    /// g_hit_min used.
    pub g_hit_min: f64,
    /// Step, world units.
    pub step: f64,
    /// d_max, world units.
    pub d_max: f64,
    /// Tolerance, world units.
    pub tolerance: f64,
}

impl BoundaryOutput {
    /// The Fig. 2 report, with mean g taken from `g` (the gradient magnitude at the voxels).
    pub fn report(&self, g: &Volume) -> Report {
        Report::new(self.hit.samples(), self.dot.samples(), self.distance.samples(), g.samples())
    }
}

/// Resolves defaults and checks every parameter against the grid.
pub fn resolve(
    params: &BoundaryParams,
    geometry: &Geometry,
    value_range: f64,
) -> Result<ResolvedParams, BoundaryError> {
    let l_min = geometry.min_spacing();
    let scale = value_range / 255.0;
    let r = ResolvedParams {
        g_min: params.g_min.unwrap_or(G_MIN_8BIT * scale),
        g_hit_min: params.g_hit_min.unwrap_or(G_HIT_MIN_8BIT * scale),
        step: params.step.unwrap_or(l_min / 5.0),
        d_max: params.d_max.unwrap_or(15.0 * l_min),
        tolerance: params.tolerance * l_min,
    };
    let bad = |m: String| Err(BoundaryError::BadParameter(m));
    if !(r.step.is_finite() && r.step > 0.0) {
        return bad(format!("--step must be positive (world units), got {}", r.step));
    }
    if !(r.d_max.is_finite() && r.d_max > 0.0) {
        return bad(format!("--d-max must be positive (world units), got {}", r.d_max));
    }
    let extent = (0..3).map(|a| (geometry.dims[a] as f64 - 1.0) * geometry.spacing[a]).fold(0.0, f64::max);
    if r.d_max > extent {
        return bad(format!(
            "--d-max {} is larger than the volume (its longest extent is {extent} world units)",
            r.d_max
        ));
    }
    if r.step > r.d_max {
        return bad(format!("--step {} is larger than --d-max {}", r.step, r.d_max));
    }
    if !(params.tolerance.is_finite() && params.tolerance > 0.0) {
        return bad(format!("--tolerance must be positive (voxels), got {}", params.tolerance));
    }
    for (name, v) in [("--g-min", r.g_min), ("--g-hit-min", r.g_hit_min)] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("{name} must be a non-negative number, got {v}"));
        }
    }
    for a in &params.alpha {
        a.validate().map_err(BoundaryError::BadParameter)?;
    }
    Ok(r)
}

/// Traces every voxel.
pub fn run(input: &BoundaryInput, params: &BoundaryParams) -> Result<BoundaryOutput, BoundaryError> {
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
    let r = resolve(params, geo, input.value_range)?;
    fn grid<'v>(v: &'v Array3<f32>, dims: [usize; 3]) -> Grid<'v> {
        Grid::new(v.as_slice().unwrap_or(&[]), dims)
    }
    let grid = |v| grid(v, geo.dims);
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
    };
    let plane = geo.dims[0] * geo.dims[1];
    let mut distance = Volume::zeros(geo.clone());
    let mut g_hit = Volume::zeros(geo.clone());
    let mut hit = Volume::zeros(geo.clone());
    let mut dot = Volume::zeros(geo.clone());
    let mut counts = TraceCounts::default();
    {
        let d = distance.data.as_slice_mut().unwrap_or(&mut []);
        let gh = g_hit.data.as_slice_mut().unwrap_or(&mut []);
        let h = hit.data.as_slice_mut().unwrap_or(&mut []);
        let dt = dot.data.as_slice_mut().unwrap_or(&mut []);
        let per_plane: Vec<TraceCounts> = d
            .par_chunks_mut(plane)
            .zip(gh.par_chunks_mut(plane))
            .zip(h.par_chunks_mut(plane))
            .zip(dt.par_chunks_mut(plane))
            .enumerate()
            .map(|(k, (((d, gh), h), dt))| {
                trace_plane(&fields, &settings, k, trace::PlaneOut { distance: d, g_hit: gh, hit: h, dot: dt })
            })
            .collect();
        for c in per_plane {
            counts += c;
        }
    }
    let hit_mask = |f: &dyn Fn(f32) -> f32| {
        let data =
            ndarray::Zip::from(&distance.data).and(&hit.data).map_collect(|&d, &h| if h == 1.0 { f(d) } else { 0.0 });
        Volume { geometry: geo.clone(), data }
    };
    let d_max = r.d_max as f32;
    let flipped = params.flipped.then(|| hit_mask(&|d| d_max - d));
    let alpha =
        params.alpha.iter().map(|a| (a.file_name().to_string(), hit_mask(&|d| a.eval(d as f64) as f32))).collect();
    Ok(BoundaryOutput { distance, g_hit, hit, dot, flipped, alpha, counts, resolved: r })
}
