//! The background of a (v, g) histogram (the value most voxels hold), the
//! material a scan's outermost boundary meets (rule 7 of the parent
//! module), and the boundary shown when none is found, placed from them by
//! percentiles.

use super::DetectedBoundary;
use crate::axis::Axis;
use crate::hvol::HistogramVolume;
use crate::materials::Material;

/// Share of the voxels whose value lies below the fallback boundary's high value.
pub const FALLBACK_HIGH_QUANTILE: f64 = 0.99;
/// Share of the boundary voxels (g above twice the median) below the fallback's peak g.
pub const FALLBACK_G_QUANTILE: f64 = 0.75;

/// A boundary to show when [`detect_boundaries`] finds none, placed by
/// percentiles instead of found: from the background value (see
/// [`background_value`]) to the value below which [`FALLBACK_HIGH_QUANTILE`]
/// of the voxels lie, its peak g the [`FALLBACK_G_QUANTILE`] quantile of
/// the g of the voxels above twice the median g, its confidence 0. None when
/// the histogram holds no such span (a constant volume).
pub fn fallback_boundary(hv: &HistogramVolume) -> Option<DetectedBoundary> {
    let [av, ag] = &hv.vg_axes;
    let (nv, ng) = (av.bins, ag.bins);
    let total: u64 = hv.count_v.iter().sum();
    let per_g: Vec<u64> = (0..ng).map(|j| hv.count_vg[j * nv..(j + 1) * nv].iter().sum()).collect();
    let quantile_bin = |counts: &[u64], q: f64| {
        let n: u64 = counts.iter().sum();
        let target = (q * n as f64).ceil() as u64;
        let mut seen = 0;
        counts.iter().position(|&c| {
            seen += c;
            seen >= target.max(1)
        })
    };
    let background = background_value(hv);
    let v_high = av.centre(quantile_bin(&hv.count_v, FALLBACK_HIGH_QUANTILE)?);
    let median_g = ag.centre(quantile_bin(&per_g, 0.5)?);
    let floor = 2.0 * median_g.max(ag.width());
    let above: Vec<u64> = per_g.iter().enumerate().map(|(j, &c)| if ag.centre(j) > floor { c } else { 0 }).collect();
    let g_peak = ag.centre(quantile_bin(&above, FALLBACK_G_QUANTILE)?);
    let (v_low, v_high) = if v_high > background { (background, v_high) } else { (av.centre(0), background) };
    if v_high <= v_low || g_peak <= 0.0 || total == 0 {
        return None;
    }
    Some(DetectedBoundary {
        v_low,
        v_low_spread: 0.0,
        v_high,
        v_high_spread: 0.0,
        v_centre: (v_low + v_high) / 2.0,
        g_peak,
        sigma: (v_high - v_low) / ((2.0 * std::f64::consts::PI).sqrt() * g_peak),
        core_voxels: above.iter().sum(),
        g_floor: floor,
        confidence: 0.0,
        meets_background: true,
    })
}

/// The background: the centre of the v bin holding the most voxels (air
/// around a CT, the dark surround of an MRI or a micrograph, the ambient
/// value of a simulation; inside a cropped scan, its commonest tissue).
pub fn background_value(hv: &HistogramVolume) -> f64 {
    mode_value(&hv.count_vg, &hv.vg_axes)
}

/// The centre of the v bin holding the most voxels of `count_vg` (v fastest).
pub(super) fn mode_value(count_vg: &[u64], axes: &[Axis; 2]) -> f64 {
    let [av, ag] = axes;
    let nv = av.bins;
    let column = |i: usize| (0..ag.bins).map(|j| count_vg.get(j * nv + i).copied().unwrap_or(0)).sum::<u64>();
    let mode = (0..nv).map(|i| (i, column(i))).max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0))).map_or(0, |(i, _)| i);
    av.centre(mode)
}

/// The value of the surround's material (rule 7 of the module docs): the
/// material nearest `background`; while none of the `boundaries` has it as
/// one side, its neighbour in value holding more still voxels (a scanner's
/// padding, the commonest value, meets the air inside its field of view
/// along a hard edge with no arch; the air is what the head meets).
pub(super) fn surround_material(
    materials: &[Material],
    background: f64,
    boundaries: &[DetectedBoundary],
) -> Option<f64> {
    let nearest = |a: &&Material, b: &&Material| (a.value - background).abs().total_cmp(&(b.value - background).abs());
    let mut at = materials.iter().enumerate().min_by(|a, b| nearest(&a.1, &b.1))?.0;
    let touched = |m: &Material| boundaries.iter().any(|b| b.v_low == m.value || b.v_high == m.value);
    let mut step: Option<isize> = None;
    while !touched(&materials[at]) {
        let side = |d: isize| at.checked_add_signed(d).filter(|&k| k < materials.len());
        let next = match step {
            Some(d) => side(d),
            None => {
                let pick = [-1, 1]
                    .into_iter()
                    .filter_map(|d| side(d).map(|k| (d, k)))
                    .max_by_key(|&(_, k)| materials[k].still_voxels);
                step = pick.map(|(d, _)| d);
                pick.map(|(_, k)| k)
            }
        };
        let Some(next) = next else { break };
        at = next;
    }
    Some(materials[at].value)
}
