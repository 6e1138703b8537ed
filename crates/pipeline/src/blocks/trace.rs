//! The work of one slab in the pre-filter and tracing passes, the same
//! whether the run does it in its own process or hands it to a task
//! ([`super::remote`]): the slab's planes grown by the pass's halo are read
//! (or derived), and only the slab's own planes come out.

use super::remote::Prefilter;
use super::slab_channels::BlockRange;
use super::{ChannelError, ChannelStore, SlabChannels, grown};
use crate::channel::Channel;
use crate::run::{RunError, at};
use mdtf_boundary::{BlockTrace, BoundaryInput, BoundaryParams, VolumeStats};
use mdtf_volume::{MultiField, Volume};
use std::ops::Range;

/// Each of `filters` on the planes of `z`: its input channel pre-filtered,
/// from its planes grown by the filter's `halo` (the inputs read, or
/// derived together, once), in the order of `filters`.
pub(super) fn prefilter_slab(
    chans: &mut SlabChannels,
    filters: &[Prefilter],
    z: &Range<usize>,
    halo: usize,
) -> Result<Vec<Volume>, RunError> {
    let read = grown(z, halo, 1, chans.nz());
    let inputs: Vec<Channel> = filters.iter().map(|f| f.input).collect();
    let grown = chans.volumes(read.clone(), &inputs).map_err(at("prefilter"))?;
    let own = z.start - read.start..z.end - read.start;
    filters
        .iter()
        .zip(grown)
        .map(|(f, (_, v))| Ok(mdtf_bilateral::run(&v, &f.params).map_err(at("prefilter"))?.z_slab(own.clone())))
        .collect()
}

/// What a tracing pass reads and how.
pub(super) struct TraceSetup<'a> {
    /// The g traced (the pre-filtered one, when there is).
    pub g: Channel,
    /// The f'' traced (likewise).
    pub f2: Channel,
    /// g and f'' are the pre-filtered ones: a derived block reads them from the store over it.
    pub prefiltered: bool,
    /// The tracing's parameters.
    pub params: &'a BoundaryParams,
    /// The whole volume's statistics behind the tracing's defaults.
    pub stats: &'a VolumeStats,
    /// Planes a ray may reach beyond its voxel's (d_max plus the interpolation's support).
    pub halo: usize,
    /// Rows a ray may reach beyond its voxel's, likewise.
    pub halo_rows: usize,
    /// Value range (max - min) of the input, value units.
    pub value_range: f64,
}

/// A block's tracing and the g it traced, on its own rows and planes.
pub(super) struct SlabTrace {
    /// The tracing's outputs and counts.
    pub trace: BlockTrace,
    /// The g traced, on the block's own rows and planes (for the Fig. 2 report).
    pub g: Volume,
}

/// The tracing of rows `rows` of the planes of `z` (every row, or a strip
/// of them when the store's channels are derived here, not read), and the
/// traced g on them; in the memory of `spent` (a block's, done with) when given.
pub(super) fn trace_slab(
    chans: &mut SlabChannels,
    setup: &TraceSetup,
    z: &Range<usize>,
    rows: &Range<usize>,
    spent: Option<SlabTrace>,
) -> Result<SlabTrace, RunError> {
    let read = grown(z, setup.halo, 1, chans.nz());
    // the derivatives over the block as derived (its planes and rows beyond the halo are never reached)
    let read_rows = grown(rows, setup.halo_rows, 1, chans.ny());
    let (place, out) = chans.derive_block(read.clone(), read_rows).map_err(at("boundary"))?;
    let block = TraceBlock::of(place, out).map_err(at("boundary"))?;
    let block = match setup.prefiltered {
        false => block,
        true => block.with_stored(&mut chans.store, setup.g, setup.f2).map_err(at("boundary"))?,
    };
    let own_planes = z.start - block.at.planes.start..z.end - block.at.planes.start;
    let own_rows = rows.start - block.at.rows.start..rows.end - block.at.rows.start;
    let input = BoundaryInput { g: &block.g, f2: &block.f2, normal: &block.normal, value_range: setup.value_range };
    let place = mdtf_boundary::BlockPlace {
        first: [0, block.at.rows.start, block.at.planes.start],
        rows: own_rows.clone(),
        planes: own_planes.clone(),
    };
    let (spent_trace, spent_g) = spent.map(|s| (s.trace, s.g)).unzip();
    let b = mdtf_boundary::trace_block_into(&input, setup.params, &place, setup.stats, spent_trace)
        .map_err(at("boundary"))?;
    let g_own = own_samples(&block.g, &own_planes, &own_rows, spent_g).map_err(at("boundary"))?;
    if let Some(out) = block.into_output() {
        chans.recycle(out);
    }
    Ok(SlabTrace { trace: b, g: g_own })
}

