//! The pre-filter, the tracing's whole-volume statistics and the tracing
//! itself, in this process or as tasks.

use super::{Derived, SlabPasses, io};
use crate::blocks::medians::SelectPass;
use crate::blocks::partials::{TracePartial, TraceSums};
use crate::blocks::remote::{Prefilter, SlabPass, SlabTasks};
use crate::blocks::trace::{self, SlabTrace, TraceSetup};
use crate::blocks::{SlabChannels, TraceBlocks, reductions, slabs};
use crate::boundary_chain::TracedVolumes;
use crate::channel::Channel;
use crate::pre_detect::VgCounts;
use crate::report::{BoundarySummary, Traced};
use crate::run::{RunError, at, fail};
use mdtf_boundary::VolumeStats;
use mdtf_volume::{KeyBuckets, overlapped};
use reductions::{detected_before_tracing, detection_axes, g_stats, g_volume_stats, median_rank};
use std::ops::Range;
use std::time::Instant;

impl SlabPasses<'_> {
    /// The pre-filter (when planned) and tracing passes, when the plan traces.
    pub(in crate::blocks) fn trace(&mut self, chans: &mut SlabChannels, derived: &Derived) -> Result<Traced, RunError> {
        if !self.plan.trace {
            return Ok(Traced::default());
        }
        let (g, f2, prefiltered) = match (self.plan.prefilter, &self.work.chain().prefilter) {
            (true, Some(pf)) => {
                self.prefilter(chans, pf)?;
                (Channel::GPrefiltered, Channel::F2Prefiltered, true)
            }
            _ => (Channel::G, Channel::F2, false),
        };
        self.progress.stage("boundary")?;
        let t = Instant::now();
        let value_range = self.value_range();
        let stats = self.tracing_stats(chans, derived, g, prefiltered)?;
        if self.median_reads_stored_g() && !self.resumable() {
            chans.store.remove(Channel::G);
        }
        // the median's reads are done: their memory is not the tracing's size
        chans.release();
        let mut sums = TraceSums::default();
        match self.tasks {
            Some(tasks) => {
                let (params, [_, halo_rows, halo]) = (self.work.chain().boundary.clone(), self.plan.reach.trace);
                let (rows, stores) = (self.trace_blocks.rows, self.plan.traced_stored());
                let pass =
                    SlabPass::Trace { g, f2, prefiltered, params, stats, halo, halo_rows, rows, value_range, stores };
                let (_, tslabs) = self.trace_strips_and_slabs();
                for mut part in self.on_tasks(tasks, pass, &mut chans.store, &tslabs)? {
                    part.merge_stats_into(&mut self.stats);
                    let no_trace = || fail("boundary")("a tracing task left no tracing partial".into());
                    sums.merge(part.trace.ok_or_else(no_trace)?);
                }
            }
            None => {
                let chain = self.work.chain();
                let setup = TraceSetup {
                    g,
                    f2,
                    prefiltered,
                    params: &chain.boundary,
                    stats: &stats,
                    halo: self.plan.reach.trace[2],
                    halo_rows: self.plan.reach.trace[1],
                    value_range,
                };
                self.trace_here(chans, &setup, &mut sums)?;
            }
        }
        let traced = self.finish_trace(sums)?;
        for c in [Channel::GPrefiltered, Channel::F2Prefiltered, Channel::Dot] {
            if !self.plan.wanted.contains(&c) && !self.resumable() {
                chans.store.remove(c);
            }
        }
        chans.release();
        let outputs = vec!["boundary/boundary_report.csv".into(), "boundary/boundary_report.png".into()];
        self.stages.done("boundary", t, self.geo.voxel_count(), outputs);
        Ok(traced)
    }

    /// The whole-volume statistics the tracing of `g` (the pre-filtered
    /// one when `prefiltered`) takes its defaults from: the noise floor
    /// from g's median, its largest value, what detection finds before it.
    fn tracing_stats(
        &mut self,
        chans: &mut SlabChannels,
        derived: &Derived,
        g: Channel,
        prefiltered: bool,
    ) -> Result<VolumeStats, RunError> {
        let buckets = match prefiltered {
            true => self.prefiltered_buckets.take(),
            false => derived.g_buckets.clone(),
        };
        if let (Some(tasks), Some(buckets)) = (self.tasks, &buckets) {
            return self.tracing_stats_by_tasks(tasks, chans, g, buckets);
        }
        let (l_min, value_range) = (self.geo.min_spacing(), self.value_range());
        let detected = match self.plan.detects_before_tracing() {
            true => detected_before_tracing(chans, &self.slabs, &self.stats, l_min)?,
            false => Default::default(),
        };
        let stats = g_stats(chans, g, buckets.as_ref(), &self.slabs, value_range, l_min, &self.stats)?;
        Ok(VolumeStats { detected, ..stats })
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
        g: Channel,
        buckets: &KeyBuckets,
    ) -> Result<VolumeStats, RunError> {
        let (l_min, value_range) = (self.geo.min_spacing(), self.value_range());
        let k = median_rank(&self.stats, g)?;
        let within = k.and_then(|k| mdtf_volume::upper_bucket_of(k, buckets));
        let detect = if self.plan.detects_before_tracing() { detection_axes(chans, &self.stats) } else { None };
        let (mut lower, mut vg) = (KeyBuckets::new(), None::<VgCounts>);
        if within.is_some() || detect.is_some() {
            let select = within.map(|b| SelectPass { channel: g, above: None, within: Some(b) });
            let pass = SlabPass::Select { select, detect };
            for part in self.on_tasks(tasks, pass, &mut chans.store, &self.slabs.clone())? {
                if let Some(c) = &part.selected {
                    lower.merge(&c.buckets);
                }
                match (&mut vg, part.vg) {
                    (Some(all), Some(slab)) => all.merge(&slab).map_err(at("boundary"))?,
                    (all, slab) => *all = all.take().or(slab),
                }
            }
        }
        let median =
            k.filter(|_| within.is_some()).and_then(|k| mdtf_volume::order_statistic_from_counts(k, buckets, &lower));
        let detected = vg.map(|c| c.detected(l_min)).unwrap_or_default();
        Ok(VolumeStats { detected, ..g_volume_stats(&self.stats, g, median, value_range, l_min) })
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
        let outputs = self.plan.traced_stored();
        let mut writer = chans.store.writer(&outputs).map_err(io("boundary"))?;
        let (progress, stats) = (&self.progress, &mut self.stats);
        // a block is traced (in the memory of one written and summed) while the one before is written and summed
        let mut make = |k: usize, spent: Option<(usize, SlabTrace)>| {
            let (rows, z) = &blocks[k];
            Ok((k, trace::trace_slab(chans, setup, z, rows, spent.map(|(_, s)| s))?))
        };
        let mut take = |(k, slab): (usize, SlabTrace)| {
            let (rows, z) = &blocks[k];
            for &c in &outputs {
                if let Some(v) = slab.trace.traced(c) {
                    writer.put_rows(c, z.start, rows.clone(), v).map_err(io("boundary"))?;
                }
            }
            stats.add(Channel::GHit, slab.trace.g_hit.samples());
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
        let filters: Vec<Prefilter> = [(Channel::G, Channel::GPrefiltered), (Channel::F2, Channel::F2Prefiltered)]
            .map(|(input, output)| {
                let range = self.stats.range(input).map_or(0.0, |(lo, hi)| (hi - lo) as f64);
                let params = crate::boundary_chain::prefilter_params(pf, range);
                Prefilter { input, output, params }
            })
            .into();
        match self.tasks {
            Some(tasks) => {
                let pass = SlabPass::Prefilter { filters, halo };
                let mut buckets = KeyBuckets::new();
                for mut part in self.on_tasks(tasks, pass, &mut chans.store, &self.slabs.clone())? {
                    part.merge_stats_into(&mut self.stats);
                    if let Some(b) = &part.g_buckets {
                        buckets.merge(b);
                    }
                }
                self.prefiltered_buckets = Some(buckets);
            }
            None => {
                for (k, z) in self.slabs.iter().enumerate() {
                    self.progress.slab(k + 1, self.slabs.len())?;
                    for (f, own) in filters.iter().zip(trace::prefilter_slab(chans, &filters, z, halo)?) {
                        chans.store.put_volume(f.output, z.start, &own).map_err(io("prefilter"))?;
                        self.stats.add(f.output, own.samples());
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
}
