//! The histogram volume with g and f'' streamed from the value slice by
//! slice equals the one of stored g and f'', bit for bit, on any thread count.

use mdtf_datagen::erf_sphere;
use mdtf_derive::{DeriveParams, Item};
use mdtf_histogram::{HvolParams, histogram_volume};
use mdtf_pipeline::hvol_streamed::histogram_volume_derived;
use mdtf_volume::{Geometry, MultiField};

#[test]
fn histogram_volume_derived_on_the_fly_equals_the_stored_one_bit_for_bit() {
    // 30 slices: the 16 fixed parts are uneven, and threads group them differently
    let v = erf_sphere(Geometry::new([40, 44, 30], [1.0, 1.0, 1.2]), 12.0, 2.0, 0.0, 255.0, None).volume();
    let d = DeriveParams { items: vec![Item::G, Item::F2], ..DeriveParams::default() };
    let out = mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap();
    let scalar = |k: usize| out.items[k].1.clone().into_scalar().unwrap();
    let c = (v.clone(), scalar(0), scalar(1));
    let stored =
        histogram_volume(c.0.samples(), c.1.samples(), c.2.samples(), c.0.plane_len(), &HvolParams::default()).unwrap();
    let input = MultiField::from(v);
    let streamed = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| histogram_volume_derived(&input, &DeriveParams::default(), &HvolParams::default())).unwrap()
    };
    let s = streamed(2);
    // the same axes (exact order statistics either way) and the same integer counts
    assert_eq!(s.hist, stored.hist);
    assert_eq!(s.count_vg, stored.count_vg);
    assert_eq!(s.count_v, stored.count_v);
    // and the same sums, bit for bit: both cut their runs at every slice and sum each part's slices in order
    assert_eq!(s.sigma.to_bits(), stored.sigma.to_bits());
    assert_eq!(
        (&s.mean_g_v, &s.mean_h_v, &s.position, &s.opacity),
        (&stored.mean_g_v, &stored.mean_h_v, &stored.position, &stored.opacity)
    );
    // and the streamed sums keep their bits on any thread count
    for threads in [1, 3, 5] {
        let t = streamed(threads);
        assert_eq!((&t.hist, &t.mean_g_v, &t.mean_h_v, &t.position), (&s.hist, &s.mean_g_v, &s.mean_h_v, &s.position));
    }
    // a multi-field input is refused by the derive pass
    let two = MultiField::from_volumes(vec![("a".into(), c.0.clone()), ("b".into(), c.1.clone())]).unwrap();
    let e = histogram_volume_derived(&two, &DeriveParams::default(), &HvolParams::default());
    assert!(e.unwrap_err().to_string().contains("one field"));
}
