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
//! that each plane is derived about once.
//!
//! The passes: input (the value's statistics); derive (the statistics of
//! g, f'' and 1/g, and the first radix pass of g's median); pre-filter;
//! tracing; kept volumes; then one pass that counts every histogram and
//! quantises every pack texture from the same slab's channels. The
//! whole-volume quantities are reductions that merge exactly: finite
//! ranges and the percentile tails ([`ChannelStats`]), medians (radix
//! selects over the slabs), histogram counts, the histogram volume's sums
//! (per fixed part of the slices, fed slice by slice, as the whole run sums
//! them; parts on parallel lanes when the budget pays for their counts),
//! the Fig. 2 report's sums (fed in voxel order) and the crossings.
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
mod medians;
mod reductions;
mod remote;
mod slab_channels;
mod store;
mod trace;

pub use budget::{automatic_budget, fit_slabs, slab_height, slabs};
pub use remote::{Prefilter, SlabJob, SlabPass, SlabTasks, TracePartial, run_task};
pub use slab_channels::SlabChannels;
pub use store::ChannelStore;

use crate::file::Pipeline;
use crate::plan::Plan;
use crate::progress::{Progress, cancelled};
use crate::report::Stages;
use crate::run::{RunError, RunOptions, RunReport, at, fail};
use mdtf_boundary::ReportAccumulator;
use mdtf_derive::DeriveParams;
use mdtf_histogram::{ChannelStats, Histogram};
use mdtf_pack::{PackParams, PackWriter, Profile};
use mdtf_volume::{Geometry, OutputFolder, PlaneReader, Volume};
use reductions::{SlabHistograms, Stats, g_stats};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::time::Instant;

/// f32 volumes the preview decodes from a pack at most (value, g, f'', three normals).
const PREVIEW_CHANNELS: usize = 6;

/// Why `p` cannot run slab by slab on an input with `fields`, if it cannot.
pub fn unsupported(p: &Pipeline, fields: usize) -> Option<String> {
    if fields > 1 {
        return Some(format!("the input has {fields} fields; slab-by-slab runs take one-field inputs"));
    }
    if p.pack.profile == Profile::ProjectedTetrahedra {
        return Some("the projected-tetrahedra profile does not run slab by slab: it meshes the whole volume".into());
    }
    if p.pack.gtf_from_mask.is_some() {
        return Some("a Gaussian fitted to a mask (pack.gtf_from_mask) reads the whole mask and its voxels".into());
    }
    if p.pack.nifti {
        return Some("NIfTI copies of the textures (pack.nifti) need each whole texture".into());
    }
    None
}

/// The budget a run of `p` without `--memory-budget` takes (see
/// [`automatic_budget`]) and the whole run's grid, when the run would not
/// fit in memory as a whole and can go by slabs: its input is a one-field
/// file read by planes (its header tells the grid without reading the
/// samples) and its profile runs by slabs. None otherwise.
pub fn automatic(p: &Pipeline, opts: &RunOptions) -> Option<(u64, Geometry)> {
    let base = opts.pipeline_path.parent().map(Path::to_path_buf).unwrap_or_default();
    if unsupported(p, 1).is_some() {
        return None;
    }
    let file = crate::inputs::input_file(p, opts, &base)?;
    let reader = PlaneReader::open(&file, &crate::inputs::read_options(p)).ok()??;
    let geo = reader.geometry().clone();
    let budget = automatic_budget(p.pack.profile, geo.voxel_count() as u64, mdtf_volume::available_memory())?;
    Some((budget, geo))
}

/// The input, read by planes where its format allows, else whole.
enum Source {
    Planes(PlaneReader),
    Whole(Volume),
}

