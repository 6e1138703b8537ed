//! Boundary detection and the default transfer function on real volumes of
//! `../shared/data/real` (see its README), with the same defaults for all.
//!
//! The references were read off each volume's (v, g) histogram, drawn with
//! every v column scaled to its own maximum (so that each column's typical
//! g shows), before the detection was tuned:
//! - engine (industrial CT, u8): air at v = 0 and the cast block at about
//!   144 (the two dips of the columns' typical g), one clear arch between
//!   them peaking near g = 45 at v = 70; denser inserts near 230.
//! - bonsai (CT, u8): still values near 0, 40, 134 and 203, arches between
//!   40 and 134 and between 134 and 203 (two humps, g up to about 30-40).
//!   Traced along the gradient (scipy, 3 voxels each way), the voxels at
//!   v 85-95 and g 20-35 lead down to 0 and to 40 in like numbers and up
//!   to 100-170: the 0 | 134 and 40 | 134 arches run at the same g, one
//!   arch in the (v, g) plane, found as 0 | 134 (the (v, g) histogram
//!   cannot part them; an LH histogram could).
//! - heptane (a simulated gas jet): soft fronts, no plateau but the ambient
//!   value 0: no boundary.

use mdtf_e2e::{mdtf_ok, read_rgb_png, shipped_pipeline};
use std::path::{Path, PathBuf};

/// A volume of `../shared/data/real`.
fn real(name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real").join(name);
    assert!(path.is_file(), "{} is missing (the shared real volumes)", path.display());
    path
}

