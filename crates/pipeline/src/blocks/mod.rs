//! Block execution: a pipeline run slab by slab under a memory budget, with
//! outputs byte-identical to the whole-volume [`run`](crate::run::run).
//!
//! The input is read once, by planes (uncompressed or gzip NIfTI/NRRD;
//! other formats and phantoms are read whole first), into a
//! [`ChannelStore`] on disk in the staging folder. Each pass works on
//! z-slabs grown by its own halo from the plan ([`Plan::reach`]): derive
//! (the kernel's support), the pre-filter (its box), the tracing (d_max plus
//! the tricubic support at the hit). What a later pass cannot remake
//! cheaply (the pre-filtered g and f'', the tracing's outputs) goes into
//! the store; the derivatives are remade from the stored value by each pass
//! that reads them ([`SlabChannels`]: on this machine's page cache that is
//! cheaper than writing them), the tracing's overlapping blocks sliding so
//! that each plane is derived about once. When whole planes grown by the
//! tracing's halo do not fit the budget (1024^2 planes in 1 GiB), the
//! tracing visits each slab in strips of rows ([`fit_trace`]), strip by
//! strip and down z within each, so the sliding still holds (with the
//! pre-filter, the filtered g and f'' are read from the store over each
//! block); its sums are exact, so the order of the blocks does not show in
//! the report.
//!
//! The passes: input (the value's statistics); derive (the statistics of
//! g, f'' and 1/g, and the first radix pass of g's median); pre-filter;
//! tracing; kept volumes; then one pass that counts every histogram and
//! quantises every pack texture from the same slab's channels. The
//! whole-volume quantities are reductions that merge exactly: finite
//! ranges and the percentile tails ([`ChannelStats`]), medians (radix
//! selects over the slabs), histogram counts, the histogram volume's sums
//! (per fixed part of the slices, fed slice by slice, as the whole run sums
//! them; parts on parallel lanes that share one array of counts), the
//! Fig. 2 report's sums (fed in voxel order) and the crossings.
//!
//! In the input, derive, tracing and pack passes a slab's outputs are
//! written (and summarised) while the next slab is made
//! ([`mdtf_volume::overlapped`]): the copies into the page cache run on one
//! thread, and would otherwise leave the other lanes idle. The budget counts
//! the two slabs' outputs that this keeps alive.
//!
//! A pass makes each slab in the memory of the slab before's (the derive
//! output handed back, the channels' copies and store reads through a
//! [`SamplePool`], the tracing's outputs, the pack's texture bytes): at
//! 1024^2 planes a slab's arrays are beyond what glibc keeps for reuse, and
//! mapping them fresh for every slab page-faults on every 4 KiB, which had
//! cost the kernel as much time as the derivation.
//!
//! The derive, pre-filter and tracing passes can run as tasks elsewhere
//! ([`RunOptions::tasks`], [`SlabTasks`]; the Python package's
//! `mdtf.dask.run` gives them to a Dask cluster): the tasks store what they
//! make ([`run_task`]) and the run reads it back slab by slab for the same
//! reductions (see the `remote` module).
//!
//! Scope: one-field inputs, the slicer-3dtf, distance-tf, peak-finding and
//! gaussian-tf profiles (with or without a TF file, pre-filter, kept
//! channels and histograms). Others are refused with the reason, before any work.

mod budget;
mod item_files;
mod medians;
mod partials;
mod passes;
mod pool;
mod reductions;
mod remote;
mod resume;
mod sizing;
mod slab_channels;
mod slab_histograms;
mod store;
mod tasks;
mod trace;
mod trace_files;

use crate::inputs::InputMeta;
pub use budget::{
    BudgetError, TraceBlocks, automatic_budget, automatic_file_budget, fit_slabs, fit_trace, slab_height, slabs,
    usable_memory,
};
pub use item_files::{ItemFiles, automatic_item_budget, derive_item_files, items_unsupported};
pub use medians::{SelectCounts, SelectPass};
pub use partials::{SlabPartial, TracePartial};
pub use pool::SamplePool;
pub use remote::{Prefilter, SlabJob, SlabPass, SlabTasks, TaskFailed};
pub use resume::WrittenPiece;
pub use sizing::{PassSize, Sizing, SizingError, sizing};
pub use slab_channels::{ChannelError, SlabChannels, by_name, channels_named};
pub use slab_histograms::{HistogramAxes, HistogramCounts};
pub use store::{ChannelStore, StoreWriter};
pub use tasks::{TaskOutcome, run_task};
pub use trace_files::{TracedFiles, automatic_trace_budget, trace_files};