impl Source {
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

/// The input of `p` as a [`Source`], its name for the report and its reader's warnings.
fn open_source(p: &Pipeline, opts: &RunOptions, base: &Path) -> Result<(Source, String, Vec<String>), RunError> {
    if let Some(f) = crate::inputs::input_file(p, opts, base)
        && p.input.series.is_none()
        && let Some(r) = PlaneReader::open(&f, &crate::inputs::read_options(p)).map_err(at("input"))?
    {
        return Ok((Source::Planes(r), f.display().to_string(), Vec::new()));
    }
    let (mf, name, warnings) = crate::inputs::load_input(p, opts, base)?;
    if let Some(why) = unsupported(p, mf.fields.len()) {
        return Err(fail("plan")(why));
    }
    let v = mf.into_scalar().map_err(at("input"))?;
    Ok((Source::Whole(v), name, warnings))
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
}

/// Runs `p` slab by slab, slabs of `size`; `on_stage(name)` is called as
/// each pass starts, `on_slab(k, slabs)` as it starts its slab k (from 1).
/// The outputs equal [`run`](crate::run::run)'s.
pub fn run(
    p: &Pipeline,
    opts: &RunOptions,
    size: SlabSize,
    on_stage: &dyn Fn(&str),
    on_slab: &dyn Fn(usize, usize),
) -> Result<RunReport, RunError> {
    // a cancelled run fails wherever it noticed (a slab's read fails first): it ends as cancelled
    run_slabs(p, opts, size, on_stage, on_slab).map_err(|e| if opts.is_cancelled() { cancelled() } else { e })
}

/// [`run`], with whatever error stopped it.
fn run_slabs(
    p: &Pipeline,
    opts: &RunOptions,
    size: SlabSize,
    on_stage: &dyn Fn(&str),
    on_slab: &dyn Fn(usize, usize),
) -> Result<RunReport, RunError> {
    let start = Instant::now();
    let base = opts.pipeline_path.parent().map(Path::to_path_buf).unwrap_or_default();
    if let Some(why) = unsupported(p, 1) {
        return Err(fail("plan")(why));
    }
    let inputs = crate::inputs::run_inputs(p, opts, &base);
    let out = OutputFolder::begin(&opts.output, &inputs).map_err(at("output"))?;
    let dir = out.path().to_path_buf();
    let mut stages = Stages::default();
    let progress = Progress::new(opts, on_stage, on_slab);

    progress.stage("input")?;
    let t = Instant::now();
    let (mut source, input_name, mut warnings) = open_source(p, opts, &base)?;
    let geo = source.geometry().clone();
    let n = geo.voxel_count();
    let nz = geo.dims[2];
    let plan = Plan::resolve(p, &[], &geo).map_err(at("plan"))?;
    let tf = crate::inputs::read_tf(p, &base)?;
    let profile = p.pack.profile;
    // the histogram volume: asked for, or the default TF's source
    let hvol_asked = p.histogram.as_ref().is_some_and(|h| h.hvol);
    let hvol_needed = hvol_asked || tf.is_none();
    let threads = rayon::current_num_threads();
    let (height, hvol_lanes) = match size {
        SlabSize::Budget(b) => fit_slabs(b, &geo, &plan, hvol_needed, threads).map_err(fail("plan"))?,
        SlabSize::Planes(h) => (h.clamp(1, nz.max(1)), threads),
    };
    let slabs = slabs(nz, height);
    progress.stage(&format!("input: {} slabs of {height} planes", slabs.len()))?;
    let mut store = ChannelStore::create(dir.join(".slabs"), geo.clone()).map_err(at("input"))?;
    let io = |stage: &'static str| at::<std::io::Error>(stage);
    let mut stats = Stats::new(&["v", "g", "f2", "g_hit", "g_prefiltered", "inv_g"], n);
    for (k, z) in slabs.iter().enumerate() {
        progress.slab(k + 1, slabs.len())?;
        let v = source.read(z.clone())?;
        stats.add("v", v.samples());
        store.put_volume("v", z.start, &v).map_err(io("input"))?;
    }
    drop(source);
    stages.done("input", t, n, vec![]);
    let finite_range = stats.range("v").map(|(lo, hi)| [lo as f64, hi as f64]);
    let value_range = finite_range.map_or(0.0, |[lo, hi]| hi - lo);
    let kernel = p.derive.kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL);

