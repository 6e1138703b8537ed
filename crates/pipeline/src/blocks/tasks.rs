//! The body of one task of a run on a cluster ([`super::remote`]): each
//! pass's work on one slab, its outputs stored by planes (or rows of
//! planes) and its part of the pass's reductions left beside the store
//! ([`SlabPartial`]). What a pass reads and finds unstored it derives from
//! the stored value, as the run's own passes do.

use super::budget::slabs;
use super::medians::{SelectCounts, SelectPass};
use super::partials::{SlabPartial, TraceSums};
use super::remote::{Prefilter, SlabJob, SlabPass};
use super::resume::{self, WriteHashes};
use super::slab_histograms::{HistogramAxes, HistogramCounts};
use super::trace::{TraceSetup, prefilter_slab, trace_slab};
use super::{ChannelStore, SlabChannels};
use crate::boundary_chain::TracedVolumes;
use crate::channel::Channel;
use crate::pre_detect::VgCounts;
use crate::run::{RunError, at, fail};
use mdtf_histogram::Axis;
use mdtf_pack::TextureTarget;
use mdtf_volume::Volume;
use mdtf_volume::{NanPolicy, PlaneReader, ReadOptions, SampleType};
use std::cell::RefCell;
use std::ops::Range;
use std::path::Path;
use std::sync::{Mutex, PoisonError};

/// What a task did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TaskOutcome {
    /// It ran its pass on its slab.
    Ran,
    /// It found its slab done already (its partial and every byte it
    /// wrote there: a rerun, or a resumed run) and did nothing.
    FoundDone,
}

/// Runs `job` on the planes `z` of the volume: the body of one task. A
/// task whose slab is done already does nothing; a task of a run that has
/// ended or was taken over fails without publishing.
pub fn run_task(job: &SlabJob, z: Range<usize>) -> Result<TaskOutcome, RunError> {
    let nz = job.geometry.dims[2];
    if z.start >= z.end || z.end > nz {
        return Err(fail("plan")(format!("planes {z:?} are not a slab of the volume's {nz}")));
    }
    resume::check_token(job)?;
    if resume::already_done(job, &z) {
        return Ok(TaskOutcome::FoundDone);
    }
    let attempts = super::remote::attempts_path(&job.store, job.pass.name(), z.start);
    let stage = job.pass.stage();
    let counted = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&attempts)
        .and_then(|mut f| std::io::Write::write_all(&mut f, b"."));
    counted.map_err(|e| fail(stage)(format!("{}: {e}", attempts.display())))?;
    let task = Task { job, z, voxels: job.geometry.voxel_count(), hashed: RefCell::default() };
    let partial = match &job.pass {
        SlabPass::Input { input, level, nan, padding } => task.input(input, *level, *nan, *padding)?,
        SlabPass::Derive { summarise, store } => task.derive(summarise, store)?,
        SlabPass::Prefilter { filters, halo } => task.prefilter(filters, *halo)?,
        SlabPass::Select { select, detect } => task.select(select.as_ref(), detect.as_ref())?,
        SlabPass::Trace { .. } => task.trace()?,
        SlabPass::Keep { channels, parts, height } => task.kept_parts(channels, parts, *height)?,
        SlabPass::Pack { textures, histograms, read, height } => {
            task.pack(textures, histograms.as_ref(), read, *height)?
        }
    };
    let written = resume::hash_written(job, &task.z, &task.hashed.borrow())?;
    let partial = SlabPartial { job: resume::job_digest(job)?, written, ..partial };
    // the last check: a task the run no longer waits for publishes nothing
    resume::check_token(job)?;
    partial.write(&job.store, job.pass.name(), task.z.start)?;
    Ok(TaskOutcome::Ran)
}

/// The channels (and the memory they hold: the slabs' samples, the
/// derivation's outputs, the value's planes) of the last task of a pass
/// this process ran, with the pass's key, kept for its next task of the
/// same pass: a task's arrays are beyond what the allocator keeps for
/// reuse, and mapping them fresh for every task page-faults on every
/// 4 KiB, at a cost like the work's. The store does not change during a
/// pass, so what they hold of it stays right.
static KEPT_CHANNELS: Mutex<Option<(String, SlabChannels)>> = Mutex::new(None);

