//! Every shipped pipeline, run end to end on a small version of its
//! built-in phantom: the pack, decoded from its manifest alone, must match
//! the phantom's analytic fields within the tolerances below (derivative
//! accuracy plus one quantisation step), not just exist.

use mdtf_datagen::{MultiFieldPhantom, RadialPhantom, erf_sphere, min_extent, voxel_position};
use mdtf_e2e::{mdtf_err, mdtf_ok, nrrd_f32, pipelines_dir, shipped_pipeline};
use mdtf_pipeline::file::{PhantomKind, Pipeline, parse};
use mdtf_volume::Geometry;
use serde_json::Value;
use std::path::{Path, PathBuf};

const SIZE: usize = 40;

/// Runs `name`.toml at SIZE^3 and returns (its parsed file, the pack folder, the manifest).
fn run(name: &str, dir: &Path) -> (Pipeline, PathBuf, Value) {
    run_file(&shipped_pipeline(name), name, dir)
}

/// [`run`] of the pipeline file `file`, into `dir/name`.
fn run_file(file: &Path, name: &str, dir: &Path) -> (Pipeline, PathBuf, Value) {
    let size = format!("input.size={SIZE}");
    let pipeline = parse(&std::fs::read_to_string(file).unwrap(), std::slice::from_ref(&size)).unwrap();
    let out = dir.join(name);
    mdtf_ok(&["run", file.to_str().unwrap(), "-o", out.to_str().unwrap(), "--set", &size, "-q"]);
    let pack = out.join("pack");
    let manifest = serde_json::from_slice(&std::fs::read(pack.join("manifest.json")).unwrap()).unwrap();
    (pipeline, pack, manifest)
}

/// A channel decoded from the manifest alone, and its quantisation step.
fn decode(pack: &Path, manifest: &Value, channel: &str) -> (Vec<f64>, f64) {
    let c = manifest["channels"].as_array().unwrap().iter().find(|c| c["name"] == channel).unwrap_or_else(|| {
        panic!("no channel {channel} in the manifest");
    });
    let t = manifest["textures"].as_array().unwrap().iter().find(|t| t["name"] == c["texture"]).unwrap();
    let comps = t["components"].as_u64().unwrap() as usize;
    let size = match t["dtype"].as_str().unwrap() {
        "u8" => 1,
        "u16" => 2,
        other => panic!("pipelines pack u8/u16, not {other}"),
    };
    let bytes = std::fs::read(pack.join(t["data"].as_str().unwrap())).unwrap();
    let (offset, scale) = (c["decode"]["offset"].as_f64().unwrap(), c["decode"]["scale"].as_f64().unwrap());
    let comp = c["component"].as_u64().unwrap() as usize;
    let values = bytes
        .chunks_exact(comps * size)
        .map(|px| {
            let code =
                if size == 1 { px[comp] as f64 } else { u16::from_le_bytes([px[2 * comp], px[2 * comp + 1]]) as f64 };
            offset + scale * code
        })
        .collect();
    (values, scale)
}

#[test]
fn every_shipped_pipeline_has_a_decode_test_here() {
    let mut shipped: Vec<String> = std::fs::read_dir(pipelines_dir())
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    shipped.sort();
    assert_eq!(shipped, ["distance-tf", "gaussian-tf", "peak-finding", "projected-tetrahedra", "slicer-3dtf"]);
}

fn geometry() -> Geometry {
    Geometry::new([SIZE; 3], [1.0; 3])
}

/// Voxel positions in x-fastest order.
fn positions(g: &Geometry) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(g.voxel_count());
    for k in 0..g.dims[2] {
        for j in 0..g.dims[1] {
            for i in 0..g.dims[0] {
                out.push(voxel_position(g, i, j, k));
            }
        }
    }
    out
}

/// The erf sphere `mdtf run` builds for a pipeline (radius 0.3 of the extent, values 0..255).
fn sphere(p: &Pipeline) -> RadialPhantom {
    assert_eq!(p.input.phantom, PhantomKind::ErfSphere);
    let g = geometry();
    erf_sphere(g.clone(), 0.3 * min_extent(&g), p.input.sigma, 0.0, 255.0, None)
}

