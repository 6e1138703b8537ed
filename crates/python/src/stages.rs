//! The stages on numpy arrays: derive, bilateral, boundary, histogram and
//! quantise. Each reads its arrays where numpy holds them (no copy), runs
//! with the GIL released ([`crate::call`]) and hands its outputs to numpy
//! without a copy.

use crate::call::run_released;
use crate::convert::{array, geometry, view};
use crate::error::{mdtf_error, parse_choice, value_error};
use mdtf_pipeline::boundary_chain::{self, BoundaryChainParams};
use mdtf_pipeline::stages::bilateral::BilateralParams;
use mdtf_pipeline::stages::boundary::BoundaryParams;
use mdtf_pipeline::stages::derive::{DeriveParams, FieldView, FieldsView, Item, Kernel};
use mdtf_pipeline::stages::histogram::{Axis, AxisSpec, count};
use mdtf_pipeline::stages::pack::Dtype;
use ndarray::{Array3, ArrayView3, Zip};
use numpy::{IntoPyArray, PyArrayDyn, PyReadonlyArray3, PyUntypedArray};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The derivative kernel named `kernel` (None: derive's default).
fn kernel(kernel: Option<&str>) -> PyResult<Kernel> {
    kernel.map_or(Ok(Kernel::default()), |k| k.parse::<Kernel>().map_err(value_error))
}

/// Views of named (z, y, x) arrays, checked to share one shape.
fn views<'a>(fields: &'a [(String, PyReadonlyArray3<'_, f32>)]) -> PyResult<Vec<(&'a str, ArrayView3<'a, f32>)>> {
    let views: Vec<(&str, ArrayView3<f32>)> =
        fields.iter().map(|(n, a)| Ok((n.as_str(), view(n, a)?))).collect::<PyResult<_>>()?;
    if let Some((first, v0)) = views.first()
        && let Some((n, v)) = views.iter().find(|(_, v)| v.dim() != v0.dim())
    {
        return Err(value_error(format!("field {n} has shape {:?}, field {first} {:?}", v.dim(), v0.dim())));
    }
    Ok(views)
}

/// The (z, y, x) shape of a view.
fn shape(v: &ArrayView3<'_, f32>) -> [usize; 3] {
    let (z, y, x) = v.dim();
    [z, y, x]
}

/// Derivative measures of `fields` (name, (z, y, x) array), one array per
/// component: `g`, `f2`, ... by item name; several components by their own
/// names (`nx`, `ny`, `nz` for the normal).
#[pyfunction]
#[pyo3(signature = (fields, spacing, items, kernel=None, border=None, epsilon=None))]
#[allow(clippy::too_many_arguments)]
pub fn derive<'py>(
    py: Python<'py>,
    fields: Vec<(String, PyReadonlyArray3<'py, f32>)>,
    spacing: [f64; 3],
    items: Vec<String>,
    kernel: Option<&str>,
    border: Option<&str>,
    epsilon: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let items = items.iter().map(|s| s.parse::<Item>().map_err(value_error)).collect::<PyResult<Vec<_>>>()?;
    let border = match border {
        Some(b) => parse_choice("border", b, mdtf_pipeline::stages::derive::BORDER_NAMES)?,
        None => mdtf_pipeline::stages::derive::Border::default(),
    };
    let params = DeriveParams { items, kernel: self::kernel(kernel)?, border, epsilon, padding: None };
    let views = views(&fields)?;
    let Some((_, first)) = views.first() else { return Err(value_error("derive: give at least one field")) };
    let geo = geometry(shape(first), spacing, [0.0; 3])?;
    // the arrays are read where numpy holds them: no copy of the input
    let out = run_released(py, None, || {
        let samples: Vec<FieldView> =
            views.iter().map(|(n, v)| FieldView { name: n, samples: v.as_slice().unwrap_or(&[]) }).collect();
        mdtf_pipeline::stages::derive::run_view(&FieldsView::new(&geo, samples)?, &params, None, &|_, _| {})
    })?
    .map_err(mdtf_error)?;
    let d = PyDict::new(py);
    for (item, mf) in out.items {
        if mf.fields.len() == 1 {
            d.set_item(item.name(), array(py, mf.into_scalar().map_err(mdtf_error)?))?;
        } else {
            for (name, v) in mf.into_volumes() {
                d.set_item(name, array(py, v))?;
            }
        }
    }
    Ok(d)
}

/// The bilateral filter of a (z, y, x) array.
#[pyfunction]
#[pyo3(signature = (values, spacing, sigma_d=1.0, sigma_r=0.05, range_units="fraction", mode="exact", k=None))]
#[allow(clippy::too_many_arguments)]
pub fn bilateral<'py>(
    py: Python<'py>,
    values: PyReadonlyArray3<'py, f32>,
    spacing: [f64; 3],
    sigma_d: f64,
    sigma_r: f64,
    range_units: &str,
    mode: &str,
    k: Option<f64>,
) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
    let defaults = BilateralParams::default();
    let params = BilateralParams {
        sigma_d,
        sigma_r,
        range_units: parse_choice("range_units", range_units, "fraction, value")?,
        mode: parse_choice("mode", mode, "exact, fast")?,
        k: k.unwrap_or(defaults.k),
    };
    let v = view("values", &values)?;
    let geo = geometry(shape(&v), spacing, [0.0; 3])?;
    let out = run_released(py, None, || {
        mdtf_pipeline::stages::bilateral::run_on(&geo, v.as_slice().unwrap_or(&[]), &params)
    })?
    .map_err(mdtf_error)?;
    Ok(array(py, out))
}

