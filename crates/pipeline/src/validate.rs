//! `mdtf validate`: every stage on the analytic phantoms, each measured
//! error next to its documented tolerance. What a user runs to trust an
//! installation; the same numbers the test suite asserts.

use mdtf_boundary::{BoundaryParams, HitCode};
use mdtf_datagen::erf_sphere;
use mdtf_histogram::{Axis, HvolParams, Scale, histogram_volume, write_hvol, write_stretched};
use mdtf_pack::{Dtype, GaussianPrimitive, Tf1d, decode_for, preintegration_table, segment, segment_by_midpoint};
use mdtf_volume::{Geometry, MultiField, Volume};
use serde::Serialize;
use std::f64::consts::PI;
use std::path::Path;

/// One line of the validation table.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// What is measured.
    pub name: String,
    /// The measured value.
    pub measured: f64,
    /// The bound it must meet.
    pub tolerance: f64,
    /// true: measured must be <= tolerance; false: >= tolerance.
    pub at_most: bool,
}

impl Check {
    /// Whether the measurement meets its bound.
    pub fn ok(&self) -> bool {
        if self.at_most { self.measured <= self.tolerance } else { self.measured >= self.tolerance }
    }
}

fn check(name: &str, measured: f64, tolerance: f64, at_most: bool) -> Check {
    Check { name: name.into(), measured, tolerance, at_most }
}

/// The stage parameters `mdtf validate` runs with: the defaults, or what
/// `--set section.key=value` changes (sections `derive`, `boundary`, `tetra`
/// as in pipeline files), so that a wrong parameter shows as a failed check.
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidateParams {
    /// `[derive]`: the kernel.
    pub derive: crate::file::DeriveSection,
    /// `[boundary]`: tracing parameters.
    pub boundary: BoundaryParams,
    /// `[tetra]`: tetrahedra per cell and the gradient method.
    pub tetra: mdtf_tetra::TetraParams,
}

impl ValidateParams {
    /// The defaults with `--set` overrides applied; unknown keys are named.
    pub fn from_overrides(overrides: &[String]) -> Result<ValidateParams, String> {
        let mut doc = toml::Table::new();
        crate::file::apply_overrides(&mut doc, overrides)?;
        let text = toml::to_string(&doc).map_err(|e| e.to_string())?;
        toml::from_str(&text).map_err(|e| format!("--set: {e}"))
    }
}

/// Runs the checks on an n^3 erf sphere (radius 0.3 n, sigma 3, values 0..255)
/// with `params`, writing the boundary report and histogram pictures into `dir`.
pub fn validate(n: usize, dir: &Path, params: &ValidateParams) -> Result<Vec<Check>, String> {
    if n < 48 {
        return Err(format!("--size {n}: the checks need at least 48 voxels per axis"));
    }
    let s = Sphere::new(n, params)?;
    let mut out = s.derive_checks();
    out.extend(s.boundary_checks());
    let rdir = dir.join("boundary");
    std::fs::create_dir_all(&rdir).map_err(|e| e.to_string())?;
    s.report.write(&rdir).map_err(|e| e.to_string())?;
    let hdir = dir.join("histogram");
    std::fs::create_dir_all(&hdir).map_err(|e| e.to_string())?;
    out.extend(s.histogram_checks(&hdir)?);
    s.write_stretched(&hdir)?;
    out.push(check("pack: worst decode error, code steps", s.worst_decode_steps()?, 0.5 + 1e-6, true));
    out.push(check("pack: pre-integration vs quadrature", preintegration_error(), 1e-4, true));
    out.push(check("pack: Gaussian segment integral vs quadrature", gaussian_integral_error(), 1e-5, true));
    out.push(check("pack: triangular GTF segment integral vs quadr.", tgtf_integral_error(), 1e-5, true));
    out.push(check("boundary: shells, least share kept per boundary", shells_least_kept(96)?, 0.95, false));
    out.push(check("tetra: vertex g mean rel. error", tetra_g_error(n, &params.tetra)?, 0.02, true));
    out.push(check("tetra: F/B, Gaussian tables vs quadr.", tetra_table_error(), 1e-4, true));
    Ok(out)
}