    // derive: the derivatives are recomputed from the stored value by every
    // pass that reads them, in the whole run's groups (the normals on their
    // own when it defers them); this pass takes their statistics
    let span = stats.range("v").map_or(0.0, |(lo, hi)| hi - lo);
    let derive = |items: Vec<mdtf_derive::Item>| DeriveParams {
        items,
        kernel,
        epsilon: Some(mdtf_derive::default_epsilon(span, geo.min_spacing())),
        ..Default::default()
    };
    let mut groups = vec![derive(plan.derive.clone())];
    if hvol_needed {
        // the default TF's histogram volume, which the whole run derives on its own from the value
        for item in [mdtf_derive::Item::G, mdtf_derive::Item::F2] {
            if !groups[0].items.contains(&item) {
                groups[0].items.push(item);
            }
        }
    }
    if plan.defer_normals {
        groups.push(derive(vec![mdtf_derive::Item::Normal]));
    }
    let tasks = opts.tasks.as_deref();
    // the derive stage's time includes its tasks'
    let derive_start = Instant::now();
    if let Some(tasks) = tasks {
        // the tasks store every derived channel; the passes below read them instead of deriving
        progress.stage("derive (tasks)")?;
        let pass = SlabPass::Derive { groups: groups.clone(), kernel_reach: plan.reach.kernel[2] };
        remote::run_pass(tasks, pass, &mut store, &slabs)?;
    }
    let mut chans = SlabChannels::new(store, groups, plan.reach.kernel[2], nz).cancelled_by(opts.cancel.clone());
    let summarised: Vec<&str> = ["g", "f2", "inv_g"].into_iter().filter(|c| chans.has(c)).collect();
    // the first radix pass of g's median (the tracing's noise floor, the (v, 1/g) axis,
    // gaussian-tf's default), taken as this pass derives g
    let mut g_buckets = summarised.contains(&"g").then(mdtf_volume::KeyBuckets::new);
    // the smallest positive 1/g, whose multiple is the top of its code range
    let mut smallest_inv_g = f32::INFINITY;
    if !summarised.is_empty() {
        progress.stage("derive")?;
        for (k, z) in slabs.iter().enumerate() {
            progress.slab(k + 1, slabs.len())?;
            for (name, v) in chans.volumes(z.clone(), &summarised).map_err(fail("derive"))? {
                stats.add(&name, v.samples());
                if name == "g"
                    && let Some(b) = &mut g_buckets
                {
                    b.add(v.samples());
                }
                if name == "inv_g" {
                    smallest_inv_g = crate::pack_inputs::smallest_positive(v.samples()).min(smallest_inv_g);
                }
            }
        }
        chans.release();
        stages.done("derive", derive_start, n, vec![]);
    }

