//! Throughput of the bilateral filter (voxels/s) on the noisy erf sphere,
//! sigma_d = 1 voxel, sigma_r = 5% of the range (radius 3 in exact mode, ITK's
//! default for that sigma). Run: `cargo bench -p mdtf-bilateral`.

use divan::counter::ItemsCount;
use mdtf_bilateral::{BilateralParams, Mode, run};
use mdtf_datagen::{add_gaussian_noise, erf_sphere};
use mdtf_volume::{Geometry, Volume};

fn main() {
    divan::main();
}

fn noisy_sphere(n: usize) -> Volume {
    let mut v = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None).volume();
    add_gaussian_noise(&mut v, 20.0, 1);
    v
}

#[divan::bench(args = [128, 256], sample_count = 3, sample_size = 1)]
fn exact(bencher: divan::Bencher, n: usize) {
    let v = noisy_sphere(n);
    let p = BilateralParams::default();
    bencher.counter(ItemsCount::new(n.pow(3))).bench(|| run(&v, &p));
}

#[divan::bench(args = [128, 256], sample_count = 5, sample_size = 1)]
fn fast(bencher: divan::Bencher, n: usize) {
    let v = noisy_sphere(n);
    let p = BilateralParams { mode: Mode::Fast, ..BilateralParams::default() };
    bencher.counter(ItemsCount::new(n.pow(3))).bench(|| run(&v, &p));
}
