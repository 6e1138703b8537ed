//! Boundaries found in the (v, g) histogram: which materials a scan holds
//! and which pairs of them meet, read as Kindlmann and Durkin read the
//! arches of the (v, g) plane, made to hold on real scans.
//!
//! An ideal boundary between values v_a < v_b, blurred by a Gaussian of
//! width sigma, draws an arch in the (v, g) histogram: at v = v_a + (v_b -
//! v_a) t the gradient is g = G exp(-z^2 / 2) with Phi(z) = t and G = (v_b -
//! v_a) / (sqrt(2 pi) sigma). Real scans break the shortcuts that work on
//! phantoms: noise swamps f'' (and with it the position function), each
//! boundary has its own sigma, materials are uneven and arches cross. So the
//! detection fits the arch's shape itself, between materials found first:
//! 1. the materials are the dips of the median g of the v columns
//!    ([`crate::materials`]): where voxels sit still;
//! 2. for every pair of materials (not only neighbours in value: the air
//!    of a sinus meets bone across the soft tissue's value), the arch of
//!    the pair is fitted: over [`ARCH_SAMPLES`] values at t from
//!    [`ARCH_T`].0 to [`ARCH_T`].1 (the arch's ends sink into the
//!    materials' noise), the share of the voxels above the pair's noise
//!    floor (twice the larger of the two materials' noise g, or, within
//!    [`STILL_SPREADS`] spreads of a material's value, twice its: those
//!    are its still voxels, not a crossing arch's) whose g lies
//!    within a factor [`ARCH_BAND`] of the arch's, times the share of those
//!    values whose band holds at least a tenth of the median band's voxels
//!    (an arch must run the whole way, not borrow one stretch of another),
//!    is its confidence; G is the one of the most confidence, searched on a
//!    geometric grid from the floor to the top of the g axis;
//! 3. a pair is a boundary when its confidence is at least
//!    [`MIN_CONFIDENCE`], its sigma is at least [`MIN_SIGMA_SPACINGS`]
//!    voxel spacings (a narrower arch is the flank of a wider one), G is
//!    at least [`MIN_PEAK_OVER_NOISE`] times the
//!    geometric mean of its materials' noise g (it stands out of the noise
//!    of both: a textured material beside a still one, like an engine's
//!    cast metal beside its inserts, has the larger noise of the two) and
//!    its core (the band within half a sigma of its centre, [`CORE_T`])
//!    holds at least [`MIN_CORE_SHARE`] of the voxels;
//! 4. boundaries are taken one at a time, the most confident first, unless
//!    a pair enclosing it (one material shared, the other farther) runs
//!    within [`ARCH_BAND`] of it over its core and on past it
//!    ([`runs_past`]): then that one (the arch of a material lying under
//!    another arch, like a head holder's under the skin-to-bone arch, fits
//!    that arch's top as well as the whole arch does). The voxels on a
//!    taken arch are removed from the histogram before the pairs are
//!    fitted again, so that a weak arch crossed by a strong one is judged
//!    on the voxels the strong one does not explain; a pair is one
//!    boundary at most; a pair whose arch peaks and runs within a factor
//!    [`ARCH_BAND`] of a taken one over half or more of the values they
//!    share is that one again, and not taken; and a pair that, fitted on
//!    the whole histogram, is a taken arch's stretch in the sense above is
//!    what the removal left of that arch, and not taken;
//! 5. the arches standing alone above the taken ones are then found as
//!    the `isolated` submodule reads them: a small object of high contrast
//!    (the air of a sinus in bone) draws an arch of a few hundred voxels
//!    over the strong ones, which the feet of those outnumber in rule 2's
//!    share. A taken arch that ran on such an arch's voxels ([`same_voxels`])
//!    took them for its top and is fitted again without them (the head
//!    holder's arch, under the skin's band, had taken the sinus's top);
//! 6. at most [`MAX_BOUNDARIES`] are taken, then listed strongest (most
//!    voxels in the core) first;
//! 7. a boundary meets the background when one of its materials is the
//!    surround: the material nearest the value most voxels hold, or, while
//!    no boundary has that one as a side, its neighbour in value with more
//!    still voxels (a scanner's padding meets the air inside its field of
//!    view along a hard edge, with no arch).
//!
//! Pure noise and a smooth field have one dip or none and no arch: nothing
//! is found.

