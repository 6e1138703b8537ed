//! Reconstruction kernel families, each a value / first / second-derivative
//! triple of 1D kernels sampled at integer offsets (mdtf measures at the
//! grid points), applied separably.
//!
//! Taps are correlation weights: `out[i] = sum_t w[t] in[i + t]`. Derivative
//! taps are divided by the spacing (and its square) so results are per world
//! unit.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Multiples of sigma at which Gaussian kernels are truncated.
pub const GAUSS_CUT: f64 = 4.0;

/// A kernel family.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum Kernel {
    /// Central differences: `f' = (f[i+1] - f[i-1]) / 2`, `f'' = f[i+1] - 2 f[i] + f[i-1]`. Second-order accurate.
    Central,
    /// Fourth-order accurate 5-point differences; mixed second derivatives from products of first-derivative stencils.
    Central4,
    /// Smoothing (approximating) cubic B-spline and its derivatives, as Teem's `cubic:1,0`, `cubicd:1,0`, `cubicdd:1,0`.
    BSpline3,
    /// Interpolating Catmull-Rom cubic and its derivatives; where its second derivative jumps (at the knots) the
    /// mean of the one-sided values is used.
    CatmullRom,
    /// Sampled Gaussian of standard deviation `sigma` (world units) and its derivatives, truncated at
    /// [`GAUSS_CUT`] sigma and normalised so that a constant keeps its value and a linear (quadratic) ramp gives
    /// its exact first (second) derivative.
    Gauss {
        /// Standard deviation in world units.
        sigma: f64,
    },
}

/// The default family: the most accurate on the erf sphere (see the crate tests).
pub const DEFAULT_KERNEL: Kernel = Kernel::Central4;

impl Default for Kernel {
    /// [`DEFAULT_KERNEL`].
    fn default() -> Kernel {
        DEFAULT_KERNEL
    }
}

/// Names accepted by `Kernel::from_str`, for messages and `--help`.
pub const KERNEL_NAMES: &str = "central, central4, bspline3, catmull-rom, gauss:SIGMA";

/// Sparse 1D taps: (offset, weight) with non-zero weights.
pub type Taps = Vec<(isize, f32)>;

/// Value, first- and second-derivative taps along one axis, in world units.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisTaps {
    /// Value reconstruction.
    pub d0: Taps,
    /// First derivative (per world unit).
    pub d1: Taps,
    /// Second derivative (per world unit squared).
    pub d2: Taps,
}

impl AxisTaps {
    /// Largest |offset| of any tap.
    pub fn radius(&self) -> usize {
        self.d0.iter().chain(&self.d1).chain(&self.d2).map(|(o, _)| o.unsigned_abs()).max().unwrap_or(0)
    }

    /// Every tap multiplied by `factor` (used for per-field normalisation).
    pub fn scaled(&self, factor: f64) -> AxisTaps {
        let s = |t: &Taps| t.iter().map(|&(o, w)| (o, (w as f64 * factor) as f32)).collect();
        AxisTaps { d0: s(&self.d0), d1: s(&self.d1), d2: s(&self.d2) }
    }
}

fn sparse(center: isize, dense: &[f64], scale: f64) -> Taps {
    dense
        .iter()
        .enumerate()
        .filter(|(_, w)| **w != 0.0)
        .map(|(i, w)| (i as isize - center, (w * scale) as f32))
        .collect()
}

impl Kernel {
    /// Taps along an axis of the given spacing (world units per voxel).
    pub fn axis_taps(&self, spacing: f64) -> AxisTaps {
        let (s1, s2) = (1.0 / spacing, 1.0 / (spacing * spacing));
        match *self {
            Kernel::Central => AxisTaps {
                d0: vec![(0, 1.0)],
                d1: sparse(1, &[-0.5, 0.0, 0.5], s1),
                d2: sparse(1, &[1.0, -2.0, 1.0], s2),
            },
            Kernel::Central4 => AxisTaps {
                d0: vec![(0, 1.0)],
                d1: sparse(2, &[1.0 / 12.0, -8.0 / 12.0, 0.0, 8.0 / 12.0, -1.0 / 12.0], s1),
                d2: sparse(2, &[-1.0 / 12.0, 16.0 / 12.0, -30.0 / 12.0, 16.0 / 12.0, -1.0 / 12.0], s2),
            },
            Kernel::BSpline3 => AxisTaps {
                d0: sparse(1, &[1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0], 1.0),
                d1: sparse(1, &[-0.5, 0.0, 0.5], s1),
                d2: sparse(1, &[1.0, -2.0, 1.0], s2),
            },
            Kernel::CatmullRom => AxisTaps {
                d0: vec![(0, 1.0)],
                d1: sparse(1, &[-0.5, 0.0, 0.5], s1),
                d2: sparse(2, &[-0.5, 3.0, -5.0, 3.0, -0.5], s2),
            },
            Kernel::Gauss { sigma } => gauss_taps(sigma / spacing, s1, s2),
        }
    }

    /// Whether the value kernel is the identity (the value item is then the input itself).
    pub fn interpolates(&self) -> bool {
        !matches!(self, Kernel::BSpline3 | Kernel::Gauss { .. })
    }
}

