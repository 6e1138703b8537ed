//! The plan's halo is what a block needs: every channel computed on a z-slab
//! grown by the planned halo equals the whole-volume result bit for bit on
//! the slab's own planes (the ground on which slab-by-slab execution stands),
//! and a thinner halo does not. The whole-volume reductions (value range,
//! g's range, the noise floor) are passed in as pass 1 would give them.

use mdtf_bilateral::BilateralParams;
use mdtf_boundary::{BoundaryInput, BoundaryParams};
use mdtf_datagen::erf_sphere;
use mdtf_derive::{DeriveParams, Item};
use mdtf_pipeline::boundary_chain::prefilter_params;
use mdtf_pipeline::file::parse;
use mdtf_pipeline::plan::Plan;
use mdtf_volume::{Geometry, MultiField, Volume};

/// An anisotropic erf sphere (1 x 0.8 x 1.7 mm voxels) whose surface crosses the test slab.
fn sphere() -> Volume {
    let geo = Geometry::new([56, 64, 48], [1.0, 0.8, 1.7]);
    erf_sphere(geo, 18.0, 2.5, 0.0, 255.0, None).volume()
}

/// The planes `interior` of the whole volume's and the slab's channel (the
/// slab starts at plane `slab_start`): how many samples differ in their bits.
fn differing(whole: &Volume, slab: &Volume, interior: std::ops::Range<usize>, slab_start: usize) -> usize {
    let a = whole.z_slab(interior.clone());
    let b = slab.z_slab(interior.start - slab_start..interior.end - slab_start);
    assert_eq!(a.data.dim(), b.data.dim());
    a.data.iter().zip(b.data.iter()).filter(|(x, y)| x.to_bits() != y.to_bits()).count()
}

/// The plan of a pipeline file's text on `v`'s grid.
fn plan(toml: &str, v: &Volume) -> Plan {
    let p = parse(toml, &[]).unwrap();
    let settings = mdtf_pipeline::settings::Settings::new(&p, &Default::default());
    Plan::resolve(&settings, &[], &v.geometry).unwrap()
}

/// Derive items of `v` with a fixed epsilon (the whole volume's, a pass-1 reduction).
fn derive(v: &Volume, kernel: mdtf_derive::Kernel, items: &[Item]) -> Vec<(String, Volume)> {
    let d = DeriveParams { items: items.to_vec(), kernel, epsilon: Some(1e-3), ..Default::default() };
    let out = mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap();
    out.items.into_iter().flat_map(|(_, mf)| mf.into_volumes()).collect()
}

#[test]
fn derivatives_on_a_slab_with_the_planned_halo_equal_the_whole_volumes() {
    let v = sphere();
    let interior = 18..30;
    for kernel in ["central", "central4", "bspline3", "catmull-rom", "gauss:1.2"] {
        let text = format!(
            "keep = [\"g\", \"f2\", \"nx\", \"ny\", \"nz\", \"inv_g\"]\n[derive]\nkernel = \"{kernel}\"\n\
             [pack]\nprofile = \"slicer-3dtf\"\n"
        );
        let plan = plan(&text, &v);
        let k = kernel.parse().unwrap();
        let items = [Item::G, Item::F2, Item::Normal, Item::InvG];
        let whole = derive(&v, k, &items);
        let halo = plan.halo[2];
        assert!(halo >= 1 && plan.halo == plan.reach.kernel, "{kernel}: {:?}", plan.halo);
        for (h, exact) in [(halo, true), (halo - 1, false)] {
            let start = interior.start - h;
            let slab = derive(&v.z_slab(start..interior.end + h), k, &items);
            let diffs: Vec<(String, usize)> = whole
                .iter()
                .zip(&slab)
                .map(|((name, w), (_, s))| (name.clone(), differing(w, s, interior.clone(), start)))
                .collect();
            let total: usize = diffs.iter().map(|(_, n)| n).sum();
            if exact {
                assert_eq!(total, 0, "{kernel}, halo {h}: {diffs:?}");
            } else {
                assert!(total > 0, "{kernel}: a halo of {h} < {halo} changes nothing, so the plan's is not tight");
            }
        }
    }
}

