//! The whole-volume reductions of a slab-by-slab run, each merged exactly
//! over the slabs: the channels' percentile statistics, the median of g
//! behind the tracing's noise floor, and the histograms.

use super::{SlabChannels, medians};
use crate::file::Pipeline;
use crate::hist_files::Counted;
use crate::progress::Progress;
use crate::run::{RunError, at, fail};
use mdtf_boundary::VolumeStats;
use mdtf_histogram::{AxisSpec, ChannelStats, Histogram, HvolAccumulator, HvolAxes, HvolParams, count, hit_mask};
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
}

/// The tracing's whole-volume statistics of the g it traces (`g_name`):
/// the noise floor from its median (a two-pass select over the slabs) and
/// its largest value.
pub(super) fn g_stats(
    chans: &mut SlabChannels,
    g_name: &str,
    slabs: &[Range<usize>],
    value_range: f64,
    l_min: f64,
    stats: &Stats,
) -> Result<VolumeStats, RunError> {
    let s = stats.0.get(g_name).ok_or_else(|| fail("boundary")(format!("no statistics of {g_name}")))?;
    let g_max = s.finite_range().map_or(0.0, |r| r.1);
    let median = match s.finite_count().checked_sub(1) {
        None => None,
        Some(last) => mdtf_volume::order_statistic_of_pieces(last / 2, |visit| {
            for z in slabs {
                visit(&chans.samples(g_name, z.clone())?);
            }
            Ok::<(), String>(())
        })
        .map_err(fail("boundary"))?,
    };
    let noise_floor = mdtf_boundary::noise_floor_of_median(median, value_range, l_min);
    Ok(VolumeStats { value_range, noise_floor, g_max })
}

/// The histograms of the pipeline (and the histogram volume when
/// `hvol_needed`), counted slab by slab from the store with the axes the
/// whole volume's statistics give.
pub(super) fn count_histograms(
    p: &Pipeline,
    chans: &mut SlabChannels,
    stats: &Stats,
    slabs: &[Range<usize>],
    n: usize,
    hvol_needed: bool,
    progress: &Progress,
) -> Result<Counted, RunError> {
    let err = at::<mdtf_histogram::HistogramError>("histogram");
    let io = fail("histogram");
    let joint = p.histogram.as_ref().is_some_and(|h| h.joint);
    let stretched = p.histogram.as_ref().is_some_and(|h| h.stretched) && chans.has("g_hit") && chans.has("hit");
    let axes = vec![stats.axis(&AxisSpec::qbert("v"), "v")?, stats.axis(&AxisSpec::qbert("g"), "g")?];
    let mut sa = axes.clone();
    sa[1].name = "g_hit".into();
    let bins = HvolParams::default().bins;
    let mut hvol = match hvol_needed {
        true => {
            let axes = HvolAxes {
                v: stats.axis(&HvolAxes::spec("v", bins[0]), "v")?,
                g: stats.axis(&HvolAxes::spec("g", bins[1]), "g")?,
                h: stats.axis(&HvolAxes::spec("f2", bins[2]), "f2")?,
            };
            Some(HvolAccumulator::new(&axes, n).map_err(err)?)
        }
        false => None,
    };
    // peak finding's TF domain (v, 1/g), over the whole g's axis
    let inv_g_axes = match joint && chans.has("inv_g") {
        true => medians::inverse_gradient_axis(chans, slabs).map_err(&io)?.map(|ia| vec![axes[0].clone(), ia]),
        false => None,
    };
    let nz = slabs.last().map_or(0, |z| z.end);
    let mut counted = Counted { voxels: n, ..Default::default() };
    let add = |into: &mut Option<Histogram>, h: Histogram| match into {
        Some(a) => a.counts.iter_mut().zip(&h.counts).for_each(|(x, y)| *x += y),
        None => *into = Some(h),
    };
    let mut stretched_pair: (Option<Histogram>, Option<Histogram>) = (None, None);
    for (k, z) in slabs.iter().enumerate() {
        progress.slab(k + 1, slabs.len())?;
        let mut names = vec!["v", "g"];
        if hvol.is_some() {
            names.push("f2");
        }
        if stretched {
            names.extend(["g_hit", "hit"]);
        }
        if inv_g_axes.is_some() {
            names.push("inv_g");
        }
        let mut slab: BTreeMap<String, Vec<f32>> = chans
            .volumes(z.clone(), &names)
            .map_err(&io)?
            .into_iter()
            .map(|(c, v)| (c, v.data.into_raw_vec_and_offset().0))
            .collect();
        let mut take = |c: &str| slab.remove(c).ok_or_else(|| fail("histogram")(format!("{c} missing")));
        let (v, g) = (take("v")?, take("g")?);
        if let Some(acc) = &mut hvol {
            let f2 = take("f2")?;
            let plane = v.len() / z.len();
            for (i, k) in z.clone().enumerate() {
                let at = i * plane..(i + 1) * plane;
                acc.add_slice(k, nz, &v[at.clone()], &g[at.clone()], &f2[at]);
            }
        }
        if joint {
            add(&mut counted.joint, count(&[&v, &g], axes.clone(), None).map_err(err)?);
        }
        if let Some(ia) = &inv_g_axes {
            add(&mut counted.inv_g, count(&[&v, &take("inv_g")?], ia.clone(), None).map_err(err)?);
        }
        if stretched {
            let g_hit = take("g_hit")?;
            let traced = hit_mask(&take("hit")?);
            add(&mut stretched_pair.0, count(&[&v, &g], axes.clone(), Some(&traced)).map_err(err)?);
            add(&mut stretched_pair.1, count(&[&v, &g_hit], sa.clone(), Some(&traced)).map_err(err)?);
        }
    }
    if let Some(acc) = hvol {
        counted.hvol = Some(HvolAccumulator::finish(vec![acc], &HvolParams::default()).map_err(err)?);
    }
    if let (Some(a), Some(b)) = stretched_pair {
        counted.stretched = Some((a, b));
    }
    Ok(counted)
}
