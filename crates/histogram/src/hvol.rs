//! The histogram volume (v, g, f'') of Kindlmann and Durkin and what it
//! yields: per-v means of g and f'', the boundary width sigma, the position
//! function p(v, g) and a default 2D opacity transfer function.
//!
//! * sigma = 2 max_v g(v) / (sqrt(e) (max_v h(v) - min_v h(v))) with g(v),
//!   h(v) the mean g and f'' of the voxels in v bin (Teem's corrected form;
//!   exact for an ideal erf boundary), over the v bins holding at least
//!   [`SIGMA_MIN_SHARE`] of the voxels.
//! * p(v, g) = -sigma^2 h(v, g) / max(g - g_thresh, 0), with h(v, g) and g
//!   the mean f'' and mean g of the voxels in the (v, g) bin (using the mean
//!   g rather than the bin centre removes the bin-width bias); 0 in empty
//!   bins and where g <= g_thresh. For an ideal boundary p is the signed
//!   distance to it, positive on the high side. Empty bins of a v that
//!   occurs use the v bin's mean f'' and the bin's centre g (the 1D form of
//!   Kindlmann and Durkin), so the default opacity has no holes.
//! * alpha(v, g) = a_max max(0, 1 - |p(v, g)| / w): a tent of half-width w
//!   (default sigma) around the boundary, 0 in empty bins.

use crate::HistogramError;
use crate::axis::{Axis, AxisSpec, Binner};
use crate::count::{Histogram, SparseCounts, check_size, for_each_run};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::atomic::{AtomicU32, Ordering};

/// Parameters of the histogram volume.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HvolParams {
    /// Bins along v, g and f''.
    pub bins: [usize; 3],
    /// g threshold of the position function; None: 4 % of the largest mean g (gkms opac's x0.04).
    pub g_thresh: Option<f64>,
    /// Half-width of the boundary-emphasis tent in p (world units); None: sigma.
    pub tent_width: Option<f64>,
    /// Opacity at p = 0.
    pub max_opacity: f64,
    /// The smallest voxel spacing of the grid, world units (None: unknown):
    /// the boundary detection reports no boundary narrower than the
    /// sampling can show (see [`crate::boundaries::MIN_SIGMA_SPACINGS`]).
    pub spacing: Option<f64>,
}

impl Default for HvolParams {
    fn default() -> Self {
        HvolParams { bins: [256, 256, 256], g_thresh: None, tent_width: None, max_opacity: 1.0, spacing: None }
    }
}

impl HvolParams {
    /// The defaults for a grid of voxel `spacing` (world units per axis).
    pub fn on_grid(spacing: [f64; 3]) -> Self {
        HvolParams { spacing: Some(spacing.into_iter().fold(f64::INFINITY, f64::min)), ..Self::default() }
    }
}

/// The histogram volume and its derived quantities.
#[derive(Debug, Clone)]
pub struct HistogramVolume {
    /// Counts over (v, g, f'').
    pub hist: Histogram,
    /// Voxels per v bin (within every axis range).
    pub count_v: Vec<u64>,
    /// Mean g per v bin (0 where empty).
    pub mean_g_v: Vec<f64>,
    /// Mean f'' per v bin (0 where empty).
    pub mean_h_v: Vec<f64>,
    /// Estimated boundary width, world units.
    pub sigma: f64,
    /// g threshold used by p.
    pub g_thresh: f64,
    /// Tent half-width used by the opacity.
    pub tent_width: f64,
    /// The opacity at p = 0 (the tent's peak).
    pub max_opacity: f64,
    /// The (v, g) axes of the 2D tables below (first axis fastest).
    pub vg_axes: [Axis; 2],
    /// Voxels per (v, g) bin.
    pub count_vg: Vec<u64>,
    /// Position function p(v, g), world units (0 where undefined: v never occurs, or g <= g_thresh).
    pub position: Vec<f32>,
    /// Default opacity alpha(v, g) in [0, 1].
    pub opacity: Vec<f32>,
    /// The smallest voxel spacing, world units ([`HvolParams::spacing`]).
    pub spacing: Option<f64>,
}

impl HistogramVolume {
    /// Gives the axes of its counts and of its (v, g) tables the units of
    /// their channels in the input's `units`.
    pub fn set_units(&mut self, units: &mdtf_volume::Units) {
        self.hist.set_units(units);
        for a in &mut self.vg_axes {
            a.unit = units.of_channel(&a.name);
        }
    }
}

