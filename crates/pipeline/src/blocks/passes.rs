//! The passes of a slab-by-slab run, in the order they run, over the state
//! they hand on ([`SlabPasses`]): input, derive, pre-filter, tracing, kept
//! volumes, then histograms and pack together, then the pack's tables.
//! Each pass visits the slabs in z order, so the reductions it feeds merge
//! in the same order whatever the slab height.

use super::partials::{SlabPartial, TracePartial};
use super::remote::{self, Derivation, Prefilter, SlabPass, SlabTasks};
use super::slab_channels::made_by;
use super::slab_histograms::SlabHistograms;
use super::trace::{self, SlabTrace, TraceSetup};
use super::{ChannelStore, SlabChannels, SlabSize, Source, medians, open_source};
use super::{TraceBlocks, reductions, slabs};
use crate::file::Pipeline;
use crate::hist_files::Written;
use crate::plan::Plan;
use crate::pre_detect::HVOL_BINS;
use crate::progress::Progress;
use crate::report::{BoundarySummary, Stages, Traced};
use crate::run::{RunError, RunOptions, at, fail};
use mdtf_boundary::VolumeStats;
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{ChannelStats, Histogram, HvolAxes};
use mdtf_pack::{PackParams, PackWriter, Profile, TfFile};
use mdtf_volume::{Geometry, KeyBuckets, Volume, overlapped};
use reductions::{Stats, detected_before_tracing, g_stats};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// An I/O error of the pass `stage`.
fn io(stage: &'static str) -> impl Fn(std::io::Error) -> RunError {
    at::<std::io::Error>(stage)
}

