//! The boundary stage on the erf sphere and the nested shells, against the
//! analytic distance, g peak and normals, as the checks define them.

use mdtf_bilateral::{BilateralParams, RangeUnits};
use mdtf_boundary::{AlphaMap, BoundaryInput, BoundaryOutput, BoundaryParams, HitCode, NO_BOUNDARY, run};
use mdtf_datagen::{RadialPhantom, RadialTruth, add_gaussian_noise, erf_sphere};
use mdtf_derive::{DeriveParams, Item, Kernel};
use mdtf_volume::{Geometry, MultiField, Volume};
use std::f64::consts::PI;

struct Derived {
    g: Volume,
    f2: Volume,
    normal: MultiField,
}

fn derive(v: &Volume) -> Derived {
    derive_with(v, DeriveParams::default().kernel)
}

fn derive_with(v: &Volume, kernel: Kernel) -> Derived {
    let d = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], kernel, ..DeriveParams::default() };
    let mut out = mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap();
    let normal = out.items.remove(2).1;
    let f2 = out.items.remove(1).1.into_scalar().unwrap();
    let g = out.items.remove(0).1.into_scalar().unwrap();
    Derived { g, f2, normal }
}

fn trace(d: &Derived, params: &BoundaryParams) -> BoundaryOutput {
    run(&BoundaryInput { g: &d.g, f2: &d.f2, normal: &d.normal, value_range: 255.0 }, params).unwrap()
}

struct Stats {
    mean_dot: f64,
    mean_err: f64,
    max_err: f64,
    traced_near: usize,
    g_hit_within_1pct: f64,
}

/// Errors over voxels with |x| <= 3 sigma that were traced to a kept hit.
fn stats(out: &BoundaryOutput, truth: &RadialTruth, sigma: f64, peak_g: impl Fn(usize) -> f64) -> Stats {
    stats_within(out, truth, 3.0 * sigma, None, peak_g)
}

/// Errors over voxels with |x| <= `near` that were traced to a kept hit,
/// leaving out (like the paper's Fig. 2) the hits below `fig2`'s thresholds
/// (g at the voxel, g at the hit) when given.
fn stats_within(
    out: &BoundaryOutput,
    truth: &RadialTruth,
    near_x: f64,
    fig2: Option<(&Volume, f64, f64)>,
    peak_g: impl Fn(usize) -> f64,
) -> Stats {
    let (mut dot, mut hits) = (0.0, 0usize);
    let (mut err, mut max_err, mut near) = (0.0, 0.0f64, 0usize);
    let mut g_ok = 0usize;
    for (i, (&h, &x)) in out.hit.samples().iter().zip(truth.x.samples()).enumerate() {
        if h != HitCode::Hit as u8 as f32 {
            continue;
        }
        if let Some((g, g_min, g_hit_min)) = fig2
            && ((g.samples()[i] as f64) < g_min || (out.g_hit.samples()[i] as f64) < g_hit_min)
        {
            continue;
        }
        hits += 1;
        dot += out.dot.samples()[i] as f64;
        let peak = peak_g(i);
        if ((out.g_hit.samples()[i] as f64 - peak) / peak).abs() <= 0.01 {
            g_ok += 1;
        }
        if (x as f64).abs() <= near_x {
            let e = (out.distance.samples()[i] as f64 - (x as f64).abs()).abs();
            err += e;
            max_err = max_err.max(e);
            near += 1;
        }
    }
    Stats {
        mean_dot: dot / hits as f64,
        mean_err: err / near as f64,
        max_err,
        traced_near: near,
        g_hit_within_1pct: g_ok as f64 / hits as f64,
    }
}

fn check_sphere(radius: f64) {
    let sigma = 3.0;
    let ph = erf_sphere(Geometry::new([128; 3], [1.0; 3]), radius, sigma, 0.0, 255.0, None);
    let d = derive(&ph.volume());
    let out = trace(&d, &BoundaryParams::default());
    let truth = ph.truth();
    let a = 255.0 / (sigma * (2.0 * PI).sqrt());
    let s = stats(&out, &truth, sigma, |_| a);
    eprintln!(
        "sphere r={radius}: mean dot {:.6}, mean |d-|x|| {:.4}, max {:.4} over {} voxels, g_hit within 1%: {:.4}; {:?}",
        s.mean_dot, s.mean_err, s.max_err, s.traced_near, s.g_hit_within_1pct, out.counts
    );
    assert!(s.traced_near > 10_000);
    assert!(s.mean_dot >= 0.9999, "mean dot {}", s.mean_dot);
    assert!(s.mean_err <= 0.05, "mean distance error {}", s.mean_err);
    assert!(s.max_err <= 0.25, "max distance error {}", s.max_err);
    assert!(s.g_hit_within_1pct >= 0.99, "g_hit within 1%: {}", s.g_hit_within_1pct);
}

