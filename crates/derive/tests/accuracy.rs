//! The derive stage against analytic ground truth (the erf sphere of
//! DESIGN.md) and against a plain brute-force convolution written here.

use mdtf_datagen::{MultiFieldPhantom, RadialPhantom, erf_sphere};
use mdtf_derive::{Border, DeriveError, DeriveParams, Item, Kernel, run};
use mdtf_volume::{Geometry, MultiField, Volume};
use ndarray::Array3;
use std::f64::consts::PI;

struct ShellErrors {
    g: f64,
    f2: f64,
}

/// Mean |error| over the shell |x| < 2 sigma, divided by the analytic peaks
/// (peak g = A, peak |f''| = A e^(-1/2) / sigma), as the issue defines them.
fn sphere_errors(ph: &RadialPhantom, kernel: Kernel) -> ShellErrors {
    let input = MultiField::from(ph.volume());
    let params = DeriveParams { items: vec![Item::G, Item::F2], kernel, ..DeriveParams::default() };
    let out = run(&input, &params).unwrap();
    let truth = ph.truth();
    let s = ph.sigma;
    let b = ph.boundaries[0];
    let a = (b.inside - ph.outside) / (s * (2.0 * PI).sqrt());
    let (peak_g, peak_f2) = (a, a * (-0.5f64).exp() / s);
    let g = &out.get(Item::G).unwrap().fields[0].data;
    let f2 = &out.get(Item::F2).unwrap().fields[0].data;
    let (mut eg, mut ef, mut n) = (0.0, 0.0, 0usize);
    for ((idx, &x), (&tg, &tf)) in truth.x.data.indexed_iter().zip(truth.g.data.iter().zip(truth.f2.data.iter())) {
        if (x as f64).abs() < 2.0 * s {
            eg += (g[idx] as f64 - tg as f64).abs();
            ef += (f2[idx] as f64 - tf as f64).abs();
            n += 1;
        }
    }
    assert!(n > 10_000, "shell too small: {n}");
    ShellErrors { g: eg / n as f64 / peak_g, f2: ef / n as f64 / peak_f2 }
}

fn issue_sphere() -> RadialPhantom {
    erf_sphere(Geometry::new([128; 3], [1.0; 3]), 38.4, 3.0, 0.0, 255.0, None)
}

#[test]
fn default_kernel_meets_the_erf_sphere_bounds() {
    let e = sphere_errors(&issue_sphere(), DeriveParams::default().kernel);
    eprintln!("default kernel: mean g error {:.3e}, mean f'' error {:.3e}", e.g, e.f2);
    assert!(e.g <= 3e-4, "g error {:.3e}", e.g);
    assert!(e.f2 <= 3e-3, "f'' error {:.3e}", e.f2);
}

#[test]
fn default_is_the_most_accurate_family_and_central_matches_numpy() {
    let ph = issue_sphere();
    let default = sphere_errors(&ph, DeriveParams::default().kernel);
    for k in ["central", "bspline3", "catmull-rom", "gauss:1", "gauss:0.7"] {
        let e = sphere_errors(&ph, k.parse().unwrap());
        eprintln!("{k}: g {:.3e}, f'' {:.3e}", e.g, e.f2);
        assert!(e.g > default.g && e.f2 > default.f2, "{k} beats the default");
    }
    // Central differences: numpy.gradient and SimpleITK measure 0.0052 mean g error here (peers/RESULTS.md).
    let c = sphere_errors(&ph, Kernel::Central);
    assert!((c.g - 0.0052).abs() < 0.0003, "central g error {:.4}", c.g);
}

#[test]
fn anisotropic_spacing_meets_the_same_bounds_in_world_units() {
    // Spacing (0.5, 0.5, 2.0); sigma = 3 samples along the coarsest axis.
    let g = Geometry::new([264, 264, 66], [0.5, 0.5, 2.0]);
    let ph = erf_sphere(g, 48.0, 6.0, 0.0, 255.0, None);
    let e = sphere_errors(&ph, DeriveParams::default().kernel);
    eprintln!("anisotropic: g {:.3e}, f'' {:.3e}", e.g, e.f2);
    assert!(e.g <= 3e-4 && e.f2 <= 3e-3, "g {:.3e} f'' {:.3e}", e.g, e.f2);
}

