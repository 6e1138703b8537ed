//! The whole-volume reductions of a slab-by-slab run, each merged exactly
//! over the slabs: the channels' percentile statistics, the median of g
//! behind the tracing's noise floor, and the detection before the tracing
//! (the histograms: [`super::slab_histograms`]).

use super::SlabChannels;
use crate::channel::Channel;
use crate::pre_detect::{HVOL_BINS, VgCounts};
use crate::run::{RunError, at, fail};
use mdtf_boundary::VolumeStats;
use mdtf_histogram::{Axis, AxisSpec, ChannelStats, HvolAxes};
use mdtf_volume::KeyBuckets;
use std::collections::BTreeMap;
use std::ops::Range;

/// Percentile statistics of the channels that need them, with qbert's
/// clips, and the voxels of the whole volume.
pub(super) struct Stats(pub(super) BTreeMap<Channel, ChannelStats>, usize);

/// The clip (low, high percent) of channel `c`'s statistics: qbert's.
pub(super) fn clip_of(c: Channel) -> (f64, f64) {
    AxisSpec::qbert(&c.name(&[])).clip_percent
}

impl Stats {
    pub(super) fn new(channels: &[Channel], n: usize) -> Stats {
        Stats(channels.iter().map(|&c| (c, ChannelStats::new(clip_of(c), n))).collect(), n)
    }

    pub(super) fn add(&mut self, c: Channel, data: &[f32]) {
        if self.0.contains_key(&c) {
            // in parallel over the slab; the candidates merge exactly
            self.merge(c, ChannelStats::of_part(data, clip_of(c), self.1));
        }
    }

    /// Merges the statistics of the next slab of channel `c`, taken
    /// elsewhere as [`Stats::add`] takes them (a task's partial).
    pub(super) fn merge(&mut self, c: Channel, slab: ChannelStats) {
        if let Some(s) = self.0.get_mut(&c) {
            let whole = std::mem::replace(s, ChannelStats::new((0.0, 0.0), 0));
            *s = whole.merge(slab);
        }
    }

    pub(super) fn axis(&self, spec: &AxisSpec, c: Channel) -> Result<mdtf_histogram::Axis, RunError> {
        let name = c.name(&[]);
        let s = self.0.get(&c).ok_or_else(|| fail("histogram")(format!("no statistics of {name}")))?;
        s.axis(spec, &name).map_err(at("histogram"))
    }

    pub(super) fn range(&self, c: Channel) -> Option<(f32, f32)> {
        self.0.get(&c).and_then(ChannelStats::finite_range)
    }

    /// Samples of channel `c` that were not finite (all, when it was never summarised).
    pub(super) fn not_finite(&self, c: Channel) -> u64 {
        self.1 as u64 - self.0.get(&c).map_or(0, ChannelStats::finite_count)
    }
}

/// The rank of the median (the lower one) among the finite samples of
/// channel `g` that `stats` summarised (None without any).
pub(super) fn median_rank(stats: &Stats, g: Channel) -> Result<Option<u64>, RunError> {
    let s = stats.0.get(&g).ok_or_else(|| fail("boundary")(format!("no statistics of {}", g.name(&[]))))?;
    Ok(s.finite_count().checked_sub(1).map(|last| last / 2))
}

/// The tracing's whole-volume statistics of the g it traces (`g`),
/// whose median is `median`: its noise floor and largest value (no
/// detection yet).
pub(super) fn g_volume_stats(
    stats: &Stats,
    g: Channel,
    median: Option<f32>,
    value_range: f64,
    l_min: f64,
) -> VolumeStats {
    let g_max = stats.range(g).map_or(0.0, |r| r.1);
    let noise_floor = mdtf_boundary::noise_floor_of_median(median, value_range, l_min);
    VolumeStats { value_range, noise_floor, g_max, detected: mdtf_boundary::Detected::default() }
}

/// The tracing's whole-volume statistics of the g it traces (`g`):
/// the noise floor from its median (a two-pass select over the slabs, one
/// pass when `buckets` counted the first) and its largest value.
pub(super) fn g_stats(
    chans: &mut SlabChannels,
    g: Channel,
    buckets: Option<&KeyBuckets>,
    slabs: &[Range<usize>],
    value_range: f64,
    l_min: f64,
    stats: &Stats,
) -> Result<VolumeStats, RunError> {
    let median = match median_rank(stats, g)? {
        None => None,
        Some(k) => {
            let pass = |visit: &mut dyn FnMut(&[f32])| {
                for z in slabs {
                    visit(chans.samples(g, z.clone())?);
                }
                Ok::<(), super::ChannelError>(())
            };
            match buckets {
                Some(b) => mdtf_volume::order_statistic_from_buckets(k, b, pass),
                None => mdtf_volume::order_statistic_of_pieces(k, pass),
            }
            .map_err(at("boundary"))?
        }
    };
    Ok(g_volume_stats(stats, g, median, value_range, l_min))
}

/// The (v, g) axes the detection before the tracing counts over, from the
/// statistics of v and g; None when those hold none or `chans` has no v or g.
pub(super) fn detection_axes(chans: &SlabChannels, stats: &Stats) -> Option<(Axis, Axis)> {
    let axis = |c: Channel| stats.axis(&HvolAxes::spec(&c.name(&[]), HVOL_BINS), c).ok();
    (chans.has(Channel::Value) && chans.has(Channel::G)).then(|| axis(Channel::Value).zip(axis(Channel::G))).flatten()
}

/// What boundary detection finds in the (v, g) histogram of every voxel
/// (`crate::pre_detect`), counted slab by slab over the axes of `stats`;
/// nothing when those hold no statistics of v and g or the store neither.
pub(super) fn detected_before_tracing(
    chans: &mut SlabChannels,
    slabs: &[Range<usize>],
    stats: &Stats,
    spacing: f64,
) -> Result<mdtf_boundary::Detected, RunError> {
    let Some((av, ag)) = detection_axes(chans, stats) else { return Ok(Default::default()) };
    let mut counts = VgCounts::new(av, ag);
    let mut v = Vec::new();
    for z in slabs {
        chans.samples_into(Channel::Value, z.clone(), &mut v).map_err(at("boundary"))?;
        let g = chans.samples(Channel::G, z.clone()).map_err(at("boundary"))?;
        counts.add(&v, g).map_err(at("boundary"))?;
    }
    Ok(counts.detected(spacing))
}
