//! Packing throughput (voxels/s) of the slicer-3dtf profile from float
//! fields at 256^3. Run: `cargo bench -p mdtf-pack`.

use divan::counter::ItemsCount;
use mdtf_datagen::erf_sphere;
use mdtf_pack::{PackParams, Profile, Provenance, encode, pack};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

fn main() {
    divan::main();
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn slicer_3dtf_256(bencher: divan::Bencher) {
    let n = 256;
    let t = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 76.8, 3.0, 0.0, 255.0, None).truth();
    let mut chans =
        vec![("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone()), ("f2".to_string(), t.f2.clone())];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        chans
            .push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let params = PackParams { profile: Profile::Slicer3dtf, ranges: BTreeMap::new(), fields: vec![] };
    let prov =
        Provenance { mdtf_version: "bench".into(), input: None, input_sha256: None, stages: serde_json::Value::Null };
    bencher
        .counter(ItemsCount::new(n * n * n))
        .bench(|| pack(&chans, &params, &[], dir.path(), prov.clone(), &BTreeMap::new()).map(|m| m.textures.len()));
}

/// The quantisation pass alone (in memory, no files), same data.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn slicer_3dtf_256_encode_only(bencher: divan::Bencher) {
    let n = 256;
    let t = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 76.8, 3.0, 0.0, 255.0, None).truth();
    let mut chans =
        vec![("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone()), ("f2".to_string(), t.f2.clone())];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        chans
            .push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    let params = PackParams { profile: Profile::Slicer3dtf, ranges: BTreeMap::new(), fields: vec![] };
    bencher
        .counter(ItemsCount::new(n * n * n))
        .bench(|| encode(&chans, &params, &BTreeMap::new()).map(|e| e.textures.len()));
}

/// The 256 x 256 pre-integration table of a 256-sample TF (target: < 100 ms).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn preintegration_256(bencher: divan::Bencher) {
    let tf = mdtf_pack::Tf1d {
        samples: (0..256)
            .map(|k| {
                let s = k as f64 / 255.0;
                [
                    s,
                    1.0 - s,
                    0.5,
                    4.0 * (-((s - 0.3) / 0.05f64).powi(2)).exp() + 1.5 * (-((s - 0.7) / 0.1f64).powi(2)).exp(),
                ]
            })
            .collect(),
    };
    bencher.bench(|| mdtf_pack::preintegration_table(&tf, 256, 1.0).len());
}
