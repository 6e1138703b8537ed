//! The passes of a slab-by-slab run, in the order they run, over the state
//! they hand on ([`SlabPasses`]): input, derive, pre-filter, tracing, kept
//! volumes, then histograms and pack together, then the pack's tables.
//! Each pass visits the slabs in z order, so the reductions it feeds merge
//! in the same order whatever the slab height. The tracing's passes
//! ([`tracing`]) and the pack's ([`packing`]) have their own files.

mod packing;
mod tracing;

use super::medians::{SelectCounts, SelectPass};
use super::partials::SlabPartial;
use super::remote::{self, Derivation, SlabPass, SlabTasks};
use super::slab_channels::made_by;
use super::{ChannelStore, SlabChannels, SlabSize, Source, open_source};
use super::{TraceBlocks, reductions, slabs};
use crate::boundary_chain::BoundaryChainParams;
use crate::channel::Channel;
use crate::file::KeepFormat;
use crate::plan::Plan;
use crate::progress::Progress;
use crate::report::Stages;
use crate::run::{RunError, RunOptions, at};
use crate::settings::{Histograms, InputSettings, Settings};
use mdtf_derive::{DeriveParams, Item};
use mdtf_pack::TfFile;
use mdtf_volume::{Geometry, KeyBuckets, overlapped};
use reductions::Stats;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// An I/O error of the pass `stage`.
fn io(stage: &'static str) -> impl Fn(std::io::Error) -> RunError {
    at::<std::io::Error>(stage)
}

/// The run's channel store in `dir` (a killed run's, taken over, when
/// `resumed`) and, for a run with tasks, its new run token (else empty).
fn open_store(dir: &Path, resumed: bool, geo: &Geometry, tasks: bool) -> Result<(ChannelStore, String), RunError> {
    let store_dir = dir.join(super::store::STORE_DIR);
    let store = match resumed {
        true => ChannelStore::resume(store_dir, geo.clone()),
        false => ChannelStore::create(store_dir, geo.clone()),
    }
    .map_err(at("input"))?;
    let token = if tasks { super::resume::new_token(store.dir())? } else { String::new() };
    Ok((store, token))
}

/// The input pass `pass` as tasks, their statistics merged into `stats`:
/// the samples in the padding's range, and the pass for the report.
fn input_by_tasks(
    tasks: &dyn SlabTasks,
    pass: SlabPass,
    store: &mut ChannelStore,
    slabs: &[Range<usize>],
    token: &str,
    stats: &mut Stats,
) -> Result<(u64, crate::report::TaskPass), RunError> {
    let nothing_derived = Derivation { groups: &[], kernel_reach: 0 };
    let (parts, ran) = remote::run_pass(tasks, pass, store, nothing_derived, slabs, token)?;
    let mut padded = 0;
    for mut part in parts {
        part.merge_stats_into(stats);
        padded += part.padded;
    }
    Ok((padded, ran))
}

/// What a slab-by-slab run makes.
#[derive(Clone, Copy)]
pub(in crate::blocks) enum SlabWork<'a> {
    /// A pipeline's outputs.
    Pipeline(&'a Settings),
    /// The tracing of `chain` on `input` alone, its channels left in the
    /// store (`mdtf boundary`'s slab tracing: the run stops after it).
    Traced {
        /// The input.
        input: &'a InputSettings,
        /// Kernel, pre-filter and tracing parameters.
        chain: &'a BoundaryChainParams,
    },
}

impl<'a> SlabWork<'a> {
    /// The run's input.
    fn input(self) -> &'a InputSettings {
        match self {
            SlabWork::Pipeline(s) => &s.input,
            SlabWork::Traced { input, .. } => input,
        }
    }

    /// Kernel, pre-filter and tracing parameters.
    fn chain(self) -> &'a BoundaryChainParams {
        match self {
            SlabWork::Pipeline(s) => &s.chain,
            SlabWork::Traced { chain, .. } => chain,
        }
    }

    /// The plan on `geo`: the pipeline's, or the steps that make every traced channel.
    fn plan(self, geo: &Geometry) -> Result<Plan, crate::plan::PlanError> {
        match self {
            SlabWork::Pipeline(s) => Plan::resolve(s, &[], geo),
            SlabWork::Traced { chain, .. } => Plan::for_channels(&crate::channel::traced_names(), &[], geo, chain),
        }
    }

    /// The pipeline's settings (None for the tracing alone, which keeps and packs nothing).
    fn settings(self) -> Option<&'a Settings> {
        match self {
            SlabWork::Pipeline(s) => Some(s),
            SlabWork::Traced { .. } => None,
        }
    }
}