/// The texture bytes of the last pack task, likewise.
static KEPT_BYTES: Mutex<Vec<Vec<u8>>> = Mutex::new(Vec::new());

/// One task: its job and its slab.
struct Task<'j> {
    job: &'j SlabJob,
    /// The slab's planes.
    z: Range<usize>,
    /// Voxels of the whole volume.
    voxels: usize,
    /// What it wrote, hashed as it wrote it (for its partial).
    hashed: RefCell<WriteHashes>,
}

impl Task<'_> {
    /// The run's channel store, with the channels `reads` adopted.
    fn open(&self, reads: &[Channel]) -> Result<ChannelStore, RunError> {
        ChannelStore::open(self.job.store.clone(), self.job.geometry.clone(), reads).map_err(at("input"))
    }

    /// Writes rows `rows` of the slab's planes of channel `c` (all rows: the
    /// whole slab) into `out`, the bytes hashed as they go.
    fn put(&self, out: &mut ChannelStore, c: Channel, rows: Range<usize>, v: &Volume) -> Result<(), RunError> {
        let stage = self.job.pass.stage();
        let [nx, ny, _] = self.job.geometry.dims;
        let file = self.job.store.join(super::store::file_name(c));
        if rows != (0..ny) {
            // a strip of rows lies in pieces in the file: it is read back for its hash
            out.put_rows(c, self.z.start, rows, v).map_err(at(stage))?;
            self.hashed.borrow_mut().unordered(&file);
            return Ok(());
        }
        // the bytes written are the bytes hashed, made once
        let bytes = super::store::stored_bytes(c, v.samples());
        out.put_stored_bytes(c, self.z.start, &bytes).map_err(at(stage))?;
        let at_byte = (self.z.start * ny * nx * super::store::stored_type(c).size()) as u64;
        self.hashed.borrow_mut().add(&file, at_byte, &bytes);
        Ok(())
    }

    /// The channels the store holds, and the derivation of the others:
    /// those the last task of this pass in this process left, if any (and
    /// still of the same stored channels).
    fn channels(&self) -> Result<SlabChannels, RunError> {
        let kept = KEPT_CHANNELS.lock().unwrap_or_else(PoisonError::into_inner).take();
        if let Some((key, chans)) = kept
            && key == self.key()
            && chans.store.channels() == self.job.stored
        {
            return Ok(chans);
        }
        let nz = self.job.geometry.dims[2];
        Ok(SlabChannels::new(self.open(&self.job.stored)?, self.job.groups.clone(), self.job.kernel_reach, nz))
    }

    /// Leaves `chans` for the next task of this pass in this process.
    fn keep(&self, chans: SlabChannels) {
        *KEPT_CHANNELS.lock().unwrap_or_else(PoisonError::into_inner) = Some((self.key(), chans));
    }

    /// What tasks whose channels are the same share: the store, the pass
    /// (its kind and settings), the channels stored and their derivation.
    fn key(&self) -> String {
        let SlabJob { store, stored, groups, kernel_reach, pass, .. } = self.job;
        format!("{}|{pass:?}|{stored:?}|{groups:?}|{kernel_reach}", store.display())
    }

    /// Reads the slab of the input store and stores it as the value.
    fn input(
        &self,
        input: &Path,
        level: usize,
        nan: NanPolicy,
        padding: Option<[f64; 2]>,
    ) -> Result<SlabPartial, RunError> {
        let read = ReadOptions { nan, level, ..ReadOptions::default() };
        let not_by_planes = || fail("input")(format!("{}: not readable by planes", input.display()));
        let mut reader = PlaneReader::open(input, &read).map_err(at("input"))?.ok_or_else(not_by_planes)?;
        let (dims, planned) = (reader.geometry().dims, self.job.geometry.dims);
        if dims != planned {
            return Err(fail("input")(format!("{}: {dims:?} voxels, the run planned {planned:?}", input.display())));
        }
        let v = reader.read(self.z.clone()).map_err(at("input"))?;
        self.put(&mut self.open(&[])?, Channel::Value, 0..dims[1], &v)?;
        let mut partial = SlabPartial::default();
        partial.summarise(Channel::Value, v.samples(), self.voxels);
        if let Some(range) = padding {
            partial.padded = crate::inputs::count_padding(v.samples(), range);
        }
        Ok(partial)
    }

    /// Derives the channels `summarise` (taking their statistics) and `store` (storing them).
    fn derive(&self, summarise: &[Channel], store: &[Channel]) -> Result<SlabPartial, RunError> {
        let mut chans = self.channels()?;
        // the outputs through their own handles: the channels kept for the next task hold only the stored ones
        let mut out = self.open(&[])?;
        let mut channels = summarise.to_vec();
        channels.extend(store.iter().filter(|c| !summarise.contains(c)));
        let mut partial = SlabPartial::default();
        for (c, v) in chans.volumes(self.z.clone(), &channels).map_err(at("derive"))? {
            if store.contains(&c) {
                self.put(&mut out, c, 0..self.job.geometry.dims[1], &v)?;
            }
            if !summarise.contains(&c) {
                continue;
            }
            partial.summarise(c, v.samples(), self.voxels);
            match c {
                Channel::G => partial.g_buckets.get_or_insert_with(mdtf_volume::KeyBuckets::new).add(v.samples()),
                Channel::InvG => partial.smallest_inv_g = Some(crate::pack_inputs::smallest_positive(v.samples())),
                _ => {}
            }
        }
        self.keep(chans);
        Ok(partial)
    }

    /// Pre-filters the slab of each of `filters`' channels (read over its `halo`) and stores it.
    fn prefilter(&self, filters: &[Prefilter], halo: usize) -> Result<SlabPartial, RunError> {
        let mut chans = self.channels()?;
        // the outputs through their own handles: the channels kept for the next task hold only the stored ones
        let mut out = self.open(&[])?;
        let mut partial = SlabPartial::default();
        for (f, own) in filters.iter().zip(prefilter_slab(&mut chans, filters, &self.z, halo)?) {
            self.put(&mut out, f.output, 0..self.job.geometry.dims[1], &own)?;
            partial.summarise(f.output, own.samples(), self.voxels);
            // the first pass of its median's select, when it is the g traced
            if f.output == Channel::GPrefiltered {
                partial.g_buckets.get_or_insert_with(mdtf_volume::KeyBuckets::new).add(own.samples());
            }
        }
        self.keep(chans);
        Ok(partial)
    }

    /// The slab's part of whole-volume medians and of the tracing's
    /// statistics: the pass `select` of a median's radix select, and its
    /// (v, g) counts over the axes `detect`.
    fn select(&self, select: Option<&SelectPass>, detect: Option<&(Axis, Axis)>) -> Result<SlabPartial, RunError> {
        let mut chans = self.channels()?;
        // each channel read once
        let mut channels: Vec<Channel> = select.map(SelectPass::reads).unwrap_or_default();
        if detect.is_some() {
            for c in [Channel::Value, Channel::G] {
                if !channels.contains(&c) {
                    channels.push(c);
                }
            }
        }
        let slab = chans.volumes(self.z.clone(), &channels).map_err(at("boundary"))?;
        let samples = |c: Channel| slab.iter().find(|(n, _)| *n == c).map(|(_, v)| v.samples()).unwrap_or_default();
        let mut partial = SlabPartial::default();
        if let Some(pass) = select {
            let mut counts = SelectCounts::default();
            let mask = pass.above.map(|(m, _)| samples(m)).unwrap_or_default();
            pass.count(samples(pass.channel), mask, &mut counts);
            partial.selected = Some(counts);
        }
        if let Some((v_axis, g_axis)) = detect {
            let mut counts = VgCounts::new(v_axis.clone(), g_axis.clone());
            counts.add(samples(Channel::Value), samples(Channel::G)).map_err(at("boundary"))?;
            partial.vg = Some(counts);
        }
        chans.give_back(slab);
        self.keep(chans);
        Ok(partial)
    }

    /// Traces the slab strip by strip and stores its outputs.
    fn trace(&self) -> Result<SlabPartial, RunError> {
        let SlabPass::Trace { g, f2, prefiltered, params, stats, halo, halo_rows, rows, value_range, stores } =
            &self.job.pass
        else {
            return Err(fail("boundary")("not a tracing pass".into()));
        };
        let mut chans = self.channels()?;
        // the outputs through their own handles: the channels kept for the next task hold only the stored ones
        let mut out = self.open(&[])?;
        let setup = TraceSetup {
            g: *g,
            f2: *f2,
            prefiltered: *prefiltered,
            params,
            stats,
            halo: *halo,
            halo_rows: *halo_rows,
            value_range: *value_range,
        };
        let (mut partial, mut sums, mut spent) = (SlabPartial::default(), TraceSums::default(), None);
        for strip in slabs(chans.ny(), (*rows).max(1)) {
            let slab = trace_slab(&mut chans, &setup, &self.z, &strip, spent.take())?;
            let b = &slab.trace;
            for &c in stores {
                if let Some(v) = b.traced(c) {
                    self.put(&mut out, c, strip.clone(), v)?;
                }
            }
            partial.summarise(Channel::GHit, b.g_hit.samples(), self.voxels);
            sums.add(&slab);
            spent = Some(slab);
        }
        partial.trace = sums.0;
        self.keep(chans);
        Ok(partial)
    }

    /// Writes the slab's planes of the `kept` channels as gzip members into
    /// their part files in `parts`, `height` planes at a time.
    fn kept_parts(&self, kept: &[Channel], parts: &Path, height: usize) -> Result<SlabPartial, RunError> {
        let mut chans = self.channels()?;
        let [nx, ny, _] = self.job.geometry.dims;
        let mut files = Vec::with_capacity(kept.len());
        for &c in kept {
            let path = super::remote::kept_part(parts, c, self.z.start);
            let file = std::fs::File::create(&path).map_err(|e| fail("keep")(format!("{}: {e}", path.display())))?;
            files.push((c, path, std::io::BufWriter::new(file), 0u64));
        }
        for planes in slabs(self.z.len(), height.max(1)) {
            let planes = self.z.start + planes.start..self.z.start + planes.end;
            let slab = chans.volumes(planes, kept).map_err(at("keep"))?;
            for (c, path, file, written) in &mut files {
                let v = slab.iter().find(|(k, _)| k == c).map(|(_, v)| v);
                let v = v.ok_or_else(|| fail("keep")(format!("no channel {} to keep", c.name(&[]))))?;
                for member in mdtf_volume::gz_members::plane_members(v.samples(), nx * ny, SampleType::F32) {
                    let wrote = std::io::Write::write_all(file, &member);
                    wrote.map_err(|e| fail("keep")(format!("{}: {e}", path.display())))?;
                    self.hashed.borrow_mut().add(path, *written, &member);
                    *written += member.len() as u64;
                }
            }
            chans.give_back(slab);
        }
        for (_, path, file, _) in files {
            file.into_inner().map_err(|e| fail("keep")(format!("{}: {}", path.display(), e.error())))?;
        }
        self.keep(chans);
        Ok(SlabPartial::default())
    }

    /// Counts the slab's histograms and writes its planes of every texture,
    /// `height` planes at a time.
    fn pack(
        &self,
        textures: &[TextureTarget],
        histograms: Option<&HistogramAxes>,
        read: &[Channel],
        height: usize,
    ) -> Result<SlabPartial, RunError> {
        let mut chans = self.channels()?;
        let mut counts = HistogramCounts::default();
        let mut bytes = std::mem::take(&mut *KEPT_BYTES.lock().unwrap_or_else(PoisonError::into_inner));
        bytes.resize(textures.len(), Vec::new());
        let nz = self.job.geometry.dims[2];
        for planes in slabs(self.z.len(), height.max(1)) {
            let planes = self.z.start + planes.start..self.z.start + planes.end;
            let slab = chans.volumes(planes.clone(), read).map_err(at("pack"))?;
            if let Some(axes) = histograms {
                counts.of_task_slab(axes, &planes, nz, &slab)?;
            }
            let slab = super::by_name(slab);
            for (t, bytes) in textures.iter().zip(&mut bytes) {
                t.write_planes(planes.clone(), &slab, bytes).map_err(at("pack"))?;
                let at_byte = (t.plane_bytes() * planes.start) as u64;
                self.hashed.borrow_mut().add(&t.file, at_byte, bytes);
            }
            chans.give_back(slab);
        }
        self.keep(chans);
        *KEPT_BYTES.lock().unwrap_or_else(PoisonError::into_inner) = bytes;
        Ok(SlabPartial { histograms: histograms.is_some().then(|| counts.finish_task()), ..SlabPartial::default() })
    }
}