use crate::progress::{Progress, cancelled};
use crate::run::{RunError, RunOptions, RunReport, at, fail};
use crate::settings::{InputSettings, Settings};
use mdtf_pack::Profile;
use mdtf_volume::{Geometry, OutputFolder, PlaneReader, Volume};
use passes::{SlabPasses, SlabWork};
use std::ops::Range;
use std::path::Path;
use std::time::Instant;

/// Bytes per voxel of the textures the preview reads from a pack at most
/// (it reads them in place: slicer-3dtf's two RGBA8 textures, gaussian-tf's
/// RGBA16 fields; distance-tf's and peak-finding's are 6 and 4).
const PREVIEW_BYTES_PER_VOXEL: usize = 8;

/// Why a slab-by-slab run cannot take an input with `fields`, if it cannot.
fn unsupported_fields(fields: usize) -> Option<String> {
    (fields > 1).then(|| format!("the input has {fields} fields; slab-by-slab runs take one-field inputs"))
}

/// Why a run of `s` cannot go slab by slab on an input with `fields`, if it cannot.
pub fn unsupported(s: &Settings, fields: usize) -> Option<String> {
    if let Some(why) = unsupported_fields(fields) {
        return Some(why);
    }
    let (pack, keep) = (&s.outputs.pack, &s.outputs.keep);
    if pack.profile == Profile::ProjectedTetrahedra {
        return Some("the projected-tetrahedra profile does not run slab by slab: it meshes the whole volume".into());
    }
    if pack.gtf_from_mask.is_some() {
        return Some("a Gaussian fitted to a mask (pack.gtf_from_mask) reads the whole mask and its voxels".into());
    }
    if keep.iter().any(|c| c == "shade") {
        return Some("the shading weight (keep = [\"shade\"]) divides by the largest g of the whole volume".into());
    }
    if pack.nifti {
        return Some("NIfTI copies of the textures (pack.nifti) need each whole texture".into());
    }
    None
}

/// The budget a run of `s` without `--memory-budget` takes (see
/// [`automatic_budget`]) and the whole run's grid, when the run would not
/// fit in memory as a whole and can go by slabs: its input is a one-field
/// file read by planes (its header tells the grid without reading the
/// samples) and its profile runs by slabs. None otherwise.
pub fn automatic(s: &Settings) -> Option<(u64, Geometry)> {
    if unsupported(s, 1).is_some() {
        return None;
    }
    let reader = PlaneReader::open(s.input.file()?, &s.input.read).ok()??;
    let geo = reader.geometry().clone();
    let budget = automatic_budget(s.profile(), geo.voxel_count() as u64, mdtf_volume::available_memory())?;
    Some((budget, geo))
}

/// The input, read by planes where its format allows, else whole.
enum Source {
    Planes(PlaneReader),
    Whole(Volume),
}

impl Source {
    /// The one-field volume in `path`: by planes when its format allows, else read whole.
    fn of_file(path: &Path, read: &mdtf_volume::ReadOptions) -> Result<Source, RunError> {
        if let Some(r) = PlaneReader::open(path, read).map_err(at("input"))? {
            return Ok(Source::Planes(r));
        }
        let mf = mdtf_volume::read(path, read).map_err(at("input"))?;
        let v = mf.into_scalar().map_err(|e| fail("input")(format!("{}: {e}", path.display())))?;
        Ok(Source::Whole(v))
    }

    fn geometry(&self) -> &Geometry {
        match self {
            Source::Planes(r) => r.geometry(),
            Source::Whole(v) => &v.geometry,
        }
    }

    fn read(&mut self, z: Range<usize>) -> Result<Volume, RunError> {
        match self {
            Source::Planes(r) => r.read(z).map_err(at("input")),
            Source::Whole(v) => Ok(v.z_slab(z)),
        }
    }
}

/// The `input` of a run of `s` (None: the tracing alone) as a [`Source`],
/// with its name, its reader's warnings and its units.
fn open_source(input: &InputSettings, s: Option<&Settings>) -> Result<(Source, InputMeta), RunError> {
    if let Some(f) = input.file()
        && input.read.dicom.series.is_none()
        && let Some(r) = PlaneReader::open(f, &input.read).map_err(at("input"))?
    {
        let (padding, padding_source) = crate::inputs::padding_of(input, None);
        let units = r.units().clone();
        let meta = InputMeta { name: f.display().to_string(), warnings: Vec::new(), units, padding, padding_source };
        return Ok((Source::Planes(r), meta));
    }
    let (mf, meta) = crate::inputs::load_input(input)?;
    let fields = mf.fields.len();
    if let Some(why) = s.map_or_else(|| unsupported_fields(fields), |s| unsupported(s, fields)) {
        return Err(fail("plan")(why));
    }
    let v = mf.into_scalar().map_err(at("input"))?;
    Ok((Source::Whole(v), meta))
}

