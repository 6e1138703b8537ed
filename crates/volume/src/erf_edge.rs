//! The profile of an ideal boundary blurred by a Gaussian (an erf edge),
//! shared by the boundary detection and the default transfer functions
//! that draw on its arch in the (v, g) plane.
//!
//! Between values v_a < v_b with width sigma, the value at t = (v - v_a) /
//! (v_b - v_a) of the way is reached where Phi(z) = t (z = x / sigma), and
//! the gradient there is G exp(-z^2 / 2), G = (v_b - v_a) / (sqrt(2 pi) sigma).

/// z with Phi(z) = t for t in (0, 1), Phi the standard normal CDF, by
/// bisection (Phi is monotone; 64 halvings of [-40, 40] reach f64's resolution).
pub fn normal_quantile(t: f64) -> f64 {
    let (mut lo, mut hi) = (-40.0f64, 40.0f64);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if 0.5 * libm::erfc(-mid / std::f64::consts::SQRT_2) < t {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// g / G of an erf edge at t in (0, 1) of its value span: exp(-z^2 / 2), Phi(z) = t.
pub fn arch_shape(t: f64) -> f64 {
    let z = normal_quantile(t);
    (-z * z / 2.0).exp()
}

/// The arch's g at value `v` of an erf edge from `v_low` to `v_high` with
/// peak gradient `g_peak` (None outside the open span).
pub fn arch_g(v_low: f64, v_high: f64, g_peak: f64, v: f64) -> Option<f64> {
    let t = (v - v_low) / (v_high - v_low);
    (t > 0.0 && t < 1.0).then(|| g_peak * arch_shape(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quantile_inverts_the_normal_cdf_and_the_arch_peaks_at_its_centre() {
        for t in [0.001, 0.1, 0.3085375387259869, 0.5, 0.9] {
            let z = normal_quantile(t);
            assert!((0.5 * libm::erfc(-z / std::f64::consts::SQRT_2) - t).abs() < 1e-12, "{t}: {z}");
        }
        // Phi(0.5) = 0.6915: half a sigma from the centre, g = G exp(-1/8)
        assert!((arch_shape(0.6914624612740131) - (-0.125f64).exp()).abs() < 1e-9);
        assert_eq!(arch_g(0.0, 10.0, 4.0, 5.0), Some(4.0));
        assert_eq!(arch_g(0.0, 10.0, 4.0, 10.0), None);
    }
}
