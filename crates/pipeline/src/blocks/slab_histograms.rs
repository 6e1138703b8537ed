//! The histograms of a slab-by-slab run (and the histogram volume when it
//! is needed), counted slab by slab over axes the whole volume's
//! statistics give: here, in z order, or by tasks elsewhere that each count
//! whole fixed parts of the histogram volume's slices and hand back their
//! counts ([`HistogramCounts`]), merged exactly.

use super::SlabChannels;
use super::reductions::Stats;
use crate::channel::Channel;
use crate::hist_files::Counted;
use crate::run::{RunError, at, fail};
use crate::settings::{Histograms, Settings};
use mdtf_histogram::{
    Axis, AxisSpec, Histogram, HistogramError, HvolAccumulator, HvolAxes, HvolBySlabs, HvolParams, HvolPart, count,
    stretched_pair,
};
use mdtf_volume::Volume;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// What each slab's histograms are counted over (serialisable: a pack
/// pass's tasks get it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistogramAxes {
    /// The (v, g) histogram is counted.
    joint: bool,
    /// The stretched pair is counted.
    stretched: bool,
    /// The (v, g) axes; the stretched pair's second is g_hit on g's axis.
    axes: Vec<Axis>,
    /// The histogram volume's axes, when it is counted.
    hvol: Option<HvolAxes>,
    /// Peak finding's TF domain (v, 1/g), over the whole g's axis.
    inv_g: Option<Vec<Axis>>,
}

impl HistogramAxes {
    /// The channels each slab's counting reads.
    pub fn channels(&self) -> Vec<Channel> {
        let mut read = vec![Channel::Value, Channel::G];
        if self.hvol.is_some() {
            read.push(Channel::F2);
        }
        if self.stretched {
            read.extend([Channel::GHit, Channel::Hit]);
        }
        if self.inv_g.is_some() {
            read.push(Channel::InvG);
        }
        read
    }

    /// Whether the histogram volume is counted.
    pub fn counts_hvol(&self) -> bool {
        self.hvol.is_some()
    }
}

/// The counts of the (v, g), (v, 1/g) and stretched histograms over some
/// slabs, and the histogram volume's counts and sums over whole fixed
/// parts of its slices (a task's): they merge exactly in any order.
#[derive(Default, Serialize, Deserialize)]
pub struct HistogramCounts {
    joint: Option<Histogram>,
    inv_g: Option<Histogram>,
    stretched: (Option<Histogram>, Option<Histogram>),
    /// The histogram volume's counts, handed over ([`HistogramCounts::finish_task`]).
    hvol: Option<HvolPart>,
    /// The histogram volume being counted by a task.
    #[serde(skip)]
    counting: Option<HvolAccumulator>,
}

impl HistogramCounts {
    /// Counts a slab's channels (at least [`HistogramAxes::channels`]) into
    /// every histogram but the histogram volume.
    fn add(&mut self, axes: &HistogramAxes, slab: &[(Channel, Volume)]) -> Result<(), RunError> {
        let err = at::<HistogramError>("histogram");
        let (v, g) = (channel(slab, Channel::Value)?, channel(slab, Channel::G)?);
        if axes.joint {
            add(&mut self.joint, count(&[v, g], axes.axes.clone(), None).map_err(err)?);
        }
        if let Some(ia) = &axes.inv_g {
            add(&mut self.inv_g, count(&[v, channel(slab, Channel::InvG)?], ia.clone(), None).map_err(err)?);
        }
        if axes.stretched {
            let (hit, g_hit) = (channel(slab, Channel::Hit)?, channel(slab, Channel::GHit)?);
            let (normal, stretched) = stretched_pair([v, g, g_hit], hit, &axes.axes, None).map_err(err)?;
            add(&mut self.stretched.0, normal);
            add(&mut self.stretched.1, stretched);
        }
        Ok(())
    }

    /// A task's counts of the slab of planes `z` of a volume of `nz`
    /// planes: every histogram, the histogram volume's slices each into its
    /// fixed part (the task must hold whole parts).
    pub fn of_task_slab(
        &mut self,
        axes: &HistogramAxes,
        z: &Range<usize>,
        nz: usize,
        slab: &[(Channel, Volume)],
    ) -> Result<(), RunError> {
        self.add(axes, slab)?;
        if let Some(hv_axes) = &axes.hvol {
            let acc = match &mut self.counting {
                Some(acc) => acc,
                None => self.counting.insert(HvolAccumulator::new(hv_axes).map_err(at("histogram"))?),
            };
            let (v, g, f2) = (channel(slab, Channel::Value)?, channel(slab, Channel::G)?, channel(slab, Channel::F2)?);
            let plane = v.len() / z.len().max(1);
            for (i, k) in z.clone().enumerate() {
                let at = i * plane..(i + 1) * plane;
                acc.add_slice(k, nz, &v[at.clone()], &g[at.clone()], &f2[at]);
            }
        }
        Ok(())
    }

    /// The counts of every slab the task added, ready to hand over (the
    /// histogram volume's as an [`HvolPart`]).
    pub fn finish_task(mut self) -> HistogramCounts {
        self.hvol = self.counting.take().map(|acc| acc.part());
        self
    }
}

/// Whether a run of `s` counts the histogram volume: its histograms ask for
/// it, or its default TF reads it (no TF file, `tf_given`).
pub(super) fn counts_hvol(s: &Settings, tf_given: bool) -> bool {
    s.outputs.histograms.hvol || !tf_given
}

/// Channel `c`'s samples in `slab`.
fn channel(slab: &[(Channel, Volume)], c: Channel) -> Result<&[f32], RunError> {
    let missing = || fail("histogram")(format!("{} missing", c.name(&[])));
    slab.iter().find(|(n, _)| *n == c).map(|(_, v)| v.samples()).ok_or_else(missing)
}

