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
//!
//! Triangular GTF (section 3.2, Table 3): the width grows with the gradient
//! magnitude, sigma = sigma' g, so the density is
//! rho(v, g) = exp(-||K (v - c)||^2 / g^2), and 0 where g = 0. Here g is
//! |grad v| for scalar data. For multi-field data the paper puts the norm
//! of D^T D (rows of D: the fields' gradients) in its place; that is a
//! squared gradient (g^2 for one field), so mdtf uses its square root,
//! sqrt(gnorm) of the pack's `gnorm` channel, and a one-field stack gets
//! the scalar TGTF. With K = 1 / sigma' in 1 / world
//! units on scalar data, a voxel is selected when it lies within about sigma'
//! world units of the isosurface v = c. Along a segment the paper
//! (section 5.2.1) integrates with the mean gradient magnitude
//! g-hat = (g1 + g2) / 2 of its endpoints: v'_j = K (v_j - c) / g-hat in
//! eq. 11.
//!
//! The tables a GPU renderer reads instead of evaluating erf
//! ([`igauss_table`], [`erf_difference_table`]) are built here too.

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
    /// A triangular GTF: the width scales with the gradient channel (the
    /// coordinate after the m fields).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub triangular: bool,
}

/// Fields up to which an evaluation keeps its coordinates on the stack (the
/// renderers evaluate every primitive at every sample; no allocation there).
const STACK_FIELDS: usize = 8;

/// Squared distance (in K's units) beyond which a segment's line adds
/// nothing: the integral is below sqrt(pi) exp(-64) / 1e-4, under 3e-24
/// (renderers evaluate every primitive at every sample, most far away).
const FAR_SQUARED: f64 = 64.0;

/// `f` given two zeroed scratch slices of length `m`, on the stack where `m` allows.
fn with_scratch<R>(m: usize, f: impl FnOnce(&mut [f64], &mut [f64]) -> R) -> R {
    if m <= STACK_FIELDS {
        let (mut a, mut b) = ([0.0; STACK_FIELDS], [0.0; STACK_FIELDS]);
        f(&mut a[..m], &mut b[..m])
    } else {
        f(&mut vec![0.0; m], &mut vec![0.0; m])
    }
}

impl GaussianPrimitive {
    /// K (v - c) into `out` (one entry per row of K).
    fn transform(&self, v: &[f64], out: &mut [f64]) {
        for (o, row) in out.iter_mut().zip(&self.k) {
            *o = row.iter().zip(v.iter().zip(&self.centre)).map(|(k, (x, c))| k * (x - c)).sum();
        }
    }

    /// The dimension m of the primitive's fields (a triangular one reads one more coordinate, g).
    pub fn fields(&self) -> usize {
        self.centre.len()
    }

    /// The gradient coordinate of a triangular primitive at `v` (m fields, then g).
    fn gradient(&self, v: &[f64]) -> f64 {
        v.get(self.centre.len()).copied().unwrap_or(0.0)
    }

    /// The density, in [0, 1]: exp(-||K (v - c)||^2); for a triangular
    /// primitive exp(-||K (v - c)||^2 / g^2) with g = v[m] (0 where g <= 0).
    pub fn density(&self, v: &[f64]) -> f64 {
        with_scratch(self.k.len(), |t, _| {
            self.transform(v, t);
            if self.triangular {
                let g = self.gradient(v);
                if g <= 0.0 {
                    return 0.0;
                }
                t.iter_mut().for_each(|x| *x /= g);
            }
            (-t.iter().map(|x| x * x).sum::<f64>()).exp()
        })
    }