/// Mean of |estimate - truth| / truth over the pairs (estimate, truth) where
/// `keep`, and how many there were.
fn mean_relative_error(pairs: impl Iterator<Item = (f64, f64, bool)>) -> (f64, usize) {
    let (sum, n) =
        pairs.filter(|p| p.2).fold((0.0, 0usize), |(s, n), (est, truth, _)| (s + (est - truth).abs() / truth, n + 1));
    (sum / n as f64, n)
}

fn max_abs_error(decoded: &[f64], truth: impl Iterator<Item = f64>, mask: impl Iterator<Item = bool>) -> f64 {
    decoded.iter().zip(truth).zip(mask).filter(|(_, m)| *m).fold(0.0f64, |w, ((d, t), _)| w.max((d - t).abs()))
}

#[test]
fn slicer_3dtf_pack_decodes_to_the_analytic_sphere() {
    let dir = tempfile::tempdir().unwrap();
    let (p, pack, m) = run("slicer-3dtf", dir.path());
    let ph = sphere(&p);
    let truth: Vec<_> = positions(&geometry()).into_iter().map(|x| ph.at(x)).collect();
    let peak_g = truth.iter().map(|t| t.g).fold(0.0, f64::max);
    let peak_f2 = truth.iter().map(|t| t.f2.abs()).fold(0.0, f64::max);
    let all = || std::iter::repeat(true);
    // derivatives within 2 voxels of a face feel the clamp-to-edge border (central4's reach)
    let inner: Vec<bool> =
        positions(&geometry()).iter().map(|x| x.iter().all(|&c| c >= 2.0 && c <= (SIZE - 3) as f64)).collect();
    let inside = || inner.iter().copied();
    let (v, sv) = decode(&pack, &m, "v");
    assert!(max_abs_error(&v, truth.iter().map(|t| t.v), all()) <= 0.5 * sv + 1e-3);
    let (g, sg) = decode(&pack, &m, "g");
    let eg = max_abs_error(&g, truth.iter().map(|t| t.g), inside());
    assert!(eg <= 0.5 * sg + 0.01 * peak_g, "g: worst {eg} (step {sg}, peak {peak_g})");
    let (f2, sf) = decode(&pack, &m, "f2");
    let ef = max_abs_error(&f2, truth.iter().map(|t| t.f2), inside());
    assert!(ef <= 0.5 * sf + 0.02 * peak_f2, "f2: worst {ef} (step {sf}, peak {peak_f2})");
    let n: Vec<Vec<f64>> = ["nx", "ny", "nz"].iter().map(|c| decode(&pack, &m, c).0).collect();
    let mut worst_dot = 1.0f64;
    for (i, t) in truth.iter().enumerate() {
        if t.g > 0.1 * peak_g && inner[i] {
            let (a, b, c) = (n[0][i], n[1][i], n[2][i]);
            let dot = (a * t.normal[0] + b * t.normal[1] + c * t.normal[2]) / (a * a + b * b + c * c).sqrt();
            worst_dot = worst_dot.min(dot);
        }
    }
    assert!(worst_dot >= 0.99, "normals: worst dot {worst_dot}");
}

