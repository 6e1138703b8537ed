//! The materials of a scalar volume, read off its (v, g) histogram: values
//! where the voxels sit still.
//!
//! Inside a material the gradient is only noise; on a boundary it is large.
//! So the typical g of the voxels of value v (the median g of the v column
//! of the (v, g) histogram) dips where v is a material's value and rises
//! between two materials, where the column holds mostly boundary voxels. A
//! material is a dip of that curve:
//! 1. the columns hold at least [`MIN_COLUMN_SHARE`] of the voxels (a
//!    column of a few stray voxels has no typical g);
//! 2. a column is a dip when its median g is the least within
//!    [`DIP_REACH`] columns on each side (of equal medians, the column
//!    holding more voxels), and the highest median g met on
//!    one side before a lower one is at least [`MIN_DEPTH`] times the dip's
//!    (one side: the other may be the material's own noise tail, or the
//!    top of the range, where an MRI's brightest tissue meets a few vessels);
//! 3. unless the dip is [`CLEAR_DEPTH`] deep, at least
//!    [`MIN_NEAR_ZERO_SHARE`] of its voxels have g at most half its median
//!    (noise spreads g from zero; where a weak arch passes under a strong
//!    one, a shallow dip holds a narrow band of g far from zero; a thin
//!    layer without noise, blurred by its neighbours, has neither noise
//!    nor a g of zero, but a deep dip);
//! 4. its basin (the columns around it whose median g is within
//!    [`BASIN_RATIO`] of the dip's, and at least [`DIP_REACH`] on each
//!    side) holds at least [`MIN_MATERIAL_SHARE`] of the voxels with g at
//!    most twice the dip's median g, its still voxels (the extremes of a
//!    material's noise are its peaks and pits, where g is least: the dip
//!    may lie in the noise's tail, the material's voxels in its basin);
//! 5. its value is the count-weighted mean v of those still voxels, its
//!    spread their standard deviation about it (both in input units), its
//!    noise g the dip's median g;
//! 6. two neighbouring dips between which the median g never rises to
//!    [`MIN_DEPTH`] times the larger one's, and no column is empty, are one
//!    material (a noisy plateau dips more than once): the deeper one (values
//!    with no voxels between them part two materials, like a scanner's
//!    padding and the air inside its field of view).
//!
//! The median g of a column is robust to the tail of strong boundaries
//! that cross it, and needs no noise model: CT noise, MRI's Rician noise and
//! a micrograph's shot noise all leave the dips where the materials are.

use crate::axis::Axis;
use serde::Serialize;

/// Least share of all voxels a v column must hold to enter the curve.
pub const MIN_COLUMN_SHARE: f64 = 1e-5;
/// Columns on each side whose voxels enter a column's median g.
pub const MEDIAN_REACH: usize = 2;
/// Columns on each side within which a dip is the least.
pub const DIP_REACH: usize = 3;
/// Least ratio of the highest median g on one side of a dip to the dip's.
pub const MIN_DEPTH: f64 = 2.0;
/// Ratio of the median g on one side of a dip to the dip's beyond which
/// the dip needs no voxels near g = 0 (rule 3 of the module docs).
pub const CLEAR_DEPTH: f64 = 4.0;
/// Least share of a dip's voxels with g at most half its median g (or in
/// the first g bin): noise spreads a material's g from zero (about a tenth
/// of a pure noise gradient lies below half its median), while a dip where
/// one arch passes under another holds a narrow band of g far from zero.
pub const MIN_NEAR_ZERO_SHARE: f64 = 0.03;
/// How far (as a ratio) the median g of a dip's basin may rise above the dip's.
pub const BASIN_RATIO: f64 = 1.5;
/// Least share of all voxels a material's still voxels must hold.
pub const MIN_MATERIAL_SHARE: f64 = 1e-3;

/// A material found in the (v, g) histogram.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Material {
    /// Its value: the mean of its still voxels (input units).
    pub value: f64,
    /// The standard deviation of its still voxels' values (input units).
    pub spread: f64,
    /// The median g of its column: the noise's gradient magnitude inside
    /// it (input units per world unit).
    pub noise_g: f64,
    /// Voxels with g at most twice `noise_g` around its value.
    pub still_voxels: u64,
}

/// The median g of each v column of `count_vg` (v fastest) taken with the
/// [`MEDIAN_REACH`] columns on each side (a boundary without noise, sampled
/// on a grid, leaves some columns empty), None where they hold fewer than
/// [`MIN_COLUMN_SHARE`] of the voxels.
pub fn column_median_g(count_vg: &[u64], axes: &[Axis; 2]) -> Vec<Option<f64>> {
    let [av, ag] = axes;
    let (nv, ng) = (av.bins, ag.bins);
    let total: u64 = count_vg.iter().sum();
    let least = ((MIN_COLUMN_SHARE * total as f64).ceil() as u64).max(1);
    (0..nv)
        .map(|i| {
            let near = i.saturating_sub(MEDIAN_REACH)..(i + MEDIAN_REACH + 1).min(nv);
            let column = (0..ng).map(|j| near.clone().map(|k| count_vg[j * nv + k]).sum::<u64>());
            let n: u64 = column.clone().sum();
            if n < least {
                return None;
            }
            let half = n.div_ceil(2);
            let mut seen = 0;
            column.enumerate().find_map(|(j, c)| {
                seen += c;
                (seen >= half).then(|| ag.centre(j))
            })
        })
        .collect()
}