/// The validation's erf sphere (radius 0.3 n, sigma 3 voxels, values
/// 0..255), its truth, its derivatives with the kernel checked and its tracing.
struct Sphere {
    n: usize,
    /// The blur, voxels.
    sigma: f64,
    /// The radius, voxels.
    r: f64,
    /// The peak g: 255 / (sigma sqrt(2 pi)).
    a: f64,
    value: Volume,
    truth: mdtf_datagen::RadialTruth,
    g: Volume,
    f2: Volume,
    /// The tracing's distance, g at the hit, hit code and dot product.
    distance: Volume,
    g_hit: Volume,
    hit: Volume,
    dot: Volume,
    /// The tracing's Fig. 2 report.
    report: mdtf_boundary::Report,
    /// The voxels within 2 sigma of the surface, where the derivatives are checked.
    shell: Vec<usize>,
}

impl Sphere {
    /// The n^3 sphere, its derivatives with `params`' kernel and its tracing with `params`' boundary section.
    fn new(n: usize, params: &ValidateParams) -> Result<Sphere, String> {
        let (sigma, r) = (3.0, 0.3 * n as f64);
        let ph = erf_sphere(Geometry::new([n; 3], [1.0; 3]), r, sigma, 0.0, 255.0, None);
        let (value, truth) = (ph.volume(), ph.truth());
        // planned and run as a command's channels are (`Plan::for_channels`)
        let chain = crate::boundary_chain::BoundaryChainParams {
            kernel: params.derive.kernel,
            boundary: params.boundary.clone(),
            ..Default::default()
        };
        let names: Vec<String> =
            ["g", "f2"].map(String::from).into_iter().chain(crate::channel::traced_names()).collect();
        let computed = crate::channels::compute_all(&MultiField::from(value.clone()), &names, &chain, &|_, _| {})
            .map_err(|e| e.to_string())?;
        let report = computed.tracing.ok_or("the plan did not trace")?.report;
        let mut made: std::collections::BTreeMap<String, Volume> = computed.channels.into_iter().collect();
        let mut take = |c: &str| made.remove(c).ok_or_else(|| format!("the run made no {c}"));
        let (g, f2, distance, g_hit, hit, dot) =
            (take("g")?, take("f2")?, take("distance")?, take("g_hit")?, take("hit")?, take("dot")?);
        let x = truth.x.samples();
        let shell = (0..x.len()).filter(|&i| x[i].abs() < 2.0 * sigma as f32).collect();
        let a = 255.0 / (sigma * (2.0 * PI).sqrt());
        Ok(Sphere { n, sigma, r, a, value, truth, g, f2, distance, g_hit, hit, dot, report, shell })
    }

    /// Mean |est - tru| over the shell, over `peak`.
    fn mean_error(&self, est: &Volume, tru: &Volume, peak: f64) -> f64 {
        let sum: f64 = self.shell.iter().map(|&i| (est.samples()[i] as f64 - tru.samples()[i] as f64).abs()).sum();
        sum / self.shell.len() as f64 / peak
    }

    /// g and f'' against the truth, and the zero crossing of f'' along the
    /// x axis line nearest the centre against the radius.
    fn derive_checks(&self) -> Vec<Check> {
        let (n, sigma, a) = (self.n, self.sigma, self.a);
        let c = (n as f64 - 1.0) / 2.0;
        let (j, k) = (n / 2, n / 2);
        let (dj, dk) = (j as f64 - c, k as f64 - c);
        let expect = (self.r * self.r - dj * dj - dk * dk).sqrt() + c;
        let mut crossing = f64::NAN;
        for i in n / 2..n - 1 {
            let (p, q) = (self.f2.data[[k, j, i]] as f64, self.f2.data[[k, j, i + 1]] as f64);
            if p < 0.0 && q >= 0.0 {
                crossing = i as f64 + p / (p - q);
                break;
            }
        }
        let f2_error = self.mean_error(&self.f2, &self.truth.f2, a * (-0.5f64).exp() / sigma);
        vec![
            check("derive: mean |g error| / peak g", self.mean_error(&self.g, &self.truth.g, a), 3e-4, true),
            check("derive: mean |f'' error| / peak |f''|", f2_error, 3e-3, true),
            check("derive: f'' zero crossing error, voxels", (crossing - expect).abs(), 0.02, true),
        ]
    }

