//! The derive stage's items written slab by slab (`mdtf derive
//! --memory-budget`) have the bytes of the whole-volume derive's files, for
//! slabs of 1, 7 and 33 planes and under a budget, on a noisy anisotropic
//! sphere read by planes (NIfTI, NRRD) and read whole (MetaImage).

use mdtf_datagen::erf_sphere;
use mdtf_derive::{Item, Kernel};
use mdtf_pipeline::blocks::{SlabSize, derive_item_files};
use mdtf_pipeline::boundary_chain::BoundaryChainParams;
use mdtf_pipeline::channels;
use mdtf_volume::{Geometry, MultiField, ReadOptions, WriteOptions, write, write_volume};
use std::path::Path;

/// The whole-volume derive of `input`'s `items`, written as `mdtf derive` writes them into `dir`.
fn whole_files(input: &Path, items: &[Item], chain: &BoundaryChainParams, dir: &Path, ext: &str) {
    let v = mdtf_volume::read(input, &ReadOptions::default()).unwrap();
    for (item, mf) in channels::derive(&v, items, chain, &|_, _| {}).unwrap() {
        write(&dir.join(format!("{}{ext}", item.name())), &mf, &WriteOptions::default(), &[]).unwrap();
    }
}

#[test]
fn items_written_slab_by_slab_have_the_whole_derives_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let geo = Geometry::new([23, 19, 41], [0.8, 1.0, 1.3]);
    let mut sphere = erf_sphere(geo, 7.0, 1.5, 10.0, 200.0, None).volume();
    // deterministic noise, so that no two planes are alike
    for (i, x) in sphere.data.iter_mut().enumerate() {
        *x += ((i * 7919) % 97) as f32 * 0.05;
    }
    let items = [Item::Hessian, Item::Value, Item::Grad, Item::G, Item::Laplacian, Item::Normal, Item::F2, Item::InvG];
    let default = BoundaryChainParams::default();
    let bspline = BoundaryChainParams { kernel: Kernel::BSpline3, epsilon: Some(0.25), ..Default::default() };
    for (input_name, ext, chain) in
        [("in.nii", ".nii.gz", &default), ("in.nrrd", ".nrrd", &bspline), ("in.mha", ".nii", &default)]
    {
        let input = tmp.path().join(input_name);
        write_volume(&input, &sphere, &WriteOptions::default(), &[]).unwrap();
        let whole = tmp.path().join(format!("whole-{input_name}"));
        std::fs::create_dir(&whole).unwrap();
        whole_files(&input, &items, chain, &whole, ext);
        // the budget: 48 MiB of fixed costs and room for about 10 planes with the kernel's halo
        let sizes =
            [SlabSize::Planes(1), SlabSize::Planes(7), SlabSize::Planes(33), SlabSize::Budget((48 << 20) + 1_100_000)];
        for (k, size) in sizes.into_iter().enumerate() {
            let dir = tmp.path().join(format!("slabs{k}-{input_name}"));
            std::fs::create_dir(&dir).unwrap();
            let read = ReadOptions::default();
            let made = derive_item_files(&input, &read, &items, chain, size, &dir, ext, &|_, _| {}).unwrap();
            assert_eq!(made.files.iter().map(|(i, _)| *i).collect::<Vec<_>>(), items, "each item, in the order asked");
            if let SlabSize::Budget(_) = size {
                assert!(made.slabs >= 3, "the budget cuts the volume: {made:?}");
            }
            for (item, path) in &made.files {
                let want = std::fs::read(whole.join(format!("{}{ext}", item.name()))).unwrap();
                assert!(std::fs::read(path).unwrap() == want, "{input_name}: {item} in slabs {size:?} differs");
            }
            // the value's store is gone: only the items' files are left
            let left = std::fs::read_dir(&dir).unwrap().count();
            assert_eq!(left, items.len(), "{input_name} {size:?}");
        }
    }
}

#[test]
fn what_needs_the_whole_volume_or_several_fields_is_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let geo = Geometry::new([12, 10, 9], [1.0; 3]);
    let input = tmp.path().join("in.nii");
    write_volume(&input, &erf_sphere(geo, 3.0, 1.0, 0.0, 1.0, None).volume(), &WriteOptions::default(), &[]).unwrap();
    let chain = BoundaryChainParams::default();
    let run = |items: &[Item], size| {
        derive_item_files(&input, &ReadOptions::default(), items, &chain, size, tmp.path(), ".nii", &|_, _| {})
            .unwrap_err()
            .to_string()
    };
    let e = run(&[Item::G, Item::Shade], SlabSize::Planes(3));
    assert!(e.contains("shade") && e.contains("largest g of the whole volume"), "{e}");
    let e = run(&[Item::Gnorm], SlabSize::Planes(3));
    assert!(e.contains("gnorm need several fields"), "{e}");
    let e = run(&[Item::G], SlabSize::Budget(1 << 20));
    assert!(e.contains("too small"), "{e}");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1, "nothing written beside the input");
    // a two-field input is refused by the reader's own words
    let two = tmp.path().join("two.nrrd");
    let v = erf_sphere(Geometry::new([12, 10, 9], [1.0; 3]), 3.0, 1.0, 0.0, 1.0, None).volume();
    let mf = MultiField::from_volumes(vec![("a".into(), v.clone()), ("b".into(), v)]).unwrap();
    write(&two, &mf, &WriteOptions::default(), &[]).unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let e = derive_item_files(
        &two,
        &ReadOptions::default(),
        &[Item::G],
        &chain,
        SlabSize::Planes(3),
        &out,
        ".nii",
        &|_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("two.nrrd"), "{e}");
}

#[test]
fn a_derive_goes_by_slabs_on_its_own_only_when_the_whole_would_not_fit() {
    use mdtf_pipeline::blocks::automatic_item_budget;
    let tmp = tempfile::tempdir().unwrap();
    let geo = Geometry::new([32, 32, 16], [1.0; 3]);
    let input = tmp.path().join("in.nii");
    write_volume(&input, &erf_sphere(geo, 5.0, 1.0, 0.0, 1.0, None).volume(), &WriteOptions::default(), &[]).unwrap();
    let read = ReadOptions::default();
    // g, f'' and the normal: 5 components and 2 more f32 a voxel, 16384 voxels: 458752 bytes
    let items = [Item::G, Item::F2, Item::Normal];
    let whole = 4 * 7 * 16384u64;
    assert_eq!(automatic_item_budget(&input, &read, &items, whole / 3 * 4 + 4), None, "it fits in 3/4");
    let (budget, grid) = automatic_item_budget(&input, &read, &items, whole).unwrap();
    assert_eq!((budget, grid.dims), (whole / 4 * 3, [32, 32, 16]));
    assert_eq!(automatic_item_budget(&input, &read, &[Item::Shade], 1), None, "shade needs the whole volume");
    let mha = tmp.path().join("in.mha");
    write_volume(
        &mha,
        &erf_sphere(Geometry::new([8; 3], [1.0; 3]), 2.0, 1.0, 0.0, 1.0, None).volume(),
        &WriteOptions::default(),
        &[],
    )
    .unwrap();
    assert_eq!(automatic_item_budget(&mha, &read, &items, 1), None, "a file not read by planes goes whole");
}
