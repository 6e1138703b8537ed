//! Boundaries found in the histogram volume: the materials a scan holds and
//! the surfaces between them, read off the (v, g) plane as Kindlmann and
//! Durkin read it.
//!
//! An ideal boundary between values v_a < v_b, blurred by a Gaussian of
//! width sigma, draws an arch in the (v, g) histogram: g = G exp(-x^2 / 2
//! sigma^2) at v = v_a + (v_b - v_a) Phi(x / sigma), with its apex, where
//! f'' = 0, at v = (v_a + v_b) / 2 and g = G = (v_b - v_a) / (sqrt(2 pi)
//! sigma). The position function p(v, g) (the signed distance to the
//! boundary, see [`crate::HistogramVolume`]) is 0 at the apex and grows
//! along the arch with v. So each boundary's core is a connected patch of
//! (v, g) bins with |p| <= [`CORE_HALF_WIDTH`] sigma, above the noise, in
//! which p rises with v. Arches of boundaries that share a v range (the
//! skin and bone of a CT both span soft tissue) are told apart by their g.
//!
//! The rule, in full:
//! 1. the noise floor is max(2 x the median g of all voxels, the histogram
//!    volume's g threshold) (the boundary stage's floor, less its spacing term);
//! 2. candidate bins hold voxels, have g above the floor and |p| <= 0.5 sigma;
//! 3. candidates connected through bins at most 4 apart on each axis form a patch; a patch
//!    is a boundary when it holds at least [`MIN_CORE_SHARE`] of the
//!    voxels, spans at least 3 bins, has a count-weighted correlation of p
//!    with v of at least [`MIN_RISE_CORRELATION`], and its peak g is at
//!    least twice the noise floor (the tracer's default g_hit_min): so
//!    the fluctuations of noise, whose g stays near the floor, are not boundaries;
//! 4. G is the patch's g weighted by count and by 1 - |p| / (0.5 sigma)
//!    (the apex counts most), the centre v its count-weighted mean v, and
//!    the two materials v_centre -+ G sqrt(2 pi) sigma / 2;
//! 5. a patch whose centre lies within a quarter of a stronger boundary's v
//!    span and whose G is within 25 % of it is part of that boundary;
//! 6. a boundary meets the background when one of its materials lies within
//!    a quarter of its span of the value most voxels hold.
//!
//! sigma is the histogram volume's one estimate for the whole volume, so
//! the material values of a boundary much sharper or blurrier than the
//! rest are off by the ratio of the widths; its centre and G are not.

use crate::hvol::HistogramVolume;
use serde::Serialize;

/// Bins along each axis within which two candidate bins belong to one patch:
/// more than the 8 neighbours, because a noise-free boundary sampled on a
/// grid leaves some v bins empty (its voxels take only certain values).
const REACH: i64 = 4;

/// Half-width of a boundary's core in p, in units of sigma.
pub const CORE_HALF_WIDTH: f64 = 0.5;
/// Least share of all voxels in a boundary's core.
pub const MIN_CORE_SHARE: f64 = 1e-4;
/// Least count-weighted correlation of p with v inside a core.
pub const MIN_RISE_CORRELATION: f64 = 0.5;

/// A boundary found in the histogram volume.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DetectedBoundary {
    /// Value of the material on the low side (input units).
    pub v_low: f64,
    /// Value of the material on the high side.
    pub v_high: f64,
    /// Value at the boundary's centre (f'' = 0).
    pub v_centre: f64,
    /// Peak gradient magnitude G, value units per world unit.
    pub g_peak: f64,
    /// The boundary width used for the material values (the volume's sigma), world units.
    pub sigma: f64,
    /// Voxels in its core (|p| <= 0.5 sigma).
    pub core_voxels: u64,
    /// The noise floor of g (rule 1 of the module docs): below it a voxel
    /// is taken for noise inside a material, not for this boundary.
    pub g_floor: f64,
    /// One of its two materials is the background, the value held by the
    /// most voxels (see [`background_value`]): the surface a ray from
    /// outside meets first.
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
}

