//! Where a widget can be non-zero on the (v, g) plane, for conservative
//! culling: the unstructured-grid paper (Song et al., section 3.1) skips a
//! cell whose (s, g) range cannot meet any widget, since s and g are linear
//! inside a tetrahedron and so every value the cell takes lies in the box of
//! its vertices' values.
//!
//! Supports:
//! * `triangle`: g in [g_low, g_high], |v - v0 - shear g| <= width g / g_high;
//! * `rectangle`: its closed rectangle;
//! * `gaussian`: its +-3 sigma box, sigma_i^2 the diagonal of the covariance
//!   Sigma = (2 K^T K)^-1 of rho = exp(-||K (x - c)||^2). Outside the box
//!   ||K (x - c)||^2 > 4.5, so the density is below exp(-4.5) ~ 1.1 % of the
//!   peak. A triangular GTF over v (width sigma' g) is the wedge
//!   |v - c| <= 3 sigma' g.
//!
//! Every test is conservative: a widget may be said to meet a box it only
//! touches on the box's bounding rectangle, never the other way round.

use crate::gaussian::GaussianPrimitive;
use crate::tf::{Rectangle, TfFile, Triangle, Widget};

/// Multiples of sigma a Gaussian widget's culling box spans on each side of its centre.
pub const GAUSSIAN_SUPPORT_SIGMAS: f64 = 3.0;

/// The region of the (v, g) plane where one widget can be non-zero, worked
/// out once per widget so that testing a cell costs a few comparisons.
#[derive(Debug, Clone, PartialEq)]
pub enum Support {
    /// Zero everywhere (opacity 0).
    Nowhere,
    /// No bound is known (a singular K, or a Gaussian over other axes).
    Everywhere,
    /// The closed box v x g ([lo, hi] each).
    Box {
        /// v interval.
        v: [f64; 2],
        /// g interval.
        g: [f64; 2],
    },
    /// Levoy's triangle (its v0, width, g thresholds and shear).
    Triangle(Triangle),
    /// |v - centre| <= reach g, for g > 0 (a triangular GTF).
    Wedge {
        /// Centre in v.
        centre: f64,
        /// Half-width in v per unit g.
        reach: f64,
    },
}

impl Support {
    /// Whether the region meets the box `v` x `g` ([lo, hi] each, in the TF's units).
    pub fn meets(&self, v: [f64; 2], g: [f64; 2]) -> bool {
        match self {
            Support::Nowhere => false,
            Support::Everywhere => true,
            Support::Box { v: bv, g: bg } => overlaps(v, *bv) && overlaps(g, *bg),
            Support::Triangle(t) => triangle_meets(t, v, g),
            // widest at the box's largest g
            Support::Wedge { centre, reach } => {
                let gap = (v[0] - centre).max(centre - v[1]).max(0.0);
                g[1] > 0.0 && gap <= reach * g[1]
            }
        }
    }
}

impl TfFile {
    /// The support of every widget, in the file's order.
    pub fn supports(&self) -> Vec<Support> {
        self.widgets.iter().map(|w| w.shape.support()).collect()
    }
}

impl Widget {
    /// Where the widget can be non-zero: it is zero (or, for a Gaussian,
    /// below exp(-4.5) of its peak) everywhere outside.
    pub fn support(&self) -> Support {
        match self {
            Widget::Triangle(t) if t.alpha > 0.0 => Support::Triangle(t.clone()),
            Widget::Rectangle(Rectangle { centre, half_size, alpha, .. }) if *alpha > 0.0 => Support::Box {
                v: [centre[0] - half_size[0], centre[0] + half_size[0]],
                g: [centre[1] - half_size[1], centre[1] + half_size[1]],
            },
            Widget::Gaussian(p) if p.alpha_max > 0.0 => gaussian_support(p),
            _ => Support::Nowhere,
        }
    }
}

fn overlaps(a: [f64; 2], b: [f64; 2]) -> bool {
    a[0] <= b[1] && a[1] >= b[0]
}

