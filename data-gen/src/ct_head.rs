//! A head CT phantom: the tissues, the head holder, the scanner's blur and
//! noise, int16 storage and the padding outside the field of view, with the
//! boundaries an expert would set a transfer function on.

use crate::noise::add_gaussian_noise;
use crate::{grid_centre, voxel_position};
use mdtf_volume::{Geometry, Volume};
use ndarray::{Array3, Zip};
use std::f64::consts::SQRT_2;

/// Values of the tissues and objects, in Hounsfield units.
pub mod hu {
    /// Air around the head and in the sinus.
    pub const AIR: f64 = -1000.0;
    /// Skin and the soft tissue of the scalp.
    pub const SKIN: f64 = 40.0;
    /// Subcutaneous fat.
    pub const FAT: f64 = -90.0;
    /// Compact bone: the skull's outer and inner tables, the frontal bone.
    pub const BONE: f64 = 1400.0;
    /// Diploe, the spongy bone between the tables.
    pub const DIPLOE: f64 = 600.0;
    /// Cerebrospinal fluid.
    pub const CSF: f64 = 8.0;
    /// Brain (grey and white matter taken together).
    pub const BRAIN: f64 = 35.0;
    /// The carbon-fibre head holder the head lies in.
    pub const HOLDER: f64 = 250.0;
    /// What the scanner stores outside its circular field of view.
    pub const PADDING: f64 = -2000.0;
}

/// The head's layers from the skin inwards, HU: skin, fat, galea, outer
/// table, diploe, inner table, CSF, brain.
pub const LAYERS: [f64; 8] = [hu::SKIN, hu::FAT, hu::SKIN, hu::BONE, hu::DIPLOE, hu::BONE, hu::CSF, hu::BRAIN];

/// A named material of the phantom and its value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tissue {
    /// Name, e.g. "bone".
    pub name: &'static str,
    /// Value in Hounsfield units.
    pub hu: f64,
}

/// A boundary between two materials of the phantom, both reaching their
/// plateau.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueBoundary {
    /// The lower-valued material.
    pub low: Tissue,
    /// The higher-valued material.
    pub high: Tissue,
    /// Blur of the edge (standard deviation of the scanner's Gaussian PSF),
    /// world units; `None` for a hard edge (the field of view's rim).
    pub sigma: Option<f64>,
    /// The two materials differ by at least [`RESOLVABLE_CNR`] noise sds
    /// and the edge is blurred: its arch stands out of the (v, g) histogram.
    pub resolvable: bool,
}

/// Least contrast, in noise sds, of a boundary whose arch a histogram shows
/// without smoothing: the arch's peak g is then about 4 times the noise's
/// own gradient magnitude at a 1-voxel blur.
pub const RESOLVABLE_CNR: f64 = 10.0;

/// The head CT phantom. Lengths in world units (mm); the grid's axes are x
/// (left-right), y (posterior-anterior, the face towards +y) and z (slices).
///
/// The head is a sphere of `head_radius` around the grid centre, in the
/// layers of [`LAYERS`] from outside in: the scalp (skin, subcutaneous fat,
/// the galea's soft tissue), the skull (outer table, diploe, inner table),
/// CSF and brain. The layers are `layer` thick each, thicker than an
/// adult's (1 to 5 mm) so that every layer reaches its plateau at 1 mm
/// voxels after the blur: the phantom tests what a histogram can show. The
/// frontal bone is a compact-bone ball (radius 2 layers) centred on the
/// diploe at the front (+y), holding an air sinus (radius 1.2 layers). The head lies in a
/// holder: a cylindrical shell along z under the back of the head, one
/// layer from the skin and one layer thick.
///
/// Every edge is the erf of its signed distance (the Gaussian PSF of sd
/// `sigma` applied to a smooth surface); white noise of sd `noise` is added,
/// values are rounded to integers (int16 storage), and every voxel farther
/// than `fov_radius` from the z axis through the centre is set to
/// [`hu::PADDING`] with no blur or noise, as scanners do.
#[derive(Debug, Clone, PartialEq)]
pub struct CtHead {
    /// The sampling grid.
    pub geometry: Geometry,
    /// Outer radius of the skin.
    pub head_radius: f64,
    /// Thickness of each layer.
    pub layer: f64,
    /// Standard deviation of the scanner's Gaussian blur.
    pub sigma: f64,
    /// Standard deviation of the noise, HU.
    pub noise: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Radius of the circular field of view around the z axis.
    pub fov_radius: f64,
}