/// Sampled Gaussian derivative taps for sigma in voxels, with moment normalisation.
fn gauss_taps(sigma: f64, s1: f64, s2: f64) -> AxisTaps {
    let r = (GAUSS_CUT * sigma).ceil().max(1.0) as isize;
    let ts: Vec<f64> = (-r..=r).map(|t| t as f64).collect();
    let g: Vec<f64> = ts.iter().map(|t| (-t * t / (2.0 * sigma * sigma)).exp()).collect();
    let sum0: f64 = g.iter().sum();
    let d0: Vec<f64> = g.iter().map(|w| w / sum0).collect();
    // f'(i) = sum_t f[i+t] G'(-t): G'(-t) = t/sigma^2 G(t)
    let raw1: Vec<f64> = ts.iter().zip(&g).map(|(t, w)| t * w).collect();
    let m1: f64 = raw1.iter().zip(&ts).map(|(w, t)| w * t).sum();
    let d1: Vec<f64> = raw1.iter().map(|w| w / m1).collect();
    // G''(-t) = (t^2/sigma^2 - 1) G(t) / sigma^2; remove its sum, then fix the second moment to 2.
    let raw2: Vec<f64> = ts.iter().zip(&g).map(|(t, w)| (t * t / (sigma * sigma) - 1.0) * w).collect();
    let mean2 = raw2.iter().sum::<f64>();
    let zero_sum: Vec<f64> = raw2.iter().zip(&d0).map(|(w, n)| w - mean2 * n).collect();
    let m2: f64 = zero_sum.iter().zip(&ts).map(|(w, t)| w * t * t).sum();
    let d2: Vec<f64> = zero_sum.iter().map(|w| 2.0 * w / m2).collect();
    AxisTaps { d0: sparse(r, &d0, 1.0), d1: sparse(r, &d1, s1), d2: sparse(r, &d2, s2) }
}

/// Error for an unknown kernel name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown kernel '{0}' (valid: {KERNEL_NAMES}, e.g. gauss:1.5 with sigma in world units)")]
pub struct UnknownKernel(pub String);

impl FromStr for Kernel {
    type Err = UnknownKernel;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        Ok(match t.as_str() {
            "central" => Kernel::Central,
            "central4" => Kernel::Central4,
            "bspline3" => Kernel::BSpline3,
            "catmull-rom" | "catmullrom" => Kernel::CatmullRom,
            _ => {
                let sigma = t
                    .strip_prefix("gauss:")
                    .and_then(|v| v.parse::<f64>().ok())
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| UnknownKernel(s.to_string()))?;
                Kernel::Gauss { sigma }
            }
        })
    }
}

impl fmt::Display for Kernel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Kernel::Central => f.write_str("central"),
            Kernel::Central4 => f.write_str("central4"),
            Kernel::BSpline3 => f.write_str("bspline3"),
            Kernel::CatmullRom => f.write_str("catmull-rom"),
            Kernel::Gauss { sigma } => write!(f, "gauss:{sigma}"),
        }
    }
}

impl TryFrom<String> for Kernel {
    type Error = UnknownKernel;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<Kernel> for String {
    fn from(k: Kernel) -> String {
        k.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moment(t: &Taps, p: i32) -> f64 {
        t.iter().map(|&(o, w)| w as f64 * (o as f64).powi(p)).sum()
    }

    #[test]
    fn every_family_is_exact_on_polynomials_of_its_order() {
        for k in [Kernel::Central, Kernel::Central4, Kernel::BSpline3, Kernel::CatmullRom, Kernel::Gauss { sigma: 1.3 }]
        {
            let t = k.axis_taps(1.0);
            assert!((moment(&t.d0, 0) - 1.0).abs() < 1e-6, "{k} d0 sum");
            assert!(moment(&t.d1, 0).abs() < 1e-6 && (moment(&t.d1, 1) - 1.0).abs() < 1e-6, "{k} d1");
            assert!(moment(&t.d2, 0).abs() < 1e-6 && (moment(&t.d2, 2) - 2.0).abs() < 1e-5, "{k} d2");
            assert!(moment(&t.d2, 1).abs() < 1e-6, "{k} d2 odd moment");
        }
        // central4 is exact up to quartics
        let t = Kernel::Central4.axis_taps(1.0);
        assert!(moment(&t.d1, 3).abs() < 1e-6 && moment(&t.d2, 4).abs() < 1e-5);
    }

    #[test]
    fn spacing_scales_derivative_taps() {
        let t = Kernel::Central.axis_taps(0.5);
        assert_eq!(t.d1, vec![(-1, -1.0), (1, 1.0)]);
        assert_eq!(t.d2, vec![(-1, 4.0), (0, -8.0), (1, 4.0)]);
    }

    #[test]
    fn gauss_truncates_at_four_sigma_of_the_axis_spacing() {
        assert_eq!(Kernel::Gauss { sigma: 2.0 }.axis_taps(1.0).radius(), 8);
        assert_eq!(Kernel::Gauss { sigma: 2.0 }.axis_taps(2.0).radius(), 4);
    }

    #[test]
    fn names_parse_and_print_back() {
        for n in ["central", "central4", "bspline3", "catmull-rom", "gauss:1.5"] {
            assert_eq!(n.parse::<Kernel>().unwrap().to_string(), n);
        }
        let e = "cubic".parse::<Kernel>().unwrap_err().to_string();
        assert!(e.contains("central4") && e.contains("gauss:SIGMA"), "{e}");
        assert!("gauss:0".parse::<Kernel>().is_err());
        assert!("gauss:x".parse::<Kernel>().is_err());
    }
}