/// What a slab-by-slab run hands from pass to pass.
pub(super) struct SlabPasses<'a> {
    work: SlabWork<'a>,
    opts: &'a RunOptions,
    /// The histograms the run makes (none for the tracing alone).
    histograms: Histograms,
    /// The staging output folder.
    pub(super) dir: PathBuf,
    pub(super) geo: Geometry,
    plan: Plan,
    pub(super) slabs: Vec<Range<usize>>,
    /// Planes per slab (the last may hold fewer).
    pub(super) height: usize,
    /// How the tracing pass cuts the volume.
    pub(super) trace_blocks: TraceBlocks,
    /// The histograms ask for the histogram volume.
    hvol_asked: bool,
    /// The histogram volume is counted: asked for, or the default TF's source.
    hvol_needed: bool,
    tf: Option<TfFile>,
    /// The input's name in the figures, the manifest and the report.
    pub(super) input_name: String,
    /// The units the input states.
    pub(super) units: mdtf_volume::Units,
    /// Values that are scanner padding (inclusive range, input units).
    pub(super) padding: Option<[f64; 2]>,
    pub(super) progress: Progress<'a>,
    pub(super) stages: Stages,
    stats: Stats,
    pub(super) warnings: Vec<String>,
    tasks: Option<&'a dyn SlabTasks>,
    /// The run token its tasks check (empty without tasks).
    token: String,
    /// The run took over a killed run's staging folder ([`super::resume`]).
    pub(super) resumed: bool,
    /// The passes that ran as tasks, for the report.
    pub(super) task_passes: Vec<crate::report::TaskPass>,
    /// The first radix pass of the pre-filtered g's median, when tasks pre-filtered it.
    prefiltered_buckets: Option<KeyBuckets>,
}

/// What the derive pass found.
pub(super) struct Derived {
    /// How the value was derived (kernel, scanner padding), for what derives it again.
    derive: DeriveParams,
    /// The first radix pass of g's median, when g was derived.
    g_buckets: Option<KeyBuckets>,
    /// The smallest positive 1/g (infinite without one).
    smallest_inv_g: f32,
}

impl Derived {
    /// Takes in a slab of channel `name` (g: the first radix pass of its
    /// median, behind the tracing's noise floor, the (v, 1/g) axis and
    /// gaussian-tf's default; 1/g: its smallest positive value, whose
    /// multiple is the top of its code range).
    fn add(&mut self, c: Channel, samples: &[f32]) {
        match c {
            Channel::G => self.g_buckets.iter_mut().for_each(|b| b.add(samples)),
            Channel::InvG => {
                self.smallest_inv_g = crate::pack_inputs::smallest_positive(samples).min(self.smallest_inv_g)
            }
            _ => {}
        }
    }

    /// Takes in a task's part of the same (its slab's g counts, its smallest positive 1/g).
    fn merge(&mut self, part: &SlabPartial) {
        if let (Some(mine), Some(theirs)) = (&mut self.g_buckets, &part.g_buckets) {
            mine.merge(theirs);
        }
        if let Some(x) = part.smallest_inv_g {
            self.smallest_inv_g = self.smallest_inv_g.min(x);
        }
    }
}

impl<'a> SlabPasses<'a> {
    /// Whether the histogram step looks for boundaries: it runs, and the
    /// histogram volume is counted (asked for, or for the default TF).
    pub(super) fn detected(&self) -> bool {
        self.hvol_needed && self.histograms.counted
    }