use crate::axis::Axis;
use crate::hvol::HistogramVolume;
use crate::materials::{Material, find_materials};
use mdtf_volume::arch_shape;
use serde::Serialize;

mod background;
mod columns;
mod isolated;

pub use background::{FALLBACK_G_QUANTILE, FALLBACK_HIGH_QUANTILE, background_value, fallback_boundary};
use background::{mode_value, surround_material};
use columns::Columns;

/// Values along an arch at which its fit is measured.
pub const ARCH_SAMPLES: usize = 29;
/// The part of an arch (t from the low material to the high one) that is fitted.
pub const ARCH_T: (f64, f64) = (0.15, 0.85);
/// The core of an arch (t from the low material to the high one): within
/// half a sigma of its centre, Phi(-0.5) to Phi(0.5). Its voxels grow with
/// the boundary's area (times its sigma), what its default opacity reads.
pub const CORE_T: (f64, f64) = (0.3085, 0.6915);
/// Factor within which a voxel's g lies on an arch.
pub const ARCH_BAND: f64 = 1.4;
/// Least confidence of a boundary.
pub const MIN_CONFIDENCE: f64 = 0.4;
/// Least ratio of a boundary's G to the geometric mean of its materials' noise g.
pub const MIN_PEAK_OVER_NOISE: f64 = 4.0;
/// Least share of all voxels on a boundary's arch.
pub const MIN_CORE_SHARE: f64 = 1e-4;
/// Least sigma of a boundary, in voxel spacings: a sampled edge, however
/// sharp, spreads over a voxel, so a kernel that interpolates (weights at
/// most 1) measures at most its step per spacing, a sigma of at least
/// spacing / sqrt(2 pi). A narrower arch is the flank of a wider one.
pub const MIN_SIGMA_SPACINGS: f64 = 0.398_942_280_401_432_7;
/// Most boundaries reported (the default TFs' distinct colours).
pub const MAX_BOUNDARIES: usize = 6;
/// Spreads around a material's value within which its still voxels (g up to
/// twice its noise g) are its own and not on any arch that crosses it.
pub const STILL_SPREADS: f64 = 2.0;
/// The end of an arch (t from its material) where its g sinks into noise.
const FOOT_T: f64 = 0.05;
/// Values sampled where an enclosing arch must run on ([`runs_past`]).
const PAST_SAMPLES: usize = 8;
/// Columns on each side of a sampled value whose voxels count with its own.
const COLUMN_REACH: usize = 2;
/// Candidate peak gradients tried per pair of materials.
const G_STEPS: usize = 160;

/// A boundary found in the (v, g) histogram.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DetectedBoundary {
    /// Value of the material on the low side (input units).
    pub v_low: f64,
    /// Standard deviation of that material's still voxels (input units).
    pub v_low_spread: f64,
    /// Value of the material on the high side (input units).
    pub v_high: f64,
    /// Standard deviation of that material's still voxels (input units).
    pub v_high_spread: f64,
    /// Value at the boundary's centre (f'' = 0), the mean of the two.
    pub v_centre: f64,
    /// Peak gradient magnitude G, input units per world unit.
    pub g_peak: f64,
    /// The boundary's width, world units: (v_high - v_low) / (sqrt(2 pi) G).
    pub sigma: f64,
    /// Voxels in its core: g within a factor [`ARCH_BAND`] of the arch's,
    /// above the floor, v within [`CORE_T`] of its value span.
    pub core_voxels: u64,
    /// The noise floor of g: twice the larger noise g of its two
    /// materials; below it a voxel is taken for noise inside a material.
    pub g_floor: f64,
    /// How sure the detection is, 0 to 1: the share of the voxels above the
    /// floor along its arch that the arch explains (see the module docs).
    pub confidence: f64,
    /// One of its two materials is the surround (rule 7 of the module docs):
    /// the surface a ray from outside meets first.
    pub meets_background: bool,
}

