//! What a task of a run on a cluster hands back besides the planes it
//! stores: its slab's part of the pass's whole-volume reductions (channel
//! statistics, both radix passes of g's median, the detection's (v, g)
//! counts, the tracing's counts and report sums, the histograms' counts),
//! a few KB to a few MB in a file beside the channel store. The run merges
//! the parts in z order, as it would have merged its own slabs', so it
//! never reads a task's channels back for them.
//!
//! Binary (CBOR): every float bit is kept, infinities included, which JSON
//! cannot hold.

use super::medians::SelectCounts;
use super::reductions::Stats;
use super::resume::WrittenPiece;
use super::slab_histograms::HistogramCounts;
use super::trace::SlabTrace;
use crate::channel::Channel;
use crate::pre_detect::VgCounts;
use crate::run::{RunError, fail};
use mdtf_boundary::{Crossings, ReportAccumulator, ReportInput, ResolvedParams, TraceCounts};
use mdtf_histogram::ChannelStats;
use mdtf_volume::KeyBuckets;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One task's part of its pass's reductions.
#[derive(Default, Serialize, Deserialize)]
pub struct SlabPartial {
    /// The statistics of each channel the task summarised, of its slab alone.
    pub stats: Vec<(Channel, ChannelStats)>,
    /// The first radix pass of the traced g's median over the slab (derive,
    /// when g is summarised; pre-filter, of the pre-filtered g).
    pub g_buckets: Option<KeyBuckets>,
    /// A median's select pass over the slab (select).
    pub selected: Option<SelectCounts>,
    /// The smallest positive 1/g of the slab (derive; infinite without one).
    pub smallest_inv_g: Option<f32>,
    /// Samples of the slab in the scanner padding's range (input).
    pub padded: u64,
    /// The tracing's part (tracing).
    pub trace: Option<TracePartial>,
    /// The histograms' counts (pack, when it counts histograms).
    pub histograms: Option<HistogramCounts>,
    /// The (v, g) counts of the detection before the tracing (select).
    pub vg: Option<VgCounts>,
    /// The digest of the task's job ([`super::resume::job_digest`]).
    pub job: String,
    /// What the task wrote, hashed, for a resumed run to check.
    pub written: Vec<WrittenPiece>,
}

/// What a tracing task hands back besides its planes.
#[derive(Clone, Serialize, Deserialize)]
pub struct TracePartial {
    /// The slab's hit codes, counted.
    pub counts: TraceCounts,
    /// The g at the slab's zero crossings.
    pub crossings: Crossings,
    /// The thresholds and sampling used.
    pub resolved: ResolvedParams,
    /// The Fig. 2 report's sums over the slab (exact: they merge in any order).
    pub report: ReportAccumulator,
}

impl SlabPartial {
    /// Adds the statistics of channel `c`'s slab `samples` (of a volume of `voxels`).
    pub fn summarise(&mut self, c: Channel, samples: &[f32], voxels: usize) {
        let part = ChannelStats::of_part(samples, super::reductions::clip_of(c), voxels);
        self.stats.push((c, part));
    }

    /// Writes the partial of `stage`'s task of the slab from plane `first`
    /// into the store folder `store` (atomically: a rerun task replaces it whole).
    pub fn write(&self, store: &Path, stage: &'static str, first: usize) -> Result<(), RunError> {
        let mut bytes = Vec::new();
        ciborium::into_writer(self, &mut bytes).map_err(|e| fail(stage)(format!("a task's partial: {e}")))?;
        mdtf_volume::write_file_atomically(&path(store, stage, first), |w| w.write_all(&bytes))
            .map_err(crate::run::at(stage))
    }

    /// The partial the task of `stage` for the slab from plane `first` left in `store`.
    pub fn read(store: &Path, stage: &'static str, first: usize) -> Result<SlabPartial, RunError> {
        let file = path(store, stage, first);
        let bytes = std::fs::read(&file).map_err(|e| fail(stage)(format!("{}: {e}", file.display())))?;
        ciborium::from_reader(bytes.as_slice())
            .map_err(|e| fail(stage)(format!("{}: not a task's partial: {e}", file.display())))
    }

    /// Merges the statistics into `stats` (in z order, as the run's own slabs').
    pub(super) fn merge_stats_into(&mut self, stats: &mut Stats) {
        for (c, part) in self.stats.drain(..) {
            stats.merge(c, part);
        }
    }
}

impl TracePartial {
    /// The sums of one block's tracing.
    fn of(slab: &SlabTrace) -> TracePartial {
        let b = &slab.trace;
        let mut report = ReportAccumulator::new(b.resolved.report_thresholds());
        let (hit, dot, distance, g_hit) = (b.hit.samples(), b.dot.samples(), b.distance.samples(), b.g_hit.samples());
        report.add(ReportInput { hit, dot, distance, g: slab.g.samples(), g_hit });
        TracePartial { counts: b.counts, crossings: b.crossings.clone(), resolved: b.resolved, report }
    }

    /// Adds the tracing of the next strip or slab.
    fn merge(&mut self, other: TracePartial) {
        self.counts += other.counts;
        self.crossings.merge(&other.crossings);
        self.report.merge(&other.report);
        self.resolved = other.resolved;
    }
}

/// The tracing's sums over the blocks or tasks seen so far (none yet: None).
#[derive(Default)]
pub(super) struct TraceSums(pub(super) Option<TracePartial>);

impl TraceSums {
    /// Adds a block's tracing.
    pub(super) fn add(&mut self, slab: &SlabTrace) {
        self.merge(TracePartial::of(slab));
    }

    /// Adds the sums of a block or task.
    pub(super) fn merge(&mut self, part: TracePartial) {
        match &mut self.0 {
            Some(sums) => sums.merge(part),
            None => self.0 = Some(part),
        }
    }
}

/// Where the task of `stage` for the slab from plane `first` leaves its partial.
pub(super) fn path(store: &Path, stage: &str, first: usize) -> PathBuf {
    store.join(format!("{stage}-{first}.partial"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_partial_keeps_every_bit_through_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut p = SlabPartial { smallest_inv_g: Some(f32::INFINITY), padded: 7, ..Default::default() };
        let samples = [1.5f32, -0.0, 3.25e-39, f32::MAX, 2.0];
        p.summarise(Channel::G, &samples, 100);
        let mut buckets = KeyBuckets::new();
        buckets.add(&samples);
        p.g_buckets = Some(buckets.clone());
        p.write(dir.path(), "derive", 12).unwrap();
        let back = SlabPartial::read(dir.path(), "derive", 12).unwrap();
        assert_eq!(back.smallest_inv_g.map(f32::to_bits), Some(f32::INFINITY.to_bits()));
        assert_eq!(back.padded, 7);
        assert_eq!(back.g_buckets, Some(buckets));
        let (c, stats) = &back.stats[0];
        assert_eq!(*c, Channel::G);
        assert_eq!(
            stats.finite_range().map(|(a, b)| (a.to_bits(), b.to_bits())),
            Some(((-0.0f32).to_bits(), f32::MAX.to_bits()))
        );
        assert_eq!(stats.finite_count(), 5);
        // another slab's file is not this one's
        assert!(SlabPartial::read(dir.path(), "derive", 0).is_err());
    }
}