    /// The pipeline's settings (a run that only traces has none: it never packs).
    fn settings(&self) -> Result<&'a Settings, RunError> {
        let none = || crate::run::fail("plan")("the tracing alone keeps and packs nothing".into());
        self.work.settings().ok_or_else(none)
    }

    /// The channels the run keeps as volumes, by name.
    fn kept(&self) -> &'a [String] {
        self.work.settings().map_or(&[], |s| &s.outputs.keep)
    }

    /// The input pass: opens the input, plans the run and sizes its slabs
    /// (`size`), and copies the value slab by slab into a channel store in
    /// `dir`, taking its statistics. A run of `work` that only traces stops
    /// after its tracing (no histogram volume is counted or budgeted).
    /// `resumed`: `dir` is a killed run's, whose store the run takes over.
    pub(super) fn read_input(
        work: SlabWork<'a>,
        opts: &'a RunOptions,
        size: SlabSize,
        (dir, resumed): (&Path, bool),
        progress: Progress<'a>,
    ) -> Result<(SlabPasses<'a>, ChannelStore), RunError> {
        progress.stage("input")?;
        let t = Instant::now();
        let settings = work.settings();
        let (mut source, meta) = open_source(work.input(), settings)?;
        let geo = source.geometry().clone();
        let nz = geo.dims[2];
        let plan = work.plan(&geo).map_err(at("plan"))?;
        let tf = match settings {
            Some(s) => crate::inputs::read_tf(&s.outputs.pack)?,
            None => None,
        };
        let histograms = settings.map(|s| s.outputs.histograms).unwrap_or_default();
        let hvol_asked = histograms.hvol;
        let hvol_needed = settings.is_some_and(|s| super::slab_histograms::counts_hvol(s, tf.is_some()));
        let (height, trace_blocks) = super::cut(size, &geo, &plan, hvol_needed).map_err(at("plan"))?;
        let slabs = slabs(nz, height);
        progress.stage(&format!("input: {} slabs of {height} planes", slabs.len()))?;
        let (mut store, token) = open_store(dir, resumed, &geo, opts.tasks.is_some())?;
        let summarised = [Channel::Value, Channel::G, Channel::F2, Channel::GHit, Channel::GPrefiltered, Channel::InvG];
        let mut stats = Stats::new(&summarised, geo.voxel_count());
        let mut task_passes = Vec::new();
        let padded = match (opts.tasks.as_deref(), &source) {
            (Some(tasks), Source::Planes(reader)) if reader.reads_any_planes() => {
                progress.stage("input (tasks)")?;
                let input = std::path::absolute(reader.path()).map_err(io("input"))?;
                let read = &work.input().read;
                let pass = SlabPass::Input { input, level: read.level, nan: read.nan, padding: meta.padding };
                let (padded, ran) = input_by_tasks(tasks, pass, &mut store, &slabs, &token, &mut stats)?;
                task_passes.push(ran);
                padded
            }
            _ => copy_input(&mut source, &mut store, &slabs, &mut stats, meta.padding, &progress)?,
        };
        let mut stages = Stages::default();
        stages.done("input", t, geo.voxel_count(), vec![]);
        let mut warnings = meta.warnings.clone();
        warnings.extend(meta.padding_note(padded, geo.voxel_count()));
        let run = SlabPasses {
            work,
            opts,
            histograms,
            dir: dir.to_path_buf(),
            geo,
            plan,
            slabs,
            height,
            trace_blocks,
            hvol_asked,
            hvol_needed,
            tf,
            input_name: meta.name,
            units: meta.units,
            padding: meta.padding,
            progress,
            stages,
            stats,
            warnings,
            tasks: opts.tasks.as_deref(),
            token,
            resumed,
            task_passes,
            prefiltered_buckets: None,
        };
        Ok((run, store))
    }

    /// [`remote::run_pass`] with the run's derivation (its derive groups and
    /// kernel reach), its tasks counted for the report.
    fn on_tasks(
        &mut self,
        tasks: &dyn SlabTasks,
        pass: SlabPass,
        store: &mut ChannelStore,
        slabs: &[Range<usize>],
    ) -> Result<Vec<SlabPartial>, RunError> {
        let groups = self.derive_groups();
        let derivation = Derivation { groups: &groups, kernel_reach: self.plan.reach.kernel[2] };
        let (parts, ran) = remote::run_pass(tasks, pass, store, derivation, slabs, &self.token)?;
        self.task_passes.push(ran);
        Ok(parts)
    }

    /// Pass `pass` of a whole-volume median's select over every slab: as
    /// tasks on a run with them, else here from `chans`.
    fn select(&mut self, chans: &mut SlabChannels, pass: SelectPass) -> Result<SelectCounts, RunError> {
        let Some(tasks) = self.tasks else {
            return super::medians::select_here(chans, &self.slabs, &pass).map_err(at("histogram"));
        };
        let mut counts = SelectCounts::default();
        let job = SlabPass::Select { select: Some(pass), detect: None };
        for part in self.on_tasks(tasks, job, &mut chans.store, &self.slabs.clone())? {
            if let Some(c) = &part.selected {
                counts.merge(c);
            }
        }
        Ok(counts)
    }

    /// Whether a killed or failed run could be resumed: its tasks' outputs
    /// stay in the store until the run ends (a task whose outputs are gone
    /// would run again), as the plan on paper's store at its fullest counts them.
    fn resumable(&self) -> bool {
        self.tasks.is_some() && self.opts.resume
    }

    /// The input's finite value range, value units.
    pub(super) fn finite_range(&self) -> Option<[f64; 2]> {
        self.stats.range(Channel::Value).map(|(lo, hi)| [lo as f64, hi as f64])
    }

    /// max - min of the input's finite values (0 without any).
    fn value_range(&self) -> f64 {
        self.finite_range().map_or(0.0, |[lo, hi]| hi - lo)
    }

    /// The derive pass. The derivatives are remade from the stored value by
    /// every later pass that reads them, in the whole run's groups (the
    /// normals on their own when it defers them); this pass takes their
    /// statistics. With tasks, the tasks take them and store only what this
    /// process reads later ([`stored_for_the_run`]); their later tasks remake
    /// the others as this process's passes do.
    pub(super) fn derive(&mut self, store: ChannelStore) -> Result<(SlabChannels, Derived), RunError> {
        let groups = self.derive_groups();
        let derive_start = Instant::now();
        let nz = self.geo.dims[2];
        let kernel_reach = self.plan.reach.kernel[2];
        let mut chans =
            SlabChannels::new(store, groups.clone(), kernel_reach, nz).cancelled_by(self.opts.cancel.clone());
        let summarised: Vec<Channel> =
            [Channel::G, Channel::F2, Channel::InvG].into_iter().filter(|&c| chans.has(c)).collect();
        let g_buckets = summarised.contains(&Channel::G).then(KeyBuckets::new);
        let derive = DeriveParams { items: Vec::new(), ..self.derive_params() };
        let mut derived = Derived { derive, g_buckets, smallest_inv_g: f32::INFINITY };
        if let Some(tasks) = self.tasks {
            self.progress.stage("derive (tasks)")?;
            let pass = SlabPass::Derive { summarise: summarised, store: self.read_later(&groups) };
            for mut part in self.on_tasks(tasks, pass, &mut chans.store, &self.slabs.clone())? {
                part.merge_stats_into(&mut self.stats);
                derived.merge(&part);
            }
            self.stages.done("derive", derive_start, self.geo.voxel_count(), vec![]);
            return Ok((chans, derived));
        }
        // g waits on disk for the second radix pass of its median before the tracing: reading
        // it back costs less than deriving every slab again (it goes once the median is known)
        let keep_g = self.median_reads_stored_g() && derived.g_buckets.is_some();
        if !summarised.is_empty() {
            self.progress.stage("derive")?;
            let mut writer = chans.store.writer(if keep_g { &[Channel::G] } else { &[] }).map_err(io("derive"))?;
            let (slabs, stats, progress) = (&self.slabs, &mut self.stats, &self.progress);
            // a slab is derived while the one before is summarised (and its g stored)
            overlapped(
                slabs.len(),
                &mut |k| progress.slab(k + 1, slabs.len()),
                &mut |k, spent| {
                    chans.give_back(spent.map(|(_, volumes)| volumes).unwrap_or_default());
                    Ok((slabs[k].start, chans.volumes(slabs[k].clone(), &summarised).map_err(at("derive"))?))
                },
                &mut |(first, volumes)| {
                    for &(c, ref v) in &volumes {
                        stats.add(c, v.samples());
                        derived.add(c, v.samples());
                        if c == Channel::G && keep_g {
                            writer.put_volume(Channel::G, first, v).map_err(io("derive"))?;
                        }
                    }
                    Ok(Some((first, volumes)))
                },
            )?;
            chans.release();
            self.stages.done("derive", derive_start, self.geo.voxel_count(), vec![]);
        }
        Ok((chans, derived))
    }

    /// How every slab derives the value: the kernel, the whole volume's
    /// epsilon (the same in every slab) and the scanner padding.
    fn derive_params(&self) -> DeriveParams {
        let span = self.stats.range(Channel::Value).map_or(0.0, |(lo, hi)| hi - lo);
        DeriveParams {
            items: Vec::new(),
            kernel: self.work.chain().kernel,
            epsilon: Some(mdtf_derive::default_epsilon(span, self.geo.min_spacing())),
            border: mdtf_derive::Border::Clamp,
            padding: self.padding.map(|r| r.map(|x| x as f32)),
        }
    }

    /// Whether the derive pass stores g for the second pass of its median,
    /// the tracing's noise floor (the tracing of g itself, not of the
    /// pre-filtered g, and in this process: tasks store every channel).
    fn median_reads_stored_g(&self) -> bool {
        self.plan.trace && !self.plan.prefilter && self.tasks.is_none()
    }

    /// The derived channels a run on tasks reads itself after its derive
    /// pass, which its derive tasks store ([`stored_for_the_run`]).
    fn read_later(&self, groups: &[DeriveParams]) -> Vec<Channel> {
        let derived: Vec<Channel> = groups.iter().flat_map(|d| d.items.iter()).flat_map(|&i| made_by(i)).collect();
        let format = self.settings().map_or(KeepFormat::NiiGz, |s| s.outputs.keep_format);
        stored_for_the_run(self.kept(), format, &derived)
    }

    /// The derive groups of the whole run: the plan's items (with g and f''
    /// for the default TF's histogram volume, which the whole run derives
    /// on its own from the value), then the deferred normals.
    fn derive_groups(&self) -> Vec<DeriveParams> {
        let derive = |items: Vec<Item>| DeriveParams { items, ..self.derive_params() };
        let mut groups = vec![derive(self.plan.derive.clone())];
        if self.hvol_needed {
            for item in [Item::G, Item::F2] {
                if !groups[0].items.contains(&item) {
                    groups[0].items.push(item);
                }
            }
        }
        if self.plan.defer_normals {
            groups.push(derive(vec![Item::Normal]));
        }
        groups
    }

    /// The kept channels, written slab by slab as volumes.
    pub(super) fn keep(&mut self, chans: &mut SlabChannels) -> Result<(), RunError> {
        if self.kept().is_empty() {
            return Ok(());
        }
        let outputs = &self.settings()?.outputs;
        let t = Instant::now();
        if let Some(tasks) = self.tasks
            && outputs.keep_format == KeepFormat::NiiGz
        {
            self.progress.stage("keep (tasks)")?;
            let written = self.keep_by_tasks(tasks, chans, outputs)?;
            self.stages.done("keep", t, self.geo.voxel_count(), written);
            return Ok(());
        }
        self.progress.stage("keep")?;
        let (geo, slabs, f32) = (&self.geo, &self.slabs, mdtf_volume::SampleType::F32);
        let store_dir = chans.store.dir().to_path_buf();
        let stored = chans.store.channels();
        let derived_here = std::sync::Mutex::new(&mut *chans);
        let written = crate::run::write_kept(outputs, &self.plan.fields, &self.dir, |c, file| {
            let c = Channel::of_store(c)?;
            if stored.contains(&c) {
                // a stored channel through a handle of its own: the kept files are written side by side
                let mut store = match ChannelStore::open(store_dir.clone(), geo.clone(), &[c]) {
                    Ok(store) => store,
                    Err(e) => return Some(Err(at("keep")(e))),
                };
                let mut slab = |z, out: &mut Vec<f32>| store.samples_into(c, z, out);
                return Some(mdtf_volume::write_slabs(file, geo, f32, slabs, &mut slab).map_err(at("keep")));
            }
            let mut chans = derived_here.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            if !chans.has(c) {
                return None;
            }
            let mut slab = |z, out: &mut Vec<f32>| chans.samples_into(c, z, out).map_err(std::io::Error::other);
            Some(mdtf_volume::write_slabs(file, geo, f32, slabs, &mut slab).map_err(at("keep")))
        })?;
        chans.release();
        self.stages.done("keep", t, self.geo.voxel_count(), written);
        Ok(())
    }
}