    /// The tracing's normals, distances and g at the hit against the truth.
    fn boundary_checks(&self) -> Vec<Check> {
        let (x, a, sigma) = (self.truth.x.samples(), self.a, self.sigma);
        let (hit, dot, distance, g_hit) =
            (self.hit.samples(), self.dot.samples(), self.distance.samples(), self.g_hit.samples());
        let hits: Vec<usize> = (0..hit.len()).filter(|&i| hit[i] == HitCode::Hit as u8 as f32).collect();
        let mean_dot = hits.iter().map(|&i| dot[i] as f64).sum::<f64>() / hits.len().max(1) as f64;
        let near = hits.iter().copied().filter(|&i| x[i].abs() <= 3.0 * sigma as f32);
        let derr: Vec<f64> = near.map(|i| (distance[i] as f64 - x[i].abs() as f64).abs()).collect();
        let g_ok = hits.iter().filter(|&&i| ((g_hit[i] as f64 - a) / a).abs() <= 0.01).count() as f64
            / hits.len().max(1) as f64;
        let mean_derr = derr.iter().sum::<f64>() / derr.len().max(1) as f64;
        vec![
            check("boundary: mean dot product", mean_dot, 0.9999, false),
            check("boundary: mean |d - |x||, voxels", mean_derr, 0.05, true),
            check("boundary: max |d - |x||, voxels", derr.iter().copied().fold(0.0, f64::max), 0.25, true),
            check("boundary: share of g_hit within 1% of A", g_ok, 0.99, false),
        ]
    }

    /// The histogram volume's sigma, and its position function against the
    /// mean true distance of each (v, g) bin's voxels; its pictures go into `hdir`.
    fn histogram_checks(&self, hdir: &Path) -> Result<Vec<Check>, String> {
        let (value, g, sigma) = (&self.value, &self.g, self.sigma);
        let params = HvolParams { g_thresh: Some(0.0), ..Default::default() };
        let hv = histogram_volume(value.samples(), g.samples(), self.f2.samples(), value.plane_len(), &params)
            .map_err(|e| e.to_string())?;
        let [av, ag] = &hv.vg_axes;
        let (mut sx, mut nx) = (vec![0.0f64; av.bins * ag.bins], vec![0u64; av.bins * ag.bins]);
        for i in 0..value.samples().len() {
            if let (Some(bv), Some(bg)) = (av.bin(value.samples()[i]), ag.bin(g.samples()[i])) {
                sx[bg * av.bins + bv] += self.truth.x.samples()[i] as f64;
                nx[bg * av.bins + bv] += 1;
            }
        }
        let worst_p = (0..sx.len())
            .filter(|&i| hv.count_vg[i] >= 50 && (sx[i] / nx[i].max(1) as f64).abs() <= 2.0 * sigma)
            .map(|i| (hv.position[i] as f64 - sx[i] / nx[i] as f64).abs())
            .fold(0.0, f64::max);
        let arches = crate::figures::boundary_arches(&mdtf_histogram::detect_boundaries(&hv));
        write_hvol(hdir, &hv, "the validation erf sphere", &arches).map_err(|e| e.to_string())?;
        Ok(vec![
            check("histogram: sigma estimate relative error", (hv.sigma - sigma).abs() / sigma, 0.02, true),
            check("histogram: worst |p(v,g) - x|, voxels", worst_p, 0.1, true),
        ])
    }

    /// The (v, g) and (v, g_hit) histograms of the traced voxels, as a picture in `hdir`.
    fn write_stretched(&self, hdir: &Path) -> Result<(), String> {
        let axes = vec![
            Axis::new("v", 0.0, 255.0, 256).map_err(|e| e.to_string())?,
            Axis::new("g", 0.0, 1.05 * self.a, 256).map_err(|e| e.to_string())?,
        ];
        let channels = [self.value.samples(), self.g.samples(), self.g_hit.samples()];
        let (normal, stretched) =
            mdtf_histogram::stretched_pair(channels, self.hit.samples(), &axes, None).map_err(|e| e.to_string())?;
        write_stretched(hdir, &normal, &stretched, Scale::Log, "the validation erf sphere", &[])
            .map_err(|e| e.to_string())
    }

    /// The worst decode(quantise(x)) error in code steps, over f'' as u8 and u16.
    fn worst_decode_steps(&self) -> Result<f64, String> {
        let mut worst_steps = 0.0f64;
        let (lo, hi) = self.f2.finite_range().map_or((0.0, 1.0), |(l, h)| (l as f64, h as f64));
        for dtype in [Dtype::U8, Dtype::U16] {
            let dec = decode_for("f2", lo, hi, dtype, true).map_err(|e| e.to_string())?;
            for &x in self.f2.samples().iter().step_by(97) {
                let back = dec.value(dec.code(x, dtype), dtype);
                worst_steps = worst_steps.max((back - x as f64).abs() / dec.scale);
            }
        }
        Ok(worst_steps)
    }
}