    /// A lower bound of the density's exponent, ||K (v - c)||^2 (over g^2 for
    /// a triangular primitive), anywhere in the box of coordinates
    /// `lo[i]..=hi[i]` (the m fields, then g for a triangular one), by
    /// interval arithmetic on each row of K. The density is at most
    /// exp(-bound) in the box, and so is the segment integral between two
    /// points of it (the box is convex). +inf where a triangular primitive's
    /// g is not positive in the whole box (its density is 0 there).
    pub fn exponent_lower_bound(&self, lo: &[f64], hi: &[f64]) -> f64 {
        let mut bound = 0.0;
        for row in &self.k {
            // the interval of K_i . (v - c) over the box
            let (mut a, mut b) = (0.0, 0.0);
            for ((k, c), (l, h)) in row.iter().zip(&self.centre).zip(lo.iter().zip(hi)) {
                let (x, y) = (k * (l - c), k * (h - c));
                a += x.min(y);
                b += x.max(y);
            }
            let nearest = if a > 0.0 {
                a
            } else if b < 0.0 {
                -b
            } else {
                0.0
            };
            bound += nearest * nearest;
        }
        if self.triangular {
            let m = self.centre.len();
            let g_high = hi.get(m).copied().unwrap_or(0.0);
            if g_high <= 0.0 {
                return f64::INFINITY;
            }
            bound /= g_high * g_high;
        }
        if bound.is_nan() { 0.0 } else { bound }
    }

    /// The mean density over the segment from v1 to v2 with linearly varying
    /// data, integral of rho(v1 + t (v2 - v1)) over t in [0, 1] (eq. 11; eq. 14 in the limit).
    /// For a triangular primitive g is held at the endpoints' mean (section
    /// 5.2.1); 0 when that mean is not positive.
    pub fn segment_integral(&self, v1: &[f64], v2: &[f64]) -> f64 {
        with_scratch(self.k.len(), |p1, d| {
            self.transform(v1, p1);
            self.transform(v2, d);
            if self.triangular {
                let g_hat = 0.5 * (self.gradient(v1) + self.gradient(v2));
                if g_hat <= 0.0 {
                    return 0.0;
                }
                p1.iter_mut().chain(d.iter_mut()).for_each(|x| *x /= g_hat);
            }
            // d = p2 - p1, in place of p2
            d.iter_mut().zip(p1.iter()).for_each(|(b, a)| *b -= a);
            let dn = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            if dn < 1e-4 {
                return (-p1.iter().zip(d.iter()).map(|(a, x)| (a + 0.5 * x).powi(2)).sum::<f64>()).exp();
            }
            let a = d.iter().zip(p1.iter()).map(|(x, y)| x * y).sum::<f64>() / dn;
            let b = a + dn;
            // the squared distance of the segment's line from the centre, summed
            // directly: |p1|^2 - a^2 cancels to garbage (even to +inf under exp)
            // when g_hat is tiny and the coordinates huge
            let perp2: f64 = p1.iter().zip(d.iter()).map(|(p, x)| (p - a * x / dn).powi(2)).sum();
            if perp2 > FAR_SQUARED {
                // the line passes far from the centre: nothing to integrate (and no erf to evaluate)
                return 0.0;
            }
            let s = (-perp2).exp();
            let diff = erf_difference(b, a);
            std::f64::consts::PI.sqrt() / 2.0 * s / dn * diff
        })
    }
}

/// Why a Gaussian cannot be fitted to a probed region.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer than m + 1 samples under the mask.
    #[error("the mask selects {0} voxels; a Gaussian over {1} fields needs at least {2}")]
    TooFew(usize, usize, usize),
    /// The samples' covariance is singular (a field is constant under the mask).
    #[error(
        "the probed voxels' covariance is singular (a field is constant in the region, or two fields are proportional)"
    )]
    Singular,
}