/// The z-range a pass reads for slab `z` with `halo` planes each side,
/// grown to at least `min` planes where the volume allows (derive needs a
/// kernel's width), clamped to `nz`.
fn grown(z: &Range<usize>, halo: usize, min: usize, nz: usize) -> Range<usize> {
    let (mut lo, mut hi) = (z.start.saturating_sub(halo), (z.end + halo).min(nz));
    while hi - lo < min.min(nz) {
        if hi < nz {
            hi += 1;
        } else {
            lo -= 1;
        }
    }
    lo..hi
}

/// How tall the slabs of a run are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlabSize {
    /// The tallest whose passes fit in this many bytes ([`slab_height`]).
    Budget(u64),
    /// This many z-planes (at least 1; for tests and benchmarks).
    Planes(usize),
    /// Slabs of `planes` z-planes (at least 1), the tracing's cut in strips
    /// of `rows` rows as well (for tests and benchmarks of the strips a
    /// tight budget makes).
    Strips {
        /// Planes per slab.
        planes: usize,
        /// Rows per strip of the tracing.
        rows: usize,
    },
}

/// How a run of `plan` on `geometry` cuts the volume with slabs of
/// `size`: the slab height (planes) and the tracing's blocks; with `hvol`
/// the histogram volume's counts are in the budget.
pub(crate) fn cut(
    size: SlabSize,
    geometry: &Geometry,
    plan: &crate::plan::Plan,
    hvol: bool,
) -> Result<(usize, TraceBlocks), BudgetError> {
    let [_, ny, nz] = geometry.dims;
    Ok(match size {
        SlabSize::Budget(b) => {
            let h = fit_slabs(b, geometry, plan, hvol, true)?;
            (h, fit_trace(b, geometry, plan, h, rayon::current_num_threads(), true)?)
        }
        SlabSize::Planes(h) => {
            let h = h.clamp(1, nz.max(1));
            (h, TraceBlocks { planes: h, rows: ny })
        }
        SlabSize::Strips { planes, rows } => {
            let h = planes.clamp(1, nz.max(1));
            (h, TraceBlocks { planes: h, rows: rows.clamp(1, ny.max(1)) })
        }
    })
}

/// Runs the pipeline of settings `s` slab by slab, slabs of `size`;
/// `on_stage(name)` is called as each pass starts, `on_slab(k, slabs)` as
/// it starts its slab k (from 1). The outputs equal [`run`](crate::run::run)'s.
pub fn run(
    s: &Settings,
    opts: &RunOptions,
    size: SlabSize,
    on_stage: &(dyn Fn(&str) + Sync),
    on_slab: &(dyn Fn(usize, usize) + Sync),
) -> Result<RunReport, RunError> {
    // a cancelled run fails wherever it noticed (a slab's read fails first): it ends as cancelled
    run_slabs(s, opts, size, on_stage, on_slab).map_err(|e| if opts.is_cancelled() { cancelled() } else { e })
}

/// [`run`], with whatever error stopped it: the passes in order.
fn run_slabs(
    s: &Settings,
    opts: &RunOptions,
    size: SlabSize,
    on_stage: &(dyn Fn(&str) + Sync),
    on_slab: &(dyn Fn(usize, usize) + Sync),
) -> Result<RunReport, RunError> {
    let start = Instant::now();
    if let Some(why) = unsupported(s, 1) {
        return Err(fail("plan")(why));
    }
    let inputs = crate::inputs::run_inputs(s);
    let resumable = opts.tasks.is_some() && opts.resume;
    let out = match resumable {
        true => OutputFolder::begin_resumable(&opts.output, &inputs, &resume::resume_key(s, size)?),
        false => OutputFolder::begin(&opts.output, &inputs),
    }
    .map_err(at("output"))?;
    if out.resumed() {
        resume::keep_task_outputs(out.path())?;
    }
    let progress = Progress::new(opts, on_stage, on_slab);
    match run_passes(s, opts, size, &out, progress) {
        Ok(done) => crate::run::finish(&done.settings, opts, out, done.report, &done.tables, start, &done.progress),
        // a failed task (a worker out of memory, a full disk) need not cost the tasks done: a rerun resumes
        Err(e) if resumable && !opts.is_cancelled() && resume::some_task_done(out.path()) => Err(resume::kept(out, e)),
        Err(e) => Err(e),
    }
}

