//! The projected-tetrahedra tables against independent fine quadratures of
//! their defining integrals (composite Simpson, optical depth accumulated
//! step by step), closed forms where they exist, and brute-force
//! integration along a segment.

use mdtf_pack::{
    Lut, Tf1d, front_back_tables, front_back_weights, gaussian_segment, gaussian_table, gaussian_widget_integral,
    preintegration_1d_table, segment_by_midpoint, sinusoid_table, triangle_tables,
};
use std::f64::consts::PI;

/// Composite Simpson with `n` (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// F and B by brute force: the extinction is sampled on a fine grid, the optical
/// depth summed by trapezoids, the outer integral by Simpson on the same grid.
fn front_back_reference(af: f64, ab: f64, d: f64) -> [f64; 2] {
    let n = 4000;
    let h = d / n as f64;
    let a = |l: f64| af + (ab - af) * l / d;
    let mut depth = vec![0.0; n + 1];
    for i in 1..=n {
        depth[i] = depth[i - 1] + 0.5 * h * (a((i - 1) as f64 * h) + a(i as f64 * h));
    }
    let weight = |i: usize| {
        if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        }
    };
    let (mut f, mut b) = (0.0, 0.0);
    for i in 0..=n {
        let l = i as f64 * h;
        let e = weight(i) * (-depth[i]).exp();
        f += (1.0 - l / d) * e;
        b += l / d * e;
    }
    [f * h / 3.0, b * h / 3.0]
}

fn centre(i: usize, n: usize, min: f64, max: f64) -> f64 {
    min + (i as f64 + 0.5) * (max - min) / n as f64
}

fn max_abs(lut: &Lut) -> f64 {
    lut.values.iter().fold(0.0f64, |m, v| m.max(v.abs() as f64))
}

#[test]
fn front_back_every_entry_matches_fine_quadrature() {
    let (size, tau_max, d_max) = ([12, 10, 16], 4.0, 4.0);
    let [f, b] = front_back_tables(size, tau_max, d_max);
    let scale = max_abs(&f).max(max_abs(&b));
    let mut worst = 0.0f64;
    for k in 0..size[2] {
        for j in 0..size[1] {
            for i in 0..size[0] {
                let (af, ab, d) = (
                    centre(i, size[0], 0.0, tau_max),
                    centre(j, size[1], 0.0, tau_max),
                    centre(k, size[2], 0.0, d_max),
                );
                let r = front_back_reference(af, ab, d);
                let idx = (k * size[1] + j) * size[0] + i;
                worst = worst.max((f.values[idx] as f64 - r[0]).abs()).max((b.values[idx] as f64 - r[1]).abs());
            }
        }
    }
    assert!(worst / scale < 1e-4, "worst |table - quadrature| / max = {:.2e}", worst / scale);
}

#[test]
fn front_back_constant_extinction_is_the_uniform_closed_form() {
    // a_f = a_b = a: F + B = (1 - exp(-a D)) / a, and F - B = int (1 - 2l/D) e^{-a l} dl
    for &(a, d) in &[(0.1, 1.0), (1.0, 2.0), (5.0, 3.0), (20.0, 0.5)] {
        let [f, b] = front_back_weights(a, a, d);
        let total = (1.0 - (-a * d).exp()) / a;
        let diff = (1.0 - (-a * d).exp()) / a - 2.0 / d * ((1.0 - (-a * d).exp() * (1.0 + a * d)) / (a * a));
        assert!(((f + b) - total).abs() < 1e-8 * total, "a {a} d {d}: F+B {} vs {total}", f + b);
        assert!(((f - b) - diff).abs() < 1e-9, "a {a} d {d}: F-B {} vs {diff}", f - b);
    }
}

