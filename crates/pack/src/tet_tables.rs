//! Pre-integration tables for projected tetrahedra with bivariate (s, g)
//! transfer functions (Song et al., preintegrated-bivariate-tf-unstructured.txt).
//!
//! Inside one tetrahedron the scalar s and the gradient magnitude g vary
//! linearly along a ray, so each ray segment (length D, entry values
//! (s_f, g_f), exit values (s_b, g_b)) is classified by a 2D transfer
//! function and integrated with the emission-absorption model
//!
//! ```text
//! C = int_0^D c(l) exp(-int_0^l a(r) dr) dl,      alpha = 1 - exp(-int_0^D a(l) dl)
//! ```
//!
//! (c: emitted colour per world unit, a: extinction per world unit). The
//! integrals that do not depend on the widget's placement are tabulated
//! here; every table stores values at cell centres (entry i of an axis
//! [min, max] with n cells sits at min + (i + 1/2) (max - min) / n, the
//! texture-lookup convention of the manifest's `luts`).
//!
//! ## Approximated pre-classification mode (paper eq. 2-3): `pt_front`, `pt_back`
//! With the colour and extinction linear between the classified end points
//! (c_f, a_f) and (c_b, a_b), the optical depth is exact,
//! q(l) = int_0^l a = a_f l + (a_b - a_f) l^2 / (2 D), and
//!
//! ```text
//! F(a_f, a_b, D) = int_0^D (1 - l/D) exp(-q(l)) dl,   B(a_f, a_b, D) = int_0^D (l/D) exp(-q(l)) dl,
//! C = c_f F + c_b B,                                   alpha = 1 - exp(-D (a_f + a_b) / 2).
//! ```
//!
//! With l = D u, x = a_f D and y = a_b D this is D times an integral over
//! u in [0, 1] of a smooth integrand whose exponent grows by at most
//! max(x, y); it is evaluated by 8-point Gauss-Legendre on pieces over which
//! the exponent grows by at most 8 (error below 1e-7 relative).
//! Axes: a_f (fastest), a_b in [0, tau_max] per world unit, D in [0, d_max] world units.
//!
//! ## Gaussian widget (section 4.2): `pt_gaussian`
//! For a(s, g) = a_max exp(-(s - s0)^2 / (2 ss^2) - (g - g0)^2 / (2 sg^2)) and
//! constant colour, the exponent along the segment is a quadratic in r,
//! (A r + B)^2 + C0, with (ds = s_b - s_f, dg = g_b - g_f)
//!
//! ```text
//! A^2 = ds^2 / (2 ss^2 D^2) + dg^2 / (2 sg^2 D^2)
//! A B = (s_f - s0) ds / (2 ss^2 D) + (g_f - g0) dg / (2 sg^2 D)
//! C0  = (s_f - s0)^2 / (2 ss^2) + (g_f - g0)^2 / (2 sg^2) - B^2
//! ```
//!
//! so int_0^l a = P (erf(A l + B) - erf(B)) with P = a_max exp(-C0) sqrt(pi) / (2 A), and
//!
//! ```text
//! C / c = exp(P erf B) / A * (T(P, A D + B) - T(P, B)),   T(P, t) = int_0^t exp(-P erf(tau)) dtau,
//! alpha = 1 - exp(-P (erf(A D + B) - erf(B))).
//! ```
//!
//! The table holds T on t in [-t_max, t_max] (fastest) and P in [0, p_max].
//! Beyond |t| > t_max, erf is +-1 to within 2e-8 (t_max = 4), so
//! T(P, t) = T(P, +-t_max) + (t -+ t_max) exp(-+P). When A = 0 (the segment
//! runs along an iso-contour of the widget) the extinction is constant and
//! the uniform formula C / c = (1 - exp(-a D)) / a applies.
//!
//! ## Banded triangle waves (section 4.3): `pt_triangle_rise`, `pt_triangle_fall`
//! On the rising flank of one band the extinction grows linearly,
//! a(l) = a_max l / Dt over a flank of length Dt; on the falling flank
//! a = a_max w / Dt with w the distance left to the flank's end. With
//! kappa = a_max Dt and x = l / Dt (or w / Dt) in [0, 1]:
//!
//! ```text
//! rise: C / c = Dt exp(kappa x1^2 / 2) (R(kappa, x2) - R(kappa, x1)),  R(kappa, x) = int_0^x exp(-kappa v^2 / 2) dv
//! fall: C / c = Dt exp(-kappa x3^2 / 2) (G(kappa, x3) - G(kappa, x4)), G(kappa, x) = int_0^x exp(+kappa v^2 / 2) dv
//! ```
//!
//! (entering the rising flank at x1, leaving at x2 > x1; entering the
//! falling flank with x3 left, leaving with x4 < x3). R has the closed form
//! sqrt(pi / (2 kappa)) erf(x sqrt(kappa / 2)); G needs the table. Axes: x
//! in [0, 1] (fastest), kappa in [0, kappa_max]. Dt is at most the mesh's
//! longest edge for the one-peak-per-cell assumption to hold.
//!
//! ## Banded sinusoids (section 4.4): `pt_sinusoid`
//! a(l) = a_max sin(k l), k = pi / Dp, within one half period. With
//! lambda = a_max / k and theta = k l in [0, pi]:
//!
//! ```text
//! C / c = exp(-lambda cos(theta1)) / k * (S(lambda, theta2) - S(lambda, theta1)),  S(lambda, theta) = int_0^theta exp(lambda cos t) dt
//! ```
//!
//! Axes: theta in [0, pi] (fastest), lambda in [0, lambda_max]. S(lambda, pi) = pi I0(lambda).
//!
//! ## The classic 1D table: `pt_preintegration_1d`
//! RGBA of a segment of length D from s_f to s_b for a 1D transfer function
//! ([`crate::segment`], with pieces half as deep), the (s_f, s_b, D) table of standard pre-integrated
//! projected tetrahedra (VTK uses 128 x 128 x 256), for comparison.

