//! The whole-volume reductions of a slab-by-slab run, each merged exactly
//! over the slabs: the channels' percentile statistics, the median of g
//! behind the tracing's noise floor, and the histograms.

use super::{SlabChannels, medians};
use crate::file::Pipeline;
use crate::hist_files::Counted;
use crate::run::{RunError, at, fail};
use mdtf_boundary::VolumeStats;
use mdtf_histogram::{Axis, AxisSpec, ChannelStats, Histogram, HvolAxes, HvolBySlabs, HvolParams, count, hit_mask};
use mdtf_volume::{KeyBuckets, Volume};
use std::collections::BTreeMap;
use std::ops::Range;

/// Percentile statistics of the channels that need them, with qbert's
/// clips, and the voxels of the whole volume.
pub(super) struct Stats(pub(super) BTreeMap<&'static str, ChannelStats>, usize);

impl Stats {
    pub(super) fn new(names: &[&'static str], n: usize) -> Stats {
        Stats(names.iter().map(|&c| (c, ChannelStats::new(AxisSpec::qbert(c).clip_percent, n))).collect(), n)
    }

    pub(super) fn add(&mut self, name: &str, data: &[f32]) {
        if let Some(s) = self.0.get_mut(name) {
            // in parallel over the slab; the candidates merge exactly
            let slab = ChannelStats::of_part(data, AxisSpec::qbert(name).clip_percent, self.1);
            let whole = std::mem::replace(s, ChannelStats::new((0.0, 0.0), 0));
            *s = whole.merge(slab);
        }
    }

    pub(super) fn axis(&self, spec: &AxisSpec, name: &str) -> Result<mdtf_histogram::Axis, RunError> {
        let s = self.0.get(name).ok_or_else(|| fail("histogram")(format!("no statistics of {name}")))?;
        s.axis(spec, name).map_err(at("histogram"))
    }

    pub(super) fn range(&self, name: &str) -> Option<(f32, f32)> {
        self.0.get(name).and_then(ChannelStats::finite_range)
    }

    /// Samples of channel `name` that were not finite (all, when it was never summarised).
    pub(super) fn not_finite(&self, name: &str) -> u64 {
        self.1 as u64 - self.0.get(name).map_or(0, ChannelStats::finite_count)
    }
}

/// The tracing's whole-volume statistics of the g it traces (`g_name`):
/// the noise floor from its median (a two-pass select over the slabs, one
/// pass when `buckets` counted the first) and its largest value.
pub(super) fn g_stats(
    chans: &mut SlabChannels,
    g_name: &str,
    buckets: Option<&KeyBuckets>,
    slabs: &[Range<usize>],
    value_range: f64,
    l_min: f64,
    stats: &Stats,
) -> Result<VolumeStats, RunError> {
    let s = stats.0.get(g_name).ok_or_else(|| fail("boundary")(format!("no statistics of {g_name}")))?;
    let g_max = s.finite_range().map_or(0.0, |r| r.1);
    let median = match s.finite_count().checked_sub(1) {
        None => None,
        Some(last) => {
            let pass = |visit: &mut dyn FnMut(&[f32])| {
                for z in slabs {
                    visit(chans.samples(g_name, z.clone())?);
                }
                Ok::<(), String>(())
            };
            match buckets {
                Some(b) => mdtf_volume::order_statistic_from_buckets(last / 2, b, pass),
                None => mdtf_volume::order_statistic_of_pieces(last / 2, pass),
            }
            .map_err(fail("boundary"))?
        }
    };
    let noise_floor = mdtf_boundary::noise_floor_of_median(median, value_range, l_min);
    Ok(VolumeStats { value_range, noise_floor, g_max, detected: mdtf_boundary::Detected::default() })
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
    use crate::pre_detect::{HVOL_BINS, VgCounts};
    let axis = |name: &str| stats.axis(&HvolAxes::spec(name, HVOL_BINS), name).ok();
    let (Some(av), Some(ag)) = (axis("v"), axis("g")) else { return Ok(Default::default()) };
    if !(chans.has("v") && chans.has("g")) {
        return Ok(Default::default());
    }
    let mut counts = VgCounts::new(av, ag);
    let mut v = Vec::new();
    for z in slabs {
        chans.samples_into("v", z.clone(), &mut v).map_err(fail("boundary"))?;
        let g = chans.samples("g", z.clone()).map_err(fail("boundary"))?;
        counts.add(&v, g).map_err(at("boundary"))?;
    }
    Ok(counts.detected(spacing))
}

/// The histograms of the pipeline (and the histogram volume when it is
/// needed), counted slab by slab with the axes the whole volume's
/// statistics give: [`SlabHistograms::add`] takes each slab's channels
/// ([`SlabHistograms::channels`]) in order.
pub(super) struct SlabHistograms {
    joint: bool,
    stretched: bool,
    /// The (v, g) axes; the stretched pair's second is g_hit.
    axes: Vec<Axis>,
    stretched_axes: Vec<Axis>,
    hvol: Option<HvolBySlabs>,
    /// Peak finding's TF domain (v, 1/g), over the whole g's axis.
    inv_g_axes: Option<Vec<Axis>>,
    counted: Counted,
    stretched_pair: (Option<Histogram>, Option<Histogram>),
}

impl SlabHistograms {
    /// Empty histograms of `p` (with the histogram volume when `hvol`,
    /// counted on a lane per thread) over the axes of `stats`, for
    /// the `slabs` of a volume of `n` voxels. Peak finding's (v, 1/g) axis
    /// takes its own passes over `chans` (one fewer with `g_buckets`, the
    /// first radix pass over g).
    pub(super) fn new(
        p: &Pipeline,
        chans: &mut SlabChannels,
        stats: &Stats,
        slabs: &[Range<usize>],
        n: usize,
        hvol: bool,
        g_buckets: Option<&KeyBuckets>,
    ) -> Result<SlabHistograms, RunError> {
        let err = at::<mdtf_histogram::HistogramError>("histogram");
        let joint = p.histogram.as_ref().is_some_and(|h| h.joint);
        let stretched = p.histogram.as_ref().is_some_and(|h| h.stretched) && chans.has("g_hit") && chans.has("hit");
        let axes = vec![stats.axis(&AxisSpec::qbert("v"), "v")?, stats.axis(&AxisSpec::qbert("g"), "g")?];
        let mut stretched_axes = axes.clone();
        stretched_axes[1].name = "g_hit".into();
        let bins = HvolParams::default().bins;
        let nz = slabs.last().map_or(0, |z| z.end);
        let hvol = match hvol {
            true => {
                let axes = HvolAxes {
                    v: stats.axis(&HvolAxes::spec("v", bins[0]), "v")?,
                    g: stats.axis(&HvolAxes::spec("g", bins[1]), "g")?,
                    h: stats.axis(&HvolAxes::spec("f2", bins[2]), "f2")?,
                };
                let plane = n / nz.max(1);
                let lanes = rayon::current_num_threads();
                Some(HvolBySlabs::new(&axes, plane, nz, lanes).map_err(err)?)
            }
            false => None,
        };
        let inv_g_axes = match joint && chans.has("inv_g") {
            true => medians::inverse_gradient_axis(chans, slabs, g_buckets)
                .map_err(fail("histogram"))?
                .map(|ia| vec![axes[0].clone(), ia]),
            false => None,
        };
        Ok(SlabHistograms {
            joint,
            stretched,
            axes,
            stretched_axes,
            hvol,
            inv_g_axes,
            counted: Counted { voxels: n, ..Default::default() },
            stretched_pair: (None, None),
        })
    }

    /// The channels each slab's [`SlabHistograms::add`] reads.
    pub(super) fn channels(&self) -> Vec<&'static str> {
        let mut names = vec!["v", "g"];
        if self.hvol.is_some() {
            names.push("f2");
        }
        if self.stretched {
            names.extend(["g_hit", "hit"]);
        }
        if self.inv_g_axes.is_some() {
            names.push("inv_g");
        }
        names
    }

    /// Counts the slab of planes from `first` on, whose channels are `slab`
    /// (at least [`SlabHistograms::channels`]); slabs come in order.
    pub(super) fn add(&mut self, first: usize, slab: &[(String, Volume)]) -> Result<(), RunError> {
        let err = at::<mdtf_histogram::HistogramError>("histogram");
        let get = |c: &str| {
            slab.iter()
                .find(|(n, _)| n == c)
                .map(|(_, v)| v.samples())
                .ok_or_else(|| fail("histogram")(format!("{c} missing")))
        };
        let (v, g) = (get("v")?, get("g")?);
        if let Some(acc) = &mut self.hvol {
            acc.add_slab(first, v, g, get("f2")?).map_err(err)?;
        }
        let counted = &mut self.counted;
        if self.joint {
            add(&mut counted.joint, count(&[v, g], self.axes.clone(), None).map_err(err)?);
        }
        if let Some(ia) = &self.inv_g_axes {
            add(&mut counted.inv_g, count(&[v, get("inv_g")?], ia.clone(), None).map_err(err)?);
        }
        if self.stretched {
            let traced = hit_mask(get("hit")?);
            let pair = &mut self.stretched_pair;
            add(&mut pair.0, count(&[v, g], self.axes.clone(), Some(&traced)).map_err(err)?);
            add(&mut pair.1, count(&[v, get("g_hit")?], self.stretched_axes.clone(), Some(&traced)).map_err(err)?);
        }
        Ok(())
    }

    /// The histograms of every slab added, of a grid of voxel `spacing`.
    pub(super) fn finish(self, spacing: [f64; 3]) -> Result<Counted, RunError> {
        let mut counted = self.counted;
        if let Some(acc) = self.hvol {
            counted.hvol = Some(acc.finish(&HvolParams::on_grid(spacing)).map_err(at("histogram"))?);
        }
        if let (Some(a), Some(b)) = self.stretched_pair {
            counted.stretched = Some((a, b));
        }
        Ok(counted)
    }
}

/// Adds the counts of `h` into `into` (h itself when it is the first).
fn add(into: &mut Option<Histogram>, h: Histogram) {
    match into {
        Some(a) => a.counts.iter_mut().zip(&h.counts).for_each(|(x, y)| *x += y),
        None => *into = Some(h),
    }
}
