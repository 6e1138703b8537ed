//! The histogram volume straight from the value, g and f'' streamed slice by
//! slice (what `mdtf histogram --hvol` runs). Run: `cargo bench -p mdtf-pipeline`.

use divan::counter::ItemsCount;
use mdtf_datagen::erf_sphere;
use mdtf_derive::DeriveParams;
use mdtf_histogram::HvolParams;
use mdtf_pipeline::hvol_streamed::histogram_volume_derived;
use mdtf_volume::{Geometry, MultiField};

fn main() {
    divan::main();
}

/// 256^3 erf sphere, the default kernel and 256^3 bins.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn hvol_with_derive_256_cubed(bencher: divan::Bencher) {
    let n = 256;
    let vol = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None).volume();
    let input = MultiField::from(vol);
    bencher.counter(ItemsCount::new(n * n * n)).bench(|| {
        histogram_volume_derived(&input, &DeriveParams::default(), &HvolParams::default()).map(|hv| hv.sigma)
    });
}
