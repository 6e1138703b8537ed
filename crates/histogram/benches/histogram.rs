//! Histogram throughput (voxels/s). Run: `cargo bench -p mdtf-histogram`.

use divan::counter::ItemsCount;
use mdtf_datagen::erf_sphere;
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{Axis, HvolParams, count, histogram_volume};
use mdtf_volume::{Geometry, MultiField};

fn main() {
    divan::main();
}

fn sphere_channels(n: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let v = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None).volume();
    let d = DeriveParams { items: vec![Item::G, Item::F2], ..DeriveParams::default() };
    let out = mdtf_derive::run(&MultiField::from(v.clone()), &d).expect("derive");
    let g = out.items[0].1.fields[0].data.iter().copied().collect();
    let h = out.items[1].1.fields[0].data.iter().copied().collect();
    (v.data.iter().copied().collect(), g, h)
}

/// Joint (v, g) histogram, 256 x 256 bins, of a 256^3 volume.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn joint_256x256_of_256_cubed(bencher: divan::Bencher) {
    let (v, g, _) = sphere_channels(256);
    let axes = vec![
        Axis::new("v", 0.0, 255.0, 256).unwrap_or_else(|e| panic!("{e}")),
        Axis::new("g", 0.0, 35.0, 256).unwrap_or_else(|e| panic!("{e}")),
    ];
    bencher.counter(ItemsCount::new(v.len())).bench(|| count(&[&v, &g], axes.clone(), None));
}

/// Histogram volume of stored v, g and f'' (what the pipeline runner does: it keeps g and f'' for the pack), 256^3.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn hvol_of_stored_channels_256_cubed(bencher: divan::Bencher) {
    let (v, g, h) = sphere_channels(256);
    bencher
        .counter(ItemsCount::new(v.len()))
        .bench(|| histogram_volume(&v, &g, &h, 256 * 256, &HvolParams::default()).map(|hv| hv.sigma));
}

/// Boundary detection (materials, arch fits) on the histogram volume of a
/// noisy 128^3 shells phantom (256 x 256 (v, g) bins; its cost does not
/// depend on the voxel count).
#[divan::bench(sample_count = 10, sample_size = 1)]
fn detect_boundaries_256x256(bencher: divan::Bencher) {
    let mut v = mdtf_datagen::RadialPhantom::tooth(Geometry::new([128; 3], [1.0; 3]), 2.0).volume();
    mdtf_datagen::add_gaussian_noise(&mut v, 3.0, 5);
    let d = DeriveParams { items: vec![Item::G, Item::F2], ..DeriveParams::default() };
    let out = mdtf_derive::run(&MultiField::from(v.clone()), &d).expect("derive");
    let (g, h) = (&out.items[0].1.fields[0].data, &out.items[1].1.fields[0].data);
    let (g, h): (Vec<f32>, Vec<f32>) = (g.iter().copied().collect(), h.iter().copied().collect());
    let hv = histogram_volume(v.samples(), &g, &h, v.plane_len(), &HvolParams::default()).expect("hvol");
    bencher.bench(|| mdtf_histogram::detect(&hv).boundaries.len());
}