/// Position of the first sign change of `f` (from the centre outwards) by linear interpolation.
fn zero_crossing(samples: &[f32]) -> Option<f64> {
    for i in 0..samples.len() - 1 {
        let (a, b) = (samples[i] as f64, samples[i + 1] as f64);
        if a < 0.0 && b >= 0.0 {
            return Some(i as f64 + a / (a - b));
        }
    }
    None
}

#[test]
fn f2_zero_crossing_along_axis_lines_is_within_two_hundredths_of_a_voxel() {
    let ph = issue_sphere();
    let input = MultiField::from(ph.volume());
    let out = run(&input, &DeriveParams { items: vec![Item::F2], ..DeriveParams::default() }).unwrap();
    let f2 = &out.get(Item::F2).unwrap().fields[0].data;
    let c = 63.5;
    let r = 38.4f64;
    let mut worst = 0.0f64;
    for (j, k) in [(63usize, 64usize), (64, 64), (60, 70), (70, 55)] {
        let (dj, dk) = (j as f64 - c, k as f64 - c);
        let expect = (r * r - dj * dj - dk * dk).sqrt();
        // along +x from the centre, -x, and the same lines along y and z
        let lines: [Vec<f32>; 4] = [
            (64..128).map(|i| f2[[k, j, i]]).collect(),
            (0..64).rev().map(|i| f2[[k, j, i]]).collect(),
            (64..128).map(|i| f2[[k, i, j]]).collect(),
            (64..128).map(|i| f2[[i, k, j]]).collect(),
        ];
        for line in &lines {
            let found = zero_crossing(line).expect("a zero crossing") + 0.5; // index 0 is 0.5 from the centre
            worst = worst.max((found - expect).abs());
        }
    }
    eprintln!("worst zero-crossing error {worst:.4} voxel");
    assert!(worst <= 0.02, "{worst}");
}

fn random_volume(dims: [usize; 3], spacing: [f64; 3], seed: u64) -> Volume {
    let mut state = seed;
    let data = Array3::from_shape_simple_fn((dims[2], dims[1], dims[0]), || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) as f64 / (1u64 << 31) as f64 * 200.0 - 100.0) as f32
    });
    Volume::new(Geometry::new(dims, spacing), data).unwrap()
}

/// The 1D stencils of each family, written out again here: value, first, second (unit spacing).
fn stencils(kernel: &str) -> [Vec<f64>; 3] {
    match kernel {
        "central" => [vec![0.0, 1.0, 0.0], vec![-0.5, 0.0, 0.5], vec![1.0, -2.0, 1.0]],
        "central4" => [
            vec![0.0, 0.0, 1.0, 0.0, 0.0],
            vec![1.0 / 12.0, -2.0 / 3.0, 0.0, 2.0 / 3.0, -1.0 / 12.0],
            vec![-1.0 / 12.0, 4.0 / 3.0, -2.5, 4.0 / 3.0, -1.0 / 12.0],
        ],
        "bspline3" => [vec![1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0], vec![-0.5, 0.0, 0.5], vec![1.0, -2.0, 1.0]],
        "catmull-rom" => {
            [vec![0.0, 0.0, 1.0, 0.0, 0.0], vec![0.0, -0.5, 0.0, 0.5, 0.0], vec![-0.5, 3.0, -5.0, 3.0, -0.5]]
        }
        _ => unreachable!(),
    }
}