/// The boundaries of `hv`, strongest (most core voxels) first; see the module docs.
pub fn detect_boundaries(hv: &HistogramVolume) -> Vec<DetectedBoundary> {
    let [av, ag] = &hv.vg_axes;
    let (nv, ng) = (av.bins, ag.bins);
    let sigma = hv.sigma;
    let total: u64 = hv.count_vg.iter().sum();
    if total == 0 || !(sigma > 0.0 && sigma.is_finite()) {
        return Vec::new();
    }
    let floor = (2.0 * median_g(hv)).max(hv.g_thresh);
    let background = background_value(hv);
    let core = CORE_HALF_WIDTH * sigma;
    let candidate = |i: usize| {
        let bg = i / nv;
        hv.count_vg[i] > 0 && ag.centre(bg) > floor && (hv.position[i] as f64).abs() <= core
    };
    let mut seen = vec![false; nv * ng];
    let mut found: Vec<DetectedBoundary> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..nv * ng {
        if seen[start] || !candidate(start) {
            continue;
        }
        // flood fill over the bins within REACH of each other
        let mut patch = Patch::default();
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            let (bv, bg) = (i % nv, i / nv);
            let p = hv.position[i] as f64;
            patch.add(hv.count_vg[i] as f64, av.centre(bv), ag.centre(bg), p, 1.0 - p.abs() / core);
            for dg in -REACH..=REACH {
                for dv in -REACH..=REACH {
                    let (v2, g2) = (bv as i64 + dv, bg as i64 + dg);
                    if v2 < 0 || g2 < 0 || v2 >= nv as i64 || g2 >= ng as i64 {
                        continue;
                    }
                    let j = g2 as usize * nv + v2 as usize;
                    if !seen[j] && candidate(j) {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if patch.bins < 3
            || patch.count < MIN_CORE_SHARE * total as f64
            || patch.rise() < MIN_RISE_CORRELATION
            || patch.g_max < 2.0 * floor
        {
            continue;
        }
        let g_peak = patch.apex_g();
        let v_centre = patch.sv / patch.count;
        let half_span = g_peak * (2.0 * std::f64::consts::PI).sqrt() * sigma / 2.0;
        let (v_low, v_high) = (v_centre - half_span, v_centre + half_span);
        let near = |v: f64| (v - background).abs() <= 0.25 * (v_high - v_low);
        found.push(DetectedBoundary {
            v_low,
            v_high,
            v_centre,
            g_peak,
            sigma,
            core_voxels: patch.count as u64,
            g_floor: floor,
            meets_background: near(v_low) || near(v_high),
        });
    }
    found.sort_by(|a, b| b.core_voxels.cmp(&a.core_voxels).then(a.v_centre.total_cmp(&b.v_centre)));
    let mut kept: Vec<DetectedBoundary> = Vec::new();
    for b in found {
        let part_of = kept.iter().any(|k| {
            (b.v_centre - k.v_centre).abs() < 0.25 * (k.v_high - k.v_low)
                && (b.g_peak - k.g_peak).abs() < 0.25 * k.g_peak
        });
        if !part_of {
            kept.push(b);
        }
    }
    kept
}

/// The background: the centre of the v bin holding the most voxels (air
/// around a CT, the dark surround of an MRI or a micrograph, the ambient
/// value of a simulation; inside a cropped scan, its commonest tissue).
pub fn background_value(hv: &HistogramVolume) -> f64 {
    let [av, _] = &hv.vg_axes;
    let mode = hv.count_v.iter().enumerate().max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0))).map_or(0, |(i, _)| i);
    av.centre(mode)
}

/// The median g of all counted voxels, from the (v, g) counts (a bin centre).
fn median_g(hv: &HistogramVolume) -> f64 {
    let [av, ag] = &hv.vg_axes;
    let (nv, ng) = (av.bins, ag.bins);
    let per_g: Vec<u64> = (0..ng).map(|bg| hv.count_vg[bg * nv..(bg + 1) * nv].iter().sum()).collect();
    let half = per_g.iter().sum::<u64>().div_ceil(2);
    let mut seen = 0;
    for (bg, c) in per_g.iter().enumerate() {
        seen += c;
        if seen >= half && seen > 0 {
            return ag.centre(bg);
        }
    }
    0.0
}

/// Count-weighted sums over one connected patch of candidate bins.
#[derive(Default)]
struct Patch {
    bins: usize,
    count: f64,
    sv: f64,
    sp: f64,
    svv: f64,
    spp: f64,
    svp: f64,
    /// Sums of count x apex weight, and of that times g.
    sw: f64,
    swg: f64,
    g_max: f64,
}

impl Patch {
    fn add(&mut self, c: f64, v: f64, g: f64, p: f64, apex_weight: f64) {
        self.bins += 1;
        self.count += c;
        self.sv += c * v;
        self.sp += c * p;
        self.svv += c * v * v;
        self.spp += c * p * p;
        self.svp += c * v * p;
        let w = c * apex_weight.max(0.0);
        self.sw += w;
        self.swg += w * g;
        self.g_max = self.g_max.max(g);
    }

    /// Count-weighted correlation of p with v (0 when either is constant).
    fn rise(&self) -> f64 {
        let n = self.count;
        let cov = self.svp / n - (self.sv / n) * (self.sp / n);
        let var_v = self.svv / n - (self.sv / n).powi(2);
        let var_p = self.spp / n - (self.sp / n).powi(2);
        if var_v > 0.0 && var_p > 0.0 { cov / (var_v * var_p).sqrt() } else { 0.0 }
    }

    /// G: the patch's g weighted towards its apex.
    fn apex_g(&self) -> f64 {
        if self.sw > 0.0 { self.swg / self.sw } else { self.g_max }
    }
}