impl DetectedBoundary {
    /// The boundary's arch to draw on a (v, g) figure, labelled and coloured.
    pub fn arch(&self, label: &str, colour: [u8; 3]) -> crate::ArchMark {
        crate::ArchMark {
            v_low: self.v_low,
            v_high: self.v_high,
            g_peak: self.g_peak,
            label: label.into(),
            colour,
            collapsed: false,
        }
    }

    /// Voxels of a (v, g) histogram `hist` (first axis v, second g, any
    /// bins) on this boundary's core, as [`DetectedBoundary::core_voxels`]
    /// counts them: bins whose centre v lies within [`CORE_T`] of its span
    /// and whose centre g lies within a factor [`ARCH_BAND`] of the arch's
    /// there (at the core's end beyond it), above the floor. 0 for a
    /// histogram of other than two axes.
    pub fn core_count(&self, hist: &crate::Histogram) -> u64 {
        let [av, ag] = match hist.axes.as_slice() {
            [av, ag] => [av, ag],
            _ => return 0,
        };
        let span = self.v_high - self.v_low;
        let mut n = 0u64;
        for i in 0..av.bins {
            let t = (av.centre(i) - self.v_low) / span;
            if !(CORE_T.0..=CORE_T.1).contains(&t) {
                continue;
            }
            let (lo, hi) = core_band(self.g_peak, self.g_floor, t);
            for j in (0..ag.bins).filter(|&j| (lo..=hi).contains(&ag.centre(j))) {
                n += hist.counts[j * av.bins + i];
            }
        }
        n
    }

    /// The arch's g at value `v` (None outside the open span).
    fn g_at(&self, v: f64) -> Option<f64> {
        mdtf_volume::arch_g(self.v_low, self.v_high, self.g_peak, v)
    }
}

/// What [`detect_boundaries`] found: the materials and the boundaries between them.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Detection {
    /// The materials, in increasing value.
    pub materials: Vec<Material>,
    /// The boundaries, strongest (most core voxels) first.
    pub boundaries: Vec<DetectedBoundary>,
}

/// The boundaries of `hv`, strongest first; see the module docs.
pub fn detect_boundaries(hv: &HistogramVolume) -> Vec<DetectedBoundary> {
    detect(hv).boundaries
}

/// The materials and boundaries of `hv`; see the module docs.
pub fn detect(hv: &HistogramVolume) -> Detection {
    let min_sigma = hv.spacing.map_or(0.0, |s| MIN_SIGMA_SPACINGS * s);
    detect_in(&hv.count_vg, &hv.vg_axes, min_sigma)
}

/// [`detect`] over (v, g) counts (v fastest), reporting no boundary
/// narrower than `min_sigma` (world units).
pub fn detect_in(count_vg: &[u64], axes: &[Axis; 2], min_sigma: f64) -> Detection {
    let materials = find_materials(count_vg, axes);
    let (mut kept, residual) = take_arches(count_vg, axes, &materials, min_sigma, Vec::new());
    let isolated = isolated::find(count_vg, &residual, axes, &materials, &kept, min_sigma);
    if !isolated.is_empty() {
        kept = refit_beside(count_vg, axes, &materials, min_sigma, kept, &isolated);
        kept.extend(isolated);
    }
    kept.sort_by(|a, b| b.core_voxels.cmp(&a.core_voxels).then(a.v_centre.total_cmp(&b.v_centre)));
    if let Some(surround) = surround_material(&materials, mode_value(count_vg, axes), &kept) {
        for b in &mut kept {
            b.meets_background = b.v_low == surround || b.v_high == surround;
        }
    }
    Detection { materials, boundaries: kept }
}