/// The triangle restricted to the box's g interval lies between the centre
/// lines at its two ends, widened by the largest half-width there.
fn triangle_meets(t: &Triangle, v: [f64; 2], g: [f64; 2]) -> bool {
    let (lo, hi) = (g[0].max(t.g_low), g[1].min(t.g_high));
    if lo > hi {
        return false;
    }
    let (c_lo, c_hi) = (t.v0 + t.shear * lo, t.v0 + t.shear * hi);
    let h = t.width * hi / t.g_high;
    overlaps(v, [c_lo.min(c_hi) - h, c_lo.max(c_hi) + h])
}

fn gaussian_support(p: &GaussianPrimitive) -> Support {
    let Some(sigma) = marginal_sigmas(&p.k) else { return Support::Everywhere };
    let span = |i: usize| {
        let r = GAUSSIAN_SUPPORT_SIGMAS * sigma[i];
        [p.centre[i] - r, p.centre[i] + r]
    };
    match (p.centre.len(), p.triangular) {
        (1, true) => Support::Wedge { centre: p.centre[0], reach: GAUSSIAN_SUPPORT_SIGMAS * sigma[0] },
        (1, false) => Support::Box { v: span(0), g: [f64::NEG_INFINITY, f64::INFINITY] },
        (2, false) => Support::Box { v: span(0), g: span(1) },
        // a Gaussian over other axes than (v, g) is not culled
        _ => Support::Everywhere,
    }
}

/// sigma_i = sqrt(Sigma_ii) with Sigma = (2 K^T K)^-1 = K^-1 K^-T / 2, so
/// Sigma_ii = sum_j (K^-1)_ij^2 / 2; None when K is singular (no bound).
fn marginal_sigmas(k: &[Vec<f64>]) -> Option<Vec<f64>> {
    let m = k.len();
    if k.iter().any(|row| row.len() != m) {
        return None;
    }
    // Gauss-Jordan with partial pivoting on [K | I]
    let mut a: Vec<Vec<f64>> = k
        .iter()
        .enumerate()
        .map(|(i, row)| row.iter().copied().chain((0..m).map(|j| f64::from(u8::from(i == j)))).collect())
        .collect();
    let scale = k.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    for col in 0..m {
        let pivot = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() <= 1e-12 * scale || a[pivot][col].is_nan() {
            return None;
        }
        a.swap(col, pivot);
        let p = a[col][col];
        a[col].iter_mut().for_each(|x| *x /= p);
        for row in 0..m {
            if row != col {
                let f = a[row][col];
                let pivot_row = a[col].clone();
                a[row].iter_mut().zip(&pivot_row).for_each(|(x, y)| *x -= f * y);
            }
        }
    }
    Some(a.iter().map(|row| (row[m..].iter().map(|x| x * x).sum::<f64>() / 2.0).sqrt()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigmas_of_a_diagonal_and_a_rotated_k_match_their_covariance() {
        // K = diag(1/(sqrt2 s)) gives exp(-x^2 / (2 s^2)): sigma = s
        let s = marginal_sigmas(&[vec![1.0 / (2f64.sqrt() * 3.0), 0.0], vec![0.0, 1.0 / (2f64.sqrt() * 0.5)]])
            .unwrap_or_default();
        assert!((s[0] - 3.0).abs() < 1e-12 && (s[1] - 0.5).abs() < 1e-12, "{s:?}");
        // a rotated and stretched K, against (2 K^T K)^-1 inverted in closed form
        let (c, sn, a, b) = (0.6f64, 0.8f64, 2.0f64, 0.25f64);
        let k = vec![vec![a * c, -a * sn], vec![b * sn, b * c]];
        let ktk = [
            [k[0][0] * k[0][0] + k[1][0] * k[1][0], k[0][0] * k[0][1] + k[1][0] * k[1][1]],
            [k[0][1] * k[0][0] + k[1][1] * k[1][0], k[0][1] * k[0][1] + k[1][1] * k[1][1]],
        ];
        let det = 2.0 * 2.0 * (ktk[0][0] * ktk[1][1] - ktk[0][1] * ktk[1][0]);
        let sigma = [2.0 * ktk[1][1] / det, 2.0 * ktk[0][0] / det];
        let s = marginal_sigmas(&k).unwrap_or_default();
        assert!((s[0] - sigma[0].sqrt()).abs() < 1e-12 && (s[1] - sigma[1].sqrt()).abs() < 1e-12, "{s:?}");
        assert!(marginal_sigmas(&[vec![1.0, 2.0], vec![2.0, 4.0]]).is_none());
    }
}