#[test]
fn papers_sphere_radius_15() {
    check_sphere(15.0);
}

#[test]
fn sphere_radius_38_4() {
    check_sphere(38.4);
}

#[test]
fn alpha_maps_follow_equations_9_to_11() {
    let ph = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 14.0, 2.0, 0.0, 255.0, None);
    let d = derive(&ph.volume());
    let maps: Vec<AlphaMap> = ["linear:a=1,dc=3", "concave:a=0.4,dc=3,n=9", "convex:a=1,dc=3,n=3"]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
    let out = trace(&d, &BoundaryParams { alpha: maps, flipped: true, ..Default::default() });
    // Eqs. 9-11 written out again here.
    let linear = |x: f64| (1.0 - x / 3.0).max(0.0); // a = 1, dc = 3
    let concave = |x: f64| if x < 3.0 { 0.4 / 3f64.powi(9) * (x - 3.0).abs().powi(9) } else { 0.0 };
    let convex = |x: f64| (1.0 - x.powi(3) / 27.0).max(0.0); // a = 1, dc = 3, n = 3
    let flipped = out.flipped.as_ref().unwrap();
    let mut checked = 0;
    for (i, &h) in out.hit.samples().iter().enumerate() {
        let dist = out.distance.samples()[i] as f64;
        let hit = h == 1.0;
        for ((_, vol), f) in out.alpha.iter().zip([&linear as &dyn Fn(f64) -> f64, &concave, &convex]) {
            let want = if hit { f(dist) } else { 0.0 };
            assert!((vol.samples()[i] as f64 - want).abs() < 1e-6, "{i}");
        }
        if hit {
            assert!((flipped.samples()[i] as f64 - (15.0 - dist)).abs() < 1e-5);
            checked += 1;
        } else {
            assert_eq!(out.distance.samples()[i], NO_BOUNDARY);
            assert_eq!(flipped.samples()[i], 0.0);
        }
    }
    assert!(checked > 1000);
    assert_eq!(
        out.alpha.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
        ["alpha_linear", "alpha_concave", "alpha_convex"]
    );
}