/// Brute force: a full 3D correlation with the outer product of 1D stencils, indices mapped by `border`.
fn brute(v: &Volume, st: &[Vec<f64>; 3], orders: [usize; 3], at: [usize; 3], border: Border) -> f64 {
    let [nx, ny, nz] = v.geometry.dims;
    let r = st[0].len() as isize / 2;
    let mut sum = 0.0;
    for dz in -r..=r {
        for dy in -r..=r {
            for dx in -r..=r {
                let w = st[orders[0]][(dx + r) as usize]
                    * st[orders[1]][(dy + r) as usize]
                    * st[orders[2]][(dz + r) as usize];
                let i = border.index(at[0] as isize + dx, nx);
                let j = border.index(at[1] as isize + dy, ny);
                let k = border.index(at[2] as isize + dz, nz);
                sum += w * v.data[[k, j, i]] as f64;
            }
        }
    }
    let s = v.geometry.spacing;
    sum / (0..3).map(|a| s[a].powi(orders[a] as i32)).product::<f64>()
}

/// Worst relative differences (first derivatives, second derivatives, f'')
/// between `kernel` on `v` and the brute-force correlation with `st`.
fn brute_force_differences(v: &Volume, kernel: &str, st: &[Vec<f64>; 3], border: Border) -> [f64; 3] {
    let input = MultiField::from(v.clone());
    let items = vec![Item::Value, Item::Grad, Item::Hessian, Item::F2, Item::Laplacian];
    let out =
        run(&input, &DeriveParams { items, kernel: kernel.parse().unwrap(), border, ..Default::default() }).unwrap();
    let value = &out.get(Item::Value).unwrap().fields;
    let grad = &out.get(Item::Grad).unwrap().fields;
    let hess = &out.get(Item::Hessian).unwrap().fields;
    let f2 = &out.get(Item::F2).unwrap().fields[0].data;
    let lap = &out.get(Item::Laplacian).unwrap().fields[0].data;
    let rel = |a: f64, b: f64, scale: f64| (a - b).abs() / scale;
    let mut worst = [0.0f64; 3];
    let [nx, ny, nz] = v.geometry.dims;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let at = [i, j, k];
                let b = |o: [usize; 3]| brute(v, st, o, at, border);
                let g = [b([1, 0, 0]), b([0, 1, 0]), b([0, 0, 1])];
                let h = [b([2, 0, 0]), b([1, 1, 0]), b([1, 0, 1]), b([0, 2, 0]), b([0, 1, 1]), b([0, 0, 2])];
                assert!(rel(value[0].data[[k, j, i]] as f64, b([0, 0, 0]), 100.0) < 1e-5, "{kernel} value");
                for c in 0..3 {
                    worst[0] = worst[0].max(rel(grad[c].data[[k, j, i]] as f64, g[c], 300.0));
                }
                for c in 0..6 {
                    worst[1] = worst[1].max(rel(hess[c].data[[k, j, i]] as f64, h[c], 1000.0));
                }
                worst[1] = worst[1].max(rel(lap[[k, j, i]] as f64, h[0] + h[3] + h[5], 1000.0));
                let gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
                let q = g[0] * g[0] * h[0]
                    + g[1] * g[1] * h[3]
                    + g[2] * g[2] * h[5]
                    + 2.0 * (g[0] * g[1] * h[1] + g[0] * g[2] * h[2] + g[1] * g[2] * h[4]);
                if gg > 1.0 {
                    worst[2] = worst[2].max(rel(f2[[k, j, i]] as f64, q / gg, 1000.0));
                }
            }
        }
    }
    worst
}

#[test]
fn every_kernel_equals_a_brute_force_convolution() {
    // 11 samples along x: short rows; 37: central's block path (16-sample
    // blocks, the last one overlapping) as well as its row ends.
    for dims in [[11, 9, 8], [37, 6, 5]] {
        let v = random_volume(dims, [0.7, 1.0, 1.6], 42);
        for name in ["central", "central4", "bspline3", "catmull-rom"] {
            let borders: &[Border] =
                if name == "central" { &[Border::Clamp, Border::Mirror, Border::Wrap] } else { &[Border::Clamp] };
            for &border in borders {
                let worst = brute_force_differences(&v, name, &stencils(name), border);
                assert!(worst.iter().all(|w| *w < 1e-5), "{name} {dims:?} {border:?}: {worst:?}");
            }
        }
    }
}

