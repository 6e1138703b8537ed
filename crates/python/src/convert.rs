//! numpy arrays and mdtf volumes: arrays are (z, y, x), C order, float32
//! (the package's Python layer converts other arrays first); spacing and
//! origin are given and returned in the same (z, y, x) order, while mdtf
//! holds them as (x, y, z).

use mdtf_volume::{Geometry, Volume};
use ndarray::ArrayView3;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A grid of `shape` (z, y, x) with `spacing` and `origin` in (z, y, x) order.
pub fn geometry(shape: [usize; 3], spacing: [f64; 3], origin: [f64; 3]) -> PyResult<Geometry> {
    if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(PyValueError::new_err(format!(
            "spacing {spacing:?} (z, y, x) must be three positive, finite numbers"
        )));
    }
    let [nz, ny, nx] = shape;
    let mut g = Geometry::new([nx, ny, nz], [spacing[2], spacing[1], spacing[0]]);
    g.origin = [origin[2], origin[1], origin[0]];
    Ok(g)
}

/// A view of a (z, y, x) float32 array; an error when it is not C-contiguous.
pub fn view<'a>(name: &str, a: &'a PyReadonlyArray3<'_, f32>) -> PyResult<ArrayView3<'a, f32>> {
    let v = a.as_array();
    if !v.is_standard_layout() {
        return Err(PyValueError::new_err(format!("{name}: the array must be C-contiguous (numpy.ascontiguousarray)")));
    }
    Ok(v)
}

/// Hands a volume's samples to numpy without copying, shape (z, y, x).
pub fn array<'py>(py: Python<'py>, v: Volume) -> Bound<'py, PyArray3<f32>> {
    v.data.into_pyarray(py)
}

/// The grid as a dict: shape, spacing and origin in (z, y, x) order, and
/// the 4 x 4 world_from_voxel matrix (world x, y, z from voxel i, j, k, as
/// NIfTI's sform).
pub fn geometry_dict<'py>(py: Python<'py>, g: &Geometry) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("shape", (g.dims[2], g.dims[1], g.dims[0]))?;
    d.set_item("spacing", (g.spacing[2], g.spacing[1], g.spacing[0]))?;
    d.set_item("origin", (g.origin[2], g.origin[1], g.origin[0]))?;
    d.set_item("world_from_voxel", g.world_from_voxel().map(Vec::from).to_vec())?;
    Ok(d)
}
