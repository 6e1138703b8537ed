//! Synthetic volumes with analytic ground truth, the reference every mdtf
//! stage is tested against.
//!
//! * [`RadialPhantom`]: concentric erf boundaries around a centre. One
//!   boundary is the erf sphere of DESIGN.md,
//!   `v = v_min + (v_max - v_min) (1 + erf(x / (sigma sqrt 2))) / 2` with
//!   `x = r - |P - c|`; three or four are the nested "tooth" shells.
//! * [`MultiFieldPhantom`]: three erf spheres with their own centres and
//!   radii, with the analytic Jacobian and ||G|| = ||Df^T Df||_F.
//! * [`CtHead`]: a head CT with its tissues, holder, blur, noise, int16
//!   values and padding, and the boundaries an expert would show.
//! * [`add_gaussian_noise`]: seeded, reproducible noise.
//!
//! All lengths (radius, sigma, distances) are in world units; the grid puts
//! voxel (i, j, k) at origin + (i sx, j sy, k sz).

mod ct_head;
mod multifield;
mod noise;
mod radial;

pub use ct_head::{CtHead, Tissue, TrueBoundary, hu};
pub use multifield::{MultiFieldPhantom, MultiFieldTruth, SphereField};
pub use noise::add_gaussian_noise;
pub use radial::{Boundary, RadialPhantom, RadialTruth, erf_sphere};

use mdtf_volume::Geometry;

/// World position of voxel (i, j, k) of an axis-aligned grid.
#[inline]
pub fn voxel_position(g: &Geometry, i: usize, j: usize, k: usize) -> [f64; 3] {
    [
        g.origin[0] + i as f64 * g.spacing[0],
        g.origin[1] + j as f64 * g.spacing[1],
        g.origin[2] + k as f64 * g.spacing[2],
    ]
}

/// World position of the grid centre, index (n - 1) / 2 on each axis.
pub fn grid_centre(g: &Geometry) -> [f64; 3] {
    [0, 1, 2].map(|a| g.origin[a] + (g.dims[a] as f64 - 1.0) / 2.0 * g.spacing[a])
}

/// Smallest extent n * s of the grid over the three axes, in world units.
pub fn min_extent(g: &Geometry) -> f64 {
    (0..3).map(|a| g.dims[a] as f64 * g.spacing[a]).fold(f64::INFINITY, f64::min)
}