#[test]
fn gauss_equals_a_brute_force_convolution_with_its_own_taps() {
    let v = random_volume([16, 16, 12], [1.0, 0.8, 1.5], 7);
    let input = MultiField::from(v.clone());
    let kernel: Kernel = "gauss:1.2".parse().unwrap();
    let out =
        run(&input, &DeriveParams { items: vec![Item::Grad, Item::Hessian], kernel, ..Default::default() }).unwrap();
    let taps: Vec<_> = (0..3).map(|a| kernel.axis_taps(v.geometry.spacing[a])).collect();
    let [nx, ny, nz] = v.geometry.dims;
    let order_taps = |a: usize, o: usize| match o {
        0 => taps[a].d0.clone(),
        1 => taps[a].d1.clone(),
        _ => taps[a].d2.clone(),
    };
    for &(i, j, k) in &[(0usize, 0usize, 0usize), (5, 5, 4), (15, 15, 11), (3, 8, 1)] {
        for (c, orders) in [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 0, 2], [2, 0, 0]].iter().enumerate() {
            let mut sum = 0.0f64;
            for &(oz, wz) in &order_taps(2, orders[2]) {
                for &(oy, wy) in &order_taps(1, orders[1]) {
                    for &(ox, wx) in &order_taps(0, orders[0]) {
                        let ii = (i as isize + ox).clamp(0, nx as isize - 1) as usize;
                        let jj = (j as isize + oy).clamp(0, ny as isize - 1) as usize;
                        let kk = (k as isize + oz).clamp(0, nz as isize - 1) as usize;
                        sum += wx as f64 * wy as f64 * wz as f64 * v.data[[kk, jj, ii]] as f64;
                    }
                }
            }
            let got = match c {
                0..=2 => out.get(Item::Grad).unwrap().fields[c].data[[k, j, i]],
                3 => out.get(Item::Hessian).unwrap().fields[1].data[[k, j, i]],
                4 => out.get(Item::Hessian).unwrap().fields[5].data[[k, j, i]],
                _ => out.get(Item::Hessian).unwrap().fields[0].data[[k, j, i]],
            };
            assert!((got as f64 - sum).abs() < 1e-5 * 300.0, "component {c} at {i},{j},{k}: {got} vs {sum}");
        }
    }
}

#[test]
fn linear_and_quadratic_ramps_are_exact_in_world_units() {
    let g = Geometry::new([24, 16, 12], [0.5, 0.75, 2.0]);
    let ramp = Array3::from_shape_fn(g.shape(), |(k, j, i)| {
        let (x, y, z) = (i as f64 * 0.5, j as f64 * 0.75, k as f64 * 2.0);
        (3.0 * x + 2.0 * y - z + 0.25 * x * x + 0.5 * x * y - 0.125 * z * z) as f32
    });
    let input = MultiField::from(Volume::new(g, ramp).unwrap());
    for name in ["central", "central4", "bspline3", "catmull-rom", "gauss:0.8"] {
        let out = run(
            &input,
            &DeriveParams {
                items: vec![Item::Grad, Item::Hessian],
                kernel: name.parse().unwrap(),
                ..Default::default()
            },
        )
        .unwrap();
        let (i, j, k) = (12usize, 8usize, 6usize);
        let (x, y, z) = (6.0, 6.0, 12.0);
        let want_g = [3.0 + 0.5 * x + 0.5 * y, 2.0 + 0.5 * x, -1.0 - 0.25 * z];
        let want_h = [0.5, 0.5, 0.0, 0.0, 0.0, -0.25];
        let gr = &out.get(Item::Grad).unwrap().fields;
        let he = &out.get(Item::Hessian).unwrap().fields;
        let tol = 1e-3;
        for c in 0..3 {
            assert!(
                (gr[c].data[[k, j, i]] as f64 - want_g[c]).abs() < tol,
                "{name} grad {c}: {}",
                gr[c].data[[k, j, i]]
            );
        }
        for c in 0..6 {
            assert!(
                (he[c].data[[k, j, i]] as f64 - want_h[c]).abs() < tol,
                "{name} hessian {c}: {}",
                he[c].data[[k, j, i]]
            );
        }
    }
}

