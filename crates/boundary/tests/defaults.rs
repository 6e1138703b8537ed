//! The tracing's default thresholds with and without the boundaries found
//! before it, against their definitions.

use mdtf_boundary::{BoundaryParams, Detected, G_HIT_MIN_FLOORS, G_HIT_MIN_PEAK_SHARE, resolve, resolve_detected};
use mdtf_volume::Geometry;

#[test]
fn a_boundary_found_below_twice_the_noise_floor_lowers_g_hit_min_to_half_its_peak_g() {
    let geo = Geometry::new([32; 3], [1.0; 3]);
    let (range, floor) = (583.0, 13.6);
    let plain = resolve(&BoundaryParams::default(), &geo, range, floor).unwrap();
    assert_eq!(plain.g_hit_min, G_HIT_MIN_FLOORS * floor);
    assert!(!plain.g_hit_min_of_boundaries && !plain.fig2_range_of_boundaries);
    assert!((plain.fig2_g_hit_min - 20.0 * range / 255.0).abs() < 1e-9);
    // a sphere of contrast 255 blurred to sigma 3.16 peaks at 255 / (sqrt(2 pi) 3.16) = 32.2
    let detected = Detected { least_g_peak: Some(32.2), material_range: Some([-2.0, 253.0]) };
    let r = resolve_detected(&BoundaryParams::default(), &geo, range, floor, &detected).unwrap();
    assert_eq!(r.g_hit_min, G_HIT_MIN_PEAK_SHARE * 32.2);
    assert!(r.g_hit_min_of_boundaries);
    // the Fig. 2 thresholds scale by the materials' span, not the noise-stretched range
    assert_eq!(r.fig2_range, 255.0);
    assert!((r.fig2_g_min - 5.0).abs() < 1e-9 && (r.fig2_g_hit_min - 20.0).abs() < 1e-9);
    assert!(r.fig2_range_of_boundaries);
    // never below the floor, never above twice it, never over a given threshold
    let weak = Detected { least_g_peak: Some(10.0), ..detected };
    assert_eq!(resolve_detected(&BoundaryParams::default(), &geo, range, floor, &weak).unwrap().g_hit_min, floor);
    let strong = Detected { least_g_peak: Some(400.0), ..detected };
    let r = resolve_detected(&BoundaryParams::default(), &geo, range, floor, &strong).unwrap();
    assert_eq!((r.g_hit_min, r.g_hit_min_of_boundaries), (G_HIT_MIN_FLOORS * floor, false));
    let given = BoundaryParams { g_hit_min: Some(60.0), ..Default::default() };
    assert_eq!(resolve_detected(&given, &geo, range, floor, &detected).unwrap().g_hit_min, 60.0);
}