#[test]
fn default_size_front_back_table_spot_checks() {
    // the default 128 x 128 x 256 at the default tau_max = 16 / d_max: 300 entries on a fixed stride
    let (size, d_max) = ([128, 128, 256], 2.0);
    let tau_max = 16.0 / d_max;
    let [f, b] = front_back_tables(size, tau_max, d_max);
    let scale = max_abs(&f).max(max_abs(&b));
    let total = size[0] * size[1] * size[2];
    for n in 0..300 {
        let idx = (n * 14_033 + 977) % total;
        let (i, j, k) = (idx % size[0], (idx / size[0]) % size[1], idx / (size[0] * size[1]));
        let r = front_back_reference(
            centre(i, size[0], 0.0, tau_max),
            centre(j, size[1], 0.0, tau_max),
            centre(k, size[2], 0.0, d_max),
        );
        let err = (f.values[idx] as f64 - r[0]).abs().max((b.values[idx] as f64 - r[1]).abs());
        assert!(err / scale < 1e-4, "entry ({i}, {j}, {k}): error {:.2e} of max", err / scale);
    }
}

#[test]
fn gaussian_table_every_entry_matches_fine_quadrature() {
    let (size, p_max, t_max) = ([48, 32], 8.0, 4.0);
    let lut = gaussian_table(size, p_max, t_max);
    let scale = max_abs(&lut);
    let mut worst = 0.0f64;
    for j in 0..size[1] {
        let p = centre(j, size[1], 0.0, p_max);
        for i in 0..size[0] {
            let t = centre(i, size[0], -t_max, t_max);
            let r = simpson(|tau| (-p * libm::erf(tau)).exp(), 0.0, t, 2000);
            worst = worst.max((lut.values[j * size[0] + i] as f64 - r).abs());
        }
    }
    assert!(worst / scale < 1e-4, "worst {:.2e} of max", worst / scale);
}

/// Colour weight and opacity of a segment under a Gaussian widget by brute
/// force: 20000 midpoint steps along the segment, extinction from the widget
/// at each step, optical depth accumulated step by step.
fn gaussian_segment_brute_force(seg: [f64; 5], widget: [f64; 5]) -> [f64; 2] {
    let [sf, gf, sb, gb, d] = seg;
    let [s0, g0, ss, sg, a_max] = widget;
    let n = 20_000;
    let h = d / n as f64;
    let (mut depth, mut weight) = (0.0, 0.0);
    for i in 0..n {
        let u = (i as f64 + 0.5) / n as f64;
        let (s, g) = (sf + u * (sb - sf), gf + u * (gb - gf));
        let a = a_max * (-(s - s0).powi(2) / (2.0 * ss * ss) - (g - g0).powi(2) / (2.0 * sg * sg)).exp();
        weight += (-(depth + 0.5 * a * h)).exp() * h;
        depth += a * h;
    }
    [weight, 1.0 - (-depth).exp()]
}

#[test]
fn gaussian_table_reproduces_segments_by_brute_force() {
    let lut = gaussian_table([256, 256], 8.0, 4.0);
    let widget = [100.0, 40.0, 12.0, 8.0, 0.8];
    let segments = [
        [80.0, 30.0, 120.0, 50.0, 5.0],  // through the centre
        [60.0, 10.0, 95.0, 45.0, 3.0],   // ends near the centre
        [100.0, 20.0, 100.0, 60.0, 4.0], // along g only
        [40.0, 40.0, 160.0, 40.0, 10.0], // long, crossing the whole widget (t beyond +-t_max)
        [110.0, 35.0, 90.0, 45.0, 1.0],  // short, inside
        [100.0, 40.0, 100.0, 40.0, 2.0], // constant (s, g): the uniform case
        [130.0, 60.0, 125.0, 58.0, 0.7], // in the tail
    ];
    for seg in segments {
        let brute = gaussian_segment_brute_force(seg, widget);
        let exact = gaussian_segment(seg, widget, None);
        let table = gaussian_segment(seg, widget, Some(&lut));
        assert!((exact[1] - brute[1]).abs() < 1e-6, "{seg:?}: alpha {} vs {}", exact[1], brute[1]);
        assert!((exact[0] - brute[0]).abs() < 1e-6 * seg[4], "{seg:?}: exact weight {} vs {}", exact[0], brute[0]);
        assert!(
            (table[0] - brute[0]).abs() < 2e-3 * brute[0].max(0.05),
            "{seg:?}: table weight {} vs brute force {}",
            table[0],
            brute[0]
        );
    }
}