#[test]
fn multi_field_gnorm_is_within_a_thousandth_of_the_analytic_value() {
    let g = Geometry::new([128; 3], [1.0; 3]);
    let ph = MultiFieldPhantom::new(g, 3.0);
    let fields = ph.volume();
    let truth = ph.truth(&fields);
    let out = run(&fields, &DeriveParams { items: vec![Item::Gnorm, Item::Jacobian], ..Default::default() }).unwrap();
    let gn = &out.get(Item::Gnorm).unwrap().fields[0].data;
    assert_eq!(out.get(Item::Jacobian).unwrap().fields.len(), 9);
    // "In the shells": voxels within 2 sigma of some field's boundary.
    let (mut sum, mut n) = (0.0, 0usize);
    for ((k, j, i), &t) in truth.gnorm.data.indexed_iter() {
        let p = [i as f64, j as f64, k as f64];
        let near = ph.fields.iter().any(|f| f.sphere.at(p).x.abs() < 2.0 * 3.0);
        if near && t > 0.0 {
            sum += ((gn[[k, j, i]] - t) / t).abs() as f64;
            n += 1;
        }
    }
    let mean = sum / n as f64;
    eprintln!("multi-field ||G||: mean relative error {mean:.3e} over {n} shell voxels");
    assert!(mean <= 1e-3, "{mean:e}");
}

/// G = D^T D of a 2 x 3 Jacobian `d` (rows: fields), and its Frobenius norm.
fn frobenius_of_dtd(d: &[[f64; 3]]) -> f64 {
    let mut sum = 0.0;
    for a in 0..3 {
        for b in 0..3 {
            let gab: f64 = d.iter().map(|row| row[a] * row[b]).sum();
            sum += gab * gab;
        }
    }
    sum.sqrt()
}

#[test]
fn multi_field_inv_g_is_one_over_the_root_of_gnorm_and_one_field_inv_g_is_one_over_g() {
    // two linear ramps, f0 = 3x + y and f1 = -2z, on an anisotropic grid:
    // normalised to [0, 1] over their ranges, D is constant and known
    let g = Geometry::new([20, 16, 12], [0.5, 1.0, 2.0]);
    let [nx, ny, nz] = [20.0, 16.0, 12.0];
    let f0 = Array3::from_shape_fn(g.shape(), |(_, j, i)| (3.0 * i as f64 * 0.5 + j as f64) as f32);
    let f1 = Array3::from_shape_fn(g.shape(), |(k, _, _)| (-2.0 * k as f64 * 2.0) as f32);
    let (r0, r1) = (3.0 * (nx - 1.0) * 0.5 + (ny - 1.0), 2.0 * (nz - 1.0) * 2.0);
    let fields = MultiField {
        geometry: g.clone(),
        fields: vec![
            mdtf_volume::Field { name: "a".into(), data: f0.clone() },
            mdtf_volume::Field { name: "b".into(), data: f1 },
        ],
    };
    let out = run(&fields, &DeriveParams { items: vec![Item::InvG, Item::Gnorm], ..Default::default() }).unwrap();
    let want_gnorm = frobenius_of_dtd(&[[3.0 / r0, 1.0 / r0, 0.0], [0.0, 0.0, -2.0 / r1]]);
    let (inv_g, gnorm) = (&out.get(Item::InvG).unwrap().fields[0].data, &out.get(Item::Gnorm).unwrap().fields[0].data);
    let at = [6, 8, 10];
    let (got_inv, got_gnorm) = (inv_g[at] as f64, gnorm[at] as f64);
    assert!((got_gnorm - want_gnorm).abs() < 1e-5 * want_gnorm, "{got_gnorm} vs {want_gnorm}");
    let want_inv = 1.0 / want_gnorm.sqrt();
    assert!((got_inv - want_inv).abs() < 1e-5 * want_inv, "{got_inv} vs {want_inv}");
    // one field: inv_g = 1 / g = 1 / |(3, 1, 0)|, in the field's own units
    let one = MultiField::from(Volume::new(g, f0).unwrap());
    let out = run(&one, &DeriveParams { items: vec![Item::InvG], ..Default::default() }).unwrap();
    let got = out.get(Item::InvG).unwrap().fields[0].data[at] as f64;
    assert!((got - 1.0 / 10f64.sqrt()).abs() < 1e-5, "{got}");
}

