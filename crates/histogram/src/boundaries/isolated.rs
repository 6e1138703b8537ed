//! Arches that stand alone above the others: the boundary of a small
//! object of high contrast (the air of a sinus in bone, a metal pin in
//! tissue) draws a faint arch of few voxels over the strong ones. Measured
//! against every voxel above its materials' noise it has no weight (the
//! feet of the strong arches outnumber it a thousand to one), so the
//! arches taken first (rules 2 to 4 of the parent module) are its
//! reference instead, after they have been taken:
//! 1. a sampled value of a pair's arch is clear where the arch lies above
//!    every taken arch's band there (its g at least [`ARCH_BAND`] times
//!    theirs); at least [`MIN_CLEAR_SAMPLES`] must be. Over those, the
//!    confidence is the share of the voxels the taken arches leave above
//!    their bands that lie within the pair's band, times the share of
//!    clear values whose band holds at least [`MIN_EXPECTED`] of what an
//!    arch holds there: the voxels of an edge crossing values at rate g
//!    number 1 / g per value, so a band that runs empty over part of the
//!    way is another arch's piece, not this one;
//! 2. G is the most confident on a geometric grid up to [`ARCH_BAND`]
//!    times the top of the g axis (qbert's clip may cut an arch's top),
//!    then the median over clear values of the median g in its band over
//!    the arch's shape (three rounds);
//! 3. it must be a ridge: where its band lies above the taken arches'
//!    bands (its g at least [`ARCH_BAND`] squared times theirs), the
//!    voxels in its band must be at least [`MIN_RIDGE`] of those in its
//!    band and in the band just under it, counted on the whole histogram
//!    less the taken arches' bands (the upper edge of a diffuse cloud of
//!    fine structure, like a bonsai's foliage, has as many voxels under
//!    its band as in it; the sinus's arch has none);
//! 4. it holds at least [`MIN_ISOLATED_VOXELS`] and [`MIN_ISOLATED_SHARE`]
//!    of all voxels in its band, is at least as wide as the parent's
//!    least sigma, stands [`MIN_PEAK_OVER_NOISE`] times above its
//!    materials' noise, and has a confidence of at least [`MIN_CONFIDENCE`].
//!
//! The most confident is taken, its voxels removed, and the pairs fitted
//! again, until none is left.

use super::{
    ARCH_BAND, ARCH_SAMPLES, ARCH_T, Columns, DetectedBoundary, G_STEPS, MAX_BOUNDARIES, MIN_CONFIDENCE,
    MIN_PEAK_OVER_NOISE, arch_between, core_voxels, explain_away, material_pairs, same_voxels,
};
use crate::axis::Axis;
use crate::materials::Material;
use mdtf_volume::arch_shape;

/// Least number of clear sampled values (rule 1 of the module docs).
pub const MIN_CLEAR_SAMPLES: usize = ARCH_SAMPLES / 3;
/// Share of an arch's expected voxels at a value below which its band
/// there counts as empty (rule 1).
pub const MIN_EXPECTED: f64 = 0.25;
/// Least share of an isolated arch's band over its band and the band under
/// it (rule 3).
pub const MIN_RIDGE: f64 = 0.8;
/// Least sampled values where the ridge is measured (rule 3).
const MIN_RIDGE_SAMPLES: usize = 3;
/// Least voxels in an isolated arch's band (rule 4): a few strays draw no arch.
pub const MIN_ISOLATED_VOXELS: u64 = 100;
/// Least share of all voxels in an isolated arch's band (rule 4).
pub const MIN_ISOLATED_SHARE: f64 = 1e-5;
/// Rounds of the median refinement of G (rule 2).
const REFINE_ROUNDS: usize = 3;

/// The isolated arches of a histogram (see the module docs): `whole` its
/// (v, g) counts, `residual` what the arches `taken` leave of them.
pub(super) fn find(
    whole: &[u64],
    residual: &[u64],
    axes: &[Axis; 2],
    materials: &[Material],
    taken: &[DetectedBoundary],
    min_sigma: f64,
) -> Vec<DetectedBoundary> {
    let total: u64 = whole.iter().sum();
    let mut beside = whole.to_vec();
    for b in taken {
        explain_away(&mut beside, axes, b);
    }
    let beside = Columns::new(&beside, axes, materials);
    let mut residual = residual.to_vec();
    let mut found: Vec<DetectedBoundary> = Vec::new();
    while taken.len() + found.len() < MAX_BOUNDARIES {
        let columns = Columns::new(&residual, axes, materials);
        let above: Vec<&DetectedBoundary> = taken.iter().chain(&found).collect();
        let is_above = |b: &DetectedBoundary| above.iter().any(|k| (k.v_low, k.v_high) == (b.v_low, b.v_high));
        let best = material_pairs(materials)
            .filter_map(|(low, high)| fit_isolated(&columns, &beside, low, high, &above))
            .filter(|(b, band)| {
                *band >= MIN_ISOLATED_VOXELS.max((MIN_ISOLATED_SHARE * total as f64) as u64)
                    && b.sigma >= min_sigma
                    && !is_above(b)
                    && !found.iter().any(|k| same_voxels(k, b))
            })
            .map(|(b, _)| b)
            .max_by(|a, b| a.confidence.total_cmp(&b.confidence).then(b.v_centre.total_cmp(&a.v_centre)));
        let Some(best) = best else { break };
        explain_away(&mut residual, axes, &best);
        found.push(best);
    }
    found
}

