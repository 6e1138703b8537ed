//! What a block of one stage reads beyond itself, and the whole-volume
//! constants a block must be given to compute what the whole volume would
//! (`mdtf.dask` builds its overlaps and passes from these).

use crate::error::{parse_choice, value_error};
use mdtf_bilateral::BilateralParams;
use mdtf_derive::{Item, Kernel};
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
    let kernel = kernel.map_or(Ok(mdtf_derive::DEFAULT_KERNEL), |k| k.parse::<Kernel>().map_err(value_error))?;
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
    Ok(zyx(mdtf_bilateral::box_radius([sx, sy, sz], &params)))
}

/// derive's default epsilon for one field whose finite values span `span`
/// on a grid of smallest spacing `min_spacing` (value units per world unit).
#[pyfunction]
pub fn default_epsilon(span: f32, min_spacing: f64) -> f32 {
    mdtf_derive::default_epsilon(span, min_spacing)
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
