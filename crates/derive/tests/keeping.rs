//! Deriving a block while keeping slices of the previous output
//! ([`run_keeping`]): the kept slices are left as given, the others are
//! computed exactly as a whole derivation computes them; an output handed
//! back for its memory, whatever its size or items, changes no bit.

use mdtf_datagen::erf_sphere;
use mdtf_derive::{DeriveParams, Item, run, run_keeping};
use mdtf_volume::{Geometry, MultiField};

#[test]
fn kept_slices_stay_and_the_others_are_derived_as_a_whole_run_derives_them() {
    let input =
        MultiField::from(erf_sphere(Geometry::new([17, 15, 20], [1.0, 1.1, 0.9]), 6.0, 1.5, 0.0, 200.0, None).volume());
    let params = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..DeriveParams::default() };
    let whole = run(&input, &params).unwrap();
    let plane = 17 * 15;
    // a previous output holding the whole run's samples on slices 5..12 and a marker elsewhere
    let mut previous = run(&input, &params).unwrap();
    for (_, mf) in &mut previous.items {
        for f in &mut mf.fields {
            let data = f.data.as_slice_mut().unwrap();
            data[..5 * plane].fill(-7.0);
            data[12 * plane..].fill(-7.0);
        }
    }
    let kept = run_keeping(&input, &params, previous, 5..12).unwrap();
    for ((item, a), (_, b)) in kept.items.iter().zip(&whole.items) {
        for (fa, fb) in a.fields.iter().zip(&b.fields) {
            let (a, b) = (fa.data.as_slice().unwrap(), fb.data.as_slice().unwrap());
            let same = a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "{item:?} {}: every slice has the whole run's bits", fa.name);
        }
    }
    // kept slices are not recomputed: a marker there stays
    let mut marked = run(&input, &params).unwrap();
    marked.items[0].1.fields[0].data.as_slice_mut().unwrap()[6 * plane] = -3.0;
    let out = run_keeping(&input, &params, marked, 5..12).unwrap();
    assert_eq!(out.items[0].1.fields[0].data.as_slice().unwrap()[6 * plane], -3.0);
}

#[test]
fn keeping_slices_of_another_output_is_refused() {
    let input = MultiField::from(erf_sphere(Geometry::new([12; 3], [1.0; 3]), 4.0, 1.5, 0.0, 200.0, None).volume());
    let params = DeriveParams { items: vec![Item::G, Item::F2], ..DeriveParams::default() };
    let g_only = run(&input, &DeriveParams { items: vec![Item::G], ..DeriveParams::default() }).unwrap();
    let e = run_keeping(&input, &params, g_only, 2..5).unwrap_err().to_string();
    assert!(e.contains("other items or another grid"), "{e}");
    let smaller =
        MultiField::from(erf_sphere(Geometry::new([12, 12, 10], [1.0; 3]), 4.0, 1.5, 0.0, 200.0, None).volume());
    let other_grid = run(&smaller, &params).unwrap();
    assert!(run_keeping(&input, &params, other_grid, 2..5).is_err());
}

#[test]
fn an_output_of_another_size_or_items_handed_back_gives_the_bits_of_a_fresh_derivation() {
    let sphere = |dims: [usize; 3]| {
        MultiField::from(erf_sphere(Geometry::new(dims, [1.0, 1.1, 0.9]), 5.0, 1.5, 0.0, 200.0, None).volume())
    };
    let (small, large) = (sphere([13, 11, 9]), sphere([17, 15, 20]));
    let three = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..DeriveParams::default() };
    let one = DeriveParams { items: vec![Item::F2], ..DeriveParams::default() };
    let bits = |out: &mdtf_derive::DeriveOutput| -> Vec<Vec<u32>> {
        out.items.iter().flat_map(|(_, mf)| &mf.fields).map(|f| f.data.iter().map(|x| x.to_bits()).collect()).collect()
    };
    // a marker in the memory handed back must not show through
    let marked = |input: &MultiField, params: &DeriveParams| {
        let mut out = run(input, params).unwrap();
        out.items.iter_mut().flat_map(|(_, mf)| &mut mf.fields).for_each(|f| f.data.fill(-7.0));
        out
    };
    for (input, params, previous) in [
        (&small, &three, marked(&large, &three)), // shorter: the memory shortened
        (&large, &three, marked(&small, &three)), // longer: grown
        (&small, &one, marked(&large, &three)),   // fewer components
        (&large, &three, marked(&large, &one)),   // more: the rest fresh
    ] {
        let fresh = run(input, params).unwrap();
        let reused = mdtf_derive::run_with_progress(input, params, Some(previous), &|_, _| {}).unwrap();
        assert_eq!(bits(&reused), bits(&fresh), "{:?} on {:?}", params.items, input.geometry.dims);
    }
}
