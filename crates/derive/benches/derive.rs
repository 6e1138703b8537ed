//! Throughput of the fused derive pass on the erf sphere (voxels/s).
//! Run: `cargo bench -p mdtf-derive` (set DIVAN_THREADS? no: rayon uses every core;
//! RAYON_NUM_THREADS=1 measures one core).

use divan::counter::ItemsCount;
use mdtf_datagen::erf_sphere;
use mdtf_derive::{DeriveParams, Item, Kernel, run, run_with_progress};
use mdtf_volume::{Geometry, MultiField};

fn main() {
    divan::main();
}

fn sphere(n: usize) -> MultiField {
    let g = Geometry::new([n; 3], [1.0; 3]);
    MultiField::from(erf_sphere(g, 0.3 * n as f64, 3.0, 0.0, 255.0, None).volume())
}

const KERNELS: [&str; 5] = ["central", "central4", "bspline3", "catmull-rom", "gauss:1"];

/// g + f'' + normal in one pass, every kernel, 256^3.
#[divan::bench(args = KERNELS, sample_count = 5, sample_size = 1)]
fn g_f2_normal_256(bencher: divan::Bencher, kernel: &str) {
    let input = sphere(256);
    let params = DeriveParams {
        items: vec![Item::G, Item::F2, Item::Normal],
        kernel: kernel.parse::<Kernel>().unwrap_or(Kernel::Central),
        ..DeriveParams::default()
    };
    bencher.counter(ItemsCount::new(256usize.pow(3))).bench(|| run(&input, &params));
}

/// Scaling with voxel count for the default kernel (g + f'' + normal).
#[divan::bench(args = [128, 256, 384], sample_count = 5, sample_size = 1)]
fn default_kernel_scaling(bencher: divan::Bencher, n: usize) {
    let input = sphere(n);
    let params = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..DeriveParams::default() };
    bencher.counter(ItemsCount::new(n.pow(3))).bench(|| run(&input, &params));
}

/// g alone with central differences (compare: SimpleITK GradientMagnitude, numpy.gradient).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn g_central_256(bencher: divan::Bencher) {
    let input = sphere(256);
    let params = DeriveParams { items: vec![Item::G], kernel: Kernel::Central, ..DeriveParams::default() };
    bencher.counter(ItemsCount::new(256usize.pow(3))).bench(|| run(&input, &params));
}

/// g + f'' + normal into reused output memory (no page faults), central and default kernels, 256^3.
#[divan::bench(args = ["central", "central4"], sample_count = 5, sample_size = 1)]
fn g_f2_normal_256_reused(bencher: divan::Bencher, kernel: &str) {
    let input = sphere(256);
    let params = DeriveParams {
        items: vec![Item::G, Item::F2, Item::Normal],
        kernel: kernel.parse::<Kernel>().unwrap_or(Kernel::Central),
        ..DeriveParams::default()
    };
    let mut previous = run(&input, &params).ok();
    bencher.counter(ItemsCount::new(256usize.pow(3))).bench_local(|| {
        previous = run_with_progress(&input, &params, previous.take(), &|_, _| {}).ok();
    });
}
