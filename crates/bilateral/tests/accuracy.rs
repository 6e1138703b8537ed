//! The bilateral filter against a brute-force triple loop written here, and
//! its effect on the noisy erf sphere against the analytic truth.

use mdtf_bilateral::{BilateralError, BilateralParams, Mode, RangeUnits, run};
use mdtf_datagen::{add_gaussian_noise, erf_sphere};
use mdtf_derive::{DeriveParams, Item, Kernel};
use mdtf_volume::{Geometry, MultiField, Volume};
use ndarray::Array3;

/// The definition, in f64, with clamped borders and the box radius ceil(k sigma_d / s).
fn brute_force(v: &Volume, sigma_d: f64, sigma_r: f64, k: f64) -> Array3<f64> {
    let g = &v.geometry;
    let [nx, ny, nz] = g.dims;
    let r: Vec<isize> = (0..3).map(|a| (k * sigma_d / g.spacing[a] - 1e-9).ceil() as isize).collect();
    let at = |i: isize, j: isize, kk: isize| {
        v.data[[
            kk.clamp(0, nz as isize - 1) as usize,
            j.clamp(0, ny as isize - 1) as usize,
            i.clamp(0, nx as isize - 1) as usize,
        ]] as f64
    };
    Array3::from_shape_fn((nz, ny, nx), |(kk, j, i)| {
        let c = at(i as isize, j as isize, kk as isize);
        let (mut num, mut den) = (0.0, 0.0);
        for dz in -r[2]..=r[2] {
            for dy in -r[1]..=r[1] {
                for dx in -r[0]..=r[0] {
                    let f = at(i as isize + dx, j as isize + dy, kk as isize + dz);
                    let d2 = (dx as f64 * g.spacing[0]).powi(2)
                        + (dy as f64 * g.spacing[1]).powi(2)
                        + (dz as f64 * g.spacing[2]).powi(2);
                    let w =
                        (-d2 / (2.0 * sigma_d * sigma_d)).exp() * (-(f - c).powi(2) / (2.0 * sigma_r * sigma_r)).exp();
                    num += w * f;
                    den += w;
                }
            }
        }
        num / den
    })
}

fn assert_matches_brute_force(v: &Volume, sigma_d: f64, sigma_r: f64) {
    let p = BilateralParams { sigma_d, sigma_r, range_units: RangeUnits::Value, ..Default::default() };
    let out = run(v, &p).unwrap();
    let want = brute_force(v, sigma_d, sigma_r, 2.5);
    let (lo, hi) = v.finite_range().unwrap();
    let scale = (hi - lo) as f64;
    let worst = out.data.iter().zip(want.iter()).map(|(&a, &b)| (a as f64 - b).abs() / scale).fold(0.0, f64::max);
    assert!(worst < 1e-5, "worst relative difference {worst:e}");
}

fn random_volume(dims: [usize; 3], spacing: [f64; 3]) -> Volume {
    let mut state = 12345u64;
    let data = Array3::from_shape_simple_fn((dims[2], dims[1], dims[0]), || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) as f64 / (1u64 << 31) as f64 * 100.0) as f32
    });
    Volume::new(Geometry::new(dims, spacing), data).unwrap()
}

fn noisy_sphere(n: usize, spacing: [f64; 3], noise: f64) -> (Volume, Volume) {
    let g = Geometry::new([n; 3], spacing);
    let e = mdtf_datagen::min_extent(&g);
    let clean = erf_sphere(g, 0.3 * e, 3.0 * spacing[0], 0.0, 255.0, None).volume();
    let mut noisy = clean.clone();
    add_gaussian_noise(&mut noisy, noise, 7);
    (clean, noisy)
}

#[test]
fn exact_mode_equals_the_brute_force_sum_on_random_data() {
    assert_matches_brute_force(&random_volume([14, 12, 10], [1.0; 3]), 1.0, 20.0);
    assert_matches_brute_force(&random_volume([14, 12, 10], [0.5, 0.8, 1.6]), 1.1, 30.0);
}

#[test]
fn exact_mode_equals_the_brute_force_sum_on_the_noisy_sphere() {
    let (_, noisy) = noisy_sphere(20, [1.0; 3], 20.0);
    assert_matches_brute_force(&noisy, 1.0, 25.0);
    let (_, noisy) = noisy_sphere(20, [0.5, 0.5, 1.25], 20.0);
    assert_matches_brute_force(&noisy, 0.8, 40.0);
}

