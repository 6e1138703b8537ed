//! Reading and writing volumes in every format mdtf knows (NIfTI, NRRD,
//! MetaImage, raw with a header, TIFF stacks, DICOM series, OME-Zarr),
//! chosen by the file name. Writes are atomic and never replace an input.

use crate::call::run_released;
use crate::convert::{array, geometry, geometry_dict, view};
use crate::error::{mdtf_error, parse_choice, value_error};
use mdtf_volume::{Field, Geometry, MultiField, ReadOptions, WriteOptions};
use numpy::PyReadonlyArray3;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

/// Reads a volume: a list of (field name, (z, y, x) float32 array), and
/// the grid (shape, spacing, origin, world_from_voxel) and what the reader
/// assumed (`warnings`).
#[pyfunction]
#[pyo3(signature = (path, level=0, nan="refuse"))]
pub fn read<'py>(
    py: Python<'py>,
    path: PathBuf,
    level: usize,
    nan: &str,
) -> PyResult<(Bound<'py, PyList>, Bound<'py, PyDict>)> {
    let opts = ReadOptions { nan: parse_choice("nan", nan, "refuse, zero, keep")?, level, ..Default::default() };
    let (mf, info) = run_released(py, None, || mdtf_volume::read_with_info(&path, &opts))?
        .map_err(|e| mdtf_error(naming(&path, e)))?;
    let meta = geometry_dict(py, &mf.geometry)?;
    meta.set_item("format", &info.format)?;
    meta.set_item("warnings", &info.warnings)?;
    let fields = PyList::empty(py);
    for (name, v) in mf.into_volumes() {
        fields.append((name, array(py, v)))?;
    }
    Ok((fields, meta))
}

/// Writes fields (name, (z, y, x) float32 array) on one grid to `path`
/// (its extension picks the format; several fields need NRRD, NIfTI or
/// OME-Zarr). The grid is `world_from_voxel` (4 x 4, as `read` returns it)
/// when given, else `spacing` and `origin` (z, y, x).
#[pyfunction]
#[pyo3(signature = (path, fields, spacing, origin, world_from_voxel=None, gzip=false))]
pub fn write(
    py: Python<'_>,
    path: PathBuf,
    fields: Vec<(String, PyReadonlyArray3<'_, f32>)>,
    spacing: [f64; 3],
    origin: [f64; 3],
    world_from_voxel: Option<[[f64; 4]; 4]>,
    gzip: bool,
) -> PyResult<()> {
    let views = fields.iter().map(|(n, a)| Ok((n.as_str(), view(n, a)?))).collect::<PyResult<Vec<_>>>()?;
    let Some((_, first)) = views.first() else { return Err(value_error("write: give at least one field")) };
    let (z, y, x) = first.dim();
    let geo = match world_from_voxel {
        Some(m) => Geometry::from_affine([x, y, z], [m[0], m[1], m[2]])
            .ok_or_else(|| value_error("world_from_voxel: a column has zero or non-finite length"))?,
        None => geometry([z, y, x], spacing, origin)?,
    };
    let opts = WriteOptions { gzip, ..Default::default() };
    run_released(py, None, || {
        let fields = views.iter().map(|(n, v)| Field { name: n.to_string(), data: v.to_owned() }).collect();
        let mf = MultiField::new(geo, fields)?;
        mdtf_volume::write(&path, &mf, &opts, &[])
    })?
    .map_err(|e| mdtf_error(naming(&path, e)))
}

/// `e`'s message, led by `path` unless it already names it first.
fn naming(path: &std::path::Path, e: impl std::fmt::Display) -> String {
    let (message, shown) = (e.to_string(), path.display().to_string());
    if message.starts_with(&shown) { message } else { format!("{shown}: {message}") }
}