impl GaussianPrimitive {
    /// The GTF of a probed region (the paper's section 6): centre the mean of
    /// the samples, K with K^T K = (2 Sigma)^-1 for their covariance Sigma,
    /// so that rho = exp(-(v - c)^T Sigma^-1 (v - c) / 2), the samples' own
    /// normal density scaled to peak 1. `fields` holds each field's samples;
    /// those with `selected` true are used. K is the inverse of the Cholesky
    /// factor of 2 Sigma (lower triangular).
    pub fn fit(
        fields: &[&[f32]],
        selected: impl Fn(usize) -> bool,
        alpha_max: f64,
        colour: [f64; 3],
    ) -> Result<GaussianPrimitive, FitError> {
        Self::fit_with_floor(fields, selected, alpha_max, colour, &vec![0.0; fields.len()])
    }

    /// [`GaussianPrimitive::fit`] with `floor[a]` (field a's units squared)
    /// added to each field's variance: the variance a measurement of
    /// limited resolution cannot go below (a field constant in the region
    /// then gets that width instead of a singular covariance).
    pub fn fit_with_floor(
        fields: &[&[f32]],
        selected: impl Fn(usize) -> bool,
        alpha_max: f64,
        colour: [f64; 3],
        floor: &[f64],
    ) -> Result<GaussianPrimitive, FitError> {
        let m = fields.len();
        let n_all = fields.first().map_or(0, |f| f.len());
        let (mut n, mut sum) = (0usize, vec![0.0f64; m]);
        for i in (0..n_all).filter(|&i| selected(i)) {
            n += 1;
            for (s, f) in sum.iter_mut().zip(fields) {
                *s += f[i] as f64;
            }
        }
        if n < m + 1 {
            return Err(FitError::TooFew(n, m, m + 1));
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / n as f64).collect();
        let mut cov = vec![vec![0.0f64; m]; m];
        for i in (0..n_all).filter(|&i| selected(i)) {
            let d: Vec<f64> = (0..m).map(|a| fields[a][i] as f64 - mean[a]).collect();
            for a in 0..m {
                for b in 0..=a {
                    cov[a][b] += d[a] * d[b];
                }
            }
        }
        // 2 Sigma = L L^T; K = L^-1
        let mut l = vec![vec![0.0f64; m]; m];
        for a in 0..m {
            for b in 0..=a {
                let floored = if a == b { floor.get(a).copied().unwrap_or(0.0) } else { 0.0 };
                let two_sigma = 2.0 * (cov[a][b] / (n - 1) as f64 + floored);
                let s = two_sigma - (0..b).map(|k| l[a][k] * l[b][k]).sum::<f64>();
                if a == b {
                    // what is left of the variance once the other fields explain it
                    if s.is_nan() || s <= 1e-12 * two_sigma || s <= 0.0 {
                        return Err(FitError::Singular);
                    }
                    l[a][a] = s.sqrt();
                } else {
                    l[a][b] = s / l[b][b];
                }
            }
        }
        let mut k = vec![vec![0.0f64; m]; m];
        for col in 0..m {
            // forward substitution of L x = e_col
            for row in 0..m {
                let e = if row == col { 1.0 } else { 0.0 };
                let s = e - (0..row).map(|j| l[row][j] * k[j][col]).sum::<f64>();
                k[row][col] = s / l[row][row];
            }
        }
        Ok(GaussianPrimitive { centre: mean, k, alpha_max, colour, triangular: false })
    }
}

/// IGauss(x1, x2), eq. 16: sqrt(pi) / 2 (erf(x1) - erf(x2)) / (x1 - x2), the
/// mean of exp(-x^2) over [x2, x1]; exp(-x1^2) where x1 = x2 (and, for
/// |x1 - x2| < 1e-4, at the midpoint, where the erf difference cancels).
pub fn igauss(x1: f64, x2: f64) -> f64 {
    if (x1 - x2).abs() < 1e-4 {
        let m = 0.5 * (x1 + x2);
        return (-m * m).exp();
    }
    std::f64::consts::PI.sqrt() / 2.0 * erf_difference(x1, x2) / (x1 - x2)
}