use crate::lut::{Lut, LutAxis};
use crate::tables::{Tf1d, segment_in_pieces};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// 8-point Gauss-Legendre nodes and weights on [0, 1].
const GL8: [(f64, f64); 8] = [
    (0.019_855_071_751_231_856, 0.050_614_268_145_188_13),
    (0.101_666_761_293_186_63, 0.111_190_517_226_687_24),
    (0.237_233_795_041_835_5, 0.156_853_322_938_943_64),
    (0.408_282_678_752_175_1, 0.181_341_891_689_181),
    (0.591_717_321_247_825, 0.181_341_891_689_181),
    (0.762_766_204_958_164_5, 0.156_853_322_938_943_64),
    (0.898_333_238_706_813_4, 0.111_190_517_226_687_24),
    (0.980_144_928_248_768_1, 0.050_614_268_145_188_13),
];

/// int_a^b f by 8-point Gauss-Legendre on `pieces` equal pieces.
fn gauss_legendre(f: impl Fn(f64) -> f64, a: f64, b: f64, pieces: usize) -> f64 {
    let h = (b - a) / pieces as f64;
    let mut sum = 0.0;
    for p in 0..pieces {
        let start = a + p as f64 * h;
        for &(x, w) in &GL8 {
            sum += w * f(start + x * h);
        }
    }
    sum * h
}

/// Centre of cell `i` of `n` cells over [min, max].
fn centre(i: usize, n: usize, min: f64, max: f64) -> f64 {
    min + (i as f64 + 0.5) * (max - min) / n as f64
}