/// The pre-integration table's worst error against a fine quadrature
/// (and the segment integral's opacity against the same).
fn preintegration_error() -> f64 {
    let tf = Tf1d::two_peaks(256);
    let table = preintegration_table(&tf, 32, 1.3);
    let mut worst_t = 0.0f64;
    for (i, j) in [(0usize, 31usize), (31, 0), (5, 20), (12, 12), (28, 3)] {
        let reference = segment_by_midpoint(&tf, i as f64 / 31.0, j as f64 / 31.0, 1.3, 4000);
        for ch in 0..4 {
            worst_t = worst_t.max((table[j * 32 + i][ch] as f64 - reference[ch]).abs());
        }
        let s = segment(&tf, i as f64 / 31.0, j as f64 / 31.0, 1.3);
        worst_t = worst_t.max((s[3] - reference[3]).abs());
    }
    worst_t
}

/// A 2D Gaussian primitive's segment integral's worst error against Simpson's rule.
fn gaussian_integral_error() -> f64 {
    let gp = GaussianPrimitive {
        centre: vec![0.4, 0.6],
        k: vec![vec![5.0, 1.0], vec![-2.0, 7.0]],
        alpha_max: 1.0,
        colour: [1.0; 3],
        triangular: false,
    };
    let mut worst_g = 0.0f64;
    for (v1, v2) in
        [([0.1, 0.2], [0.9, 0.8]), ([0.4, 0.6], [0.4, 0.6]), ([0.0, 1.0], [1.0, 0.0]), ([0.35, 0.5], [0.45, 0.7])]
    {
        let quad = simpson(|t| gp.density(&[v1[0] + t * (v2[0] - v1[0]), v1[1] + t * (v2[1] - v1[1])]), 4000);
        worst_g = worst_g.max((gp.segment_integral(&v1, &v2) - quad).abs());
    }
    worst_g
}

/// Simpson's rule with `steps` (even) intervals of f over [0, 1].
fn simpson(f: impl Fn(f64) -> f64, steps: usize) -> f64 {
    let w = |k: usize| {
        if k == 0 || k == steps {
            1.0
        } else if k % 2 == 1 {
            4.0
        } else {
            2.0
        }
    };
    (0..=steps).map(|k| w(k) * f(k as f64 / steps as f64)).sum::<f64>() / (3.0 * steps as f64)
}

/// Largest difference between the triangular GTF's analytic segment
/// integral (g held at the endpoints' mean, Gaussian-TF paper section 5.2.1)
/// and Simpson quadrature of its density along the segment at that g.
fn tgtf_integral_error() -> f64 {
    let gp = GaussianPrimitive {
        centre: vec![120.0],
        k: vec![vec![0.8]],
        alpha_max: 1.0,
        colour: [1.0; 3],
        triangular: true,
    };
    let mut worst = 0.0f64;
    for (v1, g1, v2, g2) in
        [(100.0, 20.0, 140.0, 30.0), (119.0, 2.0, 121.0, 3.0), (60.0, 40.0, 200.0, 10.0), (120.0, 5.0, 120.0, 5.0)]
    {
        let g_hat = 0.5 * (g1 + g2);
        let quad = simpson(|t| gp.density(&[v1 + t * (v2 - v1), g_hat]), 4000);
        worst = worst.max((gp.segment_integral(&[v1, g1], &[v2, g2]) - quad).abs());
    }
    worst
}