#[test]
fn distance_tf_pack_decodes_to_the_analytic_distance_and_hit_gradient() {
    let dir = tempfile::tempdir().unwrap();
    // the clean-data settings the README gives (no pre-filter, central4): the truth is the
    // unsmoothed sphere's
    let text = std::fs::read_to_string(shipped_pipeline("distance-tf")).unwrap();
    let clean = text
        .replace("[prefilter]\nsigma_d = 1.0\nsigma_r = 0.1\nmode = \"fast\"\n", "")
        .replace("\"gauss:1\"", "\"central4\"");
    let file = dir.path().join("distance-tf-clean.toml");
    std::fs::write(&file, clean).unwrap();
    let (p, pack, m) = run_file(&file, "distance-tf", dir.path());
    assert!(p.prefilter.is_none() && p.derive.kernel == mdtf_derive::Kernel::Central4);
    let ph = sphere(&p);
    let truth: Vec<_> = positions(&geometry()).into_iter().map(|x| ph.at(x)).collect();
    let peak_g = truth.iter().map(|t| t.g).fold(0.0, f64::max);
    let (v, sv) = decode(&pack, &m, "v");
    assert!(max_abs_error(&v, truth.iter().map(|t| t.v), std::iter::repeat(true)) <= 0.5 * sv + 1e-3);
    let (d, sd) = decode(&pack, &m, "distance");
    let (gh, sg) = decode(&pack, &m, "g_hit");
    // traced voxels: those with a distance (the pack stores -1 for none, decoded within a step of it)
    let traced: Vec<bool> = d.iter().map(|&x| x > -0.5).collect();
    let n_traced = traced.iter().filter(|&&t| t).count();
    let near = truth.iter().filter(|t| t.x.abs() < 2.0 * p.input.sigma).count();
    assert!(n_traced as f64 >= 0.9 * near as f64, "{n_traced} traced of {near} voxels within 2 sigma");
    let ed = max_abs_error(&d, truth.iter().map(|t| t.x.abs()), traced.iter().copied());
    assert!(ed <= 0.5 * sd + 0.1, "distance: worst {ed} (step {sd})");
    let eg = max_abs_error(&gh, std::iter::repeat(peak_g), traced.iter().copied());
    assert!(eg <= 0.5 * sg + 0.01 * peak_g, "g_hit: worst {eg} (step {sg}, A {peak_g})");
}

#[test]
fn gaussian_tf_pack_decodes_to_the_fields_and_their_multi_field_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let (p, pack, m) = run("gaussian-tf", dir.path());
    assert_eq!(p.input.phantom, PhantomKind::Multifield);
    let ph = MultiFieldPhantom::new(geometry(), p.input.sigma);
    let sampled = ph.volume();
    for f in &sampled.fields {
        let (dec, step) = decode(&pack, &m, &f.name);
        let e = max_abs_error(&dec, f.data.iter().map(|&x| x as f64), std::iter::repeat(true));
        assert!(e <= 0.5 * step + 1e-3, "field {}: worst {e} (step {step})", f.name);
    }
    let truth = ph.truth(&sampled);
    let (gn, step) = decode(&pack, &m, "gnorm");
    let peak = truth.gnorm.data.iter().fold(0.0f32, |a, &b| a.max(b)) as f64;
    let (mean, n) = mean_relative_error(
        gn.iter().zip(truth.gnorm.data.iter()).map(|(&d, &t)| (d, t as f64, t as f64 > 0.1 * peak)),
    );
    assert!(mean <= 0.02, "||G||: mean relative error {mean} over {n} voxels (step {step})");
    // every pair of fields has its joint histogram, and every field one against ||G||: the
    // (a, b) counts are the phantom's own fields binned over the axes the JSON states
    let hist = pack.parent().unwrap().join("histogram");
    for pair in ["a_b", "a_c", "b_c", "a_gnorm", "b_gnorm", "c_gnorm"] {
        assert!(hist.join(format!("hist_{pair}.png")).is_file(), "hist_{pair}.png");
    }
    let json: Value = serde_json::from_slice(&std::fs::read(hist.join("hist_a_b.json")).unwrap()).unwrap();
    let axis = |k: usize| {
        let a = &json["axes"][k];
        (a["min"].as_f64().unwrap(), a["max"].as_f64().unwrap(), a["bins"].as_u64().unwrap() as usize)
    };
    let ((lo0, hi0, n0), (lo1, hi1, n1)) = (axis(0), axis(1));
    let bin = |x: f32, lo: f64, hi: f64, n: usize| {
        let t = (x as f64 - lo) / (hi - lo);
        (0.0..=1.0).contains(&t).then(|| ((t * n as f64) as usize).min(n - 1))
    };
    let mut want = vec![0i64; n0 * n1];
    for (&a, &b) in sampled.fields[0].data.iter().zip(sampled.fields[1].data.iter()) {
        if let (Some(i), Some(j)) = (bin(a, lo0, hi0, n0), bin(b, lo1, hi1, n1)) {
            want[j * n0 + i] += 1;
        }
    }
    let got = mdtf_e2e::nrrd_u32(&hist.join("hist_a_b.nrrd"));
    let off: i64 = got.iter().zip(&want).map(|(&g, &w)| (g as i64 - w).abs()).sum();
    let total: i64 = want.iter().sum();
    assert!(
        total as usize == sampled.fields[0].data.len() && off * 10_000 <= total,
        "{off} of {total} voxels binned apart"
    );
}