/// The front and back weights [F, B] (world units) of the approximated
/// mode for extinctions `a_f`, `a_b` (per world unit) at the ends of a
/// segment of length `d` (world units); see the module docs.
pub fn front_back_weights(a_f: f64, a_b: f64, d: f64) -> [f64; 2] {
    if d <= 0.0 {
        return [0.0, 0.0];
    }
    let (x, y) = (a_f.max(0.0) * d, a_b.max(0.0) * d);
    let pieces = (x.max(y) / 8.0).ceil().max(1.0) as usize;
    let h = 1.0 / pieces as f64;
    let (mut f, mut b) = (0.0, 0.0);
    for p in 0..pieces {
        for &(node, w) in &GL8 {
            let u = (p as f64 + node) * h;
            let e = w * (-(x * u + 0.5 * (y - x) * u * u)).exp();
            f += (1.0 - u) * e;
            b += u * e;
        }
    }
    [d * f * h, d * b * h]
}

/// T(P, t) = int_0^t exp(-P erf(tau)) dtau (negative for t < 0), the Gaussian-widget integral.
pub fn gaussian_widget_integral(p: f64, t: f64) -> f64 {
    let pieces = (t.abs() * 2.0).ceil().max(1.0) as usize;
    gauss_legendre(|tau| (-p * libm::erf(tau)).exp(), 0.0, t, pieces)
}

/// G(kappa, x) = int_0^x exp(sign kappa v^2 / 2) dv: the falling (sign +1) or rising (sign -1) triangle-flank integral.
pub fn triangle_flank_integral(kappa: f64, x: f64, sign: f64) -> f64 {
    let pieces = (kappa * x * x / 8.0).ceil().max(2.0) as usize;
    gauss_legendre(|v| (sign * 0.5 * kappa * v * v).exp(), 0.0, x, pieces)
}

/// S(lambda, theta) = int_0^theta exp(lambda cos t) dt, the banded-sinusoid integral.
pub fn sinusoid_integral(lambda: f64, theta: f64) -> f64 {
    let pieces = (lambda * theta / 4.0).ceil().max(2.0) as usize;
    gauss_legendre(|t| (lambda * t.cos()).exp(), 0.0, theta, pieces)
}

/// Sizes and ranges of the projected-tetrahedra tables. Sizes are cells per
/// axis, fastest first; ranges are the upper ends of axes starting at 0
/// (the Gaussian t axis is symmetric).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TetTableParams {
    /// Which tables to build: any of `front-back`, `gaussian`, `triangle`, `sinusoid`, `preintegration-1d`.
    #[serde(default = "default_tables")]
    pub tables: Vec<TetTable>,
    /// Cells of the F/B tables along a_f, a_b, D (VTK's 1D table: 128 x 128 x 256).
    #[serde(default = "default_fb_size")]
    pub fb_size: [usize; 3],
    /// Largest extinction (per world unit) on the F/B axes; default 16 / d_max
    /// (a segment of the longest edge at that extinction transmits e^-16).
    #[serde(default)]
    pub tau_max: Option<f64>,
    /// Longest segment (world units) on the D axes; default: the mesh's longest edge.
    #[serde(default)]
    pub d_max: Option<f64>,
    /// Cells of the Gaussian table along t and P.
    #[serde(default = "default_square")]
    pub gaussian_size: [usize; 2],
    /// P range [0, p_max] (2 P is the optical depth of a whole crossing).
    #[serde(default = "default_p_max")]
    pub p_max: f64,
    /// t range [-t_max, t_max].
    #[serde(default = "default_t_max")]
    pub t_max: f64,
    /// Cells of the triangle tables along x and kappa.
    #[serde(default = "default_square")]
    pub triangle_size: [usize; 2],
    /// kappa = a_max Dt range [0, kappa_max].
    #[serde(default = "default_kappa_max")]
    pub kappa_max: f64,
    /// Cells of the sinusoid table along theta and lambda.
    #[serde(default = "default_square")]
    pub sinusoid_size: [usize; 2],
    /// lambda = a_max Dp / pi range [0, lambda_max].
    #[serde(default = "default_lambda_max")]
    pub lambda_max: f64,
    /// Cells of the classic 1D table along s_f, s_b, D.
    #[serde(default = "default_preint_size")]
    pub preint_size: [usize; 3],
}

