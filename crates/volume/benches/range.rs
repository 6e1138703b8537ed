//! Throughput of the finite-range pass (min, max and the NaN/infinity check)
//! that derive, pack and the histograms run over whole volumes.
//! Run: `cargo bench -p mdtf-volume`.

use divan::counter::ItemsCount;

fn main() {
    divan::main();
}

/// 256^3 samples of a smooth field.
#[divan::bench(sample_count = 10, sample_size = 1)]
fn finite_range_256_cubed(bencher: divan::Bencher) {
    let n = 256usize.pow(3);
    let data: Vec<f32> = (0..n).map(|i| ((i % 4099) as f32 * 0.37).sin() * 100.0).collect();
    bencher.counter(ItemsCount::new(n)).bench(|| mdtf_volume::finite_range(&data));
}