#[test]
fn peak_finding_pack_decodes_to_the_shells_and_their_inverse_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let (p, pack, m) = run("peak-finding", dir.path());
    assert_eq!(p.input.phantom, PhantomKind::Shells);
    let ph = RadialPhantom::tooth(geometry(), p.input.sigma);
    let truth: Vec<_> = positions(&geometry()).into_iter().map(|x| ph.at(x)).collect();
    let peak_g = truth.iter().map(|t| t.g).fold(0.0, f64::max);
    let (v, sv) = decode(&pack, &m, "v");
    assert!(max_abs_error(&v, truth.iter().map(|t| t.v), std::iter::repeat(true)) <= 0.5 * sv + 1e-3);
    let (inv, step) = decode(&pack, &m, "inv_g");
    let (mean, n) = mean_relative_error(inv.iter().zip(&truth).map(|(&d, t)| (d, 1.0 / t.g, t.g > 0.2 * peak_g)));
    assert!(mean <= 0.02, "1/g: mean relative error {mean} over {n} voxels (step {step})");
    // the (v, 1/g) histogram: its lowest occupied 1/g bin holds 1/g at the outer boundary's peak
    let hist = pack.parent().unwrap().join("histogram");
    let axes: Value = serde_json::from_slice(&std::fs::read(hist.join("hist_v_inv_g.json")).unwrap()).unwrap();
    let ia = &axes["axes"][1];
    let (bins, top) = (ia["bins"].as_u64().unwrap() as usize, ia["max"].as_f64().unwrap());
    let nv = axes["axes"][0]["bins"].as_u64().unwrap() as usize;
    let counts = mdtf_e2e::nrrd_u32(&hist.join("hist_v_inv_g.nrrd"));
    let lowest = (0..bins).find(|&j| counts[j * nv..(j + 1) * nv].iter().any(|&c| c > 0)).unwrap();
    let w = top / bins as f64;
    assert!(((lowest as f64 + 0.5) * w - 1.0 / peak_g).abs() <= 2.0 * w, "lowest bin {lowest} of {w} vs 1/{peak_g}");
    assert!(hist.join("hist_v_inv_g.png").exists());
}

