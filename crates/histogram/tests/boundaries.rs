//! Boundary detection in the histogram volume against phantoms whose
//! boundaries are known: the three of the shells (tooth) phantom, the one of
//! the erf sphere, none in pure noise, and the head CT phantom's small sinus.

use mdtf_datagen::{CtHead, RadialPhantom, add_gaussian_noise, erf_sphere, hu};
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{DetectedBoundary, HvolParams, detect_boundaries, histogram_volume};
use mdtf_volume::{Geometry, MultiField, Volume};
use std::f64::consts::PI;

fn detect(v: Volume) -> Vec<DetectedBoundary> {
    detect_with(v, &DeriveParams::default())
}

fn detect_with(v: Volume, derive: &DeriveParams) -> Vec<DetectedBoundary> {
    let d = DeriveParams { items: vec![Item::G, Item::F2], ..derive.clone() };
    let out = mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap();
    let (g, f2) = (&out.items[0].1.fields[0].data, &out.items[1].1.fields[0].data);
    let (g, f2) = (g.as_slice().unwrap(), f2.as_slice().unwrap());
    let hv = histogram_volume(v.samples(), g, f2, v.plane_len(), &HvolParams::default()).unwrap();
    detect_boundaries(&hv)
}

/// The boundary of `found` nearest in centre to the one between `a` and `b`.
fn nearest(found: &[DetectedBoundary], a: f64, b: f64) -> &DetectedBoundary {
    let centre = (a + b) / 2.0;
    found.iter().min_by(|x, y| (x.v_centre - centre).abs().total_cmp(&(y.v_centre - centre).abs())).unwrap()
}

#[test]
fn the_shells_three_boundaries_are_found_with_their_materials_and_peak_g() {
    let sigma = 2.0;
    let phantom = RadialPhantom::tooth(Geometry::new([96; 3], [1.0; 3]), sigma);
    let found = detect(phantom.volume());
    eprintln!("{found:#?}");
    assert_eq!(found.len(), 3, "{found:?}");
    // outside 20 | enamel 230 | dentin 140 | pulp 60
    for (a, b) in [(20.0, 230.0), (140.0, 230.0), (60.0, 140.0)] {
        let f = nearest(&found, a, b);
        let g_true = (b - a) / ((2.0 * PI).sqrt() * sigma);
        // the materials within the value span of one sigma of the boundary (its g_peak x sigma)
        let tol = g_true * sigma;
        assert!((f.v_low - a).abs() <= tol && (f.v_high - b).abs() <= tol, "{a}..{b}: {f:?} (tolerance {tol})");
        assert!((f.g_peak - g_true).abs() <= 0.05 * g_true, "{a}..{b}: g {} vs {g_true}", f.g_peak);
    }
}

#[test]
fn the_shells_under_noise_measured_with_a_smoothing_kernel_show_only_boundaries_of_the_phantom() {
    // noise of sd 4 swamps f'' from central differences; a Gaussian derivative
    // kernel, as one uses on noisy scans, does not. Blurred by sigma 2 and
    // then by the kernel, neither the enamel shell (3 voxels thick) nor the
    // pulp (a ball of radius 7.7 voxels) keeps a plateau of its own value:
    // what is found must be boundaries of the phantom (its centre between
    // the two values of one of its boundaries, its materials within them),
    // and the outer one (outside | the tooth) is found
    let mut v = RadialPhantom::tooth(Geometry::new([96; 3], [1.0; 3]), 2.0).volume();
    add_gaussian_noise(&mut v, 4.0, 5);
    let found = detect_with(v, &DeriveParams { kernel: "gauss:1.5".parse().unwrap(), ..Default::default() });
    assert!(found.iter().any(|f| (f.v_low - 20.0).abs() < 8.0), "{found:?}");
    for f in &found {
        let truth = [(20.0, 230.0), (140.0, 230.0), (60.0, 140.0)];
        assert!(
            truth.iter().any(|&(a, b)| f.v_centre > a && f.v_centre < b && f.v_low >= a - 8.0 && f.v_high <= b + 8.0),
            "{f:?} is no boundary of the phantom"
        );
    }
}