/// The materials of the (v, g) counts `count_vg` (v fastest, over `axes`),
/// in increasing value; see the module docs.
pub fn find_materials(count_vg: &[u64], axes: &[Axis; 2]) -> Vec<Material> {
    let [av, ag] = axes;
    let (nv, ng) = (av.bins, ag.bins);
    let total: u64 = count_vg.iter().sum();
    if total == 0 || count_vg.len() != nv * ng {
        return Vec::new();
    }
    let median = column_median_g(count_vg, axes);
    // a dip's g is at least one g bin's width: noise-free materials have g = 0
    let least_g = ag.width();
    let voxels: Vec<u64> = (0..nv).map(|i| (0..ng).map(|j| count_vg[j * nv + i]).sum()).collect();
    // of columns with equal median g (medians are g bin centres), the one holding more voxels
    let lower =
        |k: usize, i: usize, m: f64| median[k].is_some_and(|x| x < m || (x == m && (voxels[k], i) > (voxels[i], k)));
    let mut found = Vec::new();
    for (i, m) in median.iter().enumerate() {
        let Some(m) = *m else { continue };
        let window = i.saturating_sub(DIP_REACH)..(i + DIP_REACH + 1).min(nv);
        let least_in_window = window.clone().filter(|&k| k != i && lower(k, i, m));
        if least_in_window.count() > 0 {
            continue;
        }
        let side = |range: &mut dyn Iterator<Item = usize>| {
            let mut highest: Option<f64> = None;
            for k in range {
                let Some(x) = median[k] else { continue };
                if x < m {
                    break;
                }
                if x > m {
                    highest = Some(highest.map_or(x, |h: f64| h.max(x)));
                }
            }
            highest
        };
        let left = side(&mut (0..i).rev());
        let right = side(&mut (i + 1..nv));
        let floor = m.max(least_g);
        let highest = left.into_iter().chain(right).fold(0.0, f64::max);
        if highest < MIN_DEPTH * floor {
            continue;
        }
        // the basin of the dip: the columns around it whose median g stays within BASIN_RATIO of its
        let within = |k: usize| median[k].is_some_and(|x| x <= BASIN_RATIO * floor);
        let first = (0..i).rev().take_while(|&k| within(k)).last().unwrap_or(i);
        let last = (i + 1..nv).take_while(|&k| within(k)).last().unwrap_or(i);
        let window = first.min(window.start)..(last + 1).max(window.end);
        // noise from zero, not the band of an arch passing through
        let near_zero = (m / 2.0).max(ag.min + ag.width());
        let in_window = |keep: &dyn Fn(usize) -> bool| -> u64 {
            window.clone().flat_map(|k| (0..ng).filter(|&j| keep(j)).map(move |j| count_vg[j * nv + k])).sum()
        };
        let low = in_window(&|j| ag.min + (j + 1) as f64 * ag.width() <= near_zero + 1e-12 * ag.width());
        if highest < CLEAR_DEPTH * floor && (low as f64) < MIN_NEAR_ZERO_SHARE * in_window(&|_| true) as f64 {
            continue;
        }
        // the still voxels around the dip
        let still_g = 2.0 * floor;
        let (mut n, mut sv, mut svv) = (0u64, 0.0, 0.0);
        for k in window {
            let v = av.centre(k);
            for j in (0..ng).take_while(|&j| ag.centre(j) <= still_g) {
                let c = count_vg[j * nv + k];
                n += c;
                sv += c as f64 * v;
                svv += c as f64 * v * v;
            }
        }
        if (n as f64) < MIN_MATERIAL_SHARE * total as f64 || n == 0 {
            continue;
        }
        let value = sv / n as f64;
        let spread = (svv / n as f64 - value * value).max(0.0).sqrt();
        found.push((i, Material { value, spread, noise_g: m, still_voxels: n }));
    }
    merge_unseparated(found, &median)
}

/// Rule 6 of the module docs: neighbouring dips between which the median g
/// never rises to [`MIN_DEPTH`] times the larger dip's are one material (a
/// noisy plateau dips twice); the deeper dip (then the one with more still
/// voxels) stands for it.
fn merge_unseparated(dips: Vec<(usize, Material)>, median: &[Option<f64>]) -> Vec<Material> {
    let mut kept: Vec<(usize, Material)> = Vec::new();
    for (i, m) in dips {
        if let Some((k, last)) = kept.last_mut() {
            let between = median[*k..=i].iter().flatten().fold(0.0, |a: f64, &b| a.max(b));
            let gap = median[*k..=i].iter().any(Option::is_none);
            if !gap && between < MIN_DEPTH * last.noise_g.max(m.noise_g) {
                if (m.noise_g, std::cmp::Reverse(m.still_voxels)) < (last.noise_g, std::cmp::Reverse(last.still_voxels))
                {
                    (*k, *last) = (i, m);
                }
                continue;
            }
        }
        kept.push((i, m));
    }
    kept.into_iter().map(|(_, m)| m).collect()
}