/// derive -> pre-filter -> trace on `v`, with the whole volume's reductions given.
fn traced(
    v: &Volume,
    first_plane: usize,
    pf: &BilateralParams,
    ranges: (f64, f64, f64),
    params: &BoundaryParams,
) -> Vec<Volume> {
    let mut d = derive(v, mdtf_derive::Kernel::Central4, &[Item::G, Item::F2, Item::Normal]);
    let normal = MultiField::from_volumes(d.split_off(2)).unwrap();
    let (g, f2) = (d.remove(0).1, d.remove(0).1);
    let g = mdtf_bilateral::run(&g, &prefilter_params(pf, ranges.1)).unwrap();
    let f2 = mdtf_bilateral::run(&f2, &prefilter_params(pf, ranges.2)).unwrap();
    let input = BoundaryInput { g: &g, f2: &f2, normal: &normal, value_range: ranges.0 };
    let out = mdtf_boundary::run_block(&input, params, first_plane).unwrap();
    vec![out.distance, out.g_hit, out.hit]
}

/// A plane boundary across z at plane 35 (erf of sigma 4 mm; 1 x 0.8 x 1.7 mm voxels):
/// the voxels of planes 28..35 trace along +z straight to it (d_max is 12 mm, 7 planes).
fn plane() -> Volume {
    let geo = Geometry::new([12, 10, 48], [1.0, 0.8, 1.7]);
    let mut v = Volume::zeros(geo);
    for ((k, _, _), s) in v.data.indexed_iter_mut() {
        let x = (k as f32 - 35.0) * 1.7;
        *s = 255.0 * (1.0 + libm::erff(x / (4.0 * std::f32::consts::SQRT_2))) / 2.0;
    }
    v
}

/// Whole-volume vs slab tracing of `v` on the planes `interior` with each of
/// `halos`: how many distance, g_hit and hit samples differ.
fn trace_differences(v: &Volume, interior: std::ops::Range<usize>, halos: &[usize]) -> Vec<[usize; 3]> {
    // pass 1: the whole volume's value range, the ranges of g and f'', fixed thresholds
    let whole_d = derive(v, mdtf_derive::Kernel::Central4, &[Item::G, Item::F2]);
    let range = |x: &Volume| x.finite_range().map_or(0.0, |(lo, hi)| (hi - lo) as f64);
    let ranges = (range(v), range(&whole_d[0].1), range(&whole_d[1].1));
    let params = BoundaryParams { g_min: Some(0.2), g_hit_min: Some(1.0), ..Default::default() };
    let pf = BilateralParams { sigma_d: 1.0, sigma_r: 0.1, ..BilateralParams::default() };
    let whole = traced(v, 0, &pf, ranges, &params);
    let hits = whole[2].z_slab(interior.clone()).data.iter().filter(|&&h| h == 1.0).count();
    assert!(hits >= 100, "the boundary is traced from the slab: {hits} hits");
    halos
        .iter()
        .map(|&h| {
            let start = interior.start - h;
            let slab = traced(&v.z_slab(start..interior.end + h), start, &pf, ranges, &params);
            [0, 1, 2].map(|c| differing(&whole[c], &slab[c], interior.clone(), start))
        })
        .collect()
}

#[test]
fn the_tracing_on_a_slab_with_the_planned_halo_equals_the_whole_volumes() {
    let text = "keep = [\"distance\", \"g_hit\", \"hit\"]\n[derive]\nkernel = \"central4\"\n\
                [prefilter]\nsigma_d = 1.0\nsigma_r = 0.1\n[pack]\nprofile = \"distance-tf\"\n";
    let sphere = sphere();
    let plan = plan(text, &sphere);
    let r = plan.reach;
    // central4 reads 2 planes; the pre-filter ceil(2.5 x 1 / 1.7) = 2; rays of 15 x 0.8 mm reach
    // ceil(12 / 1.7) = 8 planes, and g at the hit is tricubic (2 planes past its cell's origin)
    assert_eq!((r.kernel[2], r.prefilter[2], r.trace[2], plan.halo[2]), (2, 2, 10, 14));
    let halo = plan.halo[2];
    // rays in every direction
    assert_eq!(trace_differences(&sphere, 20..30, &[halo]), [[0, 0, 0]]);
    // rays along z to a boundary 6 and 7 planes beyond the slab: they need the whole halo
    let thin = r.kernel[2] + r.prefilter[2];
    let diffs = trace_differences(&plane(), 20..30, &[halo, thin]);
    assert_eq!(diffs[0], [0, 0, 0], "planned halo {halo}");
    assert!(diffs[1][0] >= 100, "with a halo of {thin} (no rays' reach) the distances should change: {:?}", diffs[1]);
}