/// Least share of the voxels a v bin must hold for its mean g and f'' to
/// enter sigma's estimate.
pub const SIGMA_MIN_SHARE: f64 = 1e-4;

/// Number of fixed parts for floating-point sums: fixed so that the sums do
/// not depend on the thread count.
pub const HVOL_PARTS: usize = 16;

/// The (v, g, f'') axes of a histogram volume.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HvolAxes {
    /// Value axis.
    pub v: Axis,
    /// Gradient magnitude axis.
    pub g: Axis,
    /// Second directional derivative axis.
    pub h: Axis,
}

impl HvolAxes {
    /// The axes `params` asks for, with Teem qbert's clipping (0 / 0.002 / 0.004 percent), from stored channels.
    pub fn of(v: &[f32], g: &[f32], h: &[f32], params: &HvolParams) -> Result<HvolAxes, HistogramError> {
        let axis = |name: &str, data: &[f32], bins: usize| Self::spec(name, bins).resolve(name, data);
        Ok(HvolAxes {
            v: axis("v", v, params.bins[0])?,
            g: axis("g", g, params.bins[1])?,
            h: axis("f2", h, params.bins[2])?,
        })
    }

    /// The axis spec of channel `name` ("v", "g" or "f2") with `bins` bins
    /// (with [`ChannelStats::axis`](crate::ChannelStats::axis), for channels
    /// that are streamed rather than stored).
    pub fn spec(name: &str, bins: usize) -> AxisSpec {
        AxisSpec { bins: Some(bins), ..AxisSpec::qbert(name) }
    }

    fn list(&self) -> Vec<Axis> {
        vec![self.v.clone(), self.g.clone(), self.h.clone()]
    }

    fn binners(&self) -> [Binner; 3] {
        [self.v.binner(), self.g.binner(), self.h.binner()]
    }

    /// Index steps of the (v, g, f'') bins: v fastest.
    fn strides(&self) -> [u32; 3] {
        [1, self.v.bins as u32, (self.v.bins * self.g.bins) as u32]
    }
}

/// Counts and sums of a histogram volume over the voxels one task has seen:
/// feed it with [`HvolAccumulator::add`], then hand every task's
/// accumulator to [`HvolAccumulator::finish`]. A task in another process
/// hands its counts over as an [`HvolPart`].
pub struct HvolAccumulator {
    axes: HvolAxes,
    binners: [Binner; 3],
    strides: [u32; 3],
    counts: SparseCounts,
    sums: PartSums,
}

impl HvolAccumulator {
    /// An empty accumulator over `axes`.
    pub fn new(axes: &HvolAxes) -> Result<HvolAccumulator, HistogramError> {
        let total_bins = check_size(&axes.list())?;
        Ok(HvolAccumulator {
            axes: axes.clone(),
            binners: axes.binners(),
            strides: axes.strides(),
            counts: SparseCounts::new(total_bins),
            sums: PartSums::default(),
        })
    }

    /// Adds voxels (v, g and f'' of each) to the counts and to the sums of
    /// fixed part `part` (< [`HVOL_PARTS`]). A part's voxels must always be
    /// added in the same pieces and order for the sums to keep their bits;
    /// which task adds them does not matter.
    pub fn add(&mut self, part: usize, v: &[f32], g: &[f32], h: &[f32]) {
        let sums = self.sums.of(part, &self.axes);
        let counts = &mut self.counts;
        counts.make_room(v.len() as u64);
        count_and_sum(&[v, g, h], &self.binners, &self.strides, &mut |bin, n| counts.add(bin as usize, n), sums);
    }

    /// Adds z-slice `k` of a volume of `slices` slices (its v, g and f''
    /// samples) to the part [`fixed_parts`] puts it in. Feeding every slice
    /// in order, from any number of blocks, gives the sums of
    /// [`histogram_volume`] bit for bit.
    pub fn add_slice(&mut self, k: usize, slices: usize, v: &[f32], g: &[f32], h: &[f32]) {
        let part = fixed_parts(slices).iter().position(|p| p.contains(&k)).unwrap_or(0);
        self.add(part, v, g, h);
    }