#[test]
fn results_are_bit_identical_with_one_and_two_threads() {
    let input = MultiField::from(RadialPhantom::tooth(Geometry::new([40, 36, 30], [1.0, 1.0, 1.5]), 2.0).volume());
    // with shade: the general pass; g, f2 and normal alone: the fused loop
    for items in [vec![Item::G, Item::F2, Item::Normal, Item::Shade], vec![Item::G, Item::F2, Item::Normal]] {
        let params = DeriveParams { items, ..Default::default() };
        let with = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| run(&input, &params).unwrap())
        };
        let (a, b) = (with(1), with(2));
        for ((_, x), (_, y)) in a.items.iter().zip(&b.items) {
            for (fx, fy) in x.fields.iter().zip(&y.fields) {
                assert!(fx.data.iter().zip(fy.data.iter()).all(|(p, q)| p.to_bits() == q.to_bits()), "{}", fx.name);
            }
        }
    }
}

/// Components of `item` in `out`, as raw bits.
fn bits(out: &mdtf_derive::DeriveOutput, item: Item) -> Vec<Vec<u32>> {
    let fields = &out.get(item).unwrap().fields;
    fields.iter().map(|f| f.data.iter().map(|v| v.to_bits()).collect()).collect()
}

#[test]
fn fused_g_normal_f2_loop_equals_the_general_pass_bit_for_bit() {
    // f2, alone or with g and the normal, takes the fused loop for central;
    // adding the Laplacian forces the general pass. (The other kernels take
    // the general pass either way; they stay in the loop in case that changes.)
    // 5 samples along x leave central4 one interior sample.
    for dims in [[5, 6, 5], [11, 9, 8], [37, 6, 5]] {
        let input = MultiField::from(random_volume(dims, [0.7, 1.0, 1.6], 9));
        for name in ["central", "central4", "catmull-rom", "bspline3"] {
            for border in [Border::Clamp, Border::Mirror, Border::Wrap] {
                let params = |items: Vec<Item>| DeriveParams {
                    items,
                    kernel: name.parse().unwrap(),
                    border,
                    ..Default::default()
                };
                let general = run(&input, &params(vec![Item::G, Item::Normal, Item::F2, Item::Laplacian])).unwrap();
                let fused = run(&input, &params(vec![Item::F2, Item::G, Item::Normal])).unwrap();
                for item in [Item::G, Item::Normal, Item::F2] {
                    assert!(bits(&fused, item) == bits(&general, item), "{name} {dims:?} {border:?} {item}");
                    let alone = run(&input, &params(vec![item])).unwrap();
                    assert!(bits(&alone, item) == bits(&general, item), "{name} {dims:?} {border:?} {item} alone");
                }
            }
        }
    }
}