    // pre-filter and tracing
    let mut boundary = None;
    let mut d_max = None;
    if plan.trace {
        let (mut g_name, mut f2_name) = ("g", "f2");
        if plan.prefilter
            && let Some(pf) = &p.prefilter
        {
            progress.stage("prefilter")?;
            let t = Instant::now();
            let halo = plan.reach.prefilter[2];
            let filters: Vec<Prefilter> = [("g", "g_prefiltered"), ("f2", "f2_prefiltered")]
                .map(|(c, out)| {
                    let range = stats.range(c).map_or(0.0, |(lo, hi)| (hi - lo) as f64);
                    let params = crate::boundary_chain::prefilter_params(pf, range);
                    Prefilter { input: c.into(), output: out.into(), params }
                })
                .into();
            if let Some(tasks) = tasks {
                let pass = SlabPass::Prefilter { filters: filters.clone(), halo };
                remote::run_pass(tasks, pass, &mut chans.store, &slabs)?;
            }
            for f in &filters {
                for (k, z) in slabs.iter().enumerate() {
                    progress.slab(k + 1, slabs.len())?;
                    let own = match tasks {
                        Some(_) => chans.store.volume(&f.output, z.clone()).map_err(io("prefilter"))?,
                        None => {
                            let own = trace::prefilter_slab(&mut chans, &f.input, &f.params, z, halo)?;
                            chans.store.put_volume(&f.output, z.start, &own).map_err(io("prefilter"))?;
                            own
                        }
                    };
                    stats.add(&f.output, own.samples());
                }
            }
            (g_name, f2_name) = ("g_prefiltered", "f2_prefiltered");
            chans.release();
            stages.done("prefilter", t, n, vec![]);
        }
        progress.stage("boundary")?;
        let t = Instant::now();
        let traced_buckets = g_buckets.as_ref().filter(|_| g_name == "g");
        let g_stats = g_stats(&mut chans, g_name, traced_buckets, &slabs, value_range, geo.min_spacing(), &stats)?;
        let setup = trace::TraceSetup {
            g: g_name,
            f2: f2_name,
            stored: plan.prefilter || tasks.is_some(),
            params: &p.boundary,
            stats: &g_stats,
            halo: plan.reach.trace[2],
            value_range,
        };
        if let Some(tasks) = tasks {
            let pass = SlabPass::Trace {
                g: g_name.into(),
                f2: f2_name.into(),
                params: p.boundary.clone(),
                stats: g_stats,
                halo: setup.halo,
                value_range,
            };
            remote::run_pass(tasks, pass, &mut chans.store, &slabs)?;
        }
        let mut report: Option<ReportAccumulator> = None;
        let mut crossings: Option<mdtf_boundary::Crossings> = None;
        let mut counts = mdtf_boundary::TraceCounts::default();
        let mut resolved = None;
        for (k, z) in slabs.iter().enumerate() {
            progress.slab(k + 1, slabs.len())?;
            let b = match tasks {
                Some(_) => remote::stored_trace(&mut chans, g_name, z)?,
                None => {
                    let t = trace::trace_slab(&mut chans, &setup, z)?;
                    let b = &t.trace;
                    for (c, v) in [("g_hit", &b.g_hit), ("hit", &b.hit), ("distance", &b.distance)] {
                        chans.store.put_volume(c, z.start, v).map_err(io("boundary"))?;
                    }
                    t
                }
            };
            let (b, g_own) = (b.trace, b.g);
            report.get_or_insert_with(|| ReportAccumulator::new(b.resolved.report_thresholds())).add(
                mdtf_boundary::ReportInput {
                    hit: b.hit.samples(),
                    dot: b.dot.samples(),
                    distance: b.distance.samples(),
                    g: g_own.samples(),
                    g_hit: b.g_hit.samples(),
                },
            );
            match &mut crossings {
                Some(c) => c.merge(&b.crossings),
                None => crossings = Some(b.crossings.clone()),
            }
            counts += b.counts;
            resolved = Some(b.resolved);
            stats.add("g_hit", b.g_hit.samples());
        }
        let (Some(r), Some(report), Some(crossings)) = (resolved, report, crossings) else {
            return Err(fail("boundary")("the volume has no planes".into()));
        };
        let (lost, lost_warnings) = crossings.lost(&r);
        warnings.extend(lost_warnings.iter().map(|w| format!("boundary: {w}")));
        d_max = Some(r.d_max);
        boundary = Some(crate::report::BoundarySummary { resolved: r, counts, lost });
        let rdir = dir.join("boundary");
        std::fs::create_dir_all(&rdir).map_err(io("boundary"))?;
        report.finish().write(&rdir).map_err(at("boundary"))?;
        for c in ["g_prefiltered", "f2_prefiltered", "dot"] {
            chans.store.remove(c);
        }
        chans.release();
        stages.done(
            "boundary",
            t,
            n,
            vec!["boundary/boundary_report.csv".into(), "boundary/boundary_report.png".into()],
        );
    }