    /// Merges the accumulators of every task (counts in any order, sums in
    /// part order) and derives sigma, p(v, g) and the default opacity.
    pub fn finish(tasks: Vec<HvolAccumulator>, params: &HvolParams) -> Result<HistogramVolume, HistogramError> {
        let mut tasks = tasks.into_iter();
        let Some(first) = tasks.next() else {
            return Err(HistogramError::Degenerate("no voxels were counted".into()));
        };
        let HvolAccumulator { axes, mut counts, sums, .. } = first;
        let mut parts = vec![sums];
        for t in tasks {
            counts.merge(&t.counts);
            parts.push(t.sums);
        }
        let sums = PartSums::merged(parts, &axes);
        let hist = Histogram { axes: axes.list(), counts: counts.into_totals() };
        derive_tables(hist, axes, sums, params)
    }
}

/// How an [`HvolAccumulator`] is stored: its axes, its non-zero counts
/// (bin, count) and each part's non-zero (v, g) sums (index, count, g sum, f'' sum).
#[derive(Serialize, Deserialize)]
struct StoredAccumulator {
    axes: HvolAxes,
    #[serde(with = "crate::packed")]
    counts: Vec<(u32, u64)>,
    parts: Vec<StoredPart>,
}

/// One fixed part's non-zero (v, g) sums.
#[derive(Serialize, Deserialize)]
struct StoredPart {
    part: usize,
    #[serde(with = "crate::packed")]
    sums: Vec<StoredSums>,
}

/// One non-zero (v, g) bin of a part's sums: its index, voxel count, g sum and f'' sum.
type StoredSums = (u32, u64, f64, f64);

/// What an [`HvolAccumulator`] counted, to hand to another process
/// ([`HvolAccumulator::part`], [`HvolAccumulator::absorb`]): its non-zero
/// counts and each of its parts' non-zero sums. Serialisable; keep every
/// f64 bit (a binary format).
#[derive(Serialize, Deserialize)]
#[serde(transparent)]
pub struct HvolPart(StoredAccumulator);

impl From<&HvolAccumulator> for StoredAccumulator {
    fn from(acc: &HvolAccumulator) -> StoredAccumulator {
        let parts = acc
            .sums
            .0
            .iter()
            .map(|(p, s)| {
                let kept = (0..s.c_vg.len()).filter(|&i| s.c_vg[i] > 0);
                StoredPart { part: *p, sums: kept.map(|i| (i as u32, s.c_vg[i], s.g_vg[i], s.h_vg[i])).collect() }
            })
            .collect();
        StoredAccumulator { counts: acc.counts.nonzero(), parts, axes: acc.axes.clone() }
    }
}

impl HvolAccumulator {
    /// What this accumulator counted, for another process to absorb.
    pub fn part(&self) -> HvolPart {
        HvolPart(StoredAccumulator::from(self))
    }

    /// Takes in what another accumulator over the same axes counted (`part`),
    /// as if its voxels had been added here; its fixed parts must be others
    /// than this one's (each part's sums are kept whole, and merged in part
    /// order at the end).
    pub fn absorb(&mut self, part: HvolPart) -> Result<(), HistogramError> {
        let stored = part.0;
        if stored.axes != self.axes {
            return Err(HistogramError::Geometry("a histogram volume part over other axes".into()));
        }
        // checked whole first: a part refused leaves this accumulator as it was
        let (bins, vg_bins) = (self.counts.bins(), self.axes.v.bins * self.axes.g.bins);
        if let Some((bin, _)) = stored.counts.iter().find(|(b, _)| *b as usize >= bins) {
            return Err(HistogramError::Geometry(format!("bin {bin} of a histogram volume of {bins} bins")));
        }
        for StoredPart { part: p, sums } in &stored.parts {
            if *p >= HVOL_PARTS || self.sums.0.iter().any(|(q, _)| q == p) {
                return Err(HistogramError::Geometry(format!("part {p} twice, or not one of {HVOL_PARTS}")));
            }
            if let Some((i, ..)) = sums.iter().find(|(i, ..)| *i as usize >= vg_bins) {
                return Err(HistogramError::Geometry(format!("(v, g) bin {i} of {vg_bins}")));
            }
        }
        self.counts.add_counts(&stored.counts);
        for StoredPart { part: p, sums } in stored.parts {
            let s = self.sums.of(p, &stored.axes);
            for (i, c, g, h) in sums {
                let i = i as usize;
                (s.c_vg[i], s.g_vg[i], s.h_vg[i]) = (c, g, h);
            }
        }
        Ok(())
    }
}