/// One of the projected-tetrahedra tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TetTable {
    /// F and B of the approximated mode.
    FrontBack,
    /// T(P, t) of the Gaussian widget.
    Gaussian,
    /// Rising and falling triangle-flank integrals.
    Triangle,
    /// The banded-sinusoid integral.
    Sinusoid,
    /// The classic (s_f, s_b, D) table of a 1D transfer function.
    #[serde(rename = "preintegration-1d")]
    Preintegration1d,
}

impl std::str::FromStr for TetTable {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        serde_json::from_value(serde_json::Value::String(s.into())).map_err(|_| {
            format!("unknown table '{s}' (available: front-back, gaussian, triangle, sinusoid, preintegration-1d)")
        })
    }
}

fn default_tables() -> Vec<TetTable> {
    vec![TetTable::FrontBack, TetTable::Gaussian, TetTable::Triangle, TetTable::Sinusoid, TetTable::Preintegration1d]
}
fn default_fb_size() -> [usize; 3] {
    [128, 128, 256]
}
fn default_square() -> [usize; 2] {
    [256, 256]
}
fn default_preint_size() -> [usize; 3] {
    [128, 128, 64]
}
fn default_p_max() -> f64 {
    8.0
}
fn default_t_max() -> f64 {
    4.0
}
fn default_kappa_max() -> f64 {
    16.0
}
fn default_lambda_max() -> f64 {
    8.0
}

impl Default for TetTableParams {
    fn default() -> Self {
        TetTableParams {
            tables: default_tables(),
            fb_size: default_fb_size(),
            tau_max: None,
            d_max: None,
            gaussian_size: default_square(),
            p_max: default_p_max(),
            t_max: default_t_max(),
            triangle_size: default_square(),
            kappa_max: default_kappa_max(),
            sinusoid_size: default_square(),
            lambda_max: default_lambda_max(),
            preint_size: default_preint_size(),
        }
    }
}

fn axis(channel: &str, size: usize, min: f64, max: f64) -> LutAxis {
    LutAxis { channel: channel.into(), size, min, max }
}

/// Fills a 2D table, first axis fastest, in parallel over rows.
fn table2(a: &LutAxis, b: &LutAxis, f: impl Fn(f64, f64) -> f64 + Sync) -> Vec<f32> {
    let mut out = vec![0f32; a.size * b.size];
    out.par_chunks_mut(a.size).enumerate().for_each(|(j, row)| {
        let y = centre(j, b.size, b.min, b.max);
        for (i, e) in row.iter_mut().enumerate() {
            *e = f(centre(i, a.size, a.min, a.max), y) as f32;
        }
    });
    out
}

/// The F and B tables (two single-component LUTs `pt_front`, `pt_back`) over
/// a_f in [0, tau_max] (fastest), a_b in [0, tau_max], D in [0, d_max].
pub fn front_back_tables(size: [usize; 3], tau_max: f64, d_max: f64) -> [Lut; 2] {
    let axes = vec![
        axis("a_front", size[0], 0.0, tau_max),
        axis("a_back", size[1], 0.0, tau_max),
        axis("D", size[2], 0.0, d_max),
    ];
    let plane = size[0] * size[1];
    let mut f = vec![0f32; plane * size[2]];
    let mut b = vec![0f32; plane * size[2]];
    f.par_chunks_mut(plane).zip(b.par_chunks_mut(plane)).enumerate().for_each(|(k, (fp, bp))| {
        let d = centre(k, size[2], 0.0, d_max);
        for j in 0..size[1] {
            let ab = centre(j, size[1], 0.0, tau_max);
            for i in 0..size[0] {
                let [wf, wb] = front_back_weights(centre(i, size[0], 0.0, tau_max), ab, d);
                fp[j * size[0] + i] = wf as f32;
                bp[j * size[0] + i] = wb as f32;
            }
        }
    });
    let lut = |name: &str, meaning: &str, values| Lut {
        name: name.into(),
        meaning: meaning.into(),
        axes: axes.clone(),
        components: 1,
        values,
        unit_range: false,
        u16_range: None,
    };
    [
        lut("pt_front", "F(a_f, a_b, D) = int_0^D (1 - l/D) exp(-q(l)) dl, world units (eq. 3: C = c_f F + c_b B)", f),
        lut("pt_back", "B(a_f, a_b, D) = int_0^D (l/D) exp(-q(l)) dl, world units (eq. 3: C = c_f F + c_b B)", b),
    ]
}