/// Over several fields, peak finding's default TF is over (first field,
/// 1/sqrt(||G||)) of the normalised fields: at the first sphere's centre
/// value it is opaque for 1/sqrt(||G||) up to 1/(0.3 G/span), G = its
/// analytic peak gradient, span its range; and the preview shows it.
#[test]
fn peak_finding_over_several_fields_draws_the_first_fields_boundary() {
    let dir = tempfile::tempdir().unwrap();
    let file = shipped_pipeline("peak-finding");
    let out = dir.path().join("multi");
    let size = format!("input.size={SIZE}");
    mdtf_ok(&[
        "run",
        file.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--set",
        &size,
        "--set",
        "input.phantom=multifield",
        "-q",
    ]);
    let sigma = parse(&std::fs::read_to_string(&file).unwrap(), &[]).unwrap().input.sigma;
    let a = &MultiFieldPhantom::new(geometry(), sigma).volume().fields[0];
    let (lo, hi) = a.data.iter().fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x as f64), h.max(x as f64)));
    // field a: an erf sphere from 0 to 100 of blur sigma, peak g 100 / (sigma sqrt(2 pi)) per mm
    let g_normalised = 100.0 / (sigma * (2.0 * std::f64::consts::PI).sqrt()) / (hi - lo);
    let pack = out.join("pack");
    let m = mdtf_e2e::manifest(&pack);
    let lut = m["luts"].as_array().unwrap().iter().find(|l| l["name"] == "tf2d").expect("a default tf2d");
    let axis = |k: usize, f: &str| lut["axes"][k][f].clone();
    assert_eq!((axis(0, "channel"), axis(1, "channel")), (serde_json::json!("a"), serde_json::json!("inv_g")));
    let (nv, ni) = (axis(0, "size").as_u64().unwrap() as usize, axis(1, "size").as_u64().unwrap() as usize);
    let (v_min, v_max) = (axis(0, "min").as_f64().unwrap(), axis(0, "max").as_f64().unwrap());
    let inv_top = axis(1, "max").as_f64().unwrap();
    let table = mdtf_e2e::nrrd_f32(&pack.join(lut["file_f32"].as_str().unwrap()));
    let opaque = |i: usize| -> Vec<usize> { (0..ni).filter(|&j| table[4 * (j * nv + i) + 3] > 0.5).collect() };
    // the widget's column: at the sphere's centre value
    let column = (0..nv).max_by_key(|&i| opaque(i).len()).unwrap();
    let value = v_min + (column as f64 + 0.5) * (v_max - v_min) / nv as f64;
    assert!((value - (lo + hi) / 2.0).abs() < 0.05 * (hi - lo), "widget at {value}, range {lo}..{hi}");
    let cells = opaque(column);
    let reach = (*cells.last().unwrap() as f64 + 1.0) * inv_top / ni as f64;
    let want = 1.0 / (0.3 * g_normalised);
    eprintln!("widget at a = {value:.2}, opaque up to 1/sqrt(||G||) = {reach:.3} mm (analytic {want:.3})");
    assert!(cells[0] == 0 && (reach / want - 1.0).abs() < 0.1, "opaque up to 1/g {reach}, want {want}");
    let (w, h, px) = mdtf_e2e::read_rgb_png(&out.join("preview.png"));
    let lit = px.chunks_exact(3).filter(|c| c.iter().map(|&x| x as u32).sum::<u32>() >= 30).count();
    assert!(lit as f64 >= 0.02 * (w * h) as f64, "{lit} of {} preview pixels lit", w * h);
    // the (a, 1/g) histogram is named by the field, so the TF is drawn over it too
    let hist = out.join("histogram");
    let axes: Value = serde_json::from_slice(&std::fs::read(hist.join("hist_a_inv_g.json")).unwrap()).unwrap();
    assert_eq!((axes["axes"][0]["name"].as_str(), axes["axes"][1]["name"].as_str()), (Some("a"), Some("inv_g")));
    let (fw, fh, _) = mdtf_e2e::read_rgb_png(&hist.join("tf_tf2d.png"));
    assert!(fw >= 256 && fh >= 256 && fw <= 1200 && fh <= 1200, "tf_tf2d.png is {fw} x {fh}");
}

#[test]
fn projected_tetrahedra_pack_holds_the_sphere_s_and_g_at_every_point() {
    let dir = tempfile::tempdir().unwrap();
    let (p, pack, m) = run("projected-tetrahedra", dir.path());
    let ph = sphere(&p);
    assert_eq!(m["mesh"]["points"], SIZE * SIZE * SIZE);
    let points = nrrd_f32(&pack.join("points.nrrd"));
    let s_g = nrrd_f32(&pack.join("s_g.nrrd"));
    let (mut sum, mut n, mut worst_s) = (0.0, 0, 0.0f64);
    for (xyz, sg) in points.chunks_exact(3).zip(s_g.chunks_exact(2)) {
        let t = ph.at([xyz[0] as f64, xyz[1] as f64, xyz[2] as f64]);
        worst_s = worst_s.max((sg[0] as f64 - t.v).abs());
        let inside = xyz.iter().all(|&c| c > 0.5 && c < SIZE as f32 - 1.5);
        if t.x.abs() < 2.0 * p.input.sigma && inside {
            sum += (sg[1] as f64 - t.g).abs() / t.g;
            n += 1;
        }
    }
    assert!(worst_s < 1e-3, "s: worst {worst_s}");
    let mean = sum / n as f64;
    assert!(mean <= 0.02, "g: mean relative error {mean} over {n} points");
    let luts: Vec<&str> = m["luts"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    for t in ["pt_front", "pt_back", "pt_gaussian", "pt_triangle_rise", "pt_triangle_fall", "pt_sinusoid"] {
        assert!(luts.contains(&t), "{t} missing from {luts:?}");
    }
    // the (s, g) TF the preview draws: one TGTF at the sphere's one boundary, half way between its values
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(pack.join("gaussians.json")).unwrap()).unwrap();
    let (lo, hi) = s_g.chunks_exact(2).fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), c| (a.min(c[0]), b.max(c[0])));
    let centre = g[0]["centre"][0].as_f64().unwrap();
    let mid = 0.5 * (lo + hi) as f64;
    assert_eq!(g.as_array().unwrap().len(), 1, "{g}");
    assert!((centre - mid).abs() <= 0.05 * (hi - lo) as f64, "TGTF at {centre}, boundary at {mid}");
    assert!(pack.parent().unwrap().join("preview.png").is_file());
}