/// Rules 2 to 4 of the module docs over `count_vg`, after the arches
/// `given` (taken as they are, their voxels removed first): the boundaries
/// taken, `given` first, and the counts their arches leave.
fn take_arches(
    count_vg: &[u64],
    axes: &[Axis; 2],
    materials: &[Material],
    min_sigma: f64,
    given: Vec<DetectedBoundary>,
) -> (Vec<DetectedBoundary>, Vec<u64>) {
    let mut counts = count_vg.to_vec();
    for b in &given {
        explain_away(&mut counts, axes, b);
    }
    let total = count_vg.iter().sum::<u64>() as f64;
    let whole_counts = counts.clone();
    let whole = Columns::new(&whole_counts, axes, materials);
    let first_taken = given.len();
    let mut kept = given;
    // pairs found to be a stretch of a kept boundary's arch
    let mut refused: Vec<(f64, f64)> = Vec::new();
    while kept.len() < MAX_BOUNDARIES {
        let columns = Columns::new(&counts, axes, materials);
        let candidates: Vec<DetectedBoundary> = material_pairs(materials)
            .filter(|(low, high)| {
                let taken = |k: &(f64, f64)| *k == (low.value, high.value);
                !kept.iter().map(|k| (k.v_low, k.v_high)).any(|k| taken(&k)) && !refused.iter().any(taken)
            })
            .filter_map(|(low, high)| fit_pair(&columns, low, high).filter(|b| b.sigma >= min_sigma))
            .filter(|b| b.core_voxels as f64 >= MIN_CORE_SHARE * total && !kept.iter().any(|k| same_voxels(k, b)))
            .collect();
        let most_confident = candidates
            .iter()
            .max_by(|a, b| a.confidence.total_cmp(&b.confidence).then(b.v_centre.total_cmp(&a.v_centre)));
        let Some(most_confident) = most_confident else { break };
        // a pair nested in another sharing one material, on the same voxels, is
        // the top of the outer arch when the outer arch runs on past it
        let best = candidates
            .iter()
            .filter(|outer| encloses(outer, most_confident) && runs_past(&columns, outer, most_confident, &candidates))
            .max_by(|a, b| a.confidence.total_cmp(&b.confidence))
            .unwrap_or(most_confident)
            .clone();
        explain_away(&mut counts, axes, &best);
        // what the arches taken before leave of an arch can be the rim of one
        // of theirs: fitted on the whole histogram, such a pair is a stretch
        // of a kept arch that runs on past it, and no boundary of its own
        let material = |v: f64| materials.iter().find(|m| m.value == v);
        let on_whole = match (kept.len() > first_taken, material(best.v_low), material(best.v_high)) {
            (true, Some(low), Some(high)) => fit_pair(&whole, low, high),
            _ => None,
        };
        let stretch = on_whole
            .as_ref()
            .is_some_and(|arch| kept.iter().any(|k| encloses(k, arch) && runs_past(&whole, k, arch, &kept)));
        if stretch {
            refused.push((best.v_low, best.v_high));
            continue;
        }
        // an arch under a taken one's band keeps only its rim in what is left
        // (a head holder's under the skin's): its peak is the whole
        // histogram's where that fits it at least as surely
        let mut best = best;
        if let Some(arch) = on_whole.filter(|a| a.confidence >= best.confidence && a.sigma >= min_sigma) {
            (best.g_peak, best.sigma) = (arch.g_peak, arch.sigma);
        }
        kept.push(best);
    }
    (kept, counts)
}

/// The `taken` arches with those that run on an `isolated` arch's voxels
/// ([`same_voxels`]) fitted again on the histogram without them: such an
/// arch took them for its top (a head holder's arch, under the skin's
/// band, for the sinus's over both). One whose pair is then no boundary
/// is dropped.
fn refit_beside(
    count_vg: &[u64],
    axes: &[Axis; 2],
    materials: &[Material],
    min_sigma: f64,
    taken: Vec<DetectedBoundary>,
    isolated: &[DetectedBoundary],
) -> Vec<DetectedBoundary> {
    let mut counts = count_vg.to_vec();
    for b in isolated {
        explain_away(&mut counts, axes, b);
    }
    let columns = Columns::new(&counts, axes, materials);
    let material = |v: f64| materials.iter().find(|m| m.value == v);
    taken
        .into_iter()
        .filter_map(|b| {
            if !isolated.iter().any(|i| same_voxels(i, &b)) {
                return Some(b);
            }
            let arch = fit_pair(&columns, material(b.v_low)?, material(b.v_high)?)?;
            (arch.sigma >= min_sigma).then_some(DetectedBoundary { meets_background: b.meets_background, ..arch })
        })
        .collect()
}