#[test]
#[allow(clippy::single_range_in_vec_init)] // a one-slab list is one of the cases
fn streamed_slices_equal_the_whole_volume_pass() {
    let input = MultiField::from(RadialPhantom::tooth(Geometry::new([40, 36, 30], [1.0, 1.0, 1.5]), 2.0).volume());
    let params = DeriveParams { items: vec![Item::G, Item::F2, Item::Normal], ..Default::default() };
    let whole = run(&input, &params).unwrap();
    let plane = 40 * 36;
    for slabs in [vec![0..30], vec![0..7, 7..8, 8..20, 20..30], vec![10..30, 0..10, 30..40]] {
        // each task copies its slices into its own full-size volumes
        let parts = mdtf_derive::stream_slices(
            &input,
            &params,
            &slabs,
            |_| (vec![0.0f32; plane * 30 * 5], vec![false; 30]),
            |(vols, seen), k, comps| {
                assert_eq!(comps.len(), 5, "g, f2, nx, ny, nz");
                for (c, slice) in comps.iter().enumerate() {
                    vols[(c * 30 + k) * plane..(c * 30 + k + 1) * plane].copy_from_slice(slice);
                }
                seen[k] = true;
            },
        )
        .unwrap();
        assert_eq!(parts.len(), slabs.len());
        let mut covered = 0;
        for (vols, seen) in &parts {
            for k in (0..30).filter(|&k| seen[k]) {
                covered += 1;
                let expected = whole.items.iter().flat_map(|(_, mf)| mf.fields.iter());
                for (c, field) in expected.enumerate() {
                    let want = &field.data.as_slice().unwrap()[k * plane..(k + 1) * plane];
                    let got = &vols[(c * 30 + k) * plane..(c * 30 + k + 1) * plane];
                    assert!(want.iter().zip(got).all(|(p, q)| p.to_bits() == q.to_bits()), "{} k {k}", field.name);
                }
            }
        }
        assert_eq!(covered, 30, "every slice exactly once");
    }
    let shade = DeriveParams { items: vec![Item::Shade], ..Default::default() };
    let e = mdtf_derive::stream_slices(&input, &shade, &[0..30], |_| (), |_, _, _| {}).unwrap_err();
    assert!(e.to_string().contains("largest g"), "{e}");
}

#[test]
fn derived_channels_follow_their_definitions() {
    let ph = erf_sphere(Geometry::new([40; 3], [1.0; 3]), 12.0, 2.0, 0.0, 100.0, None);
    let input = MultiField::from(ph.volume());
    let params = DeriveParams {
        items: vec![Item::G, Item::InvG, Item::Shade, Item::Normal, Item::Laplacian, Item::Hessian],
        epsilon: Some(1e-3),
        ..Default::default()
    };
    let out = run(&input, &params).unwrap();
    let g = &out.get(Item::G).unwrap().fields[0].data;
    let inv = &out.get(Item::InvG).unwrap().fields[0].data;
    let shade = &out.get(Item::Shade).unwrap().fields[0].data;
    let n = &out.get(Item::Normal).unwrap().fields;
    let gmax = g.iter().copied().fold(0.0f32, f32::max);
    for (idx, &gv) in g.indexed_iter() {
        assert!((inv[idx] - 1.0 / gv.max(1e-3)).abs() <= 1e-6 * inv[idx].abs());
        let t = 1.0 - gv / gmax;
        assert!((shade[idx] - (1.0 - t * t)).abs() < 1e-6);
        let len = (n[0].data[idx].powi(2) + n[1].data[idx].powi(2) + n[2].data[idx].powi(2)).sqrt();
        assert!(if gv >= 1e-3 { (len - 1.0).abs() < 1e-5 } else { len == 0.0 });
    }
    assert!(shade.iter().any(|&s| s == 1.0));
}

#[test]
fn bad_input_is_refused_with_clear_errors() {
    let small = MultiField::from(Volume::zeros(Geometry::new([3, 8, 8], [1.0; 3])));
    let e = run(&small, &DeriveParams::default()).unwrap_err();
    assert!(matches!(e, DeriveError::TooSmall { need: 5, axis: 'x', .. }), "{e}");
    let mut bad = MultiField::from(Volume::zeros(Geometry::new([8, 8, 8], [1.0; 3])));
    bad.geometry.spacing[1] = 0.0;
    assert!(matches!(run(&bad, &DeriveParams::default()), Err(DeriveError::BadSpacing(_))));
    let two = MultiFieldPhantom::new(Geometry::new([16; 3], [1.0; 3]), 1.0).volume();
    let e = run(&two, &DeriveParams::default()).unwrap_err().to_string();
    assert!(e.contains("need one field"), "{e}");
    let e = run(&two, &DeriveParams { items: vec![Item::Gnorm, Item::G], ..Default::default() }).unwrap_err();
    assert!(matches!(e, DeriveError::FieldCount(_)));
    let mut nan = MultiField::from(Volume::zeros(Geometry::new([8, 8, 8], [1.0; 3])));
    nan.fields[0].data[[1, 1, 1]] = f32::NAN;
    assert!(matches!(run(&nan, &DeriveParams::default()), Err(DeriveError::NonFinite(_))));
    assert!(matches!(run(&two, &DeriveParams { items: vec![], ..Default::default() }), Err(DeriveError::NoItems)));
}