impl SlabPasses<'_> {
    /// The kept `.nii.gz` volumes written by tasks: each writes its slab's
    /// planes of every kept channel as gzip members, and each file is its
    /// header and the parts put together in z order (the bytes of the whole
    /// run's file). The files written, relative to the output folder.
    fn keep_by_tasks(
        &mut self,
        tasks: &dyn SlabTasks,
        chans: &mut SlabChannels,
        outputs: &crate::settings::Outputs,
    ) -> Result<Vec<String>, RunError> {
        let mut channels = Vec::with_capacity(outputs.keep.len());
        for name in &outputs.keep {
            match Channel::of_store(name).filter(|&c| chans.has(c)) {
                Some(c) => channels.push(c),
                None => return Err(crate::run::fail("keep")(format!("no channel '{name}' was computed"))),
            }
        }
        let parts = chans.store.dir().join("keep");
        std::fs::create_dir_all(&parts).map_err(io("keep"))?;
        let pass = SlabPass::Keep { channels, parts: parts.clone(), height: self.height };
        let slabs = self.slabs.clone();
        self.on_tasks(tasks, pass, &mut chans.store, &slabs)?;
        let geo = &self.geo;
        crate::run::write_kept(outputs, &self.plan.fields, &self.dir, |name, file| {
            let c = Channel::of_store(name)?;
            let header = mdtf_volume::nifti_gz_header(file, geo, 1, mdtf_volume::SampleType::F32);
            let put_together = |w: &mut dyn std::io::Write| {
                w.write_all(&header.map_err(std::io::Error::other)?)?;
                for z in &slabs {
                    std::io::copy(&mut std::fs::File::open(remote::kept_part(&parts, c, z.start))?, w)?;
                }
                Ok(())
            };
            Some(mdtf_volume::write_file_atomically(file, put_together).map_err(at("keep")))
        })
    }
}