/// What the passes of a run leave for its end: the settings as it
/// finishes (without an unaffordable preview), the report, the pack's
/// tables and the progress.
struct Passed<'a> {
    settings: Settings,
    report: RunReport,
    tables: Vec<String>,
    progress: Progress<'a>,
}

/// The passes of [`run`] in order, into the staging folder `out`.
fn run_passes<'a>(
    s: &'a Settings,
    opts: &'a RunOptions,
    size: SlabSize,
    out: &OutputFolder,
    progress: Progress<'a>,
) -> Result<Passed<'a>, RunError> {
    let work = SlabWork::Pipeline(s);
    let (mut run, store) = SlabPasses::read_input(work, opts, size, (out.path(), out.resumed()), progress)?;
    let (mut chans, derived) = run.derive(store)?;
    let traced = run.trace(&mut chans, &derived)?;
    run.keep(&mut chans)?;
    let (table_names, boundaries) = run.pack(&mut chans, &derived, &traced)?;
    chans.store.clear();
    let finishing = without_unaffordable_preview(s, opts, size, &run.geo, &mut run.warnings);
    let report = RunReport {
        value_range: run.finite_range(),
        boundary: traced.boundary,
        boundaries,
        hvol_built: run.detected(),
        slabs: Some(crate::report::SlabRun {
            planes: run.height,
            count: run.slabs.len(),
            budget: match size {
                SlabSize::Budget(b) => Some(b),
                SlabSize::Planes(_) | SlabSize::Strips { .. } => None,
            },
            tasks: std::mem::take(&mut run.task_passes),
            resumed: run.resumed,
        }),
        units: run.units.clone(),
        ..RunReport::of(opts, run.input_name.clone(), &run.geo)
    };
    let report = RunReport { warnings: run.warnings, stages: run.stages.0, ..report };
    Ok(Passed { settings: finishing, report, tables: table_names, progress: run.progress })
}

/// `s` without its preview when the memory it may take (a `size` budget,
/// else three quarters of the available memory: slabs of a given height
/// are no budget, and a cluster run's pack can be any size) cannot hold the
/// textures of the pack it reads (`mdtf preview` renders it where there is
/// the memory), with a warning saying so.
fn without_unaffordable_preview(
    s: &Settings,
    opts: &RunOptions,
    size: SlabSize,
    geo: &Geometry,
    warnings: &mut Vec<String>,
) -> Settings {
    let mut finishing = s.clone();
    if let Some(why) = preview_unaffordable(size, geo, mdtf_volume::available_memory())
        && s.outputs.preview
    {
        finishing.outputs.preview = false;
        let pack = opts.output.join("pack");
        warnings.push(format!(
            "preview: not rendered: {why}; `mdtf preview {}` renders it where there is the memory",
            pack.display()
        ));
    }
    finishing
}

/// Why the preview of a run of slabs of `size` on `geo` would not fit, with
/// `available` bytes of memory, if it would not.
fn preview_unaffordable(size: SlabSize, geo: &Geometry, available: u64) -> Option<String> {
    let preview_bytes = (PREVIEW_BYTES_PER_VOXEL * geo.voxel_count()) as u64;
    let (limit, what) = match size {
        SlabSize::Budget(b) => (b, "the memory budget of"),
        SlabSize::Planes(_) | SlabSize::Strips { .. } => {
            (usable_memory(available), "three quarters of the available memory,")
        }
    };
    let human = |b: u64| mdtf_volume::human_bytes(b as u128);
    (preview_bytes > limit).then(|| {
        format!(
            "it reads the pack's textures at full resolution (about {}), more than {what} {}",
            human(preview_bytes),
            human(limit)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_preview_larger_than_the_memory_it_may_take_is_skipped_whatever_cut_the_slabs() {
        // 8 bytes a voxel of 1024 x 512 x 512 are 2 GiB
        let (big, small) = (Geometry::new([1024, 512, 512], [1.0; 3]), Geometry::new([64; 3], [1.0; 3]));
        let gib = 1u64 << 30;
        let why = preview_unaffordable(SlabSize::Planes(64), &big, 2 * gib).unwrap();
        assert!(why.contains("three quarters of the available memory, 1.5 GiB") && why.contains("2.0 GiB"), "{why}");
        assert!(preview_unaffordable(SlabSize::Strips { planes: 8, rows: 8 }, &big, 2 * gib).is_some());
        assert!(preview_unaffordable(SlabSize::Planes(64), &big, 8 * gib).is_none());
        assert!(preview_unaffordable(SlabSize::Planes(64), &small, 2 * gib).is_none());
        let why = preview_unaffordable(SlabSize::Budget(gib), &big, 64 * gib).unwrap();
        assert!(why.contains("the memory budget of 1.0 GiB"), "{why}");
    }
}