/// T(P, t) over t in [-t_max, t_max] (fastest) and P in [0, p_max] (LUT `pt_gaussian`).
pub fn gaussian_table(size: [usize; 2], p_max: f64, t_max: f64) -> Lut {
    let axes = vec![axis("t", size[0], -t_max, t_max), axis("P", size[1], 0.0, p_max)];
    let values = table2(&axes[0], &axes[1], |t, p| gaussian_widget_integral(p, t));
    Lut {
        name: "pt_gaussian".into(),
        meaning: "T(P, t) = int_0^t exp(-P erf(tau)) dtau (section 4.2); beyond |t| > t_max extend linearly with \
                  slope exp(-+P)"
            .into(),
        axes,
        components: 1,
        values,
        unit_range: false,
        u16_range: None,
    }
}

/// Rising and falling triangle-flank integrals over x in [0, 1] (fastest) and kappa in [0, kappa_max].
pub fn triangle_tables(size: [usize; 2], kappa_max: f64) -> [Lut; 2] {
    let axes = vec![axis("x", size[0], 0.0, 1.0), axis("kappa", size[1], 0.0, kappa_max)];
    let lut = |name: &str, meaning: &str, sign: f64| Lut {
        name: name.into(),
        meaning: meaning.into(),
        axes: axes.clone(),
        components: 1,
        values: table2(&axes[0], &axes[1], |x, k| triangle_flank_integral(k, x, sign)),
        unit_range: false,
        u16_range: None,
    };
    [
        lut("pt_triangle_rise", "R(kappa, x) = int_0^x exp(-kappa v^2 / 2) dv, rising flank (section 4.3)", -1.0),
        lut("pt_triangle_fall", "G(kappa, x) = int_0^x exp(kappa v^2 / 2) dv, falling flank (section 4.3)", 1.0),
    ]
}

/// S(lambda, theta) over theta in [0, pi] (fastest) and lambda in [0, lambda_max] (LUT `pt_sinusoid`).
pub fn sinusoid_table(size: [usize; 2], lambda_max: f64) -> Lut {
    let axes = vec![axis("theta", size[0], 0.0, std::f64::consts::PI), axis("lambda", size[1], 0.0, lambda_max)];
    let values = table2(&axes[0], &axes[1], |theta, lambda| sinusoid_integral(lambda, theta));
    Lut {
        name: "pt_sinusoid".into(),
        meaning: "S(lambda, theta) = int_0^theta exp(lambda cos t) dt, banded sinusoid (section 4.4)".into(),
        axes,
        components: 1,
        values,
        unit_range: false,
        u16_range: None,
    }
}

/// The classic 1D pre-integration table: RGBA of a segment of length D from
/// s_f (fastest) to s_b, over the TF's value range `s_range`, D in [0, d_max].
pub fn preintegration_1d_table(tf: &Tf1d, s_range: [f64; 2], size: [usize; 3], d_max: f64) -> Lut {
    let axes = vec![
        axis("s_front", size[0], s_range[0], s_range[1]),
        axis("s_back", size[1], s_range[0], s_range[1]),
        axis("D", size[2], 0.0, d_max),
    ];
    let plane = size[0] * size[1];
    let mut values = vec![0f32; 4 * plane * size[2]];
    values.par_chunks_mut(4 * size[0]).enumerate().for_each(|(row, out)| {
        let (j, k) = (row % size[1], row / size[1]);
        let d = centre(k, size[2], 0.0, d_max);
        let sb = centre(j, size[1], 0.0, 1.0);
        for i in 0..size[0] {
            let rgba = segment_in_pieces(tf, centre(i, size[0], 0.0, 1.0), sb, d, 4.0);
            for c in 0..4 {
                out[4 * i + c] = rgba[c] as f32;
            }
        }
    });
    Lut {
        name: "pt_preintegration_1d".into(),
        meaning: "RGBA of a segment of length D from s_front to s_back under the 1D TF (classic pre-integrated PT)"
            .into(),
        axes,
        components: 4,
        values,
        unit_range: true,
        u16_range: None,
    }
}