/// Planes `planes` and rows `rows` of `v` (in its own indices), in the memory of `spent` when given.
fn own_samples(
    v: &Volume,
    planes: &Range<usize>,
    rows: &Range<usize>,
    spent: Option<Volume>,
) -> mdtf_volume::Result<Volume> {
    let [nx, ny, _] = v.geometry.dims;
    let mut samples = spent.map(|s| s.data.into_raw_vec_and_offset().0).unwrap_or_default();
    samples.clear();
    let all = v.samples();
    for k in planes.clone() {
        let row = all.get((k * ny + rows.start) * nx..(k * ny + rows.end) * nx);
        samples.extend_from_slice(row.ok_or_else(|| mdtf_volume::VolumeError::Fields("g is not the block's".into()))?);
    }
    Volume::from_samples(v.geometry.z_slab(planes.clone()).y_rows(rows.clone()), samples)
}

/// What a block's tracing reads: g, f'' and the normal on the block `at`.
struct TraceBlock {
    at: BlockRange,
    g: Volume,
    f2: Volume,
    normal: MultiField,
    /// The derive output's item order, when they came from one (to give its memory back).
    order: Option<Vec<mdtf_derive::Item>>,
}

impl TraceBlock {
    /// The block of a derive output over `at` holding g, f'' and the normal.
    fn of(at: BlockRange, out: mdtf_derive::DeriveOutput) -> Result<TraceBlock, ChannelError> {
        use mdtf_derive::Item;
        let order: Vec<Item> = out.items.iter().map(|(i, _)| *i).collect();
        let (mut g, mut f2, mut normal) = (None, None, None);
        for (item, mf) in out.items {
            match item {
                Item::G => g = Some(mf.into_scalar()?),
                Item::F2 => f2 = Some(mf.into_scalar()?),
                Item::Normal => normal = Some(mf),
                _ => {}
            }
        }
        let (Some(g), Some(f2), Some(normal)) = (g, f2, normal) else {
            return Err(ChannelError::Missing("the tracing needs g, f2 and the normal from one derive pass"));
        };
        Ok(TraceBlock { at, g, f2, normal, order: Some(order) })
    }

    /// The block with g and f'' replaced by the store's channels `g` and
    /// `f2` over it (the pre-filtered ones), read into the same memory.
    fn with_stored(self, store: &mut ChannelStore, g: Channel, f2: Channel) -> std::io::Result<TraceBlock> {
        let TraceBlock { at, g: derived_g, f2: derived_f2, normal, order } = self;
        let mut over_block = |c: Channel, v: Volume| {
            let geometry = v.geometry.clone();
            let mut samples = v.data.into_raw_vec_and_offset().0;
            store.rows_into(c, at.planes.clone(), at.rows.clone(), &mut samples)?;
            Volume::from_samples(geometry, samples).map_err(std::io::Error::other)
        };
        let (g, f2) = (over_block(g, derived_g)?, over_block(f2, derived_f2)?);
        Ok(TraceBlock { at, g, f2, normal, order })
    }

    /// The derive output it came from, for its memory.
    fn into_output(self) -> Option<mdtf_derive::DeriveOutput> {
        use mdtf_derive::Item;
        let order = self.order?;
        let (mut g, mut f2, mut normal) = (Some(self.g), Some(self.f2), Some(self.normal));
        let items = order
            .into_iter()
            .filter_map(|i| match i {
                Item::G => g.take().map(|v| (i, MultiField::from(v))),
                Item::F2 => f2.take().map(|v| (i, MultiField::from(v))),
                Item::Normal => normal.take().map(|n| (i, n)),
                _ => None,
            })
            .collect();
        Some(mdtf_derive::DeriveOutput { items })
    }
}