    // kept channels
    if !p.keep.is_empty() {
        progress.stage("keep")?;
        let t = Instant::now();
        let kdir = dir.join("volumes");
        std::fs::create_dir_all(&kdir).map_err(io("keep"))?;
        let mut written = Vec::new();
        for c in &p.keep {
            if !chans.has(c) {
                return Err(fail("keep")(format!("no channel '{c}' was computed")));
            }
            let name = p.keep_format.file_name(c);
            mdtf_volume::write_slabs(&kdir.join(&name), &geo, mdtf_volume::SampleType::F32, &slabs, &mut |z| {
                chans.samples(c, z).map_err(std::io::Error::other)
            })
            .map_err(at("keep"))?;
            written.push(format!("volumes/{name}"));
        }
        stages.done("keep", t, n, written);
    }

    // the pack's code ranges: the whole run's rule; the channels it leaves to the pack's own
    // measure (the value) get their finite range here, since no slab sees the whole channel
    let names = profile.channels(&[]);
    let mut ranges = BTreeMap::new();
    for c in &names {
        let whole = || stats.0.get(c.as_str()).cloned().unwrap_or_else(|| ChannelStats::new((0.0, 0.0), 0));
        let r = match crate::pack_inputs::range_of(c, whole, d_max).map_err(at("pack"))? {
            Some(r) => Some(r),
            None if c == "inv_g" && smallest_inv_g.is_finite() => Some(crate::pack_inputs::inv_g_range(smallest_inv_g)),
            None if matches!(c.as_str(), "nx" | "ny" | "nz") => None,
            None => stats.range(c).map(|(lo, hi)| [lo as f64, hi as f64]),
        };
        if let Some(r) = r {
            ranges.insert(c.clone(), r);
        }
    }
    let params = PackParams { profile, ranges, fields: vec![], dtype: None, nifti: false };
    let pdir = dir.join("pack");
    std::fs::create_dir_all(&pdir).map_err(io("pack"))?;
    let sources = BTreeMap::new();
    let mut writer = PackWriter::new(&pdir, &params, geo.clone(), &sources);

    // one pass over the slabs counts the histograms and quantises every texture, so each
    // slab's channels are made once; its time is the pack stage's, the histogram stage's is
    // writing the histogram files
    let counting = p.histogram.is_some() || hvol_needed;
    progress.stage(if counting { "histogram and pack" } else { "pack" })?;
    let pack_start = Instant::now();
    let mut histograms = match counting {
        true => Some(SlabHistograms::new(
            p,
            &mut chans,
            &stats,
            &slabs,
            n,
            hvol_needed.then_some(hvol_lanes),
            g_buckets.as_ref(),
        )?),
        false => None,
    };
    let layouts = mdtf_pack::texture_layouts(&params);
    let mut read: Vec<&str> = histograms.as_ref().map(SlabHistograms::channels).unwrap_or_default();
    for c in layouts.iter().flat_map(|l| l.components.iter().flatten()) {
        if !read.contains(&c.as_str()) {
            read.push(c);
        }
    }
    let mut counting_failed = None;
    let written = writer.add_slabs(&layouts, &slabs, &mut |z| {
        progress.report_slab(z.end.div_ceil(height), slabs.len());
        let slab = chans
            .volumes(z.clone(), &read)
            .map_err(|e| mdtf_pack::PackError::Io(mdtf_volume::VolumeError::Fields(e)))?;
        if let Some(h) = &mut histograms
            && let Err(e) = h.add(z.start, &slab)
        {
            counting_failed = Some(e);
            return Err(mdtf_pack::PackError::Geometry("the histograms could not count a slab".into()));
        }
        Ok(slab)
    });
    if let Some(e) = counting_failed {
        return Err(e);
    }
    written.map_err(at("pack"))?;
    chans.release();