/// The histograms of the pipeline counted slab by slab (see the module docs).
pub(super) struct SlabHistograms {
    axes: HistogramAxes,
    /// The histogram volume fed here, slab by slab in z order.
    hvol: Option<HvolBySlabs>,
    /// The histogram volume's parts counted by tasks, absorbed.
    hvol_tasks: Option<HvolAccumulator>,
    counts: HistogramCounts,
    voxels: usize,
}

impl SlabHistograms {
    /// Empty `histograms` (with the histogram volume when `hvol`,
    /// counted on a lane per thread) over the axes of `stats`, for
    /// the `slabs` of a volume of `n` voxels; the (v, 1/g) histogram over
    /// the axis `inverse_gradient`, when given (see [`Self::counts_inverse_gradient`]).
    pub(super) fn new(
        histograms: &Histograms,
        chans: &mut SlabChannels,
        stats: &Stats,
        slabs: &[Range<usize>],
        n: usize,
        hvol: bool,
        inverse_gradient: Option<Axis>,
    ) -> Result<SlabHistograms, RunError> {
        let joint = histograms.joint;
        let stretched = histograms.stretched && chans.has(Channel::GHit) && chans.has(Channel::Hit);
        let axes =
            vec![stats.axis(&AxisSpec::qbert("v"), Channel::Value)?, stats.axis(&AxisSpec::qbert("g"), Channel::G)?];
        let bins = HvolParams::default().bins;
        let nz = slabs.last().map_or(0, |z| z.end);
        let hvol_axes = match hvol {
            true => Some(HvolAxes {
                v: stats.axis(&HvolAxes::spec("v", bins[0]), Channel::Value)?,
                g: stats.axis(&HvolAxes::spec("g", bins[1]), Channel::G)?,
                h: stats.axis(&HvolAxes::spec("f2", bins[2]), Channel::F2)?,
            }),
            false => None,
        };
        let by_slabs = match &hvol_axes {
            Some(a) => {
                let (plane, lanes) = (n / nz.max(1), rayon::current_num_threads());
                Some(HvolBySlabs::new(a, plane, nz, lanes).map_err(at("histogram"))?)
            }
            None => None,
        };
        let inv_g = inverse_gradient.map(|ia| vec![axes[0].clone(), ia]);
        let axes = HistogramAxes { joint, stretched, axes, hvol: hvol_axes, inv_g };
        Ok(SlabHistograms { axes, hvol: by_slabs, hvol_tasks: None, counts: HistogramCounts::default(), voxels: n })
    }

    /// Whether the `histograms` count (v, 1/g) over the channels of `chans`.
    pub(super) fn counts_inverse_gradient(histograms: &Histograms, chans: &SlabChannels) -> bool {
        histograms.joint && chans.has(Channel::InvG)
    }

    /// What each slab is counted over.
    pub(super) fn axes(&self) -> &HistogramAxes {
        &self.axes
    }

    /// Counts the slab of planes from `first` on, whose channels are `slab`
    /// (at least [`HistogramAxes::channels`]); slabs come in order.
    pub(super) fn add(&mut self, first: usize, slab: &[(Channel, Volume)]) -> Result<(), RunError> {
        if let Some(acc) = &mut self.hvol {
            let (v, g, f2) = (channel(slab, Channel::Value)?, channel(slab, Channel::G)?, channel(slab, Channel::F2)?);
            acc.add_slab(first, v, g, f2).map_err(at("histogram"))?;
        }
        self.counts.add(&self.axes, slab)
    }

    /// Takes in a task's counts.
    pub(super) fn merge(&mut self, task: HistogramCounts) -> Result<(), RunError> {
        let HistogramCounts { joint, inv_g, stretched, hvol, .. } = task;
        for (mine, theirs) in [
            (&mut self.counts.joint, joint),
            (&mut self.counts.inv_g, inv_g),
            (&mut self.counts.stretched.0, stretched.0),
            (&mut self.counts.stretched.1, stretched.1),
        ] {
            if let Some(h) = theirs {
                add(mine, h);
            }
        }
        if let (Some(part), Some(axes)) = (hvol, &self.axes.hvol) {
            let acc = match &mut self.hvol_tasks {
                Some(acc) => acc,
                None => self.hvol_tasks.insert(HvolAccumulator::new(axes).map_err(at("histogram"))?),
            };
            acc.absorb(part).map_err(at("histogram"))?;
        }
        Ok(())
    }

    /// The histograms of every slab added or merged, of a grid of voxel `spacing`.
    pub(super) fn finish(self, spacing: [f64; 3]) -> Result<Counted, RunError> {
        let params = HvolParams::on_grid(spacing);
        let hvol = match (self.hvol, self.hvol_tasks) {
            (Some(_), Some(absorbed)) => Some(HvolAccumulator::finish(vec![absorbed], &params)),
            (Some(acc), None) => Some(acc.finish(&params)),
            (None, _) => None,
        };
        let HistogramCounts { joint, inv_g, stretched, .. } = self.counts;
        Ok(Counted {
            voxels: self.voxels,
            hvol: hvol.transpose().map_err(at("histogram"))?,
            joint,
            inv_g,
            stretched: stretched.0.zip(stretched.1),
            ..Default::default()
        })
    }
}

/// Adds the counts of `h` into `into` (h itself when it is the first).
fn add(into: &mut Option<Histogram>, h: Histogram) {
    match into {
        Some(a) => a.counts.iter_mut().zip(&h.counts).for_each(|(x, y)| *x += y),
        None => *into = Some(h),
    }
}