#[test]
fn projected_tetrahedra_meshes_a_volume_over_its_budget_from_block_averages_and_says_so() {
    // 40^3 gives 39^3 x 6 = 355914 tetrahedra; a budget of 60000 needs 2 x 2 x 2 blocks (19^3 x 6 = 41154)
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.nii.gz");
    mdtf_ok(&["synth", "erf-sphere", "-o", input.to_str().unwrap(), "--size", "40", "-q"]);
    let p = shipped_pipeline("projected-tetrahedra");
    let (pipe, i) = (p.to_str().unwrap(), input.to_str().unwrap());
    let budget = "tetra.max_tetrahedra=60000";
    let plan = mdtf_ok(&["run", pipe, "--input", i, "-o", "unused", "--set", budget, "--plan"]);
    assert!(plan.contains("355914 tetrahedra") && plan.contains("2 x 2 x 2 blocks, 20 x 20 x 20 points"), "{plan}");
    let out = dir.path().join("out");
    mdtf_ok(&["run", pipe, "--input", i, "-o", out.to_str().unwrap(), "--set", budget, "-q"]);
    let report: Value = serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap();
    let warned =
        report["warnings"].as_array().unwrap().iter().any(|w| w.as_str().unwrap().contains("2 x 2 x 2 blocks"));
    assert!(warned, "{}", report["warnings"]);
    let m: Value = serde_json::from_slice(&std::fs::read(out.join("pack/manifest.json")).unwrap()).unwrap();
    assert_eq!(m["mesh"]["points"], 20 * 20 * 20);
    assert_eq!(m["mesh"]["tetrahedra"], 19 * 19 * 19 * 6);
    // each point holds the mean of its 2 x 2 x 2 block of voxels, at the block's centre
    let v = mdtf_volume::read_scalar(&input, &mdtf_volume::ReadOptions::default()).unwrap();
    let (points, s_g) = (nrrd_f32(&out.join("pack/points.nrrd")), nrrd_f32(&out.join("pack/s_g.nrrd")));
    let g = &v.geometry;
    for (n, (xyz, sg)) in points.chunks_exact(3).zip(s_g.chunks_exact(2)).enumerate() {
        let (bi, bj, bk) = (n % 20, (n / 20) % 20, n / 400);
        let mut mean = 0.0;
        for (dz, dy, dx) in (0..8).map(|c| (c / 4, (c / 2) % 2, c % 2)) {
            mean += v.data[[2 * bk + dz, 2 * bj + dy, 2 * bi + dx]] as f64 / 8.0;
        }
        assert!((sg[0] as f64 - mean).abs() <= 1e-3 * mean.abs().max(1.0), "point {n}: {} vs {mean}", sg[0]);
        let centre = [(2 * bi) as f64 + 0.5, (2 * bj) as f64 + 0.5, (2 * bk) as f64 + 0.5];
        for a in 0..3 {
            let want = g.origin[a] + centre[a] * g.spacing[a];
            assert!((xyz[a] as f64 - want).abs() < 1e-3, "point {n} axis {a}: {} vs {want}", xyz[a]);
        }
    }
}