/// The sums of the fixed parts one task holds, each part's in its own
/// [`Sums`] (parts are merged in part order at the end, so the bits do not
/// depend on which task held which part).
#[derive(Default)]
struct PartSums(Vec<(usize, Sums)>);

impl PartSums {
    /// The sums of part `part`, made empty on its first use.
    fn of(&mut self, part: usize, axes: &HvolAxes) -> &mut Sums {
        let at = match self.0.iter().position(|(p, _)| *p == part) {
            Some(at) => at,
            None => {
                self.0.push((part, Sums::new(axes.v.bins, axes.g.bins)));
                self.0.len() - 1
            }
        };
        &mut self.0[at].1
    }

    /// The sums of every task's parts, added in part order.
    fn merged(tasks: Vec<PartSums>, axes: &HvolAxes) -> Sums {
        let mut parts: Vec<(usize, Sums)> = tasks.into_iter().flat_map(|t| t.0).collect();
        parts.sort_by_key(|(p, _)| *p);
        let mut sums = Sums::new(axes.v.bins, axes.g.bins);
        for (_, p) in &parts {
            sums.merge(p);
        }
        sums
    }
}

/// A histogram volume fed slab by slab (runs of whole z-slices, in order),
/// counted in parallel over the fixed parts a slab spans: each part always
/// goes to the same lane, which adds its slices in order, so the sums equal
/// [`histogram_volume`]'s bit for bit whatever the slabs and lanes. The
/// lanes add to one array of counts (integer adds, exact in any order), so
/// a lane costs only its parts' sums.
pub struct HvolBySlabs {
    axes: HvolAxes,
    binners: [Binner; 3],
    strides: [u32; 3],
    /// Voxels per (v, g, f'') bin, from every lane at once, since the last spill.
    counts: Vec<AtomicU32>,
    /// Voxels in `counts`: at most `room`.
    held: u64,
    /// Voxels the u32 counts take before they spill (u32::MAX: none can overflow).
    room: u64,
    /// Counts spilled from `counts` before they could overflow (empty until then).
    spilled: Vec<u64>,
    lanes: Vec<PartSums>,
    parts: Vec<Range<usize>>,
    plane: usize,
}

impl HvolBySlabs {
    /// An empty histogram volume over `axes` for a volume of `slices`
    /// z-slices of `plane` voxels, counted on `lanes` parallel lanes (at
    /// most [`HVOL_PARTS`]); the counts take 4 bytes a bin, whatever the
    /// lanes (and 8 more once over 2^32 - 1 voxels were counted).
    pub fn new(axes: &HvolAxes, plane: usize, slices: usize, lanes: usize) -> Result<HvolBySlabs, HistogramError> {
        let bins = check_size(&axes.list())?;
        Ok(HvolBySlabs {
            axes: axes.clone(),
            binners: axes.binners(),
            strides: axes.strides(),
            // calloc memory: a page of counts costs memory only once a voxel is counted in it
            counts: bytemuck::zeroed_vec(bins),
            held: 0,
            room: u64::from(u32::MAX),
            spilled: Vec::new(),
            lanes: (0..lanes.clamp(1, HVOL_PARTS)).map(|_| PartSums::default()).collect(),
            parts: fixed_parts(slices),
            plane,
        })
    }

    /// Adds the slab of z-slices from `first` on: its v, g and f'' samples,
    /// whole slices (the slabs must come in order and cover each slice once).
    pub fn add_slab(&mut self, first: usize, v: &[f32], g: &[f32], h: &[f32]) -> Result<(), HistogramError> {
        let plane = self.plane;
        let n = v.len();
        if g.len() != n || h.len() != n || !n.is_multiple_of(plane) {
            return Err(HistogramError::Geometry(format!(
                "a slab of {n}, {} and {} samples is not whole z-slices of {plane} voxels",
                g.len(),
                h.len()
            )));
        }
        let slab = first..first + n / plane;
        // a slab of at most `room` voxels fits once the counts spill
        if n as u64 > self.room {
            return Err(HistogramError::Geometry(format!("a slab of {n} voxels: at most {} at a time", self.room)));
        }
        if self.held + n as u64 > self.room {
            self.spill();
        }
        self.held += n as u64;
        let count = self.lanes.len();
        let (axes, binners, strides, counts, parts) =
            (&self.axes, &self.binners, &self.strides, &self.counts, &self.parts);
        let add = |bin: u32, n: u32| {
            if let Some(c) = counts.get(bin as usize) {
                c.fetch_add(n, Ordering::Relaxed);
            }
        };
        self.lanes.par_iter_mut().enumerate().for_each(|(lane, sums)| {
            let mut add = add;
            for (p, part) in parts.iter().enumerate().filter(|(p, _)| p % count == lane) {
                for k in part.start.max(slab.start)..part.end.min(slab.end) {
                    let at = (k - first) * plane..(k - first + 1) * plane;
                    let slice = [&v[at.clone()], &g[at.clone()], &h[at]];
                    count_and_sum(&slice, binners, strides, &mut add, sums.of(p, axes));
                }
            }
        });
        Ok(())
    }