#[test]
fn the_erf_sphere_has_exactly_one_boundary() {
    let sigma = 3.0;
    let v = erf_sphere(Geometry::new([80; 3], [1.0; 3]), 24.0, sigma, 0.0, 255.0, None).volume();
    let found = detect(v);
    assert_eq!(found.len(), 1, "{found:?}");
    let g_true = 255.0 / ((2.0 * PI).sqrt() * sigma);
    assert!((found[0].g_peak - g_true).abs() <= 0.05 * g_true, "{:?} vs {g_true}", found[0]);
    assert!((found[0].v_centre - 127.5).abs() <= 0.05 * 255.0, "{:?}", found[0]);
    // each boundary's own width, from its span and G
    assert!((found[0].sigma - sigma).abs() <= 0.1 * sigma, "{:?}", found[0]);
    assert!(found[0].v_low.abs() <= 3.0 && (found[0].v_high - 255.0).abs() <= 3.0, "{:?}", found[0]);
}

#[test]
fn pure_noise_has_no_boundary_and_a_noisy_sphere_keeps_its_one() {
    let g = Geometry::new([64; 3], [1.0; 3]);
    let mut noise = Volume::new(g.clone(), ndarray::Array3::from_elem(g.shape(), 100.0)).unwrap();
    add_gaussian_noise(&mut noise, 10.0, 7);
    let found = detect(noise);
    assert!(found.is_empty(), "{found:?}");
    let mut sphere = erf_sphere(g, 20.0, 2.0, 0.0, 255.0, None).volume();
    add_gaussian_noise(&mut sphere, 5.0, 11);
    let found = detect(sphere);
    assert_eq!(found.len(), 1, "{found:?}");
}

/// The boundaries of `v` on its own grid (the least sigma of the spacing).
fn detect_on_grid(v: &Volume) -> Vec<DetectedBoundary> {
    let d = DeriveParams { items: vec![Item::G, Item::F2], ..DeriveParams::default() };
    let out = mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap();
    let (g, f2) = (&out.items[0].1.fields[0].data, &out.items[1].1.fields[0].data);
    let (g, f2) = (g.as_slice().unwrap(), f2.as_slice().unwrap());
    let params = HvolParams::on_grid(v.geometry.spacing);
    detect_boundaries(&histogram_volume(v.samples(), g, f2, v.plane_len(), &params).unwrap())
}

#[test]
fn a_small_sinus_of_air_in_bone_is_found_above_the_head_cts_strong_arches() {
    // the sinus (air in a frontal bone ball, radius 6 mm) holds a few hundred voxels on its arch,
    // which peaks at (1400 - -1000) / (sqrt(2 pi) 1 mm) = 958 HU/mm over every other arch; at two
    // sizes of the head (its holder's arch lies under the skin's: it must keep its own peak)
    for size in [[200, 200, 48], [256, 256, 108]] {
        let head = CtHead::new(Geometry::new(size, [1.0; 3]));
        let found = detect_on_grid(&head.scan());
        let summary: Vec<_> = found.iter().map(|b| (b.v_low.round(), b.v_high.round(), b.sigma)).collect();
        eprintln!("{size:?}: {summary:?}");
        let pair = |low: f64, high: f64| {
            found.iter().find(|b| (b.v_low - low).abs() <= head.noise && (b.v_high - high).abs() <= head.noise)
        };
        for (low, high) in [(hu::AIR, hu::BONE), (hu::AIR, hu::HOLDER), (hu::AIR, hu::SKIN)] {
            let b = pair(low, high).unwrap_or_else(|| panic!("{size:?}: {low} | {high} not in {summary:?}"));
            assert!((b.sigma / head.sigma - 1.0).abs() <= 0.2, "{size:?}: {low} | {high}: sigma {}", b.sigma);
        }
    }
}
