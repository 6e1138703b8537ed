//! Per-column cumulative counts of a (v, g) histogram: the voxels of any g
//! range of a v column (and of its neighbours) in constant time, which every
//! arch fit of the detection reads many times.

use super::{COLUMN_REACH, STILL_SPREADS};
use crate::axis::Axis;
use crate::materials::Material;

/// Per-column cumulative counts over g, for the voxels of a g range of one column.
pub(super) struct Columns<'a> {
    pub(super) axes: &'a [Axis; 2],
    /// cum[j * nv + i]: voxels of column i in g bins below j (j = 0..=ng).
    cum: Vec<u64>,
    /// still[i]: the g below which column i's voxels are a material's still
    /// voxels: twice the noise g of the materials within
    /// [`STILL_SPREADS`] spreads of its value (0 where none is).
    pub(super) still: Vec<f64>,
}

impl<'a> Columns<'a> {
    pub(super) fn new(count_vg: &[u64], axes: &'a [Axis; 2], materials: &[Material]) -> Self {
        let (nv, ng) = (axes[0].bins, axes[1].bins);
        let mut cum = vec![0u64; (ng + 1) * nv];
        for j in 0..ng {
            for i in 0..nv {
                cum[(j + 1) * nv + i] = cum[j * nv + i] + count_vg.get(j * nv + i).copied().unwrap_or(0);
            }
        }
        let still = (0..nv)
            .map(|i| {
                let v = axes[0].centre(i);
                materials
                    .iter()
                    .filter(|m| (v - m.value).abs() <= STILL_SPREADS * m.spread)
                    .fold(0.0, |a: f64, m| a.max(2.0 * m.noise_g))
            })
            .collect();
        Columns { axes, cum, still }
    }

    /// The column of value `v` (None outside the v axis).
    pub(super) fn column(&self, v: f64) -> Option<usize> {
        let av = &self.axes[0];
        let b = ((v - av.min) / av.width()).floor();
        (b >= 0.0 && b < av.bins as f64).then_some(b as usize)
    }

    /// The median g (a bin centre) of the voxels of [`Columns::mass`] (None when there are none).
    pub(super) fn median_g(&self, i: usize, lo: f64, hi: f64) -> Option<f64> {
        let ag = &self.axes[1];
        let half = self.mass(i, lo, hi).div_ceil(2);
        if half == 0 {
            return None;
        }
        (0..ag.bins).find(|&j| self.mass(i, lo, ag.min + (j + 1) as f64 * ag.width()) >= half).map(|j| ag.centre(j))
    }

    /// Voxels of column `i` in g bin `j`.
    pub(super) fn in_bin(&self, i: usize, j: usize) -> u64 {
        let nv = self.axes[0].bins;
        self.cum[(j + 1) * nv + i] - self.cum[j * nv + i]
    }

    /// Voxels of column `i` alone with g in [lo, hi).
    pub(super) fn mass_of_one(&self, i: usize, lo: f64, hi: f64) -> u64 {
        self.mass_in(i..i + 1, lo, hi)
    }

    /// Voxels with g in [lo, hi) of column `i` and the [`COLUMN_REACH`]
    /// columns on each side: a boundary without noise, sampled on a grid,
    /// leaves some columns empty (its voxels take only certain values).
    pub(super) fn mass(&self, i: usize, lo: f64, hi: f64) -> u64 {
        self.mass_in(i.saturating_sub(COLUMN_REACH)..i + COLUMN_REACH + 1, lo, hi)
    }

    /// Voxels with g in [lo, hi) of the columns `cols` (clipped to the v axis).
    fn mass_in(&self, cols: std::ops::Range<usize>, lo: f64, hi: f64) -> u64 {
        let (nv, ag) = (self.axes[0].bins, &self.axes[1]);
        let edge = |g: f64| (((g - ag.min) / ag.width()).ceil().max(0.0) as usize).min(ag.bins);
        let (jl, jh) = (edge(lo), edge(hi));
        if jh <= jl {
            return 0;
        }
        (cols.start..cols.end.min(nv)).map(|c| self.cum[jh * nv + c] - self.cum[jl * nv + c]).sum()
    }
}