    // the histogram files
    let mut hists = crate::hist_files::Written::default();
    if let Some(h) = histograms {
        let t = Instant::now();
        let mut counted = h.finish()?;
        // the default TF's histogram volume is an output only when the histograms ask for it
        let default_hvol = if hvol_asked { None } else { counted.hvol.take() };
        if p.histogram.is_some() {
            let hdir = dir.join("histogram");
            std::fs::create_dir_all(&hdir).map_err(io("histogram"))?;
            hists = crate::hist_files::write(&hdir, counted, &input_name, &mut warnings).map_err(fail("histogram"))?;
            stages.done("histogram", t, n, hists.outputs.clone());
        }
        if default_hvol.is_some() {
            hists.hvol = default_hvol;
        }
    }
    let crate::hist_files::Written { boundaries, arches, figure_hists, hvol, .. } = hists;

    // the lookup tables, the manifest and the Gaussians
    // the tables read the channels' names and grid (their data only without a histogram volume)
    let stubs: Vec<(String, Volume)> = names.iter().map(|c| (c.clone(), Volume::zeros(geo.z_slab(0..1)))).collect();
    let alpha = p.pack.alpha.unwrap_or(mdtf_boundary::AlphaMap::Linear { a: 1.0, dc: None });
    let luts = crate::pack_inputs::luts(profile, tf.as_ref(), &alpha, &stubs, &params.ranges, hvol.as_ref(), kernel)
        .map_err(at("pack"))?;
    let table_names: Vec<String> = luts.iter().map(|l| l.name.clone()).collect();
    let provenance = crate::inputs::provenance(p, opts, &base, &input_name);
    writer.finish(&luts, provenance).map_err(at("pack"))?;
    if profile == Profile::GaussianTf {
        // the TF file's primitives, else a TGTF at each boundary found, else the paper's median default
        let gaussians = match (tf.as_ref(), &hvol) {
            (Some(tf), _) => tf.gaussians(),
            (None, Some(hv)) => {
                let arches = crate::pack_inputs::arches_from(&mdtf_histogram::detect_boundaries(hv));
                match arches.is_empty() {
                    false => crate::gaussians::boundary_tgtfs(&arches, &geo),
                    true => vec![medians::median_tgtf(&mut chans, &slabs, g_buckets.as_ref()).map_err(fail("pack"))?],
                }
            }
            (None, None) => return Err(fail("pack")("the default Gaussians need the histogram volume".into())),
        };
        let json = serde_json::to_string_pretty(&gaussians).map_err(at("pack"))?;
        mdtf_volume::write_file_atomically(&pdir.join("gaussians.json"), |w| w.write_all(json.as_bytes()))
            .map_err(at("pack"))?;
    }
    let mut pack_outputs: Vec<String> = vec!["pack/manifest.json".into()];
    if !figure_hists.is_empty() {
        let hists: Vec<&Histogram> = figure_hists.iter().collect();
        let written = crate::figures::write_tf_figures(&dir.join("histogram"), &luts, &hists, &input_name, &arches)
            .map_err(at("pack"))?;
        pack_outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
    }
    stages.done("pack", pack_start, n, pack_outputs);
    chans.store.clear();

    // the preview decodes the pack whole: under a budget it cannot keep, it is left to `mdtf preview`
    let mut finishing = p.clone();
    let preview_bytes = (PREVIEW_CHANNELS * n * 4) as u64;
    if let SlabSize::Budget(b) = size
        && p.preview
        && preview_bytes > b
    {
        finishing.preview = false;
        warnings.push(format!(
            "preview: not rendered: it decodes the pack at full resolution (about {}), more than the memory budget \
             of {}; `mdtf preview {}` renders it where there is the memory",
            mdtf_volume::human_bytes(preview_bytes as u128),
            mdtf_volume::human_bytes(b as u128),
            opts.output.join("pack").display()
        ));
    }
    let report = RunReport {
        value_range: finite_range,
        warnings,
        boundary,
        boundaries,
        hvol_built: hvol_asked,
        slabs: Some(crate::report::SlabRun {
            planes: height,
            count: slabs.len(),
            budget: match size {
                SlabSize::Budget(b) => Some(b),
                SlabSize::Planes(_) => None,
            },
        }),
        stages: stages.0,
        ..RunReport::of(opts, input_name, &geo)
    };
    crate::run::finish(&finishing, opts, out, report, &table_names, start, &progress)
}
