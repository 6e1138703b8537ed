//! Tracing throughput in traced voxels/s (voxels with g >= g_min) on the
//! 256^3 erf sphere (radius 76.8, sigma 3, 0..255), default parameters.
//! Run: `cargo bench -p mdtf-boundary`.

use divan::counter::ItemsCount;
use mdtf_boundary::{BoundaryInput, BoundaryParams, run};
use mdtf_datagen::erf_sphere;
use mdtf_derive::{DeriveParams, Item};
use mdtf_volume::{Geometry, MultiField};

fn main() {
    divan::main();
}

#[divan::bench(args = [128, 256], sample_count = 5, sample_size = 1)]
fn trace_sphere(bencher: divan::Bencher, n: usize) {
    let v = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None).volume();
    let d = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..DeriveParams::default() };
    let mut out = mdtf_derive::run(&MultiField::from(v), &d).expect("derive");
    let normal = out.items.remove(2).1;
    let f2 = out.items.remove(1).1.into_scalar().expect("f2");
    let g = out.items.remove(0).1.into_scalar().expect("g");
    let input = BoundaryInput { g: &g, f2: &f2, normal: &normal, value_range: 255.0 };
    let params = BoundaryParams::default();
    let traced = run(&input, &params).expect("trace").counts.traced() as usize;
    bencher.counter(ItemsCount::new(traced)).bench(|| run(&input, &params));
}