/// Every pair of `materials` (low, high), in increasing value of both.
fn material_pairs(materials: &[Material]) -> impl Iterator<Item = (&Material, &Material)> {
    materials.iter().enumerate().flat_map(|(a, low)| materials[a + 1..].iter().map(move |high| (low, high)))
}

/// Removes from `counts` the voxels on boundary `b`'s arch (within a factor
/// [`ARCH_BAND`] of its g, above its floor, over its whole value span), so
/// that the arches fitted after it are measured against the voxels it does
/// not explain: a weak arch under a strong one (skin and bone under air and
/// bone on a CT) is then judged on its own voxels.
fn explain_away(counts: &mut [u64], axes: &[Axis; 2], b: &DetectedBoundary) {
    let [av, ag] = axes;
    let nv = av.bins;
    for i in 0..nv {
        let Some(g_arch) = b.g_at(av.centre(i)) else { continue };
        for j in 0..ag.bins {
            let g = ag.centre(j);
            if g >= b.g_floor && g >= g_arch / ARCH_BAND && g <= g_arch * ARCH_BAND {
                counts[j * nv + i] = 0;
            }
        }
    }
}

/// The arch between two materials at its most confident G, or None when it
/// is not a boundary by rules 2 and 3 of the module docs (the voxel share is the caller's).
fn fit_pair(columns: &Columns, low: &Material, high: &Material) -> Option<DetectedBoundary> {
    let ag = &columns.axes[1];
    let floor = 2.0 * low.noise_g.max(high.noise_g).max(ag.width());
    // the arch must stand out of the noise of the two materials together
    let noise = (low.noise_g * high.noise_g).sqrt().max(ag.width());
    let span = high.value - low.value;
    // (column, arch shape, the column's floor: the pair's, or a material's still voxels' there)
    let samples: Vec<(usize, f64, f64)> = (0..ARCH_SAMPLES)
        .filter_map(|k| {
            let t = ARCH_T.0 + (ARCH_T.1 - ARCH_T.0) * k as f64 / (ARCH_SAMPLES - 1) as f64;
            columns.column(low.value + span * t).map(|i| (i, arch_shape(t), floor.max(columns.still[i])))
        })
        .collect();
    if samples.len() < ARCH_SAMPLES / 2 || span.is_nan() || span <= 0.0 {
        return None;
    }
    let above: u64 = samples.iter().map(|&(i, _, floor)| columns.mass(i, floor, f64::INFINITY)).sum();
    if above == 0 {
        return None;
    }
    let (g_lo, g_hi) = (floor, ag.max);
    if g_hi <= g_lo {
        return None;
    }
    let mut band = vec![0u64; samples.len()];
    let mut best: Option<(f64, f64)> = None;
    for step in 0..G_STEPS {
        let g_peak = g_lo * (g_hi / g_lo).powf(step as f64 / (G_STEPS - 1) as f64);
        for (n, &(i, shape, floor)) in band.iter_mut().zip(&samples) {
            let g = g_peak * shape;
            *n = columns.mass(i, (g / ARCH_BAND).max(floor), g * ARCH_BAND);
        }
        let confidence = band.iter().sum::<u64>() as f64 / above as f64 * coverage(&band);
        if best.is_none_or(|(c, _)| confidence > c) {
            best = Some((confidence, g_peak));
        }
    }
    let (confidence, g_coarse) = best?;
    // the confidence is flat while the band covers the arch: G is the median
    // over the sampled values of the median g in the band over the arch's shape
    let mut ratios: Vec<f64> = samples
        .iter()
        .filter_map(|&(i, shape, floor)| {
            let g = g_coarse * shape;
            columns.median_g(i, (g / ARCH_BAND).max(floor), g * ARCH_BAND).map(|m| m / shape)
        })
        .collect();
    ratios.sort_by(f64::total_cmp);
    let g_peak = ratios.get(ratios.len() / 2).copied().unwrap_or(g_coarse);
    if confidence < MIN_CONFIDENCE || g_peak < MIN_PEAK_OVER_NOISE * noise {
        return None;
    }
    Some(arch_between(low, high, g_peak, floor, core_voxels(columns, low, high, g_peak, floor), confidence))
}