/// Runs `pipeline` on `input` into `out`; returns the run report.
fn run(pipeline: &str, input: &Path, out: &Path) -> serde_json::Value {
    let p = shipped_pipeline(pipeline);
    mdtf_ok(&["run", p.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap()
}

/// (v_low, v_high) of every boundary of a run report.
fn boundaries(report: &serde_json::Value) -> Vec<(f64, f64)> {
    // (a report leaves the list out when it is empty)
    report["boundaries"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|b| (b["v_low"].as_f64().unwrap(), b["v_high"].as_f64().unwrap()))
        .collect()
}

/// The shares of the lit preview pixels whose hue is orange, blue and green
/// (the default TF's first three boundary colours), and the lit share.
fn colour_shares(preview: &Path) -> ([f64; 3], f64) {
    let (w, h, px) = read_rgb_png(preview);
    let mut counts = [0usize; 3];
    let mut lit = 0usize;
    for c in px.chunks_exact(3) {
        let (r, g, b) = (c[0] as i32, c[1] as i32, c[2] as i32);
        if r + g + b < 30 {
            continue;
        }
        lit += 1;
        if r > b + 40 && r >= g {
            counts[0] += 1;
        } else if b > r + 20 {
            counts[1] += 1;
        } else if g > r + 20 && g > b + 20 {
            counts[2] += 1;
        }
    }
    (counts.map(|n| n as f64 / lit.max(1) as f64), lit as f64 / (w * h) as f64)
}

/// Runs the default slicer-3dtf on the real volume `name`, asserts that each
/// of `pairs` (low, high) is found (both materials within 10), and that two
/// boundary colours each cover at least 5 % of the lit preview.
fn shows_in_their_own_colours(name: &str, pairs: &[(f64, f64)]) {
    let dir = tempfile::tempdir().unwrap();
    let found = boundaries(&run("slicer-3dtf", &real(name), dir.path()));
    eprintln!("{name}: {found:?}");
    for &(low, high) in pairs {
        let near = |&(a, b): &(f64, f64)| (a - low).abs() < 10.0 && (b - high).abs() < 10.0;
        assert!(found.iter().any(near), "{name}: {low} | {high} in {found:?}");
    }
    let (shares, lit) = colour_shares(&dir.path().join("preview.png"));
    eprintln!("{name} preview: {shares:?} of {lit}");
    assert!(shares.iter().filter(|&&s| s >= 0.05).count() >= 2, "{name}: {shares:?}");
}

#[test]
fn the_engine_block_and_its_inserts_show_in_their_own_colours() {
    // air | cast block
    shows_in_their_own_colours("engine.nii.gz", &[(0.0, 144.0)]);
    // the one-value TFs too: the inserts' isovalue (air | inserts, 0 to 229) is not their centre,
    // 114.5, where the block's surface lies as well (one blue block), but between 144 and 229
    for pipeline in ["gaussian-tf", "peak-finding"] {
        let dir = tempfile::tempdir().unwrap();
        run(pipeline, &real("engine.nii.gz"), dir.path());
        let (shares, lit) = colour_shares(&dir.path().join("preview.png"));
        eprintln!("engine {pipeline}: {shares:?} of {lit}");
        assert!(shares[0] >= 0.05 && shares[1] >= 0.05, "engine {pipeline}: {shares:?}");
    }
}

#[test]
fn the_bonsai_shows_its_materials_in_their_own_colours() {
    shows_in_their_own_colours("bonsai.nii.gz", &[(134.0, 203.0), (0.0, 134.0)]);
}

#[test]
fn a_smooth_simulation_field_has_no_boundary_and_its_fallback_still_shows_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("slicer");
    let report = run("slicer-3dtf", &real("heptane.nii.gz"), &out);
    assert!(boundaries(&report).is_empty(), "{:?}", boundaries(&report));
    let warnings = report["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("no boundary found")), "{warnings:?}");
    let (_, lit) = colour_shares(&out.join("preview.png"));
    assert!(lit >= 0.02, "{lit}");
    // peak finding writes its TF, its tables and its preview even so
    let out = dir.path().join("peak");
    run("peak-finding", &real("heptane.nii.gz"), &out);
    assert!(out.join("pack/tf2d_u8.nrrd").is_file());
    let (_, lit) = colour_shares(&out.join("preview.png"));
    assert!(lit >= 0.02, "{lit}");
}

/// The share of the lit pixels (channel sum above 30) of `preview` whose
/// colour is nearer in hue (cosine of RGB) to the default TF's `k`-th
/// boundary colour than to any other of the first `count`.
fn palette_share(preview: &Path, k: usize, count: usize) -> f64 {
    let (_, _, px) = read_rgb_png(preview);
    let palette = &mdtf_pack::BOUNDARY_PALETTE[..count];
    let (mut lit, mut mine) = (0usize, 0usize);
    for c in px.chunks_exact(3) {
        let c = [c[0] as f64, c[1] as f64, c[2] as f64];
        if c.iter().sum::<f64>() <= 30.0 {
            continue;
        }
        lit += 1;
        let cosine =
            |q: &[f64; 3]| (c[0] * q[0] + c[1] * q[1] + c[2] * q[2]) / (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        let nearest = (0..count).max_by(|&a, &b| cosine(&palette[a]).total_cmp(&cosine(&palette[b])));
        mine += usize::from(nearest == Some(k));
    }
    mine as f64 / lit.max(1) as f64
}

#[test]
fn a_head_ct_phantom_with_padding_and_a_holder_shows_its_bone_through_the_skin() {
    // the phantom's truth (mdtf synth ct-head: 1 mm voxels, 1 mm blur, 20 HU noise, int16,
    // -2000 padding outside the circular field of view)
    use mdtf_datagen::{CtHead, hu};
    let head = CtHead::new(mdtf_volume::Geometry::new([200, 200, 48], [1.0; 3]));
    let noise = head.noise;
    assert_eq!((noise, head.sigma), (20.0, 1.0), "the synth defaults the test reads");
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("head.nii.gz");
    mdtf_ok(&["synth", "ct-head", "-o", input.to_str().unwrap(), "--size", "200,200,48", "-q"]);
    let out = dir.path().join("out");
    let report = run("slicer-3dtf", &input, &out);
    let found: Vec<serde_json::Value> = report["boundaries"].as_array().cloned().unwrap_or_default();
    let f = |b: &serde_json::Value, k: &str| b[k].as_f64().unwrap();
    eprintln!("{:?}", found.iter().map(|b| (f(b, "v_low"), f(b, "v_high"), f(b, "sigma"))).collect::<Vec<_>>());
    // a boundary is a pair when both materials lie within one noise sd of the pair's values
    let at = |low: f64, high: f64| {
        found.iter().position(|b| (f(b, "v_low") - low).abs() <= noise && (f(b, "v_high") - high).abs() <= noise)
    };
    let truth = head.true_boundaries();
    // every resolvable pair found, sigma within 20 %: the skin, the holder, the skull on the soft
    // tissue around it, the diploe inside it, and the sinus's air in the frontal bone (a ball of
    // radius 6 mm: a few hundred voxels on an arch peaking at 958 HU/mm, over every other arch)
    let resolvable: Vec<_> = truth.iter().filter(|t| t.resolvable).collect();
    let names: Vec<_> = resolvable.iter().map(|t| (t.low.name, t.high.name)).collect();
    assert_eq!(
        names,
        [("air", "soft tissue"), ("air", "holder"), ("air", "bone"), ("soft tissue", "bone"), ("diploe", "bone")]
    );
    for t in resolvable {
        let k = at(t.low.hu, t.high.hu).unwrap_or_else(|| panic!("{} | {} not found", t.low.name, t.high.name));
        let sigma = f(&found[k], "sigma");
        assert!((sigma / t.sigma.unwrap() - 1.0).abs() <= 0.2, "{} | {}: sigma {sigma}", t.low.name, t.high.name);
    }
    // none extra: every boundary is one of the phantom's pairs (the padding meets the air along a
    // hard edge, with no arch: none is the padding's)
    for b in &found {
        let true_pair = truth.iter().any(|t| at(t.low.hu, t.high.hu).is_some_and(|k| std::ptr::eq(&found[k], b)));
        assert!(true_pair, "not a pair of the phantom: {b}");
        assert!(f(b, "v_low") > hu::PADDING + 10.0 * noise, "a boundary of the padding: {b}");
    }
    // the skin meets the surround (the air, not the padding, the commonest value)
    let skin = at(hu::AIR, hu::SKIN).unwrap();
    assert_eq!(found[skin]["meets_background"], true);
    // the bone shows through the skin: the bone boundaries' colours cover at least 10 % of the lit preview
    let preview = out.join("preview.png");
    let bone: f64 = [at(hu::SKIN, hu::BONE), at(hu::DIPLOE, hu::BONE)]
        .into_iter()
        .map(|k| palette_share(&preview, k.unwrap(), found.len()))
        .sum();
    assert!(bone >= 0.10, "bone colours on {bone} of the lit preview");
}

/// The default distance-tf run on an erf sphere (96^3, radius 28.8, sigma 3, 0 to 255) with noise
/// of sd `noise` and the extra settings `set`: the share of the shell's voxels (|x| <= sigma, x the
/// analytic signed distance) the tracing kept (distance >= 0), the run's warnings and the tracing's
/// resolved settings.
fn traced_shell(noise: f64, set: &[&str]) -> (f64, Vec<String>, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let (input, truth) = (dir.path().join("sphere.nii.gz"), dir.path().join("truth"));
    let (i, t, n) = (input.to_str().unwrap(), truth.to_str().unwrap(), noise.to_string());
    mdtf_ok(&["synth", "erf-sphere", "-o", i, "--size", "96", "--noise", &n, "--seed", "5", "--truth", t, "-q"]);
    let out = dir.path().join("out");
    let p = shipped_pipeline("distance-tf");
    let mut args = vec!["run", p.to_str().unwrap(), "--input", i, "-o", out.to_str().unwrap(), "-q"];
    for s in set {
        args.extend(["--set", s]);
    }
    mdtf_ok(&args);
    let read = |p: &Path| mdtf_volume::read(p, &mdtf_volume::ReadOptions::default()).unwrap().fields.remove(0).data;
    let (distance, x) = (read(&out.join("volumes/distance.nii.gz")), read(&truth.join("x.nii.gz")));
    let shell: Vec<bool> = x.iter().map(|x| x.abs() <= 3.0).collect();
    let kept = distance.iter().zip(&shell).filter(|&(d, &s)| s && *d >= 0.0).count();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap();
    let warnings = report["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap().to_string()).collect();
    let resolved = report["boundary"]["resolved"].clone();
    (kept as f64 / shell.iter().filter(|&&s| s).count() as f64, warnings, resolved)
}

/// Whether one of `warnings` says the tracing lost the sphere's boundary (its materials, 0 and
/// 255, named within 10 % of the contrast).
fn names_the_lost_sphere(warnings: &[String]) -> bool {
    warnings.iter().any(|w| {
        let Some(rest) = w.strip_prefix("tracing: the boundary ") else { return false };
        let mut values = rest.split(['|', '(']).map(|s| s.trim().parse::<f64>());
        matches!((values.next(), values.next()), (Some(Ok(lo)), Some(Ok(hi))) if lo.abs() < 25.5 && (hi - 255.0).abs() < 25.5)
    })
}

#[test]
fn the_default_distance_tf_traces_a_noisy_sphere_or_names_the_boundary_it_lost() {
    // noise of 5, 10 and 15 % of the contrast: the shipped pipeline (bilateral pre-filter, gauss:1)
    // keeps at least 80 % of the shell, or says which boundary it lost
    for noise in [12.75, 25.5, 38.25] {
        let (share, warnings, resolved) = traced_shell(noise, &[]);
        eprintln!("noise {noise}: {share} of the shell traced; {warnings:?}; {resolved}");
        assert!(share >= 0.8 || names_the_lost_sphere(&warnings), "noise {noise}: {share}, {warnings:?}");
        // the thresholds follow the boundary found before the tracing, not the noise: g_hit_min at
        // most half its peak g (255 / (sqrt(2 pi) sigma) with the gauss:1 kernel's blur, sigma =
        // sqrt(3^2 + 1^2) voxels, is 32.2), and the Fig. 2 range the materials' span (255, where
        // the min-max range grows with the noise to 583 at 15 %)
        let g_true = 255.0 / ((2.0 * std::f64::consts::PI).sqrt() * 10f64.sqrt());
        let (g_hit_min, range) = (resolved["g_hit_min"].as_f64().unwrap(), resolved["fig2_range"].as_f64().unwrap());
        assert!(g_hit_min <= 0.55 * g_true, "noise {noise}: g_hit_min {g_hit_min}");
        assert!((range / 255.0 - 1.0).abs() <= 0.15, "noise {noise}: Fig. 2 range {range}");
    }
    // the other side: a g_hit_min above the boundary's peak g (34) rejects its crossings, and the
    // run names the boundary it lost
    let (share, warnings, _) = traced_shell(25.5, &["boundary.g_hit_min=60"]);
    assert!(share < 0.8, "{share}");
    assert!(names_the_lost_sphere(&warnings), "{warnings:?}");
}