/// erf(x) - erf(y), through erfc in the tails where the plain difference loses precision.
pub fn erf_difference(x: f64, y: f64) -> f64 {
    if x > 3.0 && y > 3.0 {
        libm::erfc(y) - libm::erfc(x)
    } else if x < -3.0 && y < -3.0 {
        libm::erfc(-x) - libm::erfc(-y)
    } else {
        libm::erf(x) - libm::erf(y)
    }
}

/// Domain of the IGauss table on both axes (section 5.2.1).
pub const IGAUSS_DOMAIN: [f64; 2] = [-10.0, 10.0];
/// Cells of the IGauss table per axis (the paper's 128).
pub const IGAUSS_SIZE: usize = 128;
/// Domain of the erf-difference table on both axes (section 5.2.2); a
/// renderer clamps its coordinates to it, erf being +-1 to 2e-7 beyond.
pub const ERF_DOMAIN: [f64; 2] = [-3.6, 3.6];
/// Cells of the erf-difference table per axis.
pub const ERF_SIZE: usize = 256;

/// A square table of `f` at the cell centres of `size` cells over `domain`
/// on both axes, first axis fastest.
fn square_table(size: usize, domain: [f64; 2], f: impl Fn(f64, f64) -> f64) -> Vec<f32> {
    let w = (domain[1] - domain[0]) / size as f64;
    let centre = |i: usize| domain[0] + (i as f64 + 0.5) * w;
    (0..size).flat_map(|j| (0..size).map(move |i| (i, j))).map(|(i, j)| f(centre(i), centre(j)) as f32).collect()
}

/// [`igauss`] at the cell centres of a [`IGAUSS_SIZE`]^2 table over [`IGAUSS_DOMAIN`]^2 (x1 fastest).
pub fn igauss_table() -> Vec<f32> {
    square_table(IGAUSS_SIZE, IGAUSS_DOMAIN, igauss)
}