#[test]
fn nested_shells_find_their_own_nearest_boundary() {
    let sigma = 2.0;
    let ph = RadialPhantom::tooth(Geometry::new([128; 3], [1.0; 3]), sigma);
    let d = derive(&ph.volume());
    let out = trace(&d, &BoundaryParams::default());
    let truth = ph.truth();
    // g at the hit is the peak of the boundary the voxel belongs to: |jump| / (sigma sqrt(2 pi)).
    let c = ph.centre;
    let jumps: Vec<(f64, f64)> = {
        let mut outer = ph.outside;
        ph.boundaries
            .iter()
            .map(|b| {
                let j = (b.radius, (b.inside - outer).abs() / (sigma * (2.0 * PI).sqrt()));
                outer = b.inside;
                j
            })
            .collect()
    };
    let [nx, ny, _] = ph.geometry.dims;
    let peak = |i: usize| {
        let (x, y, z) = ((i % nx) as f64, ((i / nx) % ny) as f64, (i / (nx * ny)) as f64);
        let rho = ((x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt();
        jumps.iter().min_by(|a, b| (a.0 - rho).abs().total_cmp(&(b.0 - rho).abs())).map_or(1.0, |j| j.1)
    };
    // within 2 sigma: halfway between the enamel's two boundaries (4.5 voxels
    // from each) their tails overlap and shift g's peak off the ideal radius
    let s = stats_within(&out, &truth, 2.0 * sigma, None, peak);
    eprintln!(
        "shells: mean dot {:.6}, mean err {:.4}, max {:.4} over {}, {:?}",
        s.mean_dot, s.mean_err, s.max_err, s.traced_near, out.counts
    );
    assert!(s.mean_err <= 0.05 && s.max_err <= 0.25, "{} {}", s.mean_err, s.max_err);
    assert!(s.mean_dot >= 0.999, "{}", s.mean_dot);
}

#[test]
fn noisy_sphere_with_prefilter_stays_on_its_boundary() {
    let sigma = 3.0;
    let ph = erf_sphere(Geometry::new([128; 3], [1.0; 3]), 38.4, sigma, 0.0, 255.0, None);
    let mut v = ph.volume();
    add_gaussian_noise(&mut v, 10.0, 11);
    // Noisy data: smoothing derivatives (Gaussian, sigma 1 voxel), as Teem users pick for noise.
    let mut d = derive_with(&v, Kernel::Gauss { sigma: 1.0 });
    // The paper's pre-filter: bilateral on g and f''.
    let bf = |vol: &Volume| {
        let range = vol.finite_range().map_or(1.0, |(lo, hi)| (hi - lo) as f64);
        let p = BilateralParams {
            sigma_d: 1.0,
            sigma_r: 0.1 * range,
            range_units: RangeUnits::Value,
            ..Default::default()
        };
        mdtf_bilateral::run(vol, &p).unwrap()
    };
    d.g = bf(&d.g);
    d.f2 = bf(&d.f2);
    let out = trace(&d, &BoundaryParams::default());
    // every voxel above the noise floor is traced: the statistics leave out
    // the noise's boundaries with the paper's Fig. 2 thresholds, as it does
    let fig2 = Some((&d.g, out.resolved.fig2_g_min, out.resolved.fig2_g_hit_min));
    let s = stats_within(&out, &ph.truth(), 3.0 * sigma, fig2, |_| 255.0 / (sigma * (2.0 * PI).sqrt()));
    eprintln!(
        "noisy+prefilter: mean dot {:.5}, mean err {:.4}, max {:.4}, {:?}",
        s.mean_dot, s.mean_err, s.max_err, out.counts
    );
    assert!(s.mean_dot >= 0.99, "{}", s.mean_dot);
    assert!(s.mean_err <= 0.3, "{}", s.mean_err);
}

#[test]
fn same_bits_with_one_and_two_threads() {
    let ph = RadialPhantom::tooth(Geometry::new([40, 40, 36], [1.0, 1.0, 1.2]), 1.5);
    let d = derive(&ph.volume());
    let with = |t| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| trace(&d, &BoundaryParams::default()))
    };
    let (a, b) = (with(1), with(2));
    for (x, y) in [(&a.distance, &b.distance), (&a.g_hit, &b.g_hit), (&a.dot, &b.dot), (&a.hit, &b.hit)] {
        assert!(x.samples().iter().zip(y.samples()).all(|(p, q)| p.to_bits() == q.to_bits()));
    }
}

#[test]
fn a_block_cut_in_y_and_z_traces_its_voxels_as_the_whole_volume_does() {
    use mdtf_boundary::{BlockPlace, VolumeStats, trace_block};
    let geo = Geometry::new([40, 44, 36], [1.0, 0.8, 1.2]);
    let ph = RadialPhantom::tooth(geo, 1.5);
    let d = derive(&ph.volume());
    let params = BoundaryParams { d_max: Some(4.0), ..BoundaryParams::default() };
    let whole = trace(&d, &params);
    let stats = VolumeStats::of(&d.g, 255.0);
    // the halo a ray and the tricubic support at its hit need: d_max in voxels plus 2
    let halo = |spacing: f64| (4.0 / spacing).ceil() as usize + 2;
    let (rows, planes) = (14..23usize, 11..19usize);
    let (y0, y1) = (rows.start - halo(0.8), rows.end + halo(0.8));
    let (z0, z1) = (planes.start - halo(1.2), planes.end + halo(1.2));
    assert!(y0 > 0 && y1 < 44 && z0 > 0 && z1 < 36, "the cut faces lie inside the volume");
    let cut = |v: &Volume| {
        let data = ndarray::Array3::from_shape_fn((z1 - z0, y1 - y0, 40), |(k, j, i)| v.data[[z0 + k, y0 + j, i]]);
        Volume::new(v.geometry.z_slab(z0..z1).y_rows(y0..y1), data).unwrap()
    };
    let normal =
        MultiField::from_volumes((0..3).map(|i| (format!("n{i}"), cut(&d.normal.field_volume(i).unwrap()))).collect())
            .unwrap();
    let (g, f2) = (cut(&d.g), cut(&d.f2));
    let place = BlockPlace {
        first: [0, y0, z0],
        rows: rows.start - y0..rows.end - y0,
        planes: planes.start - z0..planes.end - z0,
    };
    let input = BoundaryInput { g: &g, f2: &f2, normal: &normal, value_range: 255.0 };
    let block = trace_block(&input, &params, &place, &stats).unwrap();
    assert_eq!(block.distance.geometry.dims, [40, rows.len(), planes.len()]);
    let mut hits = 0;
    for (name, b, w) in [
        ("distance", &block.distance, &whole.distance),
        ("g_hit", &block.g_hit, &whole.g_hit),
        ("dot", &block.dot, &whole.dot),
        ("hit", &block.hit, &whole.hit),
    ] {
        for ((k, j, i), p) in b.data.indexed_iter() {
            let q = w.data[[planes.start + k, rows.start + j, i]];
            assert_eq!(p.to_bits(), q.to_bits(), "{name} at ({i}, {j}, {k}): {p} vs {q}");
        }
        hits += b.data.iter().filter(|&&h| name == "hit" && h == 1.0).count();
    }
    assert!(hits > 100, "the block holds traced boundary voxels ({hits})");
}