/// A value sampled along a pair's arch.
struct Sample {
    /// Its column.
    column: usize,
    /// The arch's shape there (g over G).
    shape: f64,
    /// The noise floor there.
    floor: f64,
    /// The top of the taken arches' bands there (0 where none runs).
    top: f64,
}

/// The isolated arch between `low` and `high` by rules 1 to 3 and the
/// noise and confidence of rule 4, with the voxels in its band; None when
/// it is none.
fn fit_isolated(
    columns: &Columns,
    beside: &Columns,
    low: &Material,
    high: &Material,
    above: &[&DetectedBoundary],
) -> Option<(DetectedBoundary, u64)> {
    let ag = &columns.axes[1];
    let floor = 2.0 * low.noise_g.max(high.noise_g).max(ag.width());
    let noise = (low.noise_g * high.noise_g).sqrt().max(ag.width());
    let span = high.value - low.value;
    if span.is_nan() || span <= 0.0 {
        return None;
    }
    let samples: Vec<Sample> = (0..ARCH_SAMPLES)
        .filter_map(|k| {
            let t = ARCH_T.0 + (ARCH_T.1 - ARCH_T.0) * k as f64 / (ARCH_SAMPLES - 1) as f64;
            let v = low.value + span * t;
            let top = above.iter().filter_map(|b| b.g_at(v)).fold(0.0, f64::max) * ARCH_BAND;
            columns.column(v).map(|column| Sample {
                column,
                shape: arch_shape(t),
                floor: floor.max(columns.still[column]),
                top,
            })
        })
        .collect();
    if samples.len() < ARCH_SAMPLES / 2 {
        return None;
    }
    let g_hi = ag.max * ARCH_BAND;
    if g_hi <= floor {
        return None;
    }
    let coarse = (0..G_STEPS)
        .map(|step| floor * (g_hi / floor).powf(step as f64 / (G_STEPS - 1) as f64))
        .filter_map(|g_peak| clear_confidence(columns, &samples, g_peak).map(|(c, _)| (c, g_peak)))
        .max_by(|a, b| a.0.total_cmp(&b.0))?;
    let mut g_peak = coarse.1;
    for _ in 0..REFINE_ROUNDS {
        let mut ratios: Vec<f64> = samples
            .iter()
            .filter(|s| g_peak * s.shape >= s.top)
            .filter_map(|s| {
                let g = g_peak * s.shape;
                columns.median_g(s.column, (g / ARCH_BAND).max(s.floor).max(s.top), g * ARCH_BAND).map(|m| m / s.shape)
            })
            .collect();
        ratios.sort_by(f64::total_cmp);
        g_peak = *ratios.get(ratios.len() / 2)?;
    }
    let (confidence, band) = clear_confidence(columns, &samples, g_peak)?;
    if confidence < MIN_CONFIDENCE
        || g_peak < MIN_PEAK_OVER_NOISE * noise
        || ridge(columns, beside, &samples, g_peak)? < MIN_RIDGE
    {
        return None;
    }
    let core = core_voxels(columns, low, high, g_peak, floor);
    Some((arch_between(low, high, g_peak, floor, core, confidence), band))
}

/// Rule 1's confidence of the arch of peak `g_peak` over the clear samples,
/// and the voxels in its band there; None with fewer than
/// [`MIN_CLEAR_SAMPLES`] clear samples or no voxel in its band.
fn clear_confidence(columns: &Columns, samples: &[Sample], g_peak: f64) -> Option<(f64, u64)> {
    let (mut in_band, mut left, mut per_shape) = (Vec::new(), 0u64, 0.0);
    for s in samples.iter().filter(|s| g_peak * s.shape >= s.top) {
        let g = g_peak * s.shape;
        let lo = s.floor.max(s.top);
        in_band.push((columns.mass(s.column, (g / ARCH_BAND).max(lo), g * ARCH_BAND), s.shape));
        left += columns.mass(s.column, lo, f64::INFINITY);
        per_shape += 1.0 / s.shape;
    }
    let band: u64 = in_band.iter().map(|&(n, _)| n).sum();
    if in_band.len() < MIN_CLEAR_SAMPLES || band == 0 {
        return None;
    }
    // an edge's voxels at a value number 1 / g: the band's expected count
    let scale = band as f64 / per_shape;
    let full = in_band.iter().filter(|&&(n, shape)| n as f64 >= MIN_EXPECTED * scale / shape).count();
    Some((band as f64 / left as f64 * full as f64 / in_band.len() as f64, band))
}

/// Rule 3's share of the band over the band and the band under it, where
/// the band lies above the taken arches' bands; None where it nowhere does
/// at [`MIN_RIDGE_SAMPLES`] values.
fn ridge(columns: &Columns, beside: &Columns, samples: &[Sample], g_peak: f64) -> Option<f64> {
    let (mut on, mut under, mut n) = (0u64, 0u64, 0usize);
    for s in samples.iter().filter(|s| g_peak * s.shape >= ARCH_BAND * s.top) {
        let g = g_peak * s.shape;
        let lo = (g / ARCH_BAND).max(s.floor);
        on += columns.mass(s.column, lo, g * ARCH_BAND);
        under += beside.mass(s.column, (lo / ARCH_BAND).max(s.floor), lo);
        n += 1;
    }
    (n >= MIN_RIDGE_SAMPLES && on > 0).then(|| on as f64 / (on + under) as f64)
}