/// A signed-distance shape, positive inside, world units.
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// A ball of `radius` around `centre`.
    Ball { centre: [f64; 3], radius: f64 },
    /// The part of the shell between two cylinders along z (axis through
    /// `axis`, radii `inner` < `outer`) lying below the plane y = `y_max`.
    Cradle { axis: [f64; 2], inner: f64, outer: f64, y_max: f64 },
}

impl Shape {
    /// Signed distance of `p` to the surface, positive inside (exact for the
    /// ball, the usual min/max bound for the cradle's intersection).
    fn depth(&self, p: [f64; 3]) -> f64 {
        match *self {
            Shape::Ball { centre, radius } => {
                let d = [p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]];
                radius - (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
            }
            Shape::Cradle { axis, inner, outer, y_max } => {
                let r = (p[0] - axis[0]).hypot(p[1] - axis[1]);
                (outer - r).min(r - inner).min(y_max - p[1])
            }
        }
    }
}

impl CtHead {
    /// The phantom on `geometry` (world units taken as mm), with a head of
    /// radius 0.4 of the smallest in-plane extent, 5 mm layers, a 1 mm blur,
    /// 20 HU noise and the field of view touching the grid's in-plane edges.
    pub fn new(geometry: Geometry) -> CtHead {
        let extent = |a: usize| geometry.dims[a] as f64 * geometry.spacing[a];
        let in_plane = extent(0).min(extent(1));
        CtHead {
            geometry,
            head_radius: 0.4 * in_plane,
            layer: 5.0,
            sigma: 1.0,
            noise: 20.0,
            seed: 7,
            fov_radius: 0.5 * in_plane,
        }
    }

    /// The objects painted in order, each over what lies under it.
    fn objects(&self) -> Vec<(Shape, f64)> {
        let c = grid_centre(&self.geometry);
        let l = self.layer;
        let mut objects = vec![(
            Shape::Cradle {
                axis: [c[0], c[1]],
                inner: self.head_radius + l,
                outer: self.head_radius + 2.0 * l,
                y_max: c[1],
            },
            hu::HOLDER,
        )];
        for (k, &value) in LAYERS.iter().enumerate() {
            objects.push((Shape::Ball { centre: c, radius: self.head_radius - k as f64 * l }, value));
        }
        // the frontal bone is centred on the diploe at the front
        let front = [c[0], c[1] + self.head_radius - 4.5 * l, c[2]];
        objects.push((Shape::Ball { centre: front, radius: 2.0 * l }, hu::BONE));
        objects.push((Shape::Ball { centre: front, radius: 1.2 * l }, hu::AIR));
        objects
    }

    /// The blurred, noise-free head in HU (no padding), f32.
    pub fn clean(&self) -> Volume {
        let objects = self.objects();
        let s = self.sigma * SQRT_2;
        let g = &self.geometry;
        let mut data = Array3::<f32>::zeros((g.dims[2], g.dims[1], g.dims[0]));
        Zip::indexed(&mut data).par_for_each(|(k, j, i), v| {
            let p = voxel_position(g, i, j, k);
            let mut value = hu::AIR;
            for (shape, inside) in &objects {
                let w = 0.5 * (1.0 + libm::erf(shape.depth(p) / s));
                value += (inside - value) * w;
            }
            *v = value as f32;
        });
        Volume { geometry: g.clone(), data }
    }