/// Colour weight C / c and opacity of a segment under one Gaussian widget,
/// evaluated with `table` (T, looked up with bilinear interpolation) or,
/// when `table` is None, with the exact integral. `seg` is (s_f, g_f, s_b, g_b, D);
/// the widget is (s0, g0, ss, sg, a_max).
pub fn gaussian_segment(seg: [f64; 5], widget: [f64; 5], table: Option<&Lut>) -> [f64; 2] {
    let [sf, gf, sb, gb, d] = seg;
    let [s0, g0, ss, sg, a_max] = widget;
    let (ks, kg) = (1.0 / (2.0 * ss * ss), 1.0 / (2.0 * sg * sg));
    let (ds, dg) = ((sb - sf) / d, (gb - gf) / d);
    let (es, eg) = (sf - s0, gf - g0);
    let a2 = ks * ds * ds + kg * dg * dg;
    let c_all = ks * es * es + kg * eg * eg;
    if a2 < 1e-18 {
        let a = a_max * (-c_all).exp();
        let alpha = 1.0 - (-a * d).exp();
        return [if a > 0.0 { alpha / a } else { d }, alpha];
    }
    let a = a2.sqrt();
    let b = (ks * es * ds + kg * eg * dg) / a;
    let c0 = c_all - b * b;
    let p = a_max * (-c0).exp() * std::f64::consts::PI.sqrt() / (2.0 * a);
    let t_of = |t: f64| match table {
        Some(lut) => lookup_gaussian(lut, p, t),
        None => gaussian_widget_integral(p, t),
    };
    let weight = (p * libm::erf(b)).exp() / a * (t_of(a * d + b) - t_of(b));
    let alpha = 1.0 - (-p * (libm::erf(a * d + b) - libm::erf(b))).exp();
    [weight, alpha]
}

/// T(P, t) from the `pt_gaussian` table: bilinear between cell centres,
/// linear extension beyond |t| > t_max (P clamped to the table's range).
pub fn lookup_gaussian(lut: &Lut, p: f64, t: f64) -> f64 {
    let (Some(ta), Some(pa)) = (lut.axes.first(), lut.axes.get(1)) else {
        return gaussian_widget_integral(p, t);
    };
    if ta.size < 2 || pa.size < 1 || lut.values.len() < ta.size * pa.size {
        // not a usable table: the exact integral
        return gaussian_widget_integral(p, t);
    }
    let t_max = ta.max;
    let (tc, tail) = if t > t_max {
        (t_max, (t - t_max) * (-p).exp())
    } else if t < -t_max {
        (-t_max, (t + t_max) * p.exp())
    } else {
        (t, 0.0)
    };
    let coord = |x: f64, a: &LutAxis| {
        let f = ((x - a.min) / (a.max - a.min) * a.size as f64 - 0.5).clamp(0.0, (a.size - 1) as f64);
        let i = (f.floor() as usize).min(a.size.saturating_sub(2));
        (i, f - i as f64)
    };
    // the outermost cell centres are half a cell inside +-t_max: extrapolate linearly to the edge
    let ft = (tc - ta.min) / (ta.max - ta.min) * ta.size as f64 - 0.5;
    let it = (ft.floor().max(0.0) as usize).min(ta.size - 2);
    let wt = ft - it as f64;
    let (ip, wp) = coord(p, pa);
    let at = |i: usize, j: usize| lut.values[j * ta.size + i] as f64;
    let row = |j: usize| at(it, j) + wt * (at(it + 1, j) - at(it, j));
    let v = row(ip) + wp * (row((ip + 1).min(pa.size - 1)) - row(ip));
    v + tail
}
