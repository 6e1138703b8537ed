//! Gaussian transfer-function primitives (Kniss et al., "Gaussian transfer
//! functions for multi-field volume visualization"): evaluation and the
//! analytic integral of the density along a segment on which the data vary
//! linearly (their eqs. 11-14).
//!
//! Density: rho(v) = exp(-||K (v - c)||^2). Along v(t) = v1 + t (v2 - v1),
//! with v'_i = K (v_i - c) and d = v'_2 - v'_1, the exponent is the quadratic
//! ||v'_1 + t d||^2 = (t ||d|| + A)^2 + ||v'_1||^2 - A^2 with A = d . v'_1 / ||d||,
//! so the integral over t in [0, 1] is
//! rho' = sqrt(pi)/2 * S / ||d|| * (erf(B) - erf(A)), B = A + ||d||,
//! S = exp(-||v'_1||^2 + A^2) (eq. 11). As ||d|| -> 0 it tends to rho(v1)
//! (eq. 14); for ||d|| < 1e-4 the midpoint value rho(v(1/2)) is used
//! (error below 1e-8), since the erf difference cancels catastrophically there.

use serde::{Deserialize, Serialize};

/// One Gaussian primitive over an m-dimensional transfer-function domain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaussianPrimitive {
    /// Centre c (m values, in data units).
    pub centre: Vec<f64>,
    /// The m x m matrix K (rows), its inverse width; diagonal K scales each axis.
    pub k: Vec<Vec<f64>>,
    /// Peak opacity (extinction scale tau).
    pub alpha_max: f64,
    /// Colour (RGB, 0..1).
    pub colour: [f64; 3],
}

impl GaussianPrimitive {
    fn transform(&self, v: &[f64]) -> Vec<f64> {
        self.k
            .iter()
            .map(|row| row.iter().zip(v.iter().zip(&self.centre)).map(|(k, (x, c))| k * (x - c)).sum())
            .collect()
    }

    /// The density rho(v) = exp(-||K (v - c)||^2), in [0, 1].
    pub fn density(&self, v: &[f64]) -> f64 {
        let t = self.transform(v);
        (-t.iter().map(|x| x * x).sum::<f64>()).exp()
    }

    /// The mean density over the segment from v1 to v2 with linearly varying
    /// data, integral of rho(v1 + t (v2 - v1)) over t in [0, 1] (eq. 11; eq. 14 in the limit).
    pub fn segment_integral(&self, v1: &[f64], v2: &[f64]) -> f64 {
        let p1 = self.transform(v1);
        let p2 = self.transform(v2);
        let d: Vec<f64> = p2.iter().zip(&p1).map(|(b, a)| b - a).collect();
        let dn = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        if dn < 1e-4 {
            let mid: Vec<f64> = p1.iter().zip(&d).map(|(a, x)| a + 0.5 * x).collect();
            return (-mid.iter().map(|x| x * x).sum::<f64>()).exp();
        }
        let a = d.iter().zip(&p1).map(|(x, y)| x * y).sum::<f64>() / dn;
        let b = a + dn;
        let p1n2: f64 = p1.iter().map(|x| x * x).sum();
        let s = (-p1n2 + a * a).exp();
        // erf(B) - erf(A) via erfc when both are far on the same side, to keep precision in the tails
        let diff = if a > 3.0 {
            libm::erfc(a) - libm::erfc(b)
        } else if b < -3.0 {
            libm::erfc(-b) - libm::erfc(-a)
        } else {
            libm::erf(b) - libm::erf(a)
        };
        std::f64::consts::PI.sqrt() / 2.0 * s / dn * diff
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn simpson(f: impl Fn(f64) -> f64, n: usize) -> f64 {
        let h = 1.0 / n as f64;
        let mut s = f(0.0) + f(1.0);
        for i in 1..n {
            s += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    }

    #[test]
    fn analytic_segment_integral_matches_quadrature_for_random_primitives() {
        let mut state = 7u64;
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst = 0.0f64;
        for case in 0..500 {
            let m = 1 + case % 3;
            let centre: Vec<f64> = (0..m).map(|_| rnd() * 2.0 - 0.5).collect();
            let k: Vec<Vec<f64>> = (0..m).map(|_| (0..m).map(|_| rnd() * 8.0 - 2.0).collect()).collect();
            let g = GaussianPrimitive { centre, k, alpha_max: 1.0, colour: [1.0; 3] };
            let v1: Vec<f64> = (0..m).map(|_| rnd() * 2.0 - 0.5).collect();
            let v2: Vec<f64> = if case % 10 == 0 {
                v1.clone() // the degenerate segment
            } else if case % 10 == 1 {
                v1.iter().map(|x| x + 1e-6 * rnd()).collect()
            } else {
                (0..m).map(|_| rnd() * 2.0 - 0.5).collect()
            };
            let quad = simpson(
                |t| {
                    let v: Vec<f64> = v1.iter().zip(&v2).map(|(a, b)| a + t * (b - a)).collect();
                    g.density(&v)
                },
                4000,
            );
            let analytic = g.segment_integral(&v1, &v2);
            worst = worst.max((analytic - quad).abs());
            if v1 == v2 {
                assert_eq!(analytic, g.density(&v1), "eq. 14");
            }
        }
        assert!(worst < 1e-5, "{worst:e}");
    }
}