/// The number before `unit` on the line of `text` that starts with `label` (after spaces), in that unit's bytes.
fn bytes_on(text: &str, label: &str, column: usize) -> f64 {
    let line = text.lines().find(|l| l.trim_start().starts_with(label)).unwrap_or_else(|| panic!("{label}: {text}"));
    let words: Vec<&str> = line.split_whitespace().collect();
    let (n, unit) = (words[column].parse::<f64>().unwrap(), words[column + 1]);
    let scale = match unit {
        "B" => 1.0,
        "KiB" => 1024.0,
        "MiB" => 1024f64.powi(2),
        "GiB" => 1024f64.powi(3),
        "TiB" => 1024f64.powi(4),
        other => panic!("unit {other} in {line}"),
    };
    n * scale
}

#[test]
fn a_run_at_4096_cubed_is_sized_on_paper_before_it_runs() {
    let p = shipped_pipeline("distance-tf");
    let plan = mdtf_ok(&["run", p.to_str().unwrap(), "--plan", "--dims", "4096", "--memory-budget", "8GiB"]);
    // every task within its budget; the derive slabs cover the 4096 planes
    let line = |pass: &str| -> Vec<String> {
        let l = plan.lines().find(|l| l.trim_start().starts_with(pass)).unwrap_or_else(|| panic!("{pass}: {plan}"));
        l.split_whitespace().map(String::from).collect()
    };
    let slab_planes: usize = plan
        .lines()
        .find_map(|l| l.trim_start().strip_prefix("slabs of "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{plan}"));
    // the histograms count in 64 bits: 2^36 voxels are no reason to refuse
    assert!(!plan.contains("REFUSED"), "{plan}");
    let tasks: usize = line("derive ")[1].parse().unwrap();
    assert_eq!(tasks, 4096usize.div_ceil(slab_planes), "{plan}");
    for pass in ["input ", "derive ", "prefilter ", "boundary ", "keep ", "pack "] {
        assert!(bytes_on(&plan, pass, 2) <= 8.0 * 1024f64.powi(3), "{pass}: {plan}");
    }
    // the store holds v, the pre-filtered g and f'' and the three traced outputs the run reads
    // (distance, g_hit, hit: not dot), 4 bytes a voxel each but the hit codes' one; not g, whose
    // median the tasks take
    let voxels = 4096f64.powi(3);
    // (21 x 2^36 bytes = 1.3125 TiB, printed to a tenth)
    let store = bytes_on(&plan, "channel store", 5);
    assert!((store - 21.0 * voxels).abs() < 0.06 * 1024f64.powi(4), "{plan}");
    // kept: distance and g_hit as f32 before compression
    assert_eq!(bytes_on(&plan, "kept volumes", 4), 2.0 * 4.0 * voxels, "{plan}");
    // the textures' bytes a voxel are those of a real pack of this pipeline
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("small");
    let sets = ["--set", "input.size=24", "--set", "preview=false"];
    mdtf_ok(&[&["run", p.to_str().unwrap(), "-q", "-o", out.to_str().unwrap()][..], &sets[..]].concat());
    let raw: u64 = std::fs::read_dir(out.join("pack"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|f| f.extension().is_some_and(|e| e == "raw"))
        .map(|f| std::fs::metadata(f).unwrap().len())
        .sum();
    let per_voxel = raw as f64 / (24.0 * 24.0 * 24.0);
    assert_eq!(bytes_on(&plan, "pack textures", 2), per_voxel * voxels, "{plan}");
    assert!(plan.contains("us of one core per voxel") && plan.contains("core-hours"), "{plan}");
    // a budget that cannot hold one plane is said once, with what one plane needs
    let small = mdtf_err(&["run", p.to_str().unwrap(), "--plan", "--dims", "4096", "--memory-budget", "100MiB"]);
    assert_eq!(small.matches("too small for planes of 4096 x 4096").count(), 1, "{small}");
    assert!(small.contains("a slab of one plane with its halo needs"), "{small}");
}