/// Voxels of `columns` on the core of the arch from `low` to `high` of
/// peak `g_peak` over the noise floor `floor` (within half a sigma of its
/// centre, [`CORE_T`]).
fn core_voxels(columns: &Columns, low: &Material, high: &Material, g_peak: f64, floor: f64) -> u64 {
    let span = high.value - low.value;
    let (first, last) = (columns.column(low.value + span * CORE_T.0), columns.column(low.value + span * CORE_T.1));
    match (first, last) {
        (Some(first), Some(last)) => (first..=last)
            .map(|i| {
                let t = (columns.axes[0].centre(i) - low.value) / span;
                let (lo, hi) = core_band(g_peak, floor, t);
                columns.mass_of_one(i, lo, hi)
            })
            .sum(),
        _ => 0,
    }
}

/// The boundary from `low` to `high` of peak gradient `g_peak`, noise floor
/// `floor`, `core_voxels` and `confidence` (not yet known to meet the background).
fn arch_between(
    low: &Material,
    high: &Material,
    g_peak: f64,
    floor: f64,
    core_voxels: u64,
    confidence: f64,
) -> DetectedBoundary {
    let span = high.value - low.value;
    DetectedBoundary {
        v_low: low.value,
        v_low_spread: low.spread,
        v_high: high.value,
        v_high_spread: high.spread,
        v_centre: (low.value + high.value) / 2.0,
        g_peak,
        sigma: span / ((2.0 * std::f64::consts::PI).sqrt() * g_peak),
        core_voxels,
        g_floor: floor,
        confidence,
        meets_background: false,
    }
}

/// The share of an arch's sampled values whose band holds at least a tenth
/// of the median band's voxels (0 when the median band is empty).
fn coverage(band: &[u64]) -> f64 {
    let mut sorted = band.to_vec();
    sorted.sort_unstable();
    let median = sorted[sorted.len() / 2];
    if median == 0 {
        return 0.0;
    }
    band.iter().filter(|&&n| n * 10 >= median).count() as f64 / band.len() as f64
}

/// The g range of an arch of peak `g_peak` and noise floor `floor` at `t`
/// of its value span (clamped to its core, [`CORE_T`]): within a factor
/// [`ARCH_BAND`] of the arch's g, above the floor.
fn core_band(g_peak: f64, floor: f64, t: f64) -> (f64, f64) {
    let g = g_peak * arch_shape(t.clamp(CORE_T.0, CORE_T.1));
    ((g / ARCH_BAND).max(floor), g * ARCH_BAND)
}

/// Whether `outer` spans `inner` and more, with one material in common,
/// and `inner`'s arch runs within a factor [`ARCH_BAND`] of `outer`'s over
/// its core ([`CORE_T`]): `inner` may be a stretch of `outer`.
fn encloses(outer: &DetectedBoundary, inner: &DetectedBoundary) -> bool {
    let shares = (outer.v_low == inner.v_low) != (outer.v_high == inner.v_high);
    if !(shares && outer.v_low <= inner.v_low && outer.v_high >= inner.v_high) {
        return false;
    }
    (0..8).all(|k| {
        let t = CORE_T.0 + (CORE_T.1 - CORE_T.0) * k as f64 / 7.0;
        let v = inner.v_low + (inner.v_high - inner.v_low) * t;
        match (outer.g_at(v), inner.g_at(v)) {
            (Some(x), Some(y)) if x > 0.0 && y > 0.0 => (x / y).ln().abs() <= ARCH_BAND.ln(),
            _ => false,
        }
    })
}