    /// Moves the u32 counts into the u64 ones.
    fn spill(&mut self) {
        if self.spilled.is_empty() {
            self.spilled = vec![0; self.counts.len()];
        }
        for (s, c) in self.spilled.iter_mut().zip(&mut self.counts) {
            *s += u64::from(std::mem::take(c.get_mut()));
        }
        self.held = 0;
    }

    /// The histogram volume of every slab added.
    pub fn finish(mut self, params: &HvolParams) -> Result<HistogramVolume, HistogramError> {
        let sums = PartSums::merged(std::mem::take(&mut self.lanes), &self.axes);
        let counts = match self.spilled.is_empty() {
            true => self.counts.into_iter().map(|c| u64::from(c.into_inner())).collect(),
            false => {
                self.spill();
                self.spilled
            }
        };
        derive_tables(Histogram { axes: self.axes.list(), counts }, self.axes, sums, params)
    }
}

/// Builds the histogram volume of value `v`, gradient magnitude `g` and
/// second derivative `h`, x-fastest volumes of `plane` voxels per z-slice.
/// The sums are kept per fixed part of the slices and their runs of equal
/// bins are cut at every slice, so the result does not depend on the thread
/// count and equals, bit for bit, the one fed slice by slice (derivatives
/// streamed slice by slice, a slab-by-slab run: see [`HvolAccumulator::add_slice`]).
pub fn histogram_volume(
    v: &[f32],
    g: &[f32],
    h: &[f32],
    plane: usize,
    params: &HvolParams,
) -> Result<HistogramVolume, HistogramError> {
    let n = v.len();
    if g.len() != n || h.len() != n {
        return Err(HistogramError::Geometry("v, g and f2 must have the same number of voxels".into()));
    }
    if plane == 0 || !n.is_multiple_of(plane) {
        return Err(HistogramError::Geometry(format!("{n} voxels are not whole z-slices of {plane} voxels")));
    }
    let axes = HvolAxes::of(v, g, h, params)?;
    let slices = n / plane;
    let parts = fixed_parts(slices);
    let tasks: Vec<HvolAccumulator> = part_groups(rayon::current_num_threads())
        .into_par_iter()
        .map(|group| {
            let mut acc = HvolAccumulator::new(&axes)?;
            for k in parts[group.start].start..parts[group.end - 1].end {
                let at = k * plane..(k + 1) * plane;
                acc.add_slice(k, slices, &v[at.clone()], &g[at.clone()], &h[at]);
            }
            Ok(acc)
        })
        .collect::<Result<_, HistogramError>>()?;
    HvolAccumulator::finish(tasks, params)
}

/// [`HVOL_PARTS`] contiguous ranges covering `0..len` (voxels, or z-slices
/// when streamed; some empty when len is smaller): the fixed parts whose
/// sums a caller feeding [`HvolAccumulator`]s must keep in one accumulator each.
pub fn fixed_parts(len: usize) -> Vec<Range<usize>> {
    (0..HVOL_PARTS).map(|p| p * len / HVOL_PARTS..(p + 1) * len / HVOL_PARTS).collect()
}

/// The part indices grouped into one run of whole parts per thread, so that
/// no part's sums are split between tasks.
pub fn part_groups(threads: usize) -> Vec<Range<usize>> {
    let per = HVOL_PARTS.div_ceil(threads.clamp(1, HVOL_PARTS));
    (0..HVOL_PARTS).step_by(per).map(|first| first..(first + per).min(HVOL_PARTS)).collect()
}