#[test]
fn a_block_traced_into_the_memory_of_another_has_the_bits_of_a_fresh_one() {
    use mdtf_boundary::{BlockPlace, VolumeStats, trace_block, trace_block_into};
    let geo = Geometry::new([30, 28, 26], [1.0, 0.9, 1.1]);
    let d = derive(&RadialPhantom::tooth(geo, 1.5).volume());
    let params = BoundaryParams { d_max: Some(4.0), ..BoundaryParams::default() };
    let stats = VolumeStats::of(&d.g, 255.0);
    let input = BoundaryInput { g: &d.g, f2: &d.f2, normal: &d.normal, value_range: 255.0 };
    let place = |rows: std::ops::Range<usize>, planes| BlockPlace { first: [0; 3], rows, planes };
    let bits = |v: &Volume| v.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    // a larger block's and a smaller block's outputs, marked where the tracing may leave a voxel alone
    for spent_place in [place(0..28, 0..26), place(3..5, 7..8)] {
        let mut spent = trace_block(&input, &params, &spent_place, &stats).unwrap();
        for v in [&mut spent.distance, &mut spent.g_hit, &mut spent.hit, &mut spent.dot] {
            v.data.fill(-7.0);
        }
        let at = place(4..20, 6..17);
        let fresh = trace_block(&input, &params, &at, &stats).unwrap();
        let reused = trace_block_into(&input, &params, &at, &stats, Some(spent)).unwrap();
        for (a, b) in [(&reused.distance, &fresh.distance), (&reused.g_hit, &fresh.g_hit), (&reused.hit, &fresh.hit)] {
            assert_eq!((&a.geometry, bits(a)), (&b.geometry, bits(b)));
        }
        assert_eq!(bits(&reused.dot), bits(&fresh.dot));
        assert!(fresh.hit.data.iter().any(|&h| h == 0.0), "the block has voxels the tracing leaves alone");
    }
}

#[test]
fn bad_input_is_refused() {
    let ph = erf_sphere(Geometry::new([24; 3], [1.0; 3]), 7.0, 1.5, 0.0, 255.0, None);
    let d = derive(&ph.volume());
    let other = erf_sphere(Geometry::new([24; 3], [1.0, 1.0, 2.0]), 7.0, 1.5, 0.0, 255.0, None).volume();
    let e =
        run(&BoundaryInput { g: &d.g, f2: &other, normal: &d.normal, value_range: 255.0 }, &BoundaryParams::default());
    assert!(e.unwrap_err().to_string().contains("must share one grid"));
    for (p, what) in [
        (BoundaryParams { step: Some(0.0), ..Default::default() }, "boundary.step must be positive"),
        (BoundaryParams { d_max: Some(-1.0), ..Default::default() }, "boundary.d_max must be positive"),
        (BoundaryParams { d_max: Some(100.0), ..Default::default() }, "larger than the volume"),
    ] {
        let e = run(&BoundaryInput { g: &d.g, f2: &d.f2, normal: &d.normal, value_range: 255.0 }, &p)
            .unwrap_err()
            .to_string();
        assert!(e.contains(what), "{e}");
    }
}