/// The derived channels (of `derived`) a run on tasks reads itself after
/// its derive pass, which its derive tasks store: the `kept` ones when
/// they are written as OME-Zarr (the tasks remake every other channel, take
/// the medians' passes themselves and write the kept `.nii.gz` volumes).
pub(super) fn stored_for_the_run(kept: &[String], format: KeepFormat, derived: &[Channel]) -> Vec<Channel> {
    if format == KeepFormat::NiiGz {
        return Vec::new();
    }
    let kept = kept.iter().filter_map(|c| Channel::of_store(c));
    kept.filter(|c| derived.contains(c)).collect()
}

/// Copies the input's value slab by slab into `store`, taking its
/// statistics; the samples in the `padding` range, counted.
fn copy_input(
    source: &mut Source,
    store: &mut ChannelStore,
    slabs: &[Range<usize>],
    stats: &mut Stats,
    padding: Option<[f64; 2]>,
    progress: &Progress,
) -> Result<u64, RunError> {
    let mut writer = store.writer(&[Channel::Value]).map_err(io("input"))?;
    let mut padded = 0u64;
    // a slab is read while the one before is summarised and stored
    overlapped(
        slabs.len(),
        &mut |k| progress.slab(k + 1, slabs.len()),
        &mut |k, _| Ok((slabs[k].start, source.read(slabs[k].clone())?)),
        &mut |(first, v)| {
            stats.add(Channel::Value, v.samples());
            if let Some(range) = padding {
                padded += crate::inputs::count_padding(v.samples(), range);
            }
            writer.put_volume(Channel::Value, first, &v).map_err(io("input"))?;
            Ok(None)
        },
    )?;
    Ok(padded)
}