/// Mean radius of the f'' zero crossing (inside negative to outside positive)
/// over rays from the centre, f'' sampled by trilinear interpolation.
fn mean_zero_crossing_radius(f2: &Array3<f32>, centre: f64, r: f64) -> f64 {
    let n = f2.dim().0;
    let sample = |p: [f64; 3]| {
        let i = p.map(|c| c.floor() as usize);
        let t = [p[0] - i[0] as f64, p[1] - i[1] as f64, p[2] - i[2] as f64];
        let mut v = 0.0;
        for (dz, wz) in [(0, 1.0 - t[2]), (1, t[2])] {
            for (dy, wy) in [(0, 1.0 - t[1]), (1, t[1])] {
                for (dx, wx) in [(0, 1.0 - t[0]), (1, t[0])] {
                    v += wx
                        * wy
                        * wz
                        * f2[[(i[2] + dz).min(n - 1), (i[1] + dy).min(n - 1), (i[0] + dx).min(n - 1)]] as f64;
                }
            }
        }
        v
    };
    let rays = 400;
    let mut sum = 0.0;
    for q in 0..rays {
        // Fibonacci sphere directions
        let z = 1.0 - 2.0 * (q as f64 + 0.5) / rays as f64;
        let phi = q as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let d = [(1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z];
        let at = |rho: f64| sample([centre + rho * d[0], centre + rho * d[1], centre + rho * d[2]]);
        let (mut best, mut rho) = (f64::NAN, r - 4.0);
        while rho < r + 4.0 {
            let (a, b) = (at(rho), at(rho + 0.05));
            if a < 0.0 && b >= 0.0 {
                let x = rho + 0.05 * a / (a - b);
                if best.is_nan() || (x - r).abs() < (best - r).abs() {
                    best = x;
                }
            }
            rho += 0.05;
        }
        sum += best;
    }
    sum / rays as f64
}

#[test]
fn noisy_sphere_loses_its_noise_and_keeps_its_boundary() {
    let (clean, noisy) = noisy_sphere(128, [1.0; 3], 20.0);
    let p = BilateralParams { sigma_d: 1.0, sigma_r: 50.0, range_units: RangeUnits::Value, ..Default::default() };
    let out = run(&noisy, &p).unwrap();
    let (r, s, c) = (38.4, 3.0, 63.5);
    let homogeneous = |(k, j, i): (usize, usize, usize)| {
        let rho = ((i as f64 - c).powi(2) + (j as f64 - c).powi(2) + (k as f64 - c).powi(2)).sqrt();
        (rho - r).abs() > 4.0 * s
    };
    let rmse = |v: &Volume| {
        let (mut sum, mut n) = (0.0, 0usize);
        for (idx, &x) in v.data.indexed_iter() {
            if homogeneous(idx) {
                sum += (x as f64 - clean.data[idx] as f64).powi(2);
                n += 1;
            }
        }
        (sum / n as f64).sqrt()
    };
    let (before, after) = (rmse(&noisy), rmse(&out));
    eprintln!("homogeneous RMSE {before:.2} -> {after:.2} ({:.2}x)", before / after);
    assert!(before / after >= 3.0, "{before} -> {after}");

    let f2 = |v: &Volume| {
        let d = DeriveParams { items: vec![Item::F2], kernel: Kernel::Central4, ..Default::default() };
        mdtf_derive::run(&MultiField::from(v.clone()), &d).unwrap().items.remove(0).1.fields.remove(0).data
    };
    let crossing = mean_zero_crossing_radius(&f2(&out), c, r);
    eprintln!("f'' zero crossing after filtering: mean radius {crossing:.3} (true {r})");
    assert!((crossing - r).abs() <= 0.1, "{crossing}");
}

#[test]
fn fast_mode_is_within_40_db_of_exact_mode_at_default_parameters() {
    let (_, noisy) = noisy_sphere(128, [1.0; 3], 20.0);
    let exact = run(&noisy, &BilateralParams::default()).unwrap();
    let fast = run(&noisy, &BilateralParams { mode: Mode::Fast, ..Default::default() }).unwrap();
    let mse = exact.data.iter().zip(fast.data.iter()).map(|(&a, &b)| ((a - b) as f64).powi(2)).sum::<f64>()
        / exact.data.len() as f64;
    let psnr = 10.0 * (255.0f64.powi(2) / mse).log10();
    eprintln!("fast vs exact: PSNR {psnr:.1} dB");
    assert!(psnr >= 40.0, "{psnr}");
}

#[test]
fn same_bits_with_one_and_two_threads() {
    let (_, noisy) = noisy_sphere(40, [1.0, 1.0, 1.5], 10.0);
    for mode in [Mode::Exact, Mode::Fast] {
        let p = BilateralParams { mode, ..Default::default() };
        let with =
            |t| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap().install(|| run(&noisy, &p).unwrap());
        let (a, b) = (with(1), with(2));
        assert!(a.data.iter().zip(b.data.iter()).all(|(x, y)| x.to_bits() == y.to_bits()), "{mode:?}");
    }
}

#[test]
fn bad_parameters_are_named() {
    let v = random_volume([8, 8, 8], [1.0; 3]);
    let e = run(&v, &BilateralParams { sigma_d: 0.0, ..Default::default() }).unwrap_err().to_string();
    assert!(e.contains("bilateral.sigma_d must be a positive number"), "{e}");
    let e = run(&v, &BilateralParams { sigma_r: f64::NAN, ..Default::default() }).unwrap_err().to_string();
    assert!(e.contains("bilateral.sigma_r must be a positive number"), "{e}");
    let e = run(&v, &BilateralParams { sigma_d: 4.0, ..Default::default() }).unwrap_err();
    assert!(matches!(e, BilateralError::RadiusTooLarge { radius: 10, axis: 'x', .. }), "{e}");
    // a huge sigma is refused before its neighbour list is built (it asked for more memory than there is)
    let e = run(&v, &BilateralParams { sigma_d: 1e9, ..Default::default() }).unwrap_err();
    assert!(matches!(e, BilateralError::RadiusTooLarge { axis: 'x', .. }), "{e}");
    // a one-sample axis with a large radius: the neighbourhood box is too big even though no axis is exceeded
    let flat = Volume::new(Geometry::new([200, 200, 1], [0.01, 0.01, 0.01]), Array3::zeros((1, 200, 200))).unwrap();
    let e = run(&flat, &BilateralParams { sigma_d: 0.6, ..Default::default() }).unwrap_err();
    assert!(matches!(e, BilateralError::TooManyNeighbours { radius: [150, 150, 150], .. }), "{e}");
    let mut nan = v.clone();
    nan.data[[1, 1, 1]] = f32::INFINITY;
    assert!(matches!(run(&nan, &BilateralParams::default()), Err(BilateralError::NonFinite)));
}