/// Per boundary of the shells (outermost first): the share of the voxels
/// within one voxel of its radius that were kept with g_hit within 5 % of
/// its peak |jump| / (sigma sqrt(2 pi)).
fn kept_per_boundary(ph: &RadialPhantom, out: &BoundaryOutput) -> Vec<f64> {
    let mut outer = ph.outside;
    let [nx, ny, _] = ph.geometry.dims;
    let c = ph.centre;
    ph.boundaries
        .iter()
        .map(|b| {
            let peak = (b.inside - outer).abs() / (ph.sigma * (2.0 * PI).sqrt());
            outer = b.inside;
            let (mut near, mut kept) = (0usize, 0usize);
            for i in 0..out.hit.samples().len() {
                let (x, y, z) = ((i % nx) as f64, ((i / nx) % ny) as f64, (i / (nx * ny)) as f64);
                let rho = ((x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt();
                if (rho - b.radius).abs() <= 1.0 {
                    near += 1;
                    let gh = out.g_hit.samples()[i] as f64;
                    if out.hit.samples()[i] == 1.0 && ((gh - peak) / peak).abs() <= 0.05 {
                        kept += 1;
                    }
                }
            }
            kept as f64 / near as f64
        })
        .collect()
}

#[test]
fn shells_keep_every_boundary_by_default_and_a_threshold_that_cuts_one_is_reported() {
    let sigma = 2.0;
    let ph = RadialPhantom::tooth(Geometry::new([128; 3], [1.0; 3]), sigma);
    let d = derive(&ph.volume());
    let range = 210.0; // enamel 230 over background 20
    let run_with = |p: &BoundaryParams| {
        run(&BoundaryInput { g: &d.g, f2: &d.f2, normal: &d.normal, value_range: range }, p).unwrap()
    };
    let out = run_with(&BoundaryParams::default());
    let kept = kept_per_boundary(&ph, &out);
    eprintln!("defaults: kept per boundary {kept:?}, {:?}, {:?}", out.resolved, out.counts);
    assert!(kept.iter().all(|&k| k >= 0.95), "{kept:?}");
    assert!(out.lost.is_empty() && out.warnings.is_empty(), "{:?}", out.warnings);

    // the paper's Fig. 2 threshold at the hit, 20 x 210 / 255 = 16.5, is above the
    // dentin-pulp peak of 80 / (2 sqrt(2 pi)) = 15.96
    let pulp_peak = 80.0 / (sigma * (2.0 * PI).sqrt());
    let cut = run_with(&BoundaryParams { g_hit_min: Some(20.0 * range / 255.0), ..Default::default() });
    let kept = kept_per_boundary(&ph, &cut);
    eprintln!("g_hit_min 16.5: kept {kept:?}, lost {:?}", cut.lost);
    assert!(kept[0] >= 0.95 && kept[1] >= 0.95 && kept[2] == 0.0, "{kept:?}");
    assert_eq!(cut.lost.len(), 1, "{:?}", cut.lost);
    assert!((cut.lost[0].g_peak - pulp_peak).abs() / pulp_peak < 0.03, "{:?}", cut.lost);
    assert!(cut.warnings[0].contains("below g_hit_min 16.47"), "{}", cut.warnings[0]);
    // the same cut made at the voxel: its voxels are not traced, and it is still reported
    let cut = run_with(&BoundaryParams { g_min: Some(16.5), ..Default::default() });
    assert_eq!(cut.lost.len(), 1, "{:?}", cut.lost);
    assert!(cut.warnings[0].contains("below g_min 16.5"), "{}", cut.warnings[0]);
}

#[test]
fn the_noise_floor_is_twice_the_median_g_or_a_thousandth_of_the_range() {
    // 1000 samples: the median (the 500th smallest) is 499
    let g: Vec<f32> = (0..1000).rev().map(|k| k as f32).collect();
    assert_eq!(mdtf_boundary::noise_floor(&g, 255.0, 1.0), 998.0);
    assert_eq!(mdtf_boundary::noise_floor(&[0.0; 10], 255.0, 0.5), 0.51);
    assert_eq!(mdtf_boundary::noise_floor(&[], 1000.0, 1.0), 1.0);
}
