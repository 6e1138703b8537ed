//! Three overlapping erf spheres as a multi-field volume, with the analytic
//! Jacobian of the range-normalised fields and ||G|| = ||Df^T Df||_F.

use crate::radial::{RadialPhantom, erf_sphere};
use crate::{grid_centre, min_extent, voxel_position};
use mdtf_volume::{Field, Geometry, MultiField, Volume};
use ndarray::{Array3, Zip};

/// One field of the phantom: an erf sphere.
#[derive(Debug, Clone, PartialEq)]
pub struct SphereField {
    /// Field name.
    pub name: String,
    /// The sphere (one boundary).
    pub sphere: RadialPhantom,
}

/// Three erf spheres with their own centres, radii and value ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct MultiFieldPhantom {
    /// The sampling grid.
    pub geometry: Geometry,
    /// The fields.
    pub fields: Vec<SphereField>,
}

/// Analytic truth of the normalised fields.
#[derive(Debug, Clone)]
pub struct MultiFieldTruth {
    /// Jacobian Df of the normalised fields, m x 3 entries per voxel, named
    /// "d{field}/d{x,y,z}", per world unit.
    pub jacobian: MultiField,
    /// Frobenius norm of G = Df^T Df, per world unit squared.
    pub gnorm: Volume,
}

impl MultiFieldPhantom {
    /// The default phantom: spheres of radius 0.25, 0.22 and 0.28 of the
    /// smallest extent, centres shifted by 0.08 of it along x, y and -z, value
    /// ranges 0..100, 10..50 and 200..0 (the last one darker inside), blur `sigma`.
    pub fn new(geometry: Geometry, sigma: f64) -> MultiFieldPhantom {
        let e = min_extent(&geometry);
        let c = grid_centre(&geometry);
        let shift = 0.08 * e;
        let specs = [
            ("a", [shift, 0.0, 0.0], 0.25, 0.0, 100.0),
            ("b", [0.0, shift, 0.0], 0.22, 10.0, 50.0),
            ("c", [0.0, 0.0, -shift], 0.28, 200.0, 0.0),
        ];
        let fields = specs
            .iter()
            .map(|&(name, d, r, vmin, vmax)| SphereField {
                name: name.into(),
                sphere: erf_sphere(
                    geometry.clone(),
                    r * e,
                    sigma,
                    vmin,
                    vmax,
                    Some([c[0] + d[0], c[1] + d[1], c[2] + d[2]]),
                ),
            })
            .collect();
        MultiFieldPhantom { geometry, fields }
    }

    /// The sampled fields (not normalised).
    pub fn volume(&self) -> MultiField {
        let fields = self.fields.iter().map(|f| Field { name: f.name.clone(), data: f.sphere.volume().data }).collect();
        MultiField { geometry: self.geometry.clone(), fields }
    }

    /// Truth for the fields normalised to [0, 1] over the ranges of `sampled`
    /// (the observed min and max of each field, as the derive stage uses).
    pub fn truth(&self, sampled: &MultiField) -> MultiFieldTruth {
        let ranges: Vec<f64> = sampled
            .fields
            .iter()
            .map(|f| {
                let (lo, hi) =
                    f.data.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
                ((hi - lo) as f64).max(f64::MIN_POSITIVE)
            })
            .collect();
        let g = &self.geometry;
        let m = self.fields.len();
        // Normalised gradient of field f at p.
        let grad = |f: usize, p: [f64; 3]| {
            let t = self.fields[f].sphere.at(p);
            t.normal.map(|n| n * t.g / ranges[f])
        };
        let mut jac = Vec::with_capacity(3 * m);
        for f in 0..m {
            for a in 0..3 {
                let mut data = Array3::<f32>::zeros(g.shape());
                Zip::indexed(&mut data).par_for_each(|(k, j, i), o| *o = grad(f, voxel_position(g, i, j, k))[a] as f32);
                jac.push(Field { name: format!("d{}/d{}", self.fields[f].name, ["x", "y", "z"][a]), data });
            }
        }
        let mut gnorm = Array3::<f32>::zeros(g.shape());
        Zip::indexed(&mut gnorm).par_for_each(|(k, j, i), o| {
            let p = voxel_position(g, i, j, k);
            let grads: Vec<[f64; 3]> = (0..m).map(|f| grad(f, p)).collect();
            let mut sum = 0.0;
            for r in 0..3 {
                for c in 0..3 {
                    let gij: f64 = grads.iter().map(|d| d[r] * d[c]).sum();
                    sum += gij * gij;
                }
            }
            *o = sum.sqrt() as f32;
        });
        MultiFieldTruth {
            jacobian: MultiField { geometry: g.clone(), fields: jac },
            gnorm: Volume { geometry: g.clone(), data: gnorm },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gnorm_matches_finite_differences_of_the_normalised_values() {
        let geo = Geometry::new([40, 40, 40], [1.0, 1.0, 1.5]);
        let ph = MultiFieldPhantom::new(geo.clone(), 1.5);
        let mf = ph.volume();
        let t = ph.truth(&mf);
        let ranges: Vec<f64> = mf
            .fields
            .iter()
            .map(|f| {
                let (lo, hi) = f.data.iter().fold((f32::MAX, f32::MIN), |(l, h), &v| (l.min(v), h.max(v)));
                (hi - lo) as f64
            })
            .collect();
        let h = 1e-4;
        let mut checked = 0;
        for (k, j, i) in [(20, 20, 30), (20, 29, 20), (14, 20, 20), (25, 12, 28), (20, 20, 20), (10, 30, 12)] {
            let p = voxel_position(&geo, i, j, k);
            let grads: Vec<[f64; 3]> = (0..3)
                .map(|f| {
                    [0, 1, 2].map(|a| {
                        let mut hi = p;
                        let mut lo = p;
                        hi[a] += h;
                        lo[a] -= h;
                        (ph.fields[f].sphere.at(hi).v - ph.fields[f].sphere.at(lo).v) / (2.0 * h) / ranges[f]
                    })
                })
                .collect();
            let mut sum = 0.0;
            for r in 0..3 {
                for c in 0..3 {
                    let gij: f64 = grads.iter().map(|d| d[r] * d[c]).sum();
                    sum += gij * gij;
                }
            }
            let expect = sum.sqrt();
            let got = t.gnorm.data[[k, j, i]] as f64;
            assert!((got - expect).abs() <= 1e-4 * expect + 1e-9, "({k},{j},{i}): {got} vs {expect}");
            let dadx = t.jacobian.fields[0].data[[k, j, i]] as f64;
            assert!((dadx - grads[0][0]).abs() <= 1e-4 * grads[0][0].abs() + 1e-9);
            if expect > 1e-4 {
                checked += 1;
            }
        }
        assert!(checked >= 4, "{checked}");
    }
}