/// Distance to the nearest boundary of a (z, y, x) value array: derive (g,
/// f'', normal), the optional bilateral pre-filter of g and f'', and the
/// tracing, as `mdtf boundary --input` runs them. A z-slab of a larger
/// volume passes the whole volume's `epsilon` and its `first_plane` there.
#[pyfunction]
#[pyo3(signature = (values, spacing, kernel=None, prefilter=None, g_min=None, g_hit_min=None, step=None, d_max=None, tolerance=None, epsilon=None, first_plane=0))]
#[allow(clippy::too_many_arguments)]
pub fn boundary<'py>(
    py: Python<'py>,
    values: PyReadonlyArray3<'py, f32>,
    spacing: [f64; 3],
    kernel: Option<&str>,
    prefilter: Option<(f64, f64)>,
    g_min: Option<f64>,
    g_hit_min: Option<f64>,
    step: Option<f64>,
    d_max: Option<f64>,
    tolerance: Option<f64>,
    epsilon: Option<f32>,
    first_plane: usize,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
    let defaults = BoundaryParams::default();
    let params = BoundaryChainParams {
        kernel: self::kernel(kernel)?,
        prefilter: prefilter.map(|(sigma_d, sigma_r)| BilateralParams { sigma_d, sigma_r, ..Default::default() }),
        boundary: BoundaryParams {
            g_min,
            g_hit_min,
            step,
            d_max,
            tolerance: tolerance.unwrap_or(defaults.tolerance),
            ..defaults
        },
        ..Default::default()
    };
    let v = view("values", &values)?;
    let geo = geometry(shape(&v), spacing, [0.0; 3])?;
    let out = run_released(py, None, || {
        let at = boundary_chain::Placement { epsilon, first_plane };
        boundary_chain::run_on(&geo, v.as_slice().unwrap_or(&[]), &params, &at)
    })?
    .map_err(mdtf_error)?;
    let mut b = out.boundary;
    let arrays = PyDict::new(py);
    for (name, v) in boundary_chain::take_traced(&mut b) {
        arrays.set_item(name, array(py, v))?;
    }
    arrays.set_item("g", array(py, out.g))?;
    arrays.set_item("f2", array(py, out.f2))?;
    let summary = PyDict::new(py);
    let r = b.resolved;
    for (name, x) in [
        ("noise_floor", r.noise_floor),
        ("g_min", r.g_min),
        ("g_hit_min", r.g_hit_min),
        ("step", r.step),
        ("d_max", r.d_max),
        ("tolerance", r.tolerance),
    ] {
        summary.set_item(name, x)?;
    }
    let c = b.counts;
    for (name, n) in
        [("hits", c.hits), ("not_traced", c.not_traced), ("no_crossing", c.no_crossing), ("rejected", c.rejected)]
    {
        summary.set_item(name, n)?;
    }
    summary.set_item("warnings", b.warnings)?;
    Ok((arrays, summary))
}