/// sigma, p(v, g) and the default opacity from the merged counts and sums.
fn derive_tables(
    hist: Histogram,
    axes: HvolAxes,
    sums: Sums,
    params: &HvolParams,
) -> Result<HistogramVolume, HistogramError> {
    let (av, ag) = (axes.v, axes.g);
    let nv = av.bins;
    let ng = ag.bins;
    let (c_v, g_v, h_v) = sums.per_v(nv);
    let mean = |sum: f64, c: u64| if c > 0 { sum / c as f64 } else { 0.0 };
    let mean_g_v: Vec<f64> = (0..nv).map(|b| mean(g_v[b], c_v[b])).collect();
    let mean_h_v: Vec<f64> = (0..nv).map(|b| mean(h_v[b], c_v[b])).collect();
    // sigma reads the extremes of the per-v means: v bins with a handful of
    // voxels (the tails of noise, whose few voxels are its peaks and pits,
    // with large |f''|) would set them, so bins below SIGMA_MIN_SHARE of the voxels do not count
    let counted: u64 = c_v.iter().sum();
    let least = ((SIGMA_MIN_SHARE * counted as f64).ceil() as u64).max(1);
    let filled = || (0..nv).filter(|&b| c_v[b] >= least);
    let max_g = filled().map(|b| mean_g_v[b]).fold(0.0, f64::max);
    let max_h = filled().map(|b| mean_h_v[b]).fold(f64::NEG_INFINITY, f64::max);
    let min_h = filled().map(|b| mean_h_v[b]).fold(f64::INFINITY, f64::min);
    if !(max_h > min_h && max_g > 0.0) {
        return Err(HistogramError::Degenerate("f'' does not vary with v: no boundary to measure sigma from".into()));
    }
    let sigma = 2.0 * max_g / (std::f64::consts::E.sqrt() * (max_h - min_h));
    let g_thresh = params.g_thresh.unwrap_or(0.04 * max_g);
    let tent_width = params.tent_width.unwrap_or(sigma);
    if !(tent_width > 0.0 && tent_width.is_finite()) {
        return Err(HistogramError::BadAxis(format!("tent width must be positive, got {tent_width}")));
    }
    let mut position = vec![0f32; nv * ng];
    let mut opacity = vec![0f32; nv * ng];
    for i in 0..nv * ng {
        let c = sums.c_vg[i];
        let (bv, bg) = (i % nv, i / nv);
        // Empty (v, g) bins fall back to Kindlmann and Durkin's 1D form: the v bin's mean f''
        // at the bin's centre g, so the default opacity is defined wherever v occurs.
        let (gm, hm) = if c > 0 {
            (sums.g_vg[i] / c as f64, sums.h_vg[i] / c as f64)
        } else if c_v[bv] > 0 {
            (ag.centre(bg), mean_h_v[bv])
        } else {
            continue;
        };
        if gm - g_thresh <= 0.0 {
            continue;
        }
        let p = -sigma * sigma * hm / (gm - g_thresh);
        position[i] = p as f32;
        opacity[i] = (params.max_opacity * (1.0 - p.abs() / tent_width).max(0.0)) as f32;
    }
    Ok(HistogramVolume {
        hist,
        count_v: c_v,
        mean_g_v,
        mean_h_v,
        sigma,
        g_thresh,
        tent_width,
        max_opacity: params.max_opacity,
        vg_axes: [av, ag],
        count_vg: sums.c_vg,
        position,
        opacity,
        spacing: params.spacing,
    })
}

/// Counts the voxels, `count(bin, voxels)` for each run of voxels in one
/// bin (index v + nv (g + ng f'')), and adds the run's sums to `s`.
#[multiversion::multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
fn count_and_sum(
    channels: &[&[f32]; 3],
    binners: &[Binner; 3],
    strides: &[u32; 3],
    count: &mut impl FnMut(u32, u32),
    s: &mut Sums,
) {
    let (g, h) = (channels[1], channels[2]);
    let n = channels.iter().map(|c| c.len()).min().unwrap_or(0);
    for_each_run(channels, binners, strides, None, 0..n, |bin, voxels| {
        count(bin, voxels.len() as u32);
        s.add(Run { bin, count: voxels.len() as u64, g: sum(&g[voxels.clone()]), h: sum(&h[voxels]) });
    });
}

/// Lanes of [`sum`]: eight f64 accumulators (one AVX-512 register), so that
/// the background's long runs are not one chain of dependent additions.
const SUM_LANES: usize = 8;