/// Whether the arch of `outer` runs on where `inner`'s cannot: over the
/// values between the material `inner` does not share and `outer`'s own
/// (leaving out [`STILL_SPREADS`] spreads around each and the outer arch's
/// last [`FOOT_T`] at its end), the voxels within its band and on no other
/// candidate's that crosses it (one running on the same voxels,
/// [`same_voxels`], is the same arch) outnumber those above its band in at
/// least half of [`PAST_SAMPLES`] columns. The head holder
/// (250 HU) lies under the skin-to-bone arch (40 to 1400 HU): the holder's
/// arch to bone fits that arch's top; below 250 HU the skin's arch runs
/// on, the holder's would end.
fn runs_past(
    columns: &Columns,
    outer: &DetectedBoundary,
    inner: &DetectedBoundary,
    others: &[DetectedBoundary],
) -> bool {
    let span = outer.v_high - outer.v_low;
    let (from, to) = if outer.v_low == inner.v_low {
        (
            inner.v_high + STILL_SPREADS * inner.v_high_spread,
            outer.v_high - (FOOT_T * span).max(STILL_SPREADS * outer.v_high_spread),
        )
    } else {
        (
            outer.v_low + (FOOT_T * span).max(STILL_SPREADS * outer.v_low_spread),
            inner.v_low - STILL_SPREADS * inner.v_low_spread,
        )
    };
    if to <= from {
        return false;
    }
    // the arches that cross the outer one (not itself, the inner one, or the same arch again)
    let crossing_arches: Vec<&DetectedBoundary> = others
        .iter()
        .filter(|o| !std::ptr::eq(*o, outer) && !std::ptr::eq(*o, inner) && !same_voxels(o, outer))
        .collect();
    let on_arch = (0..PAST_SAMPLES)
        .filter(|k| {
            let v = from + (to - from) * (*k as f64 + 0.5) / PAST_SAMPLES as f64;
            let (Some(i), Some(g)) = (columns.column(v), outer.g_at(v)) else { return false };
            let floor = outer.g_floor.max(columns.still[i]);
            // the voxels of the band on no crossing arch's band
            let crossing: Vec<f64> = crossing_arches.iter().filter_map(|o| o.g_at(v)).collect();
            let ag = &columns.axes[1];
            let own = |j: usize| {
                let x = ag.centre(j);
                x >= floor.max(g / ARCH_BAND)
                    && x < g * ARCH_BAND
                    && !crossing.iter().any(|&c| x >= c / ARCH_BAND && x < c * ARCH_BAND)
            };
            let band: u64 = (0..ag.bins).filter(|&j| own(j)).map(|j| columns.in_bin(i, j)).sum();
            band > 0 && band >= columns.mass_of_one(i, (g * ARCH_BAND).max(floor), f64::INFINITY)
        })
        .count();
    2 * on_arch >= PAST_SAMPLES
}

/// Whether two arches peak within a factor [`ARCH_BAND`] of each other and
/// run so over half or more of the values they share (16 values across the
/// overlap). Arches of different peaks sharing a material converge towards
/// it: they are not the same arch.
fn same_voxels(a: &DetectedBoundary, b: &DetectedBoundary) -> bool {
    let (lo, hi) = (a.v_low.max(b.v_low), a.v_high.min(b.v_high));
    if hi <= lo || (a.g_peak / b.g_peak).ln().abs() > ARCH_BAND.ln() {
        return false;
    }
    let close = (0..16)
        .filter(|k| {
            let v = lo + (hi - lo) * (*k as f64 + 0.5) / 16.0;
            match (a.g_at(v), b.g_at(v)) {
                (Some(x), Some(y)) if x > 0.0 && y > 0.0 => (x / y).ln().abs() <= ARCH_BAND.ln(),
                _ => false,
            }
        })
        .count();
    close >= 8
}