#[test]
fn triangle_tables_match_the_closed_form_and_quadrature() {
    let (size, kappa_max) = ([40, 30], 16.0);
    let [rise, fall] = triangle_tables(size, kappa_max);
    let (rs, fs) = (max_abs(&rise), max_abs(&fall));
    for j in 0..size[1] {
        let kappa = centre(j, size[1], 0.0, kappa_max);
        for i in 0..size[0] {
            let x = centre(i, size[0], 0.0, 1.0);
            let closed = (PI / (2.0 * kappa)).sqrt() * libm::erf(x * (kappa / 2.0).sqrt());
            let fine = simpson(|v| (0.5 * kappa * v * v).exp(), 0.0, x, 2000);
            let idx = j * size[0] + i;
            assert!((rise.values[idx] as f64 - closed).abs() / rs < 1e-4, "rise kappa {kappa} x {x}");
            assert!((fall.values[idx] as f64 - fine).abs() / fs < 1e-4, "fall kappa {kappa} x {x}");
        }
    }
}

/// Modified Bessel function I0 by its power series.
fn bessel_i0(x: f64) -> f64 {
    let (mut term, mut sum) = (1.0, 1.0);
    for k in 1..60 {
        term *= (x / 2.0) * (x / 2.0) / (k * k) as f64;
        sum += term;
    }
    sum
}

#[test]
fn sinusoid_table_matches_quadrature_and_bessel() {
    let (size, lambda_max) = ([40, 30], 8.0);
    let lut = sinusoid_table(size, lambda_max);
    let scale = max_abs(&lut);
    for j in 0..size[1] {
        let lambda = centre(j, size[1], 0.0, lambda_max);
        for i in 0..size[0] {
            let theta = centre(i, size[0], 0.0, PI);
            let fine = simpson(|t| (lambda * t.cos()).exp(), 0.0, theta, 2000);
            assert!((lut.values[j * size[0] + i] as f64 - fine).abs() / scale < 1e-4, "lambda {lambda} theta {theta}");
        }
        // over the whole half period the integral is pi I0(lambda)
        let whole = mdtf_pack::sinusoid_integral(lambda, PI);
        assert!(
            (whole - PI * bessel_i0(lambda)).abs() < 1e-9 * whole,
            "lambda {lambda}: {whole} vs {}",
            PI * bessel_i0(lambda)
        );
    }
}

#[test]
fn gaussian_integral_is_odd_in_p_sign_pattern() {
    // T(0, t) = t, and T(P, -t) = int_0^t exp(+P erf) (mirror)
    assert!((gaussian_widget_integral(0.0, 2.5) - 2.5).abs() < 1e-12);
    let (p, t) = (3.0, 1.7);
    let mirror = simpson(|tau| (p * libm::erf(tau)).exp(), 0.0, t, 2000);
    assert!((gaussian_widget_integral(p, -t) + mirror).abs() < 1e-8 * mirror);
}

#[test]
fn classic_1d_table_matches_midpoint_reference() {
    let tf = Tf1d::two_peaks(64);
    let (size, d_max) = ([16, 16, 8], 3.0);
    let lut = preintegration_1d_table(&tf, [0.0, 1.0], size, d_max);
    for k in 0..size[2] {
        for j in 0..size[1] {
            for i in 0..size[0] {
                let (sf, sb, d) = (centre(i, 16, 0.0, 1.0), centre(j, 16, 0.0, 1.0), centre(k, 8, 0.0, d_max));
                let r = segment_by_midpoint(&tf, sf, sb, d, 4000);
                let at = 4 * ((k * size[1] + j) * size[0] + i);
                for c in 0..4 {
                    assert!(
                        (lut.values[at + c] as f64 - r[c]).abs() < 1e-4,
                        "({i},{j},{k}) c{c}: {} vs {}",
                        lut.values[at + c],
                        r[c]
                    );
                }
            }
        }
    }
}
