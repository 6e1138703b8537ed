//! Concentric erf boundaries: the erf sphere and the nested shells.

use crate::{grid_centre, voxel_position};
use mdtf_volume::{Field, Geometry, MultiField, Volume};
use ndarray::{Array3, Zip};
use std::f64::consts::{PI, SQRT_2};

/// One spherical boundary: inside `radius` the value steps to `inside`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Boundary {
    /// Radius in world units.
    pub radius: f64,
    /// Value of the material inside this boundary (and outside the next one in).
    pub inside: f64,
}

/// Concentric erf-blurred boundaries around `centre`, each blurred by a
/// Gaussian of standard deviation `sigma` (world units).
#[derive(Debug, Clone, PartialEq)]
pub struct RadialPhantom {
    /// The sampling grid.
    pub geometry: Geometry,
    /// Centre in world coordinates.
    pub centre: [f64; 3],
    /// Blur of every boundary, world units.
    pub sigma: f64,
    /// Value far outside every boundary.
    pub outside: f64,
    /// Boundaries, outermost first (radii strictly decreasing).
    pub boundaries: Vec<Boundary>,
}

/// Analytic values at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointTruth {
    /// Value v.
    pub v: f64,
    /// Gradient magnitude g = |grad v|, per world unit.
    pub g: f64,
    /// Second derivative along the gradient, f'' = n^T H n.
    pub f2: f64,
    /// Signed distance to the nearest boundary, positive on its high-value side.
    pub x: f64,
    /// Unit gradient direction (towards higher v); 0 where g is 0.
    pub normal: [f64; 3],
}

/// The analytic fields on every voxel.
#[derive(Debug, Clone)]
pub struct RadialTruth {
    /// Value (noise-free).
    pub v: Volume,
    /// Gradient magnitude.
    pub g: Volume,
    /// Second directional derivative along the gradient.
    pub f2: Volume,
    /// Signed distance to the nearest boundary (positive on its high side).
    pub x: Volume,
    /// Unit normal, fields nx, ny, nz.
    pub normal: MultiField,
    /// Kindlmann-Durkin boundary position p = -sigma^2 f'' / g, equal to x.
    pub p: Volume,
}

/// Unit Gaussian density of standard deviation `sigma` at `x`.
fn gauss(x: f64, sigma: f64) -> f64 {
    (-x * x / (2.0 * sigma * sigma)).exp() / (sigma * (2.0 * PI).sqrt())
}

/// The erf sphere of DESIGN.md: radius and sigma in world units, centre at
/// the grid centre unless given.
pub fn erf_sphere(
    geometry: Geometry,
    radius: f64,
    sigma: f64,
    v_min: f64,
    v_max: f64,
    centre: Option<[f64; 3]>,
) -> RadialPhantom {
    let centre = centre.unwrap_or_else(|| grid_centre(&geometry));
    RadialPhantom { geometry, centre, sigma, outside: v_min, boundaries: vec![Boundary { radius, inside: v_max }] }
}

impl RadialPhantom {
    /// Three nested materials like a tooth seen in CT: enamel outside (high),
    /// dentin (middle), pulp (low) in a background, so that the boundary
    /// arches overlap in the (v, g) histogram. Radii are 0.40, 0.33 and 0.16
    /// of the smallest grid extent.
    pub fn tooth(geometry: Geometry, sigma: f64) -> RadialPhantom {
        let e = crate::min_extent(&geometry);
        let centre = grid_centre(&geometry);
        RadialPhantom {
            geometry,
            centre,
            sigma,
            outside: 20.0,
            boundaries: vec![
                Boundary { radius: 0.40 * e, inside: 230.0 },
                Boundary { radius: 0.33 * e, inside: 140.0 },
                Boundary { radius: 0.16 * e, inside: 60.0 },
            ],
        }
    }

    /// Analytic value and derivatives at world position `p`.
    pub fn at(&self, p: [f64; 3]) -> PointTruth {
        let d = [p[0] - self.centre[0], p[1] - self.centre[1], p[2] - self.centre[2]];
        let rho = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let s = self.sigma;
        let mut v = self.outside;
        let mut dv = 0.0; // dv/drho
        let mut d2v = 0.0; // d2v/drho2
        let mut outer = self.outside;
        let mut nearest = (f64::INFINITY, 0.0);
        for b in &self.boundaries {
            let step = b.inside - outer; // jump crossing inward
            let x = b.radius - rho;
            v += step * 0.5 * (1.0 + libm::erf(x / (s * SQRT_2)));
            let gx = gauss(x, s);
            dv -= step * gx;
            d2v -= step * x / (s * s) * gx;
            if x.abs() < nearest.0.abs() || nearest.0.is_infinite() {
                nearest = (x, step.signum());
            }
            outer = b.inside;
        }
        let g = dv.abs();
        // Radial gradient dv/drho * rho_hat; its direction points to higher v.
        let normal = if g > 0.0 && rho > 0.0 { d.map(|c| c / rho * dv.signum()) } else { [0.0; 3] };
        PointTruth { v, g, f2: d2v, x: nearest.0 * nearest.1, normal }
    }

    /// The noise-free volume.
    pub fn volume(&self) -> Volume {
        let data = self.sample(|t| t.v);
        Volume { geometry: self.geometry.clone(), data }
    }

