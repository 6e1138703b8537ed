//! Histogram axes: value ranges, bin counts and the binning rule.

use crate::HistogramError;
use crate::percentile::ChannelStats;
use serde::{Deserialize, Serialize};

/// One axis: `bins` equal cells over [min, max]. A value v goes to bin
/// floor((v - min) / (max - min) * bins); v == max goes to the last bin;
/// values outside [min, max] (and NaN) are not counted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// Channel name, e.g. "v", "g", "f2", "g_hit".
    pub name: String,
    /// Lower edge of the first bin.
    pub min: f64,
    /// Upper edge of the last bin.
    pub max: f64,
    /// Number of bins.
    pub bins: usize,
    /// Unit of the channel's values, e.g. "HU/mm" for g (None: the input does not say).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

impl Axis {
    /// The display axis of 1/g, [0, 8 / g_b] in `bins` bins, where g_b is
    /// the median g of the boundary voxels (those with g above twice the
    /// median g). Automatic ranges run to 1/epsilon in homogeneous regions
    /// and leave the boundaries in the first bin; a boundary of peak g_p
    /// lies at 1/g = 1/g_p at its centre and exp(x^2 / 2 sigma^2) / g_p at x,
    /// so this range shows every boundary with g_p >= g_b out to 2 sigma.
    /// None when no voxel has a gradient.
    pub fn inverse_gradient(g: &[f32], bins: usize) -> Option<Axis> {
        let median = mdtf_volume::median;
        let cut = 2.0 * median(g)?;
        let boundary: Vec<f32> = g.iter().copied().filter(|&x| x > cut && x.is_finite()).collect();
        Axis::inverse_gradient_at(median(&boundary)?, bins)
    }

    /// The [`Axis::inverse_gradient`] axis from `g_b`, the median g of the
    /// voxels above twice the median g (for callers that take the medians
    /// in pieces): [0, 8 / g_b], None unless g_b > 0.
    pub fn inverse_gradient_at(g_b: f32, bins: usize) -> Option<Axis> {
        let g_b = g_b as f64;
        (g_b > 0.0).then(|| Axis { name: "inv_g".into(), min: 0.0, max: 8.0 / g_b, bins, unit: None })
    }

    /// A checked axis.
    pub fn new(name: &str, min: f64, max: f64, bins: usize) -> Result<Axis, HistogramError> {
        if bins == 0 {
            return Err(HistogramError::BadAxis(format!("axis {name}: zero bins")));
        }
        // (a histogram holds at most 2^28 bins in all; bin indices are u32)
        if bins > 1 << 28 {
            return Err(HistogramError::BadAxis(format!("axis {name}: {bins} bins is too many (at most 2^28)")));
        }
        if !(min.is_finite() && max.is_finite() && max > min) {
            return Err(HistogramError::BadAxis(format!(
                "axis {name}: range [{min}, {max}] is inverted, degenerate or not finite"
            )));
        }
        Ok(Axis { name: name.to_string(), min, max, bins, unit: None })
    }

    /// The bin of `v`, or None outside the range: floor((v - min) * (bins / (max - min))),
    /// the maximum itself in the last bin.
    #[inline(always)]
    pub fn bin(&self, v: f32) -> Option<usize> {
        self.binner().bin(v)
    }

    /// The bin rule with its constants precomputed, for counting loops.
    pub fn binner(&self) -> Binner {
        Binner { min: self.min, max: self.max, scale: self.bins as f64 / (self.max - self.min), last: self.bins - 1 }
    }

    /// Centre of bin `b`.
    pub fn centre(&self, b: usize) -> f64 {
        self.min + (b as f64 + 0.5) * (self.max - self.min) / self.bins as f64
    }

    /// Width of one bin.
    pub fn width(&self) -> f64 {
        (self.max - self.min) / self.bins as f64
    }
}

/// [`Axis::bin`] with precomputed constants.
#[derive(Debug, Clone, Copy)]
pub struct Binner {
    min: f64,
    max: f64,
    scale: f64,
    last: usize,
}

impl Binner {
    /// The bin of `v`, or None outside [min, max] (or NaN).
    #[inline(always)]
    pub fn bin(&self, v: f32) -> Option<usize> {
        let (bin, inside) = self.bin_unchecked(v);
        inside.then_some(bin as usize)
    }

    /// [`Binner::bin`] without a branch, for loops that vectorise: the bin
    /// (clamped into range; meaningless when outside) and whether `v` is
    /// inside [min, max] (false for NaN).
    #[inline(always)]
    pub fn bin_unchecked(&self, v: f32) -> (u32, bool) {
        let v = v as f64;
        let inside = v >= self.min && v <= self.max;
        // floor, clamp, then the integer from the low mantissa bits of
        // x + 2^52: no float-to-int conversion, so the loop stays in vector
        // registers (NaN clamps to 0; it is outside anyway)
        const MAGIC: f64 = 4_503_599_627_370_496.0;
        let x = ((v - self.min) * self.scale).floor().max(0.0).min(self.last as f64);
        ((x + MAGIC).to_bits() as u32, inside)
    }
}

