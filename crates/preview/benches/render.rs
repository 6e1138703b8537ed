//! The preview's ray caster with and without empty-space skipping, for the
//! Gaussian classifier (two primitives over (v, sqrt g), analytic segments)
//! on a 160^3 erf sphere at the run preview's size and step.
//! Run: `cargo bench -p mdtf-preview`.

use mdtf_pack::GaussianPrimitive;
use mdtf_preview::{Camera, Classifier, render, render_without_skipping};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

fn main() {
    divan::main();
}

fn scene() -> (BTreeMap<String, Volume>, Classifier) {
    let t = mdtf_datagen::erf_sphere(Geometry::new([160; 3], [1.0; 3]), 50.0, 2.0, 10.0, 240.0, None).truth();
    let channels = [("v".to_string(), t.v), ("g".to_string(), t.g)].into_iter().collect();
    let classify = Classifier::Gaussian {
        primitives: vec![
            GaussianPrimitive {
                centre: vec![125.0, 7.0],
                k: vec![vec![0.05, 0.0], vec![0.0, 0.6]],
                alpha_max: 1.5,
                colour: [1.0, 0.6, 0.3],
                triangular: false,
            },
            GaussianPrimitive {
                centre: vec![200.0],
                k: vec![vec![0.02]],
                alpha_max: 0.7,
                colour: [0.2, 0.5, 1.0],
                triangular: true,
            },
        ],
        channels: vec!["v".into(), "g".into()],
        analytic: true,
        sqrt_last: true,
    };
    (channels, classify)
}

const CAMERA: Camera = Camera { azimuth: 30.0, elevation: 20.0, size: 256, step: 0.5, shaded: true };

#[divan::bench(sample_count = 5, sample_size = 1)]
fn gaussian_with_skipping(bencher: divan::Bencher) {
    let (channels, classify) = scene();
    bencher.bench(|| render(&channels, &classify, &CAMERA));
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn gaussian_without_skipping(bencher: divan::Bencher) {
    let (channels, classify) = scene();
    bencher.bench(|| render_without_skipping(&channels, &classify, &CAMERA));
}