/// erf(x) - erf(y) at the cell centres of an [`ERF_SIZE`]^2 table over [`ERF_DOMAIN`]^2 (x fastest).
pub fn erf_difference_table() -> Vec<f32> {
    square_table(ERF_SIZE, ERF_DOMAIN, erf_difference)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exponent_bound_holds_at_every_point_of_a_box_and_is_reached_at_its_nearest() {
        let full = GaussianPrimitive {
            centre: vec![100.0, 40.0],
            k: vec![vec![0.05, 0.02], vec![-0.01, 0.08]],
            alpha_max: 2.0,
            colour: [1.0, 0.5, 0.0],
            triangular: false,
        };
        let tri = GaussianPrimitive { k: vec![vec![0.5]], centre: vec![100.0], triangular: true, ..full.clone() };
        let mut state = 9u64;
        let mut uniform = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            let (lo, hi): (Vec<f64>, Vec<f64>) = (0..3)
                .map(|_| {
                    let (a, b) = (uniform() * 300.0 - 50.0, uniform() * 300.0 - 50.0);
                    (a.min(b), a.max(b))
                })
                .unzip();
            for gp in [&full, &tri] {
                let bound = gp.exponent_lower_bound(&lo, &hi);
                // brute force: the density at points of the box never exceeds exp(-bound)
                for _ in 0..50 {
                    let v: Vec<f64> = (0..3).map(|k| lo[k] + uniform() * (hi[k] - lo[k])).collect();
                    let most = (-bound).exp();
                    assert!(gp.density(&v) <= most * (1.0 + 1e-12) + 1e-300, "{lo:?} {hi:?} {v:?}");
                }
            }
        }
        // a box around the centre bounds nothing; a point box is exact
        assert_eq!(full.exponent_lower_bound(&[90.0, 30.0], &[110.0, 50.0]), 0.0);
        let at = [130.0, 10.0];
        let exact = -full.density(&at).ln();
        assert!((full.exponent_lower_bound(&at, &at) - exact).abs() < 1e-9 * exact);
        assert_eq!(tri.exponent_lower_bound(&[0.0, -5.0], &[200.0, 0.0]), f64::INFINITY);
    }

    fn simpson(f: impl Fn(f64) -> f64, n: usize) -> f64 {
        let h = 1.0 / n as f64;
        let mut s = f(0.0) + f(1.0);
        for i in 1..n {
            s += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    }

    /// Uniform numbers in [0, 1) from a fixed LCG seeded with `seed`.
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn analytic_segment_integral_matches_quadrature_for_random_primitives() {
        let mut rnd = uniform(7);
        let mut worst = 0.0f64;
        for case in 0..500 {
            let m = 1 + case % 3;
            let centre: Vec<f64> = (0..m).map(|_| rnd() * 2.0 - 0.5).collect();
            let k: Vec<Vec<f64>> = (0..m).map(|_| (0..m).map(|_| rnd() * 8.0 - 2.0).collect()).collect();
            let g = GaussianPrimitive { centre, k, alpha_max: 1.0, colour: [1.0; 3], triangular: false };
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

    /// The triangular GTF with g-hat held at the endpoints' mean: the
    /// analytic segment integral against Simpson quadrature of
    /// exp(-||K (v(t) - c)||^2 / g-hat^2), written out here.
    #[test]
    fn triangular_segment_integral_matches_quadrature_with_the_mean_gradient() {
        let mut rnd = uniform(3);
        let mut worst = 0.0f64;
        for case in 0..500 {
            let m = 1 + case % 3;
            let centre: Vec<f64> = (0..m).map(|_| rnd() * 200.0).collect();
            let k: Vec<Vec<f64>> = (0..m)
                .map(|r| (0..m).map(|c| if r == c { 0.2 + rnd() * 3.0 } else { rnd() - 0.5 }).collect())
                .collect();
            let p = GaussianPrimitive {
                centre: centre.clone(),
                k: k.clone(),
                alpha_max: 1.0,
                colour: [1.0; 3],
                triangular: true,
            };
            let point = |rnd: &mut dyn FnMut() -> f64| -> Vec<f64> {
                let mut v: Vec<f64> = centre.iter().map(|c| c + (rnd() - 0.5) * 40.0).collect();
                v.push(1.0 + rnd() * 30.0);
                v
            };
            let v1 = point(&mut rnd);
            let v2 = if case % 10 == 0 { v1.clone() } else { point(&mut rnd) };
            let g_hat = 0.5 * (v1[m] + v2[m]);
            let rho = |t: f64| {
                let x: Vec<f64> = (0..m).map(|i| v1[i] + t * (v2[i] - v1[i]) - centre[i]).collect();
                let e: f64 = k.iter().map(|row| row.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>().powi(2)).sum();
                (-e / (g_hat * g_hat)).exp()
            };
            let quad = simpson(rho, 4000);
            worst = worst.max((p.segment_integral(&v1, &v2) - quad).abs());
        }
        assert!(worst < 1e-5, "{worst:e}");
        // at a point: exp(-(K (v - c) / g)^2), and 0 without a gradient
        let p = GaussianPrimitive {
            centre: vec![100.0],
            k: vec![vec![0.5]],
            alpha_max: 1.0,
            colour: [1.0; 3],
            triangular: true,
        };
        assert!((p.density(&[104.0, 4.0]) - (-0.25f64).exp()).abs() < 1e-15);
        assert_eq!(p.density(&[100.0, 0.0]), 0.0);
        assert_eq!(p.segment_integral(&[100.0, 0.0], &[101.0, 0.0]), 0.0);
        // a near-zero gradient (a mesh's flat background) puts the segment ~1e32
        // from the centre: the density there is 0, not NaN
        let far = p.segment_integral(&[255.0, 1e-30], &[254.0, 3e-30]);
        assert_eq!(far, 0.0, "far from the centre with g ~ 1e-30");
        // and a segment crossing the centre with a tiny g still integrates to ~ sqrt(pi)/2 g / (K |dv|)
        let g = 1e-3;
        let across = p.segment_integral(&[90.0, g], &[110.0, g]);
        let expected = std::f64::consts::PI.sqrt() * g / (0.5 * 20.0);
        assert!((across - expected).abs() < 1e-9 * expected.max(1e-12) + 1e-15, "{across:e} vs {expected:e}");
    }

    #[test]
    fn a_fitted_gaussian_is_the_samples_normal_density_scaled_to_one() {
        // correlated samples on a lattice: x, y = 0.5 x + z
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        for i in 0..40 {
            for j in 0..30 {
                let (x, z) = (i as f32 * 0.5, j as f32 * 0.2);
                xs.push(10.0 + x);
                ys.push(3.0 + 0.5 * x + z);
            }
        }
        // one sample outside the mask, far away
        xs.push(1e4);
        ys.push(-1e4);
        let last = xs.len() - 1;
        let p = GaussianPrimitive::fit(&[&xs, &ys], |i| i != last, 1.0, [1.0; 3]).unwrap();
        // brute force: mean, covariance, and the quadratic form through the inverse covariance
        let n = last as f64;
        let mx = xs[..last].iter().map(|&v| v as f64).sum::<f64>() / n;
        let my = ys[..last].iter().map(|&v| v as f64).sum::<f64>() / n;
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for i in 0..last {
            let (dx, dy) = (xs[i] as f64 - mx, ys[i] as f64 - my);
            sxx += dx * dx;
            sxy += dx * dy;
            syy += dy * dy;
        }
        let (sxx, sxy, syy) = (sxx / (n - 1.0), sxy / (n - 1.0), syy / (n - 1.0));
        let det = sxx * syy - sxy * sxy;
        assert!((p.centre[0] - mx).abs() < 1e-9 && (p.centre[1] - my).abs() < 1e-9);
        for &(x, y) in &[(12.0, 5.0), (20.0, 8.0), (mx, my), (25.0, 4.0)] {
            let (dx, dy) = (x - mx, y - my);
            let q = (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det;
            let want = (-q / 2.0).exp();
            assert!((p.density(&[x, y]) - want).abs() < 1e-9, "({x}, {y}): {} vs {want}", p.density(&[x, y]));
        }
        assert_eq!(GaussianPrimitive::fit(&[&xs], |i| i < 1, 1.0, [1.0; 3]), Err(FitError::TooFew(1, 1, 2)));
        let flat = vec![5.0f32; 100];
        assert_eq!(GaussianPrimitive::fit(&[&xs[..100], &flat], |_| true, 1.0, [1.0; 3]), Err(FitError::Singular));
    }

    #[test]
    fn igauss_is_the_mean_of_exp_minus_x_squared_over_the_interval() {
        for &(a, b) in &[(-10.0, 10.0), (0.3, -2.0), (4.0, 4.00001), (-9.7, -3.1), (2.0, 2.0), (5.5, 9.0)] {
            let quad = simpson(|t| (-(b + t * (a - b)) * (b + t * (a - b))).exp(), 20000);
            assert!((igauss(a, b) - quad).abs() < 1e-9, "({a}, {b}): {} vs {quad}", igauss(a, b));
        }
        let t = igauss_table();
        assert_eq!(t.len(), IGAUSS_SIZE * IGAUSS_SIZE);
        // cell (i, j) is at x1 = -10 + (i + 0.5) 20 / 128, x2 likewise
        let c = |i: usize| -10.0 + (i as f64 + 0.5) * 20.0 / 128.0;
        assert!((t[5 * 128 + 70] as f64 - igauss(c(70), c(5))).abs() < 1e-7);
        let e = erf_difference_table();
        let c = |i: usize| -3.6 + (i as f64 + 0.5) * 7.2 / 256.0;
        assert!((e[200 * 256 + 3] as f64 - (libm::erf(c(3)) - libm::erf(c(200)))).abs() < 1e-7);
    }
}