/// One axis of a histogram: its channel's name, and how to choose its range and bins.
type AxisRequest = (String, Option<(f64, f64)>, Option<usize>);

/// A resolved axis: name, min, max, bins.
type AxisOut = (String, f64, f64, usize);

/// The joint histogram of 1 to 3 (z, y, x) arrays, each axis named (its
/// default range clipped as Teem's qbert clips that channel, see
/// `mdtf histogram --help`). Returns the counts, shape (bins of the last
/// axis, ..., bins of the first), and the axes (name, min, max, bins).
#[pyfunction]
#[pyo3(signature = (channels, axes, mask=None))]
pub fn histogram<'py>(
    py: Python<'py>,
    channels: Vec<PyReadonlyArray3<'py, f32>>,
    axes: Vec<AxisRequest>,
    mask: Option<PyReadonlyArray3<'py, bool>>,
) -> PyResult<(Bound<'py, PyArrayDyn<u64>>, Vec<AxisOut>)> {
    if channels.len() != axes.len() {
        return Err(value_error(format!(
            "{} channels and {} axes: give one axis per channel",
            channels.len(),
            axes.len()
        )));
    }
    let views: Vec<ArrayView3<f32>> = channels.iter().map(|a| view("channel", a)).collect::<PyResult<_>>()?;
    let mask_view = mask.as_ref().map(|m| m.as_array());
    if let Some(m) = &mask_view
        && (views.first().is_some_and(|v| v.dim() != m.dim()) || !m.is_standard_layout())
    {
        return Err(value_error("mask: must be a C-contiguous boolean array of the channels' shape"));
    }
    let h = run_released(py, None, || -> Result<_, mdtf_pipeline::stages::histogram::HistogramError> {
        let samples: Vec<&[f32]> = views.iter().map(|v| v.as_slice().unwrap_or(&[])).collect();
        let resolved: Vec<Axis> = axes
            .iter()
            .zip(&samples)
            .map(|((name, range, bins), data)| {
                let spec = AxisSpec { range: *range, bins: *bins, ..AxisSpec::qbert(name) };
                spec.resolve(name, data)
            })
            .collect::<Result<_, _>>()?;
        count(&samples, resolved, mask_view.as_ref().and_then(|m| m.as_slice()))
    })?
    .map_err(mdtf_error)?;
    let shape: Vec<usize> = h.axes.iter().rev().map(|a| a.bins).collect();
    let counts = ndarray::ArrayD::from_shape_vec(shape, h.counts).map_err(mdtf_error)?;
    let axes = h.axes.into_iter().map(|a| (a.name, a.min, a.max, a.bins)).collect();
    Ok((counts.into_pyarray(py), axes))
}

/// The codes of a (z, y, x) array stored as `dtype` over [min, max], as the
/// pack stores a channel (value = offset + scale * code; with `signed`, 0
/// is exactly a code). Returns (codes, offset, scale).
#[pyfunction]
#[pyo3(signature = (values, min, max, dtype="u8", signed=false, name="channel"))]
pub fn quantise<'py>(
    py: Python<'py>,
    values: PyReadonlyArray3<'py, f32>,
    min: f64,
    max: f64,
    dtype: &str,
    signed: bool,
    name: &str,
) -> PyResult<(Bound<'py, PyUntypedArray>, f64, f64)> {
    let dtype: Dtype = parse_choice("dtype", dtype, "u8, u16, f16, f32")?;
    let decode = mdtf_pipeline::stages::pack::decode_for(name, min, max, dtype, signed).map_err(mdtf_error)?;
    let v = view("values", &values)?;
    let codes = run_released(py, None, || {
        let mut codes = Array3::<u32>::zeros(v.dim());
        Zip::from(&mut codes).and(&v).par_for_each(|c, &x| *c = decode.code(x, dtype));
        codes
    })?;
    let out: Bound<'py, PyUntypedArray> = match dtype {
        Dtype::U8 => codes.mapv(|c| c as u8).into_pyarray(py).into_any().cast_into()?,
        Dtype::U16 | Dtype::F16 => codes.mapv(|c| c as u16).into_pyarray(py).into_any().cast_into()?,
        Dtype::F32 => codes.mapv(f32::from_bits).into_pyarray(py).into_any().cast_into()?,
    };
    Ok((out, decode.offset, decode.scale))
}
