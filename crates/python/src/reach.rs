//! What a block of one stage reads beyond itself, and the whole-volume
//! constants a block must be given to compute what the whole volume would
//! (`mdtf.dask` builds its overlaps and passes from these).

use crate::error::{parse_choice, value_error};
use mdtf_pipeline::stages::bilateral::BilateralParams;
use mdtf_pipeline::stages::derive::{Item, Kernel};
use pyo3::prelude::*;

/// mdtf's (x, y, z) as Python's (z, y, x).
fn zyx([x, y, z]: [usize; 3]) -> (usize, usize, usize) {
    (z, y, x)
}

/// The voxels (z, y, x) derive's kernel reads on each side of a voxel, on a
/// grid of `spacing` (z, y, x); None: the default kernel.
#[pyfunction]
#[pyo3(signature = (spacing, kernel=None))]
pub fn kernel_reach(spacing: [f64; 3], kernel: Option<&str>) -> PyResult<(usize, usize, usize)> {
    let kernel = kernel.map_or(Ok(Kernel::default()), |k| k.parse::<Kernel>().map_err(value_error))?;
    let [sz, sy, sx] = spacing;
    Ok(zyx([sx, sy, sz].map(|s| kernel.axis_taps(s).radius())))
}

/// The voxels (z, y, x) the bilateral filter reads on each side of a voxel.
#[pyfunction]
#[pyo3(signature = (spacing, sigma_d=1.0, mode="exact", k=None))]
pub fn bilateral_reach(spacing: [f64; 3], sigma_d: f64, mode: &str, k: Option<f64>) -> PyResult<(usize, usize, usize)> {
    let defaults = BilateralParams::default();
    let params = BilateralParams {
        sigma_d,
        mode: parse_choice("mode", mode, "exact, fast")?,
        k: k.unwrap_or(defaults.k),
        ..defaults
    };
    let [sz, sy, sx] = spacing;
    Ok(zyx(mdtf_pipeline::stages::bilateral::box_radius([sx, sy, sz], &params)))
}

/// derive's default epsilon for one field whose finite values span `span`
/// on a grid of smallest spacing `min_spacing` (value units per world unit).
#[pyfunction]
pub fn default_epsilon(span: f32, min_spacing: f64) -> f32 {
    mdtf_pipeline::stages::derive::default_epsilon(span, min_spacing)
}

/// The arrays derive returns for `items` of one field, in order (the keys of
/// `mdtf.derive`'s result).
#[pyfunction]
pub fn derive_components(items: Vec<String>) -> PyResult<Vec<String>> {
    let mut out = Vec::new();
    for s in &items {
        let item = s.parse::<Item>().map_err(value_error)?;
        if item == Item::Jacobian || item == Item::Gnorm {
            return Err(value_error(format!("{s}: an item of several fields")));
        }
        out.extend(item.components().iter().map(|c| c.to_string()));
    }
    Ok(out)
}

/// The voxels (z, y, x) the tracing reads on each side of a voxel: d_max
/// (world units) and the tricubic g at the hit (derive's reach comes on top).
#[pyfunction]
pub fn trace_reach(spacing: [f64; 3], d_max: f64) -> (usize, usize, usize) {
    let [sz, sy, sx] = spacing;
    zyx(mdtf_pipeline::channel::Reach::new(Kernel::default(), [0; 3], d_max, [sx, sy, sz]).trace)
}

/// The tracing's thresholds for a whole volume of `shape` (z, y, x): `median_g` (its lower median
/// of g; None without any), `value_range` (max - min of the values) and the
/// parameters given (None: the default). Returns (g_min, g_hit_min, step,
/// d_max, tolerance in voxels) as every block must be given them.
#[pyfunction]
#[pyo3(signature = (shape, spacing, value_range, median_g=None, g_min=None, g_hit_min=None, step=None, d_max=None, tolerance=None))]
#[allow(clippy::too_many_arguments)]
pub fn boundary_thresholds(
    shape: [usize; 3],
    spacing: [f64; 3],
    value_range: f64,
    median_g: Option<f32>,
    g_min: Option<f64>,
    g_hit_min: Option<f64>,
    step: Option<f64>,
    d_max: Option<f64>,
    tolerance: Option<f64>,
) -> PyResult<(f64, f64, f64, f64, f64)> {
    let geo = crate::convert::geometry(shape, spacing, [0.0; 3])?;
    let defaults = mdtf_pipeline::stages::boundary::BoundaryParams::default();
    let tolerance = tolerance.unwrap_or(defaults.tolerance);
    let params =
        mdtf_pipeline::stages::boundary::BoundaryParams { g_min, g_hit_min, step, d_max, tolerance, ..defaults };
    let floor = mdtf_pipeline::stages::boundary::noise_floor_of_median(median_g, value_range, geo.min_spacing());
    let r = mdtf_pipeline::stages::boundary::resolve(&params, &geo, value_range, floor)
        .map_err(crate::error::mdtf_error)?;
    Ok((r.g_min, r.g_hit_min, r.step, r.d_max, tolerance))
}
