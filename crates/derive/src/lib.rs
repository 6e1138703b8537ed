//! Derivative stage of mdtf: reconstruction kernels and the measures that
//! multidimensional transfer functions are built on.
//!
//! [`run`] computes any set of [`Item`]s (value, gradient, g, normal,
//! Hessian, f'', Laplacian, 1/g, shading weight, and for multi-field input
//! the Jacobian and ||G||) in one fused separable pass over the volume, with
//! the [`Kernel`] family and [`Border`] policy of [`DeriveParams`].
//! Derivatives are per world unit along the grid axes (spacing applied);
//! outputs keep the input geometry.
//!
//! f'' is n^T H n with n = grad f / g (Kindlmann's second directional
//! derivative; Teem's `2ndDD`), 0 where g < epsilon. Multi-field measures
//! normalise each field to [0, 1] over its range first, so fields of
//! different units weigh alike (Kniss et al. 9.3.2).

mod border;
mod engine;
mod fused;
mod items;
mod kernel;
mod measures;
mod padding;
mod view;

pub use border::{BORDER_NAMES, Border};
pub use items::{ITEM_NAMES, Item, Needs, UnknownItem};
pub use kernel::{AxisTaps, DEFAULT_KERNEL, GAUSS_CUT, KERNEL_NAMES, Kernel, UnknownKernel};
pub use view::{FieldView, FieldsView};

use engine::{Engine, FieldInput, Stencil};
use mdtf_volume::{Field, MultiField};
use measures::{Layout, finish_shade};
use padding::PaddingMask;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Parameters of the derive stage (shared by `mdtf derive` and pipeline files).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DeriveParams {
    /// Items to compute. Default: g and f2.
    pub items: Vec<Item>,
    /// Kernel family. Default: central4, the most accurate on the erf sphere.
    pub kernel: Kernel,
    /// Border policy. Default: clamp.
    pub border: Border,
    /// g below this counts as zero for normal, f2 and inv_g (value units per world unit).
    /// Default (None): 1e-6 x value range / smallest spacing.
    pub epsilon: Option<f32>,
    /// Values of the first field that are scanner padding, not data
    /// (inclusive range, input units): every derived sample whose kernel
    /// reads one is NaN (see the `padding` module). None: no padding.
    pub padding: Option<[f32; 2]>,
}

impl Default for DeriveParams {
    fn default() -> Self {
        DeriveParams {
            items: vec![Item::G, Item::F2],
            kernel: Kernel::default(),
            border: Border::Clamp,
            epsilon: None,
            padding: None,
        }
    }
}

/// The default [`DeriveParams::epsilon`] of data whose finite values span
/// `span` (1 for fields normalised to [0, 1]) on a grid of smallest spacing
/// `min_spacing`: 1e-6 x span / min_spacing. A slab-by-slab run passes the
/// whole volume's, so every slab uses the same.
pub fn default_epsilon(span: f32, min_spacing: f64) -> f32 {
    1e-6 * span / min_spacing as f32
}

/// Errors of the derive stage.
#[derive(Debug, thiserror::Error)]
pub enum DeriveError {
    /// No items were requested.
    #[error("no items requested (valid: {ITEM_NAMES})")]
    NoItems,
    /// A multi-field item on one field, or a single-field item on several.
    #[error("{0}")]
    FieldCount(String),
    /// The volume is smaller than the kernel support along an axis.
    #[error("the volume is {dims} but kernel {kernel} needs at least {need} samples along {axis}")]
    TooSmall {
        /// Volume dims.
        dims: String,
        /// Kernel name.
        kernel: Kernel,
        /// Samples needed.
        need: usize,
        /// Axis name.
        axis: char,
    },
    /// A spacing is zero, negative or not finite.
    #[error("spacing {0:?} must be positive and finite")]
    BadSpacing([f64; 3]),
    /// The input holds NaN or infinite samples.
    #[error("field '{0}' holds NaN or infinite samples")]
    NonFinite(String),
    /// A parameter is out of range.
    #[error("{0}")]
    BadParameter(String),
}

