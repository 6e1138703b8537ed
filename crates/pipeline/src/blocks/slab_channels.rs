//! The channels of a slab-by-slab run on any planes: those the run stored
//! (the value, the tracing's outputs, the pre-filtered g and f'') read from
//! the [`ChannelStore`], the derivatives recomputed from the stored value
//! over the planes grown by the kernel's support. Recomputing the
//! derivatives costs less than writing them to disk and reading them back,
//! and the items are derived in the groups the whole-volume run derives them
//! in, so every sample has its bits. Blocks that overlap (the tracing's,
//! grown by its halo) keep the planes they share and derive only the new
//! ones ([`SlabChannels::derive_block`]).

use super::{ChannelStore, SamplePool, grown};
use crate::channel::Channel;
use mdtf_derive::{DeriveOutput, DeriveParams, Item};
use mdtf_volume::{MultiField, Volume};
use std::ops::Range;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Why a slab's channels could not be had.
#[derive(Debug, thiserror::Error)]
pub enum ChannelError {
    /// The run was cancelled.
    #[error("cancelled")]
    Cancelled,
    /// The channel store could not be read.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// A channel's samples do not make a volume of its planes.
    #[error("{0}")]
    Volume(#[from] mdtf_volume::VolumeError),
    /// The derivation failed.
    #[error("derive: {0}")]
    Derive(#[from] mdtf_derive::DeriveError),
    /// The derivation did not give what it was asked for (a bug, not the input's fault).
    #[error("{0}")]
    Missing(&'static str),
    /// A stage asked for a channel by a name no one-field run has.
    #[error("no channel is named '{0}'")]
    Unknown(String),
}

/// The channels a stage crate names (a pack layout's components, a
/// histogram's axes), as a one-field run's channels.
pub fn channels_named<S: AsRef<str>>(names: &[S]) -> Result<Vec<Channel>, ChannelError> {
    names
        .iter()
        .map(|n| Channel::of_store(n.as_ref()).ok_or_else(|| ChannelError::Unknown(n.as_ref().into())))
        .collect()
}

/// A slab's channels by name, for the stage crates, which take them so.
pub fn by_name(slab: Vec<(Channel, Volume)>) -> Vec<(String, Volume)> {
    slab.into_iter().map(|(c, v)| (c.name(&[]), v)).collect()
}

/// Stored and derivable channels (see the module docs).
pub struct SlabChannels {
    /// The stored channels.
    pub store: ChannelStore,
    /// The derive passes, each with the channels it makes.
    groups: Vec<(DeriveParams, Vec<Channel>)>,
    /// Planes (and rows: a kernel's support is the same along every axis) the kernel reads on each side.
    kernel_reach: usize,
    nz: usize,
    /// The last block derived whole and where it lies, for the next (see [`SlabChannels::derive_block`]).
    recycled: Option<(BlockRange, DeriveOutput)>,
    /// Where the last block [`SlabChannels::derive_block`] handed out lies.
    last_block: BlockRange,
    /// Each group's last output, whose memory its next derivation reuses.
    previous: Vec<Option<DeriveOutput>>,
    /// Memory of the last value block read, holding its samples.
    value_buffer: Vec<f32>,
    /// Where the block in `value_buffer` lies (empty: it holds none).
    value_block: BlockRange,
    /// Memory of the channels handed out, handed back for the next slab's.
    pool: SamplePool,
    /// The samples [`SlabChannels::samples`] last handed out.
    samples_buffer: Vec<f32>,
    /// When set, every read fails: a cancelled run stops in the middle of a pass.
    cancel: Option<Arc<AtomicBool>>,
}

/// Where a block of a blocked pass lies: its planes and rows in the whole volume.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockRange {
    /// Planes (z).
    pub planes: Range<usize>,
    /// Rows (y) of each plane.
    pub rows: Range<usize>,
}

impl BlockRange {
    /// No block (no planes, no rows).
    const NONE: BlockRange = BlockRange { planes: 0..0, rows: 0..0 };

    /// Whether a block derived over `self` can hand its exact planes on to
    /// `next`: as tall, the same rows, starting inside it further along z.
    fn slides_to(&self, next: &BlockRange) -> bool {
        self.rows == next.rows
            && self.planes.len() == next.planes.len()
            && self.planes.start < next.planes.start
            && next.planes.start < self.planes.end
    }
}

/// The channels derive item `item` makes (its components are table rows:
/// `channel::tests::every_derive_item_makes_table_channels`).
pub(super) fn made_by(item: Item) -> Vec<Channel> {
    item.components().iter().filter_map(|c| Channel::of_store(c)).collect()
}

impl SlabChannels {
    /// Channels of `store` (holding the value, "v"), with the derive passes
    /// `groups` (each its items, kernel and epsilon); the kernel reads
    /// `kernel_reach` planes each side; the volume has `nz` planes.
    pub fn new(store: ChannelStore, groups: Vec<DeriveParams>, kernel_reach: usize, nz: usize) -> SlabChannels {
        let groups: Vec<(DeriveParams, Vec<Channel>)> = groups
            .into_iter()
            .filter(|d| !d.items.is_empty())
            .map(|d| {
                let names = d.items.iter().flat_map(|&i| made_by(i)).collect();
                (d, names)
            })
            .collect();
        let previous = groups.iter().map(|_| None).collect();
        SlabChannels {
            store,
            groups,
            kernel_reach,
            nz,
            recycled: None,
            last_block: BlockRange::NONE,
            previous,
            value_buffer: Vec::new(),
            value_block: BlockRange::NONE,
            pool: SamplePool::default(),
            samples_buffer: Vec::new(),
            cancel: None,
        }
    }

    /// These channels, whose reads fail once `cancel` is set.
    pub fn cancelled_by(self, cancel: Option<Arc<AtomicBool>>) -> SlabChannels {
        SlabChannels { cancel, ..self }
    }

    /// An error once the run is cancelled.
    fn check(&self) -> Result<(), ChannelError> {
        if crate::progress::is_set(&self.cancel) { Err(ChannelError::Cancelled) } else { Ok(()) }
    }

    /// Planes of the volume.
    pub fn nz(&self) -> usize {
        self.nz
    }

    /// Rows of each plane.
    pub fn ny(&self) -> usize {
        self.store.geometry().dims[1]
    }

    /// Whether channel `c` is stored or derivable.
    pub fn has(&self, c: Channel) -> bool {
        self.store.has(c) || self.groups.iter().any(|(_, made)| made.contains(&c))
    }

    /// Channels `channels` on planes `z`, in that order.
    pub fn volumes(&mut self, z: Range<usize>, channels: &[Channel]) -> Result<Vec<(Channel, Volume)>, ChannelError> {
        self.check()?;
        let mut derived: Vec<(Channel, Volume)> = Vec::new();
        for g in 0..self.groups.len() {
            let (d, made) = &self.groups[g];
            if !channels.iter().any(|&c| !self.store.has(c) && made.contains(&c)) {
                continue;
            }
            // only the items asked for: an item alone has the bits it has among others
            // (derive's fused loop equals its general pass), and the others cost time
            let mut d = d.clone();
            d.items.retain(|&i| made_by(i).iter().any(|m| channels.contains(m)));
            let k = self.kernel_reach;
            let read = grown(&z, k, 2 * k + 1, self.nz);
            let value = self.value_planes(read.clone())?;
            let out = mdtf_derive::run_with_progress(&value, &d, self.previous[g].take(), &|_, _| {})?;
            self.keep_value(value);
            let own = z.start - read.start..z.end - read.start;
            for (_, mf) in &out.items {
                for f in &mf.fields {
                    if let Some(c) = Channel::of_store(&f.name).filter(|c| channels.contains(c)) {
                        derived.push((c, self.own_planes(mf, f, own.clone())?));
                    }
                }
            }
            self.previous[g] = Some(out);
        }
        channels
            .iter()
            .map(|&c| match derived.iter().position(|(d, _)| *d == c) {
                Some(i) => Ok(derived.swap_remove(i)),
                None => self.stored(c, z.clone()).map(|v| (c, v)),
            })
            .collect()
    }

    /// Planes `own` of field `f` of the derive output `mf`, copied into the pool's memory.
    fn own_planes(
        &mut self,
        mf: &MultiField,
        f: &mdtf_volume::Field,
        own: Range<usize>,
    ) -> Result<Volume, ChannelError> {
        let plane = mf.geometry.dims[0] * mf.geometry.dims[1];
        let all = f.data.as_slice().ok_or(ChannelError::Missing("a derived field is not contiguous"))?;
        let from =
            all.get(own.start * plane..own.end * plane).ok_or(ChannelError::Missing("a derived field is too short"))?;
        let mut samples = self.pool.take(from.len());
        samples.copy_from_slice(from);
        Ok(Volume::from_samples(mf.geometry.z_slab(own), samples)?)
    }

    /// Stored channel `c` on planes `z` (clamped to the grid), read into the pool's memory.
    fn stored(&mut self, c: Channel, z: Range<usize>) -> Result<Volume, ChannelError> {
        let geometry = self.store.geometry().clone();
        let nz = geometry.dims[2];
        let z = z.start.min(nz)..z.end.min(nz).max(z.start.min(nz));
        let mut samples = self.pool.take(z.len() * self.store.plane_len());
        self.store.rows_into_slice(c, z.clone(), 0..geometry.dims[1], &mut samples)?;
        Ok(Volume::from_samples(geometry.z_slab(z), samples)?)
    }

    /// Takes back channels handed out by [`SlabChannels::volumes`], done
    /// with: the next slab's are made in their memory.
    pub fn give_back<K>(&mut self, channels: Vec<(K, Volume)>) {
        self.pool.give_volumes(channels.into_iter().map(|(_, v)| v));
    }

    /// The first derive pass's g, f'' and normal over rows `rows` of planes `z`, both
    /// grown by the kernel's support (clamped to the volume), and those
    /// grown ranges (planes, rows): exact on `z`'s planes and `rows`' rows
    /// (and wherever the growth reached the volume's faces), not beyond.
    /// For a pass that reads only those of it, this avoids copying them
    /// out; hand the output back with [`SlabChannels::recycle`] and the
    /// next block of the same size is derived into its memory, as is the
    /// value read for it (fresh memory page-faults, which costs as much as
    /// the derivation). When the next block has the same rows and overlaps
    /// it in z (blocks grown by a halo, visited in z order), the planes the
    /// last one had exact are moved to their new place and only the others
    /// are derived: they are the same samples a derivation would give.
    pub fn derive_block(
        &mut self,
        z: Range<usize>,
        rows: Range<usize>,
    ) -> Result<(BlockRange, DeriveOutput), ChannelError> {
        let Some((d, _)) = self.groups.first() else { return Err(ChannelError::Missing("nothing is derived")) };
        let k = self.kernel_reach;
        let read = BlockRange { planes: grown(&z, k, 2 * k + 1, self.nz), rows: grown(&rows, k, 2 * k + 1, self.ny()) };
        let mut d = d.clone();
        // only what the tracing reads (a kept Hessian would cost it time; the output it hands back has these)
        d.items.retain(|i| matches!(i, Item::G | Item::F2 | Item::Normal));
        let value = self.value(&read)?;
        let out = match self.recycled.take() {
            Some((last, mut out)) if last.slides_to(&read) => {
                let kept = self.slide(&last, &read, &mut out);
                mdtf_derive::run_keeping(&value, &d, out, kept)
            }
            recycled => mdtf_derive::run_with_progress(&value, &d, recycled.map(|(_, o)| o), &|_, _| {}),
        }?;
        self.keep_value(value);
        self.last_block = read.clone();
        Ok((read, out))
    }

    /// Moves the planes of `out` (derived over `last`) that are exact there
    /// and lie in `read` (as tall, the same rows, further along z) to their
    /// place in `read`; returns where they now are, in `read`'s planes.
    fn slide(&self, last: &BlockRange, read: &BlockRange, out: &mut DeriveOutput) -> Range<usize> {
        let k = self.kernel_reach;
        let (last, read_planes) = (&last.planes, &read.planes);
        // exact planes of the last block: all but a kernel's reach from a cut (not a volume face)
        let exact_start = if last.start == 0 { 0 } else { last.start + k };
        let exact_end = if last.end == self.nz { last.end } else { last.end - k };
        let (from, to) = (exact_start.max(read_planes.start), exact_end.min(read_planes.end));
        if from >= to {
            return 0..0;
        }
        let plane = self.store.geometry().dims[0] * read.rows.len();
        let mut fields: Vec<&mut [f32]> = Vec::new();
        for (_, mf) in &mut out.items {
            for f in &mut mf.fields {
                match f.data.as_slice_mut() {
                    Some(data) => fields.push(data),
                    None => return 0..0,
                }
            }
        }
        for data in fields {
            data.copy_within(
                (from - last.start) * plane..(to - last.start) * plane,
                (from - read_planes.start) * plane,
            );
        }
        from - read_planes.start..to - read_planes.start
    }

    /// The stored value on planes `z` (every row), read into the memory of the last one.
    fn value_planes(&mut self, z: Range<usize>) -> Result<MultiField, ChannelError> {
        let rows = 0..self.ny();
        self.value(&BlockRange { planes: z, rows })
    }

    /// The stored value on a block, read into the memory of the last one.
    /// When the block slides along z from the last (the same rows), the
    /// planes they share are moved, and only the new ones read.
    fn value(&mut self, block: &BlockRange) -> Result<MultiField, ChannelError> {
        self.check()?;
        let mut buffer = std::mem::take(&mut self.value_buffer);
        let last = std::mem::replace(&mut self.value_block, BlockRange::NONE);
        let plane = self.store.geometry().dims[0] * block.rows.len();
        let (planes, rows) = (&block.planes, &block.rows);
        let shared = last.rows == *rows
            && last.planes.start <= planes.start
            && planes.start < last.planes.end
            && last.planes.end <= planes.end
            && buffer.len() == last.planes.len() * plane;
        if shared {
            let kept = last.planes.end - planes.start;
            buffer.copy_within((planes.start - last.planes.start) * plane.., 0);
            buffer.resize(planes.len() * plane, 0.0);
            let new_planes = last.planes.end..planes.end;
            self.store.rows_into_slice(Channel::Value, new_planes, rows.clone(), &mut buffer[kept * plane..])?;
        } else {
            self.store.rows_into(Channel::Value, planes.clone(), rows.clone(), &mut buffer)?;
        }
        let geometry = self.store.geometry().z_slab(planes.clone()).y_rows(rows.clone());
        let value = Volume::from_samples(geometry, buffer)?;
        self.value_block = block.clone();
        Ok(MultiField::from(value))
    }

    /// Keeps the memory of a value read by [`SlabChannels::value`] (and its
    /// samples, for a next block that shares planes with it).
    fn keep_value(&mut self, value: MultiField) {
        self.value_buffer =
            value.fields.into_iter().next().map(|f| f.data.into_raw_vec_and_offset().0).unwrap_or_default();
    }

    /// Frees the memory kept for reuse (between passes, whose blocks differ in size).
    pub fn release(&mut self) {
        self.recycled = None;
        self.previous.iter_mut().for_each(|p| *p = None);
        self.value_buffer = Vec::new();
        self.value_block = BlockRange::NONE;
        self.samples_buffer = Vec::new();
        self.pool.clear();
    }

    /// Gives back the output of [`SlabChannels::derive_block`] for reuse.
    pub fn recycle(&mut self, out: DeriveOutput) {
        self.recycled = Some((self.last_block.clone(), out));
    }

    /// The samples of channel `c` on planes `z`, in memory of the
    /// channels' own that the next call reuses.
    pub fn samples(&mut self, c: Channel, z: Range<usize>) -> Result<&[f32], ChannelError> {
        let mut samples = std::mem::take(&mut self.samples_buffer);
        let read = self.samples_into(c, z, &mut samples);
        self.samples_buffer = samples;
        read.map(|()| self.samples_buffer.as_slice())
    }

    /// Sets `samples` (its memory reused) to those of channel `c` on planes `z`.
    pub fn samples_into(&mut self, c: Channel, z: Range<usize>, samples: &mut Vec<f32>) -> Result<(), ChannelError> {
        self.check()?;
        if self.store.has(c) {
            return Ok(self.store.samples_into(c, z, samples)?);
        }
        let (_, v) = self.volumes(z, &[c])?.pop().ok_or(ChannelError::Missing("no samples"))?;
        self.pool.give(std::mem::replace(samples, v.data.into_raw_vec_and_offset().0));
        Ok(())
    }
}