    /// What the scanner stores: the clean head with noise, rounded to
    /// integers, and the padding outside the field of view.
    pub fn scan(&self) -> Volume {
        let mut v = self.clean();
        add_gaussian_noise(&mut v, self.noise, self.seed);
        let c = grid_centre(&self.geometry);
        let g = self.geometry.clone();
        Zip::indexed(&mut v.data).par_for_each(|(_, j, i), x| {
            let p = voxel_position(&g, i, j, 0);
            *x = if (p[0] - c[0]).hypot(p[1] - c[1]) > self.fov_radius {
                hu::PADDING as f32
            } else {
                x.round().clamp(i16::MIN as f32, i16::MAX as f32)
            };
        });
        v
    }

    /// The boundaries of the phantom as pairs of materials. CSF (8 HU),
    /// brain (35 HU), skin and the galea (40 HU) lie within 1.6 noise sds
    /// of each other: in any histogram they are one material, soft tissue
    /// (listed at the skin's 40 HU). The pairs:
    /// * air | soft tissue (the skin), air | holder, air | bone (the sinus),
    ///   soft tissue | bone (the galea on the outer table, the inner table
    ///   on the CSF, the frontal bone), diploe | bone: contrast at least
    ///   [`RESOLVABLE_CNR`] noise sds and blurred, `resolvable`;
    /// * fat | soft tissue (the scalp's fat): 130 HU, 6.5 noise sds at the
    ///   default noise, resolvable only when the noise is below a tenth
    ///   of it;
    /// * padding | air (the field of view's rim): a hard edge, no sigma, not
    ///   `resolvable` (no arch: no voxel takes a value between the two).
    pub fn true_boundaries(&self) -> Vec<TrueBoundary> {
        let t = |name, hu| Tissue { name, hu };
        let (air, soft, fat) = (t("air", hu::AIR), t("soft tissue", hu::SKIN), t("fat", hu::FAT));
        let (bone, diploe, holder) = (t("bone", hu::BONE), t("diploe", hu::DIPLOE), t("holder", hu::HOLDER));
        let blurred = |low: Tissue, high: Tissue| TrueBoundary {
            low,
            high,
            sigma: Some(self.sigma),
            resolvable: high.hu - low.hu >= RESOLVABLE_CNR * self.noise,
        };
        vec![
            blurred(air, soft),
            blurred(air, holder),
            blurred(air, bone),
            blurred(soft, bone),
            blurred(diploe, bone),
            blurred(fat, soft),
            TrueBoundary { low: t("padding", hu::PADDING), high: air, sigma: None, resolvable: false },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_layer_reaches_its_plateau_and_the_padding_lies_outside_the_field_of_view() {
        let head = CtHead::new(Geometry::new([120, 120, 16], [1.0; 3]));
        let clean = head.clean();
        let c = grid_centre(&head.geometry);
        let at = |depth: f64| {
            // on the +x axis through the centre (no holder, no frontal bone there)
            let x = c[0] + head.head_radius - depth;
            clean.data[[8, c[1] as usize, x.round() as usize]] as f64
        };
        let l = head.layer;
        for (k, want) in LAYERS.iter().enumerate() {
            let got = at((k as f64 + 0.5) * l);
            assert!((got - want).abs() < 0.05 * (hu::BONE - hu::AIR), "layer {k}: {got} HU, want {want}");
        }
        let scan = head.scan();
        assert_eq!(scan.data[[0, 0, 0]], hu::PADDING as f32, "a corner is outside the field of view");
        assert!(scan.data.iter().all(|v| v.fract() == 0.0), "integers, as stored in int16");
        // the air between the head and the field of view's rim is air plus noise
        let air = scan.data[[8, 116, c[0] as usize]] as f64;
        assert!((air - hu::AIR).abs() < 6.0 * head.noise, "{air}");
    }
}