/// The f64 sum of `d`, lane by lane in a fixed order (a run is summed the
/// same way whichever thread counts it).
#[inline(always)]
fn sum(d: &[f32]) -> f64 {
    let (chunks, tail) = d.as_chunks::<SUM_LANES>();
    let mut lanes = [0.0f64; SUM_LANES];
    for c in chunks {
        for l in 0..SUM_LANES {
            lanes[l] += c[l] as f64;
        }
    }
    lanes.iter().chain(&[tail.iter().fold(0.0f64, |acc, &x| acc + x as f64)]).fold(0.0, |acc, &x| acc + x)
}

/// Consecutive voxels in one (v, g, f'') bin: their count and sums of g and f''.
struct Run {
    bin: u32,
    count: u64,
    g: f64,
    h: f64,
}

/// Per (v, g) bin sums; the per-v sums are taken from them at the end.
struct Sums {
    c_vg: Vec<u64>,
    g_vg: Vec<f64>,
    h_vg: Vec<f64>,
}

impl Sums {
    fn new(nv: usize, ng: usize) -> Sums {
        Sums { c_vg: vec![0; nv * ng], g_vg: vec![0.0; nv * ng], h_vg: vec![0.0; nv * ng] }
    }

    /// Adds a run of voxels of one bin (index v + nv (g + ng f'')).
    #[inline(always)]
    fn add(&mut self, run: Run) {
        // the (v, g) index is the bin modulo nv ng; u32, since bins are u32
        let i = (run.bin % self.c_vg.len() as u32) as usize;
        if let (Some(c), Some(g), Some(h)) = (self.c_vg.get_mut(i), self.g_vg.get_mut(i), self.h_vg.get_mut(i)) {
            *c += run.count;
            *g += run.g;
            *h += run.h;
        }
    }

    /// Count, g sum and f'' sum per v bin: the (v, g) sums of each v added
    /// in g order (a fixed order, so the bits do not depend on the threads).
    fn per_v(&self, nv: usize) -> (Vec<u64>, Vec<f64>, Vec<f64>) {
        let (mut c, mut g, mut h) = (vec![0u64; nv], vec![0f64; nv], vec![0f64; nv]);
        for i in 0..self.c_vg.len() {
            let bv = i % nv;
            c[bv] += self.c_vg[i];
            g[bv] += self.g_vg[i];
            h[bv] += self.h_vg[i];
        }
        (c, g, h)
    }

    fn merge(&mut self, o: &Sums) {
        self.c_vg.iter_mut().zip(&o.c_vg).for_each(|(x, y)| *x += y);
        self.g_vg.iter_mut().zip(&o.g_vg).for_each(|(x, y)| *x += y);
        self.h_vg.iter_mut().zip(&o.h_vg).for_each(|(x, y)| *x += y);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_spilled_into_u64_between_slabs_are_the_counts_of_no_spill() {
        // pseudo-random v, g, f'' over 12 slices of 30 x 20
        let (plane, slices) = (600, 12);
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % 10_000) as f32 / 100.0
        };
        let n = plane * slices;
        let (v, g, h): (Vec<f32>, Vec<f32>, Vec<f32>) = (0..n).map(|_| (next(), next(), next() - 50.0)).collect();
        let params = HvolParams::default();
        let axes = HvolAxes::of(&v, &g, &h, &params).unwrap();
        let run = |room: u64| {
            let mut by_slabs = HvolBySlabs::new(&axes, plane, slices, 2).unwrap();
            by_slabs.room = room;
            for first in (0..slices).step_by(2) {
                let at = first * plane..(first + 2) * plane;
                by_slabs.add_slab(first, &v[at.clone()], &g[at.clone()], &h[at]).unwrap();
            }
            let spilled = !by_slabs.spilled.is_empty();
            (by_slabs.finish(&params).unwrap().hist, spilled)
        };
        let (plain, spilled) = run(u64::from(u32::MAX));
        assert!(!spilled);
        // room for three slices: the counts spill before every second slab
        let (with_spills, spilled) = run(3 * plane as u64);
        assert!(spilled);
        assert_eq!(with_spills, plain);
        assert_eq!(plain.total(), n as u64);
        let mut too_small = HvolBySlabs::new(&axes, plane, slices, 2).unwrap();
        too_small.room = plane as u64;
        assert!(too_small.add_slab(0, &v[..2 * plane], &g[..2 * plane], &h[..2 * plane]).is_err());
    }
}
