//! Tracing throughput in traced voxels/s (voxels with g >= g_min) on the
//! 256^3 erf sphere (radius 76.8, sigma 3, 0..255), default parameters.
//! Run: `cargo bench -p mdtf-boundary`.

use divan::counter::ItemsCount;
use mdtf_boundary::{BoundaryInput, BoundaryParams, run};
use mdtf_datagen::{add_gaussian_noise, erf_sphere};
use mdtf_derive::{DeriveParams, Item};
use mdtf_volume::{Geometry, MultiField, Volume};

fn main() {
    divan::main();
}

/// g, f'' and the normal of `v` (default kernel), as the stage reads them.
fn derived(v: Volume) -> (Volume, Volume, MultiField) {
    let d = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..DeriveParams::default() };
    let mut out = mdtf_derive::run(&MultiField::from(v), &d).expect("derive");
    let normal = out.items.remove(2).1;
    let f2 = out.items.remove(1).1.into_scalar().expect("f2");
    let g = out.items.remove(0).1.into_scalar().expect("g");
    (g, f2, normal)
}

/// Traces `v` with `params`, counting traced voxels.
fn bench_trace(bencher: divan::Bencher, v: Volume, params: &BoundaryParams) {
    let (g, f2, normal) = derived(v);
    let input = BoundaryInput { g: &g, f2: &f2, normal: &normal, value_range: 255.0 };
    let traced = run(&input, params).expect("trace").counts.traced() as usize;
    bencher.counter(ItemsCount::new(traced)).bench(|| run(&input, params));
}

#[divan::bench(args = [128, 256], sample_count = 5, sample_size = 1)]
fn trace_sphere(bencher: divan::Bencher, n: usize) {
    let v = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None).volume();
    bench_trace(bencher, v, &BoundaryParams::default());
}

/// The workload of the prototype in ../shared/research/ANCHORS.md (5.3: 32 M
/// traced voxels/s): step 0.5 voxel, at most 16 steps, a noisy sphere on
/// which nearly every voxel is traced, so the per-volume cost is spread
/// over 16 M traces instead of the 1.4 M of the default run. Compares the tracer, not the issue's
/// defaults.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn trace_like_the_anchor_prototype_256(bencher: divan::Bencher) {
    let mut v = erf_sphere(Geometry::new([256; 3], [1.0; 3]), 76.8, 3.0, 0.0, 255.0, None).volume();
    add_gaussian_noise(&mut v, 2.0, 11);
    let params = BoundaryParams { g_min: Some(0.0), step: Some(0.5), d_max: Some(8.0), ..BoundaryParams::default() };
    bench_trace(bencher, v, &params);
}