/// On the `shells` phantom (n^3, sigma 2) traced with the default
/// thresholds: for each of its three boundaries, the share of the voxels
/// within one voxel of its radius that are kept with g_hit within 5 % of the
/// boundary's peak |jump| / (sigma sqrt(2 pi)); the least of the three.
fn shells_least_kept(n: usize) -> Result<f64, String> {
    let sigma = 2.0;
    let ph = mdtf_datagen::RadialPhantom::tooth(Geometry::new([n; 3], [1.0; 3]), sigma);
    let chain = crate::boundary_chain::run(&ph.volume(), &Default::default()).map_err(|e| e.to_string())?;
    let out = &chain.boundary;
    let [nx, ny, _] = ph.geometry.dims;
    let c = ph.centre;
    let mut outer = ph.outside;
    let mut least = 1.0f64;
    for b in &ph.boundaries {
        let peak = (b.inside - outer).abs() / (sigma * (2.0 * PI).sqrt());
        outer = b.inside;
        let (mut near, mut kept) = (0usize, 0usize);
        for i in 0..out.hit.samples().len() {
            let (x, y, z) = ((i % nx) as f64, ((i / nx) % ny) as f64, (i / (nx * ny)) as f64);
            let rho = ((x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt();
            if (rho - b.radius).abs() <= 1.0 {
                near += 1;
                let gh = out.g_hit.samples()[i] as f64;
                kept += usize::from(out.hit.samples()[i] == 1.0 && ((gh - peak) / peak).abs() <= 0.05);
            }
        }
        least = least.min(kept as f64 / near.max(1) as f64);
    }
    Ok(least)
}

/// Mean relative error of per-vertex g on the mesh (`params.tets` per cell) of an n^3
/// erf sphere (radius 0.3 n, sigma 3) over the points with |x| < 2 sigma.
fn tetra_g_error(n: usize, params: &mdtf_tetra::TetraParams) -> Result<f64, String> {
    let phantom = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 0.3 * n as f64, 3.0, 0.0, 255.0, None);
    let mesh = mdtf_tetra::tetrahedralise(&phantom.volume(), params.tets, "v").map_err(|e| e.to_string())?;
    let g = mdtf_tetra::magnitudes(&mdtf_tetra::vertex_gradients(&mesh, params.gradient));
    let (mut sum, mut count) = (0.0, 0usize);
    for (p, &gv) in mesh.points.iter().zip(&g) {
        let truth = phantom.at(*p);
        if truth.x.abs() < 6.0 {
            sum += (gv as f64 - truth.g).abs() / truth.g;
            count += 1;
        }
    }
    Ok(sum / count.max(1) as f64)
}

/// Worst error of sampled F/B and Gaussian-widget table entries against
/// midpoint quadratures of their defining integrals, relative to each table's maximum.
fn tetra_table_error() -> f64 {
    let (size, tau_max, d_max) = ([16, 16, 16], 6.0, 2.0);
    let [f, b] = mdtf_pack::front_back_tables(size, tau_max, d_max);
    let centre = |i: usize, n: usize, lo: f64, hi: f64| lo + (i as f64 + 0.5) * (hi - lo) / n as f64;
    let max_of = |v: &[f32]| v.iter().fold(0.0f64, |m, x| m.max(x.abs() as f64));
    let scale = max_of(&f.values).max(max_of(&b.values));
    let mut worst = 0.0f64;
    for (i, j, k) in [(0, 0, 0), (15, 0, 15), (0, 15, 15), (7, 9, 3), (15, 15, 15), (3, 12, 8)] {
        let (af, ab, d) = (centre(i, 16, 0.0, tau_max), centre(j, 16, 0.0, tau_max), centre(k, 16, 0.0, d_max));
        let steps = 20_000;
        let h = d / steps as f64;
        let (mut depth, mut rf, mut rb) = (0.0, 0.0, 0.0);
        for m in 0..steps {
            let l = (m as f64 + 0.5) * h;
            let a = af + (ab - af) * l / d;
            let e = (-(depth + 0.5 * a * h)).exp() * h;
            rf += (1.0 - l / d) * e;
            rb += l / d * e;
            depth += a * h;
        }
        let at = (k * 16 + j) * 16 + i;
        worst = worst.max((f.values[at] as f64 - rf).abs() / scale).max((b.values[at] as f64 - rb).abs() / scale);
    }
    let gauss = mdtf_pack::gaussian_table([32, 16], 8.0, 4.0);
    let gscale = max_of(&gauss.values);
    for (i, j) in [(0, 0), (31, 15), (0, 15), (16, 8), (20, 3)] {
        let (t, p) = (centre(i, 32, -4.0, 4.0), centre(j, 16, 0.0, 8.0));
        let steps = 20_000;
        let reference: f64 =
            (0..steps).map(|m| (-p * libm::erf((m as f64 + 0.5) * t / steps as f64)).exp() * t / steps as f64).sum();
        worst = worst.max((gauss.values[j * 32 + i] as f64 - reference).abs() / gscale);
    }
    worst
}