#[test]
fn border_policies_differ_only_at_the_border() {
    let v = random_volume([10, 10, 10], [1.0; 3], 3);
    let input = MultiField::from(v);
    let grad = |border| {
        run(&input, &DeriveParams { items: vec![Item::Grad], kernel: Kernel::Central, border, ..Default::default() })
            .unwrap()
    };
    let (c, m, w) = (grad(Border::Clamp), grad(Border::Mirror), grad(Border::Wrap));
    let gx = |o: &mdtf_derive::DeriveOutput| o.get(Item::Grad).unwrap().fields[0].data.clone();
    let (c, m, w) = (gx(&c), gx(&m), gx(&w));
    assert_eq!(c[[5, 5, 5]], m[[5, 5, 5]]);
    assert_eq!(c[[5, 5, 5]], w[[5, 5, 5]]);
    // mirror: f[-1] = f[1], so the central difference at the edge is 0
    assert_eq!(m[[4, 4, 0]], 0.0);
    let d = &input.fields[0].data;
    assert_eq!(c[[4, 4, 0]], (d[[4, 4, 1]] - d[[4, 4, 0]]) * 0.5);
    assert_eq!(w[[4, 4, 0]], (d[[4, 4, 1]] - d[[4, 4, 9]]) * 0.5);
}

/// Mean relative error of the mean curvature against 1/rho, the curvature
/// of the sphere of radius rho through each voxel (every isosurface of a
/// radial field is one), over the shell |x| < 2 sigma.
fn curvature_error(ph: &RadialPhantom, kernel: Kernel) -> f64 {
    let input = MultiField::from(ph.volume());
    let params = DeriveParams { items: vec![Item::Curvature], kernel, ..DeriveParams::default() };
    let out = run(&input, &params).unwrap();
    let k = &out.get(Item::Curvature).unwrap().fields[0].data;
    let truth = ph.truth();
    let (mut e, mut n) = (0.0, 0usize);
    for ((z, y, x), &d) in truth.x.data.indexed_iter() {
        if (d as f64).abs() < 2.0 * ph.sigma {
            let p = mdtf_datagen::voxel_position(&ph.geometry, x, y, z);
            let rho = (0..3).map(|a| (p[a] - ph.centre[a]).powi(2)).sum::<f64>().sqrt();
            e += (k[[z, y, x]] as f64 * rho - 1.0).abs();
            n += 1;
        }
    }
    assert!(n > 10_000, "shell too small: {n}");
    e / n as f64
}

#[test]
fn the_mean_curvature_is_one_over_the_radius_on_the_erf_sphere() {
    let e = curvature_error(&issue_sphere(), DeriveParams::default().kernel);
    eprintln!("curvature, default kernel: mean relative error {e:.3e}");
    assert!(e < 5e-3, "mean relative error {e:.3e}");
    // anisotropic voxels, the sphere dark on a bright background: the sign follows the brighter side
    let g = Geometry::new([72, 60, 90], [1.0, 1.2, 0.8]);
    let dark = erf_sphere(g.clone(), 24.0, 2.5, 200.0, 10.0, None);
    let e = curvature_error(&dark, DeriveParams::default().kernel);
    eprintln!("curvature, dark anisotropic sphere: mean relative error against -1/rho {e:.3e}");
    assert!(e > 1.9, "a dark sphere's curvature is negative: {e:.3e}");
    let flipped = curvature_error(&erf_sphere(g, 24.0, 2.5, 10.0, 200.0, None), DeriveParams::default().kernel);
    assert!(flipped < 1e-2, "mean relative error {flipped:.3e}");
}