/// The computed items, in the order requested, each a multi-field volume of
/// its components (e.g. normal: nx, ny, nz) with the input geometry.
#[derive(Debug, Clone)]
pub struct DeriveOutput {
    /// (item, its components).
    pub items: Vec<(Item, MultiField)>,
}

impl DeriveOutput {
    /// The output of one item, if it was requested.
    pub fn get(&self, item: Item) -> Option<&MultiField> {
        self.items.iter().find(|(i, _)| *i == item).map(|(_, m)| m)
    }
}

/// Runs the derive stage on `input`.
pub fn run(input: &MultiField, params: &DeriveParams) -> Result<DeriveOutput, DeriveError> {
    run_with_progress(input, params, None, &|_, _| {})
}

/// [`run`], reusing the memory of a `previous` output when its components
/// have the same count and size (slab-by-slab or repeated runs then skip
/// allocating and page-faulting fresh output memory, which on this class of
/// machine costs about as much as the pass itself), and calling
/// `progress(done, total)` as z-slices complete (from worker threads).
pub fn run_with_progress(
    input: &MultiField,
    params: &DeriveParams,
    previous: Option<DeriveOutput>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DeriveOutput, DeriveError> {
    run_view(&FieldsView::from(input), params, previous, progress)
}

/// [`run_with_progress`] on borrowed samples (no copy of the input).
pub fn run_view(
    input: &FieldsView,
    params: &DeriveParams,
    previous: Option<DeriveOutput>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DeriveOutput, DeriveError> {
    derive_slices(input, params, previous, 0..0, progress)
}

/// [`run_with_progress`] that computes every z-slice but those of `kept`:
/// their samples are `previous`'s, as they are (a caller sliding a block
/// along z moves the planes it already has to their new place first, and
/// derives only the new ones). `previous` must have this call's items and
/// grid; `shade` is refused (it is scaled by the whole output's largest g).
pub fn run_keeping(
    input: &MultiField,
    params: &DeriveParams,
    previous: DeriveOutput,
    kept: std::ops::Range<usize>,
) -> Result<DeriveOutput, DeriveError> {
    if params.items.contains(&Item::Shade) {
        return Err(DeriveError::BadParameter("shade is scaled by the whole output: no slice can be kept".into()));
    }
    let fits = previous.items.iter().map(|(i, _)| *i).eq(dedup(&params.items))
        && previous.items.iter().all(|(_, mf)| mf.geometry.dims == input.geometry.dims);
    if !fits {
        return Err(DeriveError::BadParameter(
            "the slices kept come from an output of other items or another grid".into(),
        ));
    }
    derive_slices(&FieldsView::from(input), params, Some(previous), kept, &|_, _| {})
}

/// The derive pass over every z-slice of `input` but those of `kept` (left as `previous` holds them).
fn derive_slices(
    input: &FieldsView,
    params: &DeriveParams,
    previous: Option<DeriveOutput>,
    kept: std::ops::Range<usize>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DeriveOutput, DeriveError> {
    let Prepared { items, layout, engine } = prepare(input, params)?;
    let g = input.geometry;
    let [nx, ny, nz] = g.dims;
    let plane = nx * ny;
    let mut buffers = reuse_buffers(previous, layout.components(), plane * nz);
    {
        let mut per_slice: Vec<Vec<&mut [f32]>> = (0..nz).map(|_| Vec::with_capacity(buffers.len())).collect();
        for buf in buffers.iter_mut() {
            for (k, chunk) in buf.chunks_mut(plane).enumerate() {
                per_slice[k].push(chunk);
            }
        }
        let done = AtomicUsize::new(0);
        per_slice.into_par_iter().enumerate().filter(|(k, _)| !kept.contains(k)).for_each_init(
            || engine.scratch(),
            |scratch, (k, mut outs)| {
                engine::compute_slice(&engine, &layout, k, scratch, &mut outs);
                progress(done.fetch_add(1, Ordering::Relaxed) + 1, nz);
            },
        );
    }

    let mut buffers = buffers.into_iter();
    let mut out = Vec::with_capacity(items.len());
    for &(item, _, n) in &layout.items {
        let names: Vec<String> = if item == Item::Jacobian {
            input.fields.iter().flat_map(|f| ["x", "y", "z"].map(|a| format!("d{}/d{a}", f.name))).collect()
        } else {
            item.components().iter().map(|s| s.to_string()).collect()
        };
        let mut comps = Vec::with_capacity(n);
        for name in names {
            let mut data = buffers.next().unwrap_or_default();
            if item == Item::Shade {
                finish_shade(&mut data);
            }
            let array = ndarray::Array3::from_shape_vec(g.shape(), data)
                .map_err(|e| DeriveError::BadParameter(format!("internal shape error: {e}")))?;
            comps.push(Field { name, data: array });
        }
        out.push((item, MultiField { geometry: g.clone(), fields: comps }));
    }
    Ok(DeriveOutput { items: out })
}

/// The derive pass without whole-volume outputs: computes `params.items`
/// z-slice by z-slice into buffers of one slice (nx ny samples per
/// component, x fastest; components in item order, e.g. `[g, f2]` for items
/// g, f2) and hands each slice to `consume(state, k, components)`.
///
/// Each range of `slabs` (z-slice indices, clipped to the volume) is one
/// rayon task, worked in increasing k with its own `init(task)` state; the
/// states come back in slab order. Results depend on the thread count only
/// if the slabs do: keep floating-point sums per fixed slab. `shade` is
/// refused: it needs the whole volume's largest g first.
pub fn stream_slices<S: Send>(
    input: &MultiField,
    params: &DeriveParams,
    slabs: &[std::ops::Range<usize>],
    init: impl Fn(usize) -> S + Sync,
    consume: impl Fn(&mut S, usize, &[Vec<f32>]) + Sync,
) -> Result<Vec<S>, DeriveError> {
    if params.items.contains(&Item::Shade) {
        return Err(DeriveError::BadParameter(
            "shade cannot be streamed slice by slice: it is scaled by the whole volume's largest g".into(),
        ));
    }
    let Prepared { layout, engine, .. } = prepare(&FieldsView::from(input), params)?;
    let [nx, ny, nz] = input.geometry.dims;
    Ok(slabs
        .par_iter()
        .enumerate()
        .map(|(t, slab)| {
            let mut state = init(t);
            let mut scratch = engine.scratch();
            let mut slices: Vec<Vec<f32>> = (0..layout.components()).map(|_| vec![0.0f32; nx * ny]).collect();
            for k in slab.start.min(nz)..slab.end.min(nz) {
                let mut outs: Vec<&mut [f32]> = slices.iter_mut().map(|b| b.as_mut_slice()).collect();
                engine::compute_slice(&engine, &layout, k, &mut scratch, &mut outs);
                consume(&mut state, k, &slices);
            }
            state
        })
        .collect())
}

/// Everything one derive pass needs, checked: the items (deduplicated), where
/// their components go, and the engine over the input's fields.
struct Prepared<'a> {
    items: Vec<Item>,
    layout: Layout,
    engine: Engine<'a>,
}

/// Checks that `items` can be derived together from `fields` fields:
/// multi-field items (gnorm, jacobian) and one-field items (g, f2, ...)
/// cannot be mixed, and one-field items need exactly one field.
pub fn check_field_count(items: &[Item], fields: usize) -> Result<(), DeriveError> {
    let multi: Vec<Item> = items.iter().copied().filter(|i| i.is_multi_field()).collect();
    let single: Vec<Item> = items.iter().copied().filter(|i| !i.is_multi_field() && !i.is_any_field_count()).collect();
    if !multi.is_empty() && !single.is_empty() {
        return Err(DeriveError::FieldCount(format!(
            "multi-field items ({}) and single-field items ({}) cannot be requested together",
            names(&multi),
            names(&single)
        )));
    }
    if !single.is_empty() && fields != 1 {
        return Err(DeriveError::FieldCount(format!(
            "items {} need one field, the input has {fields}; pick one field",
            names(&single)
        )));
    }
    Ok(())
}

/// Checks `params` against `input` and builds the pass (shared by [`run`]
/// and [`stream_slices`]).
fn prepare<'a>(input: &FieldsView<'a>, params: &DeriveParams) -> Result<Prepared<'a>, DeriveError> {
    let items = dedup(&params.items);
    if items.is_empty() {
        return Err(DeriveError::NoItems);
    }
    let g = input.geometry;
    let m = input.fields.len();
    check_field_count(&items, m)?;
    let multi: Vec<Item> = items.iter().copied().filter(|i| i.is_multi_field()).collect();
    if g.spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(DeriveError::BadSpacing(g.spacing));
    }
    if let Some(e) = params.epsilon
        && !(e.is_finite() && e >= 0.0)
    {
        return Err(DeriveError::BadParameter(format!("epsilon must be a non-negative number, got {e}")));
    }
    if let Kernel::Gauss { sigma } = params.kernel
        && !(sigma.is_finite() && sigma > 0.0)
    {
        return Err(DeriveError::BadParameter(format!("gauss sigma must be positive, got {sigma}")));
    }

    let ranges: Vec<(f32, f32)> = input
        .fields
        .iter()
        .map(|f| mdtf_volume::finite_range(f.samples).ok_or_else(|| DeriveError::NonFinite(f.name.to_string())))
        .collect::<Result<_, _>>()?;
    let base = [0, 1, 2].map(|a| params.kernel.axis_taps(g.spacing[a]));
    for (a, taps) in base.iter().enumerate() {
        let need = 2 * taps.radius() + 1;
        if g.dims[a] < need {
            return Err(DeriveError::TooSmall {
                dims: g.dims_string(),
                kernel: params.kernel,
                need,
                axis: ['x', 'y', 'z'][a],
            });
        }
    }

    let normalise = !multi.is_empty() || m > 1;
    let fields: Vec<FieldInput> = input
        .fields
        .iter()
        .zip(&ranges)
        .map(|(f, &(lo, hi))| {
            let factor = if normalise { if hi > lo { 1.0 / (hi as f64 - lo as f64) } else { 0.0 } } else { 1.0 };
            // Every derivative is a product of one x, one y and one z tap: scaling z's taps scales them all once.
            let [x, y, z] = base.clone();
            let z = z.scaled(factor);
            FieldInput { data: f.samples, stencil: Stencil { x, y, z } }
        })
        .collect();
    let epsilon = params.epsilon.unwrap_or_else(|| {
        let span = ranges.iter().map(|(l, h)| h - l).fold(0.0f32, f32::max);
        default_epsilon(if normalise { 1.0 } else { span }, g.min_spacing())
    });

    let fused = measures::fusable_items(&items) && Engine::fusable(&fields);
    let radius = [0, 1, 2].map(|a| base[a].radius());
    let padding =
        params.padding.zip(input.fields.first()).map(|(range, f)| PaddingMask::new(f.samples, g.dims, range, radius));
    let engine = Engine::new(fields, g.dims, params.border, Needs::of(&items), epsilon, fused).with_padding(padding);
    let layout = Layout::new(&items, m, epsilon, fused);
    Ok(Prepared { items, layout, engine })
}

/// `count` buffers of `len` samples (their contents are overwritten), in
/// the memory of `previous`'s while it has some (grown or shortened): a
/// caller deriving block after block hands each output back, and its blocks
/// differ in size at the volume's faces or in their items; fresh memory
/// page-faults, which costs about as much as the derivation.
fn reuse_buffers(previous: Option<DeriveOutput>, count: usize, len: usize) -> Vec<Vec<f32>> {
    // in order: a caller keeping slices (`run_keeping`) gets each component's own back
    let mut old = previous
        .map(|p| {
            p.items
                .into_iter()
                .flat_map(|(_, mf)| mf.fields.into_iter().map(|f| f.data.into_raw_vec_and_offset().0))
                .collect::<Vec<_>>()
        })
        .unwrap_or_default()
        .into_iter();
    (0..count)
        .map(|_| match old.next() {
            Some(mut b) => {
                b.resize(len, 0.0);
                b
            }
            None => vec![0.0f32; len],
        })
        .collect()
}

fn dedup(items: &[Item]) -> Vec<Item> {
    let mut out: Vec<Item> = Vec::new();
    for &i in items {
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

fn names(items: &[Item]) -> String {
    items.iter().map(|i| i.name()).collect::<Vec<_>>().join(", ")
}