    fn sample(&self, f: impl Fn(&PointTruth) -> f64 + Sync) -> Array3<f32> {
        let g = &self.geometry;
        let mut out = Array3::<f32>::zeros(g.shape());
        Zip::indexed(&mut out).par_for_each(|(k, j, i), o| {
            *o = f(&self.at(voxel_position(g, i, j, k))) as f32;
        });
        out
    }

    /// The analytic fields on every voxel.
    pub fn truth(&self) -> RadialTruth {
        let vol = |data| Volume { geometry: self.geometry.clone(), data };
        let normal =
            (0..3).map(|c| Field { name: ["nx", "ny", "nz"][c].into(), data: self.sample(|t| t.normal[c]) }).collect();
        RadialTruth {
            v: vol(self.sample(|t| t.v)),
            g: vol(self.sample(|t| t.g)),
            f2: vol(self.sample(|t| t.f2)),
            x: vol(self.sample(|t| t.x)),
            normal: MultiField { geometry: self.geometry.clone(), fields: normal },
            p: vol(self.sample(|t| if t.g > 0.0 { -self.sigma * self.sigma * t.f2 / t.g } else { 0.0 })),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent evaluation of DESIGN.md's closed forms for the erf sphere.
    fn design_formulas(x: f64, sigma: f64, vmin: f64, vmax: f64) -> (f64, f64, f64) {
        let a = (vmax - vmin) / (sigma * (2.0 * PI).sqrt());
        let v = vmin + (vmax - vmin) * (1.0 + libm::erf(x / (sigma * SQRT_2))) / 2.0;
        let g = a * (-x * x / (2.0 * sigma * sigma)).exp();
        (v, g, -x * g / (sigma * sigma))
    }

    #[test]
    fn erf_sphere_matches_the_closed_forms_with_the_right_signs() {
        let geo = Geometry::new([64, 64, 64], [0.5, 0.5, 2.0]);
        let ph = erf_sphere(geo.clone(), 9.0, 1.5, 0.0, 255.0, None);
        let c = crate::grid_centre(&geo);
        for &(dx, dy, dz) in &[(1.0, 0.0, 0.0), (0.0, 8.0, 0.0), (6.0, 6.0, 3.0), (0.0, 0.0, 11.0), (-3.0, 9.5, 0.1)] {
            let p = [c[0] + dx, c[1] + dy, c[2] + dz];
            let rho: f64 = (dx * dx + dy * dy + dz * dz).sqrt();
            let x = 9.0 - rho;
            let t = ph.at(p);
            let (v, g, f2) = design_formulas(x, 1.5, 0.0, 255.0);
            assert!((t.v - v).abs() < 1e-9 && (t.g - g).abs() < 1e-9 && (t.f2 - f2).abs() < 1e-9);
            assert!((t.x - x).abs() < 1e-12);
            // f'' < 0 inside (high side), > 0 outside; normal points to the centre.
            assert_eq!(t.f2 < 0.0, x > 0.0);
            let dot = (t.normal[0] * dx + t.normal[1] * dy + t.normal[2] * dz) / rho;
            assert!((dot + 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn derivatives_match_finite_differences_of_the_value() {
        let geo = Geometry::new([32, 32, 32], [1.0; 3]);
        let ph = RadialPhantom::tooth(geo, 1.2);
        let c = ph.centre;
        let h = 1e-4;
        for rho in [3.0, 5.1, 10.2, 10.9, 12.6, 13.0, 15.0] {
            let dir = [0.6, 0.0, 0.8];
            let at = |r: f64| ph.at([c[0] + r * dir[0], c[1] + r * dir[1], c[2] + r * dir[2]]).v;
            let d1 = (at(rho + h) - at(rho - h)) / (2.0 * h);
            let d2 = (at(rho + h) - 2.0 * at(rho) + at(rho - h)) / (h * h);
            let t = ph.at([c[0] + rho * dir[0], c[1] + rho * dir[1], c[2] + rho * dir[2]]);
            assert!((t.g - d1.abs()).abs() < 1e-5 * (1.0 + t.g), "g at {rho}");
            assert!((t.f2 - d2).abs() < 1e-3 * (1.0 + t.f2.abs()), "f2 at {rho}: {} vs {d2}", t.f2);
        }
    }

    #[test]
    fn position_function_equals_signed_distance_near_a_single_boundary() {
        let ph = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 15.0, 3.0, 0.0, 255.0, None);
        let t = ph.truth();
        let (p, x) = (t.p.data, t.x.data);
        let worst =
            p.iter().zip(x.iter()).filter(|(_, x)| x.abs() < 6.0).map(|(p, x)| (p - x).abs()).fold(0.0, f32::max);
        assert!(worst < 1e-4, "{worst}");
    }

    #[test]
    fn shells_signed_distance_is_positive_on_the_high_side_of_each_boundary() {
        let ph = RadialPhantom::tooth(Geometry::new([100; 3], [1.0; 3]), 2.0);
        let c = ph.centre;
        // just inside enamel (230 inside, 20 outside): high side is inside
        assert!(ph.at([c[0] + 39.0, c[1], c[2]]).x > 0.0);
        // just inside dentin (140 inside, 230 outside): high side is outside
        assert!(ph.at([c[0] + 32.0, c[1], c[2]]).x < 0.0);
        assert!((ph.at([c[0] + 32.0, c[1], c[2]]).x + 1.0).abs() < 1e-9);
    }
}
