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

/// v, g, f'' and the normal of the analytic erf sphere, as float fields.
fn sphere_channels(n: usize) -> Vec<(String, Volume)> {
    let t = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None).truth();
    let mut chans =
        vec![("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone()), ("f2".to_string(), t.f2.clone())];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        chans
            .push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    chans
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn slicer_3dtf_256(bencher: divan::Bencher) {
    let n = 256;
    let chans = sphere_channels(n);
    let dir = tempfile::tempdir().expect("tempdir");
    let params = PackParams::new(Profile::Slicer3dtf);
    let prov = Provenance {
        mdtf_version: "bench".into(),
        input: None,
        input_sha256: None,
        stages: serde_json::Value::Null,
        ..Default::default()
    };
    bencher
        .counter(ItemsCount::new(n * n * n))
        .bench(|| pack(&chans, &params, &[], dir.path(), prov.clone(), &BTreeMap::new()).map(|m| m.textures.len()));
}

/// The quantisation pass alone into whole in-memory textures (fresh memory: page faults included), same data.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn slicer_3dtf_256_encode_only(bencher: divan::Bencher) {
    let n = 256;
    let chans = sphere_channels(n);
    let params = PackParams::new(Profile::Slicer3dtf);
    bencher
        .counter(ItemsCount::new(n * n * n))
        .bench(|| encode(&chans, &params, &BTreeMap::new()).map(|e| e.textures.len()));
}

/// The quantisation pass as `pack` runs it, textures streamed a slab of
/// z-slices at a time through one reused buffer, here into a sink that only
/// looks at the bytes (no files, no whole-texture memory), same data.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn slicer_3dtf_256_encode_streamed(bencher: divan::Bencher) {
    let n = 256;
    let chans = sphere_channels(n);
    let params = PackParams::new(Profile::Slicer3dtf);
    bencher.counter(ItemsCount::new(n * n * n)).bench(|| {
        let mut bytes = 0usize;
        mdtf_pack::encode_streamed(&chans, &params, &BTreeMap::new(), &mut |_, slab| {
            bytes += divan::black_box(slab).len();
            Ok(())
        })
        .map(|_| bytes)
    });
}

/// The 256 x 256 pre-integration table of a 256-sample TF (target: < 100 ms).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn preintegration_256(bencher: divan::Bencher) {
    let tf = mdtf_pack::Tf1d::two_peaks(256);
    bencher.bench(|| mdtf_pack::preintegration_table(&tf, 256, 1.0).len());
}

/// Rasterising a 256 x 128 x 8 (v, g, f'') LUT from three widgets (target: < 50 ms).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn lut_256x128x8(bencher: divan::Bencher) {
    let tf = mdtf_pack::parse_tf(
        r#"{"v_range": [0, 255], "g_range": [0, 40], "f2_range": [-10, 10], "boundary_emphasis": 0.25,
            "widgets": [
              {"type": "triangle", "v0": 128, "width": 30, "g_low": 5, "g_high": 35, "shear": 0.5, "alpha": 0.8, "colour": [1, 0.5, 0]},
              {"type": "rectangle", "centre": [60, 10], "half_size": [20, 8], "falloff": "pyramid", "alpha": 0.6, "colour": [0, 0, 1]},
              {"type": "gaussian", "centre": [200, 25], "k": [[0.05, 0], [0, 0.2]], "alpha_max": 0.9, "colour": [0, 1, 0]}]}"#,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    bencher.bench(|| tf.table3(256, 128, 8).len());
}