/// How to choose an axis's range and bins.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisSpec {
    /// Explicit [min, max], or None to take it from the data.
    pub range: Option<(f64, f64)>,
    /// Percent of the samples clipped off each end when the range comes from the data (low, high).
    pub clip_percent: (f64, f64),
    /// Number of bins, or None: one bin per integer for integer data spanning at most
    /// [`MAX_INTEGER_BINS`] values, else [`DEFAULT_BINS`].
    pub bins: Option<usize>,
}

/// Default bin count.
pub const DEFAULT_BINS: usize = 256;
/// Integer data spanning at most this many values get one bin per value.
pub const MAX_INTEGER_BINS: usize = 4096;

impl AxisSpec {
    /// Teem qbert's percentile clipping for a channel: 0 % for v, 0.002 % for
    /// g, 0.004 % for f'' (each end); 0 for anything else.
    pub fn qbert(channel: &str) -> AxisSpec {
        let p = match channel {
            "g" | "g_hit" => 0.002,
            "f2" => 0.004,
            _ => 0.0,
        };
        AxisSpec { range: None, clip_percent: (p, p), bins: None }
    }

    /// Resolves the axis for `data` (NaN and infinities ignored): the range
    /// explicit or the finite range with the clip removed (exact order
    /// statistics, see [`ChannelStats`]), the bins explicit, one per integer
    /// for integer data, or [`DEFAULT_BINS`].
    pub fn resolve(&self, name: &str, data: &[f32]) -> Result<Axis, HistogramError> {
        let clip = if self.range.is_some() { (0.0, 0.0) } else { self.clip_percent };
        ChannelStats::of(data, clip).axis(self, name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_inverse_gradient_axis_spans_eight_over_the_boundary_voxels_median() {
        // 600 homogeneous voxels (g 0..0.6), 400 on boundaries (g 10..50)
        let mut g: Vec<f32> = (0..600).map(|k| k as f32 * 1e-3).collect();
        g.extend((0..400).map(|k| 10.0 + k as f32 * 0.1));
        // brute force: median of all, then of those above twice it
        let mut sorted = g.clone();
        sorted.sort_by(f32::total_cmp);
        let cut = 2.0 * sorted[(sorted.len() - 1) / 2];
        let mut b: Vec<f32> = g.iter().copied().filter(|&x| x > cut).collect();
        b.sort_by(f32::total_cmp);
        let want = 8.0 / b[(b.len() - 1) / 2] as f64;
        let a = Axis::inverse_gradient(&g, 128).unwrap();
        assert_eq!((a.name.as_str(), a.min, a.bins), ("inv_g", 0.0, 128));
        assert!((a.max - want).abs() < 1e-12, "{} vs {want}", a.max);
        assert!(Axis::inverse_gradient(&[0.0; 10], 128).is_none());
    }

    #[test]
    fn edges_follow_the_documented_rule() {
        let a = Axis::new("v", 0.0, 10.0, 5).unwrap();
        assert_eq!(a.bin(0.0), Some(0));
        assert_eq!(a.bin(1.999), Some(0));
        assert_eq!(a.bin(2.0), Some(1));
        assert_eq!(a.bin(10.0), Some(4), "the maximum goes to the last bin");
        assert_eq!(a.bin(10.001), None);
        assert_eq!(a.bin(-0.001), None);
        assert_eq!(a.bin(f32::NAN), None);
        assert!(Axis::new("v", 1.0, 1.0, 4).is_err());
        assert!(Axis::new("v", 2.0, 1.0, 4).is_err());
        assert!(Axis::new("v", 0.0, 1.0, 0).is_err());
    }

    #[test]
    fn integer_data_gets_one_bin_per_value() {
        let data: Vec<f32> = (0..1000).map(|i| (i % 17) as f32 + 3.0).collect();
        let a = AxisSpec::qbert("v").resolve("v", &data).unwrap();
        assert_eq!((a.min, a.max, a.bins), (2.5, 19.5, 17));
        assert_eq!(a.bin(3.0), Some(0));
        assert_eq!(a.bin(19.0), Some(16));
    }

    #[test]
    fn percentile_clipping_drops_the_tails() {
        let mut data: Vec<f32> = (0..100_000).map(|i| (i % 1000) as f32 * 0.01).collect();
        data.push(1e6);
        let spec = AxisSpec { range: None, clip_percent: (0.0, 0.002), bins: Some(64) };
        let a = spec.resolve("g", &data).unwrap();
        // 0.002 % of 100 001 samples is 2 clipped (1e6 and one 9.99): the largest kept is 9.99
        assert_eq!(a.max, 9.99f32 as f64);
        assert_eq!(a.min, 0.0);
    }
}