/// What a slab-by-slab run hands from pass to pass.
pub(super) struct SlabPasses<'a> {
    p: &'a Pipeline,
    opts: &'a RunOptions,
    /// The pipeline file's folder (relative paths in it start there).
    base: PathBuf,
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
    fn add(&mut self, name: &str, samples: &[f32]) {
        match name {
            "g" => self.g_buckets.iter_mut().for_each(|b| b.add(samples)),
            "inv_g" => self.smallest_inv_g = crate::pack_inputs::smallest_positive(samples).min(self.smallest_inv_g),
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
        self.hvol_needed && self.p.histogram.is_some()
    }

    /// The input pass: opens the input, plans the run and sizes its slabs
    /// (`size`), and copies the value slab by slab into a channel store in
    /// `dir`, taking its statistics. Without `packs` the run stops after its
    /// tracing and kept volumes (no histogram volume is counted or budgeted).
    pub(super) fn read_input(
        p: &'a Pipeline,
        opts: &'a RunOptions,
        size: SlabSize,
        dir: &Path,
        progress: Progress<'a>,
        packs: bool,
    ) -> Result<(SlabPasses<'a>, ChannelStore), RunError> {
        let base = opts.base();
        progress.stage("input")?;
        let t = Instant::now();
        let (mut source, meta) = open_source(p, opts, &base)?;
        let geo = source.geometry().clone();
        let nz = geo.dims[2];
        let plan = Plan::resolve(p, &[], &geo).map_err(at("plan"))?;
        let tf = crate::inputs::read_tf(p, &base)?;
        let hvol_asked = p.histogram.as_ref().is_some_and(|h| h.hvol);
        let hvol_needed = packs && (hvol_asked || tf.is_none());
        if let Some(why) = super::sizing::too_many_to_count(p, &geo, hvol_needed) {
            return Err(fail("plan")(why));
        }
        let (height, trace_blocks) = super::cut(size, &geo, &plan, hvol_needed).map_err(fail("plan"))?;
        let slabs = slabs(nz, height);
        progress.stage(&format!("input: {} slabs of {height} planes", slabs.len()))?;
        let mut store = ChannelStore::create(dir.join(".slabs"), geo.clone()).map_err(at("input"))?;
        let mut stats = Stats::new(&["v", "g", "f2", "g_hit", "g_prefiltered", "inv_g"], geo.voxel_count());
        let mut task_passes = Vec::new();
        let padded = match (opts.tasks.as_deref(), &source) {
            (Some(tasks), Source::Planes(reader)) if reader.reads_any_planes() => {
                progress.stage("input (tasks)")?;
                let input = std::path::absolute(reader.path()).map_err(io("input"))?;
                let (level, nan, padding) = (p.input.level, p.input.nan, meta.padding);
                let pass = SlabPass::Input { input, level, nan, padding };
                let mut padded = 0;
                let nothing_derived = Derivation { groups: &[], kernel_reach: 0 };
                let (parts, ran) = remote::run_pass(tasks, pass, &mut store, nothing_derived, &slabs)?;
                task_passes.push(ran);
                for mut part in parts {
                    part.merge_stats_into(&mut stats);
                    padded += part.padded;
                }
                padded
            }
            _ => copy_input(&mut source, &mut store, &slabs, &mut stats, meta.padding, &progress)?,
        };
        let mut stages = Stages::default();
        stages.done("input", t, geo.voxel_count(), vec![]);
        let mut warnings = meta.warnings.clone();
        warnings.extend(meta.padding_note(padded, geo.voxel_count()));
        let run = SlabPasses {
            p,
            opts,
            base,
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
            task_passes,
            prefiltered_buckets: None,
        };
        Ok((run, store))
    }

    /// [`remote::run_pass`], its tasks counted for the report.
    fn on_tasks(
        &mut self,
        tasks: &dyn SlabTasks,
        pass: SlabPass,
        store: &mut ChannelStore,
        derivation: Derivation,
        slabs: &[Range<usize>],
    ) -> Result<Vec<SlabPartial>, RunError> {
        let (parts, ran) = remote::run_pass(tasks, pass, store, derivation, slabs)?;
        self.task_passes.push(ran);
        Ok(parts)
    }

    /// The input's finite value range, value units.
    pub(super) fn finite_range(&self) -> Option<[f64; 2]> {
        self.stats.range("v").map(|(lo, hi)| [lo as f64, hi as f64])
    }

    /// max - min of the input's finite values (0 without any).
    fn value_range(&self) -> f64 {
        self.finite_range().map_or(0.0, |[lo, hi]| hi - lo)
    }

    /// The derive pass. The derivatives are remade from the stored value by
    /// every later pass that reads them, in the whole run's groups (the
    /// normals on their own when it defers them); this pass takes their
    /// statistics. With tasks, the tasks store every derived channel and the
    /// later passes read them instead.
    pub(super) fn derive(&mut self, store: ChannelStore) -> Result<(SlabChannels, Derived), RunError> {
        let groups = self.derive_groups();
        let derive_start = Instant::now();
        let nz = self.geo.dims[2];
        let kernel_reach = self.plan.reach.kernel[2];
        let mut chans =
            SlabChannels::new(store, groups.clone(), kernel_reach, nz).cancelled_by(self.opts.cancel.clone());
        let summarised: Vec<&str> = ["g", "f2", "inv_g"].into_iter().filter(|c| chans.has(c)).collect();
        let g_buckets = summarised.contains(&"g").then(KeyBuckets::new);
        let derive = DeriveParams { items: Vec::new(), ..self.derive_params() };
        let mut derived = Derived { derive, g_buckets, smallest_inv_g: f32::INFINITY };
        if let Some(tasks) = self.tasks {
            self.progress.stage("derive (tasks)")?;
            let summarise = summarised.iter().map(|c| c.to_string()).collect();
            let pass = SlabPass::Derive { summarise, store: self.read_later(&groups) };
            let derivation = Derivation { groups: &groups, kernel_reach };
            for mut part in self.on_tasks(tasks, pass, &mut chans.store, derivation, &self.slabs.clone())? {
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
            let mut writer = chans.store.writer(if keep_g { &["g"] } else { &[] }).map_err(io("derive"))?;
            let (slabs, stats, progress) = (&self.slabs, &mut self.stats, &self.progress);
            // a slab is derived while the one before is summarised (and its g stored)
            overlapped(
                slabs.len(),
                &mut |k| progress.slab(k + 1, slabs.len()),
                &mut |k, spent| {
                    chans.give_back(spent.map(|(_, volumes)| volumes).unwrap_or_default());
                    Ok((slabs[k].start, chans.volumes(slabs[k].clone(), &summarised).map_err(fail("derive"))?))
                },
                &mut |(first, volumes)| {
                    for (name, v) in &volumes {
                        stats.add(name, v.samples());
                        derived.add(name, v.samples());
                        if name == "g" && keep_g {
                            writer.put_volume("g", first, v).map_err(io("derive"))?;
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
        let span = self.stats.range("v").map_or(0.0, |(lo, hi)| hi - lo);
        DeriveParams {
            items: Vec::new(),
            kernel: self.p.derive.kernel.unwrap_or(mdtf_derive::DEFAULT_KERNEL),
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
    fn read_later(&self, groups: &[DeriveParams]) -> Vec<String> {
        let derived: Vec<String> = groups.iter().flat_map(|d| d.items.iter()).flat_map(|&i| made_by(i)).collect();
        stored_for_the_run(self.p, &self.plan, self.tf.is_some(), &derived)
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

    /// The pre-filter (when planned) and tracing passes, when the plan traces.
    pub(super) fn trace(&mut self, chans: &mut SlabChannels, derived: &Derived) -> Result<Traced, RunError> {
        if !self.plan.trace {
            return Ok(Traced::default());
        }
        let (g, f2, prefiltered) = match (self.plan.prefilter, &self.p.prefilter) {
            (true, Some(pf)) => {
                self.prefilter(chans, pf)?;
                ("g_prefiltered", "f2_prefiltered", true)
            }
            _ => ("g", "f2", false),
        };
        self.progress.stage("boundary")?;
        let t = Instant::now();
        let traced_buckets = match prefiltered {
            true => self.prefiltered_buckets.take(),
            false => derived.g_buckets.clone(),
        };
        let l_min = self.geo.min_spacing();
        let value_range = self.value_range();
        let stats = match (self.tasks, &traced_buckets) {
            (Some(tasks), Some(buckets)) => self.tracing_stats_by_tasks(tasks, chans, g, buckets)?,
            _ => {
                let detected = match self.plan.detects_before_tracing() {
                    true => detected_before_tracing(chans, &self.slabs, &self.stats, l_min)?,
                    false => Default::default(),
                };
                let traced_buckets = traced_buckets.as_ref();
                VolumeStats {
                    detected,
                    ..g_stats(chans, g, traced_buckets, &self.slabs, value_range, l_min, &self.stats)?
                }
            }
        };
        if self.median_reads_stored_g() {
            chans.store.remove("g");
        }
        // the median's reads are done: their memory is not the tracing's size
        chans.release();
        let mut sums = TraceSums::default();
        match self.tasks {
            Some(tasks) => {
                let (params, [_, halo_rows, halo]) = (self.p.boundary.clone(), self.plan.reach.trace);
                let (g, f2, rows) = (g.into(), f2.into(), self.trace_blocks.rows);
                let pass = SlabPass::Trace { g, f2, prefiltered, params, stats, halo, halo_rows, rows, value_range };
                let groups = self.derive_groups();
                let derivation = Derivation { groups: &groups, kernel_reach: self.plan.reach.kernel[2] };
                let (_, tslabs) = self.trace_strips_and_slabs();
                for mut part in self.on_tasks(tasks, pass, &mut chans.store, derivation, &tslabs)? {
                    part.merge_stats_into(&mut self.stats);
                    let no_trace = || fail("boundary")("a tracing task left no tracing partial".into());
                    sums.merge(part.trace.ok_or_else(no_trace)?);
                }
            }
            None => {
                let p = self.p;
                let setup = TraceSetup {
                    g,
                    f2,
                    prefiltered,
                    params: &p.boundary,
                    stats: &stats,
                    halo: self.plan.reach.trace[2],
                    halo_rows: self.plan.reach.trace[1],
                    value_range,
                };
                self.trace_here(chans, &setup, &mut sums)?;
            }
        }
        let traced = self.finish_trace(sums)?;
        for c in ["g_prefiltered", "f2_prefiltered", "dot"] {
            if !self.plan.wants(c) {
                chans.store.remove(c);
            }
        }
        chans.release();
        let outputs = vec!["boundary/boundary_report.csv".into(), "boundary/boundary_report.png".into()];
        self.stages.done("boundary", t, self.geo.voxel_count(), outputs);
        Ok(traced)
    }

    /// The tracing's whole-volume statistics (see [`g_stats`] and
    /// [`detected_before_tracing`]) from one round of tasks: the second pass
    /// of the select for the median of the traced g (`g`, whose first pass
    /// is `buckets`) and the (v, g) counts of the detection, each slab's
    /// counted where it is and merged here.
    fn tracing_stats_by_tasks(
        &mut self,
        tasks: &dyn SlabTasks,
        chans: &mut SlabChannels,
        g: &str,
        buckets: &KeyBuckets,
    ) -> Result<VolumeStats, RunError> {
        let (l_min, value_range) = (self.geo.min_spacing(), self.value_range());
        let s = self.stats.0.get(g).ok_or_else(|| fail("boundary")(format!("no statistics of {g}")))?;
        let g_max = s.finite_range().map_or(0.0, |r| r.1);
        let k = s.finite_count().checked_sub(1).map(|last| last / 2);
        let median = k.and_then(|k| mdtf_volume::upper_bucket_of(k, buckets)).map(|hi| (g.to_string(), hi));
        let axis = |name: &str| self.stats.axis(&HvolAxes::spec(name, HVOL_BINS), name).ok();
        let detect = match self.plan.detects_before_tracing() && chans.has("v") && chans.has("g") {
            true => axis("v").zip(axis("g")),
            false => None,
        };
        let (mut lower, mut vg) = (KeyBuckets::new(), None::<crate::pre_detect::VgCounts>);
        if median.is_some() || detect.is_some() {
            let pass = SlabPass::Select { median: median.clone(), detect };
            let groups = self.derive_groups();
            let derivation = Derivation { groups: &groups, kernel_reach: self.plan.reach.kernel[2] };
            for part in self.on_tasks(tasks, pass, &mut chans.store, derivation, &self.slabs.clone())? {
                if let Some(b) = &part.g_buckets {
                    lower.merge(b);
                }
                match (&mut vg, part.vg) {
                    (Some(all), Some(slab)) => all.merge(&slab).map_err(at("boundary"))?,
                    (all, slab) => *all = all.take().or(slab),
                }
            }
        }
        let median =
            k.filter(|_| median.is_some()).and_then(|k| mdtf_volume::order_statistic_from_counts(k, buckets, &lower));
        let noise_floor = mdtf_boundary::noise_floor_of_median(median, value_range, l_min);
        let detected = vg.map(|c| c.detected(l_min)).unwrap_or_default();
        Ok(VolumeStats { value_range, noise_floor, g_max, detected })
    }

    /// The tracing in this process, block by block (strips of rows, z-slabs
    /// within each), each block's outputs stored and summed into `sums`.
    fn trace_here(
        &mut self,
        chans: &mut SlabChannels,
        setup: &TraceSetup,
        sums: &mut TraceSums,
    ) -> Result<(), RunError> {
        let (strips, tslabs) = self.trace_strips_and_slabs();
        if strips.len() > 1 {
            let TraceBlocks { planes, rows } = self.trace_blocks;
            let what = format!("boundary: {} blocks of {planes} planes x {rows} rows", strips.len() * tslabs.len());
            self.progress.stage(&what)?;
        }
        let blocks: Vec<(Range<usize>, Range<usize>)> =
            strips.iter().flat_map(|rows| tslabs.iter().map(move |z| (rows.clone(), z.clone()))).collect();
        // dot only when the run keeps it
        let outputs = &["g_hit", "hit", "distance", "dot"][..if self.plan.wants("dot") { 4 } else { 3 }];
        let mut writer = chans.store.writer(outputs).map_err(io("boundary"))?;
        let (progress, stats) = (&self.progress, &mut self.stats);
        // a block is traced (in the memory of one written and summed) while the one before is written and summed
        let mut make = |k: usize, spent: Option<(usize, SlabTrace)>| {
            let (rows, z) = &blocks[k];
            Ok((k, trace::trace_slab(chans, setup, z, rows, spent.map(|(_, s)| s))?))
        };
        let mut take = |(k, slab): (usize, SlabTrace)| {
            let (rows, z) = &blocks[k];
            let made = [&slab.trace.g_hit, &slab.trace.hit, &slab.trace.distance, &slab.trace.dot];
            for (c, v) in outputs.iter().zip(made) {
                writer.put_rows(c, z.start, rows.clone(), v).map_err(io("boundary"))?;
            }
            stats.add("g_hit", slab.trace.g_hit.samples());
            sums.add(&slab);
            Ok(Some((k, slab)))
        };
        let n = blocks.len();
        overlapped(n, &mut |k| progress.slab(k + 1, n), &mut make, &mut take)
    }

    /// The tracing's strips of rows (one of every row without strips) and
    /// its slabs (the other passes' when it reads stored channels): strip by
    /// strip, down z within each, so that each block hands its derivatives
    /// on to the next.
    fn trace_strips_and_slabs(&self) -> (Vec<Range<usize>>, Vec<Range<usize>>) {
        let [_, ny, nz] = self.geo.dims;
        (slabs(ny, self.trace_blocks.rows), slabs(nz, self.trace_blocks.planes))
    }

    /// The pre-filter pass: g and f'' filtered into the store, their statistics taken.
    fn prefilter(&mut self, chans: &mut SlabChannels, pf: &mdtf_bilateral::BilateralParams) -> Result<(), RunError> {
        self.progress.stage("prefilter")?;
        let t = Instant::now();
        let halo = self.plan.reach.prefilter[2];
        let filters: Vec<Prefilter> = [("g", "g_prefiltered"), ("f2", "f2_prefiltered")]
            .map(|(c, out)| {
                let range = self.stats.range(c).map_or(0.0, |(lo, hi)| (hi - lo) as f64);
                let params = crate::boundary_chain::prefilter_params(pf, range);
                Prefilter { input: c.into(), output: out.into(), params }
            })
            .into();
        match self.tasks {
            Some(tasks) => {
                let pass = SlabPass::Prefilter { filters, halo };
                let groups = self.derive_groups();
                let derivation = Derivation { groups: &groups, kernel_reach: self.plan.reach.kernel[2] };
                let mut buckets = KeyBuckets::new();
                for mut part in self.on_tasks(tasks, pass, &mut chans.store, derivation, &self.slabs.clone())? {
                    part.merge_stats_into(&mut self.stats);
                    if let Some(b) = &part.g_buckets {
                        buckets.merge(b);
                    }
                }
                self.prefiltered_buckets = Some(buckets);
            }
            None => {
                for f in &filters {
                    for (k, z) in self.slabs.iter().enumerate() {
                        self.progress.slab(k + 1, self.slabs.len())?;
                        let own = trace::prefilter_slab(chans, &f.input, &f.params, z, halo)?;
                        chans.store.put_volume(&f.output, z.start, &own).map_err(io("prefilter"))?;
                        self.stats.add(&f.output, own.samples());
                    }
                }
            }
        }
        chans.release();
        self.stages.done("prefilter", t, self.geo.voxel_count(), vec![]);
        Ok(())
    }

    /// The tracing's summary and its Fig. 2 report (written), from the slabs' sums.
    fn finish_trace(&mut self, sums: TraceSums) -> Result<Traced, RunError> {
        let Some(TracePartial { report, crossings, counts, resolved: r }) = sums.0 else {
            return Err(fail("boundary")("the volume has no planes".into()));
        };
        let (lost, lost_warnings) = crossings.lost(&r);
        self.warnings.extend(lost_warnings.iter().map(|w| format!("boundary: {w}")));
        let rdir = self.dir.join("boundary");
        std::fs::create_dir_all(&rdir).map_err(io("boundary"))?;
        let report = report.finish();
        report.write(&rdir).map_err(at("boundary"))?;
        let boundary = Some(BoundarySummary { resolved: r, counts, lost });
        Ok(Traced { d_max: Some(r.d_max), boundary, report: Some(report) })
    }

    /// The kept channels, written slab by slab as volumes.
    pub(super) fn keep(&mut self, chans: &mut SlabChannels) -> Result<(), RunError> {
        if self.p.keep.is_empty() {
            return Ok(());
        }
        self.progress.stage("keep")?;
        let t = Instant::now();
        let (geo, slabs) = (&self.geo, &self.slabs);
        let written = crate::run::write_kept(self.p, &self.plan.fields, &self.dir, |c, file| {
            if !chans.has(c) {
                return None;
            }
            let f32 = mdtf_volume::SampleType::F32;
            let mut slab = |z, out: &mut Vec<f32>| chans.samples_into(c, z, out).map_err(std::io::Error::other);
            Some(mdtf_volume::write_slabs(file, geo, f32, slabs, &mut slab).map_err(at("keep")))
        })?;
        chans.release();
        self.stages.done("keep", t, self.geo.voxel_count(), written);
        Ok(())
    }

    /// The pack's code ranges: the whole run's rule; the channels it leaves
    /// to the pack's own measure (the value) get their finite range here,
    /// since no slab sees the whole channel.
    fn pack_params(&self, derived: &Derived, traced: &Traced) -> Result<PackParams, RunError> {
        let profile = self.p.pack.profile;
        let mut ranges = BTreeMap::new();
        for c in &profile.channels(&[]) {
            let whole = || self.stats.0.get(c.as_str()).cloned().unwrap_or_else(|| ChannelStats::new((0.0, 0.0), 0));
            let r = match crate::pack_inputs::range_of(c, whole, traced.d_max).map_err(at("pack"))? {
                Some(r) => Some(r),
                None if c == "inv_g" && derived.smallest_inv_g.is_finite() => {
                    Some(crate::pack_inputs::inv_g_range(derived.smallest_inv_g))
                }
                None if matches!(c.as_str(), "nx" | "ny" | "nz") => None,
                None => self.stats.range(c).map(|(lo, hi)| [lo as f64, hi as f64]),
            };
            if let Some(r) = r {
                ranges.insert(c.clone(), r);
            }
        }
        Ok(PackParams { profile, ranges, fields: vec![], dtype: None, nifti: false })
    }

    /// The pack (with the histograms counted in the same pass): its
    /// textures, tables, manifest and figures; the names of the tables and
    /// the boundaries the histogram volume shows.
    pub(super) fn pack(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        traced: &Traced,
    ) -> Result<(Vec<String>, Vec<mdtf_histogram::DetectedBoundary>), RunError> {
        let params = self.pack_params(derived, traced)?;
        let pdir = self.dir.join("pack");
        std::fs::create_dir_all(&pdir).map_err(io("pack"))?;
        let sources = BTreeMap::new();
        let mut writer = PackWriter::new(&pdir, &params, self.geo.clone(), &sources);
        let started = Instant::now();
        let hists = self.histograms_and_textures(chans, derived, &params, &mut writer)?;
        self.finish_pack(chans, derived, &params, writer, hists, started)
    }

    /// One pass over the slabs that counts every histogram and quantises
    /// every texture, so each slab's channels are made once; its time is
    /// the pack stage's (the histogram stage's is writing the histogram
    /// files, which this writes too).
    fn histograms_and_textures(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        params: &PackParams,
        writer: &mut PackWriter,
    ) -> Result<Written, RunError> {
        let counting = self.p.histogram.is_some() || self.hvol_needed;
        let what = if counting { "histogram and pack" } else { "pack" };
        self.progress.stage(&format!("{what}{}", if self.tasks.is_some() { " (tasks)" } else { "" }))?;
        let n = self.geo.voxel_count();
        let mut histograms = match counting {
            true => {
                let g_buckets = derived.g_buckets.as_ref();
                Some(SlabHistograms::new(self.p, chans, &self.stats, &self.slabs, n, self.hvol_needed, g_buckets)?)
            }
            false => None,
        };
        let layouts = mdtf_pack::texture_layouts(params);
        let mut read: Vec<&str> = histograms.as_ref().map(|h| h.axes().channels()).unwrap_or_default();
        for c in layouts.iter().flat_map(|l| l.components.iter().flatten()) {
            if !read.contains(&c.as_str()) {
                read.push(c);
            }
        }
        if let Some(tasks) = self.tasks {
            let targets = writer.task_textures(&layouts).map_err(at("pack"))?;
            let axes = histograms.as_ref().map(|h| h.axes().clone());
            // a task counting the histogram volume holds whole fixed parts of its slices
            let task_slabs = match axes.as_ref().is_some_and(|a| a.counts_hvol()) {
                true => mdtf_histogram::fixed_parts(self.geo.dims[2]).into_iter().filter(|p| !p.is_empty()).collect(),
                false => self.slabs.clone(),
            };
            let read = read.iter().map(|c| c.to_string()).collect();
            let pass = SlabPass::Pack { textures: targets.clone(), histograms: axes, read, height: self.height };
            let groups = self.derive_groups();
            let derivation = Derivation { groups: &groups, kernel_reach: self.plan.reach.kernel[2] };
            for part in self.on_tasks(tasks, pass, &mut chans.store, derivation, &task_slabs)? {
                if let (Some(h), Some(counts)) = (&mut histograms, part.histograms) {
                    h.merge(counts)?;
                }
            }
            writer.adopt_task_textures(&targets).map_err(at("pack"))?;
            return match histograms {
                Some(h) => self.write_histograms(h),
                None => Ok(Written::default()),
            };
        }
        let mut counting_failed = None;
        let (progress, height, count) = (&self.progress, self.height, self.slabs.len());
        let written = writer.add_slabs(&layouts, &self.slabs, &mut |z, spent| {
            progress.report_slab(z.end.div_ceil(height), count);
            chans.give_back(spent);
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
        match histograms {
            Some(h) => self.write_histograms(h),
            None => Ok(Written::default()),
        }
    }

    /// The histogram files (when the pipeline asks for histograms), and
    /// the histogram volume the default TF reads.
    fn write_histograms(&mut self, h: SlabHistograms) -> Result<Written, RunError> {
        let t = Instant::now();
        let mut counted = h.finish(self.geo.spacing)?;
        counted.set_units(&self.units);
        counted.without_g = self.stats.not_finite("g");
        // the default TF's histogram volume is an output only when the histograms ask for it
        let default_hvol = if self.hvol_asked { None } else { counted.hvol.take() };
        let mut hists = Written::default();
        if self.p.histogram.is_some() {
            let hdir = self.dir.join("histogram");
            std::fs::create_dir_all(&hdir).map_err(io("histogram"))?;
            hists =
                crate::hist_files::write(&hdir, counted, default_hvol.as_ref(), &self.input_name, &mut self.warnings)
                    .map_err(fail("histogram"))?;
            self.stages.done("histogram", t, self.geo.voxel_count(), hists.outputs.clone());
        }
        if default_hvol.is_some() {
            hists.hvol = default_hvol;
        }
        Ok(hists)
    }

    /// The pack's lookup tables, manifest, Gaussians and TF figures, after
    /// its textures (`writer`, started at `started`).
    fn finish_pack(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        params: &PackParams,
        writer: PackWriter,
        hists: Written,
        started: Instant,
    ) -> Result<(Vec<String>, Vec<mdtf_histogram::DetectedBoundary>), RunError> {
        let Written { arches, figure_hists, hvol, boundaries, .. } = hists;
        let profile = params.profile;
        // the tables read the channels' names and grid (their data only without a histogram volume)
        let stubs: Vec<(String, Volume)> =
            profile.channels(&[]).into_iter().map(|c| (c, Volume::zeros(self.geo.z_slab(0..1)))).collect();
        let alpha = self.p.pack.alpha_map();
        let tf = self.tf.as_ref();
        let luts =
            crate::pack_inputs::luts(profile, tf, &alpha, &stubs, &params.ranges, hvol.as_ref(), &derived.derive)
                .map_err(at("pack"))?;
        let provenance = crate::inputs::provenance(self.p, self.opts, &self.base, self.geo.dims, &self.units);
        writer.finish(&luts, provenance).map_err(at("pack"))?;
        let mut outputs: Vec<String> = vec!["pack/manifest.json".into()];
        if profile == Profile::GaussianTf {
            let gaussians = self.write_gaussians(chans, derived, hvol.as_ref())?;
            let hdir = self.dir.join("histogram");
            let written =
                crate::figures::write_gaussian_figures(&hdir, &gaussians, &figure_hists, &[], &self.input_name)
                    .map_err(at("pack"))?;
            outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
        }
        if !figure_hists.is_empty() {
            let hists: Vec<&Histogram> = figure_hists.iter().collect();
            let hdir = self.dir.join("histogram");
            let written = crate::figures::write_tf_figures(&hdir, &luts, &hists, &self.input_name, &arches)
                .map_err(at("pack"))?;
            outputs.extend(written.into_iter().map(|f| format!("histogram/{f}")));
        }
        self.stages.done("pack", started, self.geo.voxel_count(), outputs);
        Ok((luts.into_iter().map(|l| l.name).collect(), boundaries))
    }

    /// gaussian-tf's primitives: the TF file's, else a TGTF at each boundary
    /// the histogram volume shows, else the paper's median default; written
    /// into the pack and returned.
    fn write_gaussians(
        &self,
        chans: &mut SlabChannels,
        derived: &Derived,
        hvol: Option<&mdtf_histogram::HistogramVolume>,
    ) -> Result<Vec<mdtf_pack::GaussianPrimitive>, RunError> {
        let gaussians = match (self.tf.as_ref(), hvol) {
            (Some(tf), _) => tf.gaussians(),
            (None, Some(hv)) => {
                let arches = crate::pack_inputs::arches_from(&mdtf_histogram::detect_boundaries(hv));
                match arches.is_empty() {
                    false => crate::gaussians::boundary_tgtfs(&arches, &self.geo),
                    true => vec![
                        medians::median_tgtf(chans, &self.slabs, derived.g_buckets.as_ref()).map_err(fail("pack"))?,
                    ],
                }
            }
            (None, None) => return Err(fail("pack")("the default Gaussians need the histogram volume".into())),
        };
        crate::gaussians::write(&self.dir.join("pack"), &gaussians).map_err(at("pack"))?;
        Ok(gaussians)
    }
}

/// The derived channels (of `derived`) a run of `p` on tasks reads itself
/// after its derive pass, which its derive tasks store (the tasks remake
/// every other channel): the kept ones, and g where the run takes a median
/// of it (the tracing's noise floor and the detection before it, the
/// (v, 1/g) axis, gaussian-tf's default without a TF file, `tf_given`).
pub(super) fn stored_for_the_run(p: &Pipeline, plan: &Plan, tf_given: bool, derived: &[String]) -> Vec<String> {
    let mut store: Vec<String> = p.keep.iter().filter(|c| derived.contains(c)).cloned().collect();
    let joint = p.histogram.as_ref().is_some_and(|h| h.joint);
    let medians_of_g = plan.trace
        || (joint && derived.iter().any(|c| c == "inv_g"))
        || (p.pack.profile == Profile::GaussianTf && !tf_given);
    if medians_of_g && derived.iter().any(|c| c == "g") && !store.iter().any(|c| c == "g") {
        store.push("g".into());
    }
    store
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
    let mut writer = store.writer(&["v"]).map_err(io("input"))?;
    let mut padded = 0u64;
    // a slab is read while the one before is summarised and stored
    overlapped(
        slabs.len(),
        &mut |k| progress.slab(k + 1, slabs.len()),
        &mut |k, _| Ok((slabs[k].start, source.read(slabs[k].clone())?)),
        &mut |(first, v)| {
            stats.add("v", v.samples());
            if let Some(range) = padding {
                padded += crate::inputs::count_padding(v.samples(), range);
            }
            writer.put_volume("v", first, &v).map_err(io("input"))?;
            Ok(None)
        },
    )?;
    Ok(padded)
}

/// The tracing's whole-volume sums, fed block by block (or task by task).
#[derive(Default)]
struct TraceSums(Option<TracePartial>);

impl TraceSums {
    /// Adds the next block's tracing.
    fn add(&mut self, slab: &SlabTrace) {
        self.merge(TracePartial::of(slab));
    }

    /// Adds the next slab's tracing, made by a task.
    fn merge(&mut self, part: TracePartial) {
        match &mut self.0 {
            Some(sums) => sums.merge(part),
            None => self.0 = Some(part),
        }
    }
}
