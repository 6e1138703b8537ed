//! The tracing written slab by slab (`mdtf boundary --memory-budget`) has
//! the bytes of the whole-volume tracing's files (distance, g_hit, hit, dot,
//! the flipped distance and an alpha map) and its Fig. 2 report, for slabs
//! of 1, 7 and 33 planes and under a budget, with and without the
//! pre-filter, on a noisy anisotropic sphere.

use mdtf_datagen::erf_sphere;
use mdtf_pipeline::blocks::{SlabSize, trace_files};
use mdtf_pipeline::boundary_chain::BoundaryChainParams;
use mdtf_pipeline::channels;
use mdtf_pipeline::stages::bilateral::BilateralParams;
use mdtf_pipeline::stages::boundary::{AlphaMap, BoundaryParams};
use mdtf_volume::{Geometry, MultiField, ReadOptions, Volume, WriteOptions, write, write_volume};
use std::path::Path;

/// The whole-volume tracing of `input` as `mdtf boundary` writes it into
/// `dir` (channels, flipped, alpha maps; the report in `dir`/boundary); its mean dot.
fn whole_files(input: &Path, chain: &BoundaryChainParams, dir: &Path) -> f64 {
    let v = mdtf_volume::read(input, &ReadOptions::default()).unwrap();
    let names = mdtf_pipeline::channel::traced_names();
    let mut all = channels::compute_all(&v, &names, chain, &|_, _| {}).unwrap();
    let mut t = all.tracing.take().unwrap();
    let mut files: Vec<(String, Volume)> = all.channels;
    files.extend(t.flipped.take().map(|f| ("flipped".to_string(), f)));
    files.append(&mut t.alpha);
    for (name, v) in files {
        write(&dir.join(format!("{name}.nii.gz")), &MultiField::from(v), &WriteOptions::default(), &[]).unwrap();
    }
    std::fs::create_dir(dir.join("boundary")).unwrap();
    t.report.write(&dir.join("boundary")).unwrap();
    t.report.mean_dot
}

#[test]
fn the_tracing_written_slab_by_slab_has_the_whole_tracings_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let geo = Geometry::new([30, 26, 40], [0.9, 1.0, 1.2]);
    let mut sphere = erf_sphere(geo, 9.0, 1.5, 20.0, 220.0, None).volume();
    // deterministic noise, so that no two planes are alike
    for (i, x) in sphere.data.iter_mut().enumerate() {
        *x += ((i * 7919) % 97) as f32 * 0.1;
    }
    let input = tmp.path().join("in.nrrd");
    write_volume(&input, &sphere, &WriteOptions::default(), &[]).unwrap();
    let boundary = BoundaryParams {
        d_max: Some(6.0),
        flipped: true,
        alpha: vec![AlphaMap::Linear { a: 1.0, dc: Some(2.0) }],
        ..Default::default()
    };
    let plain = BoundaryChainParams { boundary: boundary.clone(), ..Default::default() };
    let prefilter = BilateralParams { sigma_d: 1.0, sigma_r: 0.1, ..Default::default() };
    let filtered = BoundaryChainParams { prefilter: Some(prefilter), boundary, ..Default::default() };
    for (what, chain) in [("plain", &plain), ("prefiltered", &filtered)] {
        let whole = tmp.path().join(format!("whole-{what}"));
        std::fs::create_dir(&whole).unwrap();
        let mean_dot = whole_files(&input, chain, &whole);
        assert!(mean_dot > 0.95, "{what}: the sphere's normals agree at the hits: {mean_dot}");
        // the budget: 48 MiB of fixed costs and room for about 10 planes with the tracing's halo
        let sizes =
            [SlabSize::Planes(1), SlabSize::Planes(7), SlabSize::Planes(33), SlabSize::Budget((48 << 20) + 1_000_000)];
        for (k, size) in sizes.into_iter().enumerate() {
            let dir = tmp.path().join(format!("slabs{k}-{what}"));
            std::fs::create_dir(&dir).unwrap();
            let read = ReadOptions::default();
            let t = trace_files(&input, &read, chain, size, &dir, ".nii.gz", &|_| {}, &|_, _| {}).unwrap();
            let names: Vec<&str> = t.files.iter().map(|(n, _)| n.as_str()).collect();
            assert_eq!(names, ["distance", "g_hit", "hit", "dot", "flipped", "alpha_linear"], "{what}");
            if let SlabSize::Budget(_) = size {
                assert!(t.slabs >= 3, "the budget cuts the volume: {} slabs", t.slabs);
            }
            for (name, path) in &t.files {
                let want = std::fs::read(whole.join(format!("{name}.nii.gz"))).unwrap();
                assert!(std::fs::read(path).unwrap() == want, "{what}: {name} in slabs {size:?} differs");
            }
            // the report comes back (the run's folder holds only the files)
            assert!(!dir.join("boundary").exists(), "no report left in the folder");
            std::fs::create_dir(dir.join("boundary")).unwrap();
            t.report.write(&dir.join("boundary")).unwrap();
            for f in ["boundary_report.csv", "boundary_report.png"] {
                let (a, b) =
                    (std::fs::read(whole.join("boundary").join(f)), std::fs::read(dir.join("boundary").join(f)));
                assert!(a.unwrap() == b.unwrap(), "{what}: {f} in slabs {size:?} differs");
            }
            assert_eq!(t.report.mean_dot, mean_dot, "{what} {size:?}");
            assert!(t.summary.counts.hits > 1000, "{:?}", t.summary.counts);
            assert!(!dir.join(".slabs").exists(), "the store is removed");
        }
    }
}
