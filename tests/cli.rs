//! The `mdtf` binary end to end: synth, info, convert, and its errors.

use mdtf_e2e::{mdtf, mdtf_err, mdtf_ok, shipped_pipeline};
use mdtf_volume::{ReadOptions, read, read_scalar};
use std::f64::consts::{PI, SQRT_2};
use std::path::Path;

#[test]
fn synth_truth_files_match_the_closed_forms_of_design_md() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.nii.gz");
    let truth = dir.path().join("truth");
    let (r, s, vmin, vmax) = (9.0, 1.5, 10.0, 210.0);
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        out.to_str().unwrap(),
        "--size",
        "40,36,20",
        "--spacing",
        "0.5,0.5,1.25",
        "--radius",
        "9",
        "--sigma",
        "1.5",
        "--vmin",
        "10",
        "--vmax",
        "210",
        "--origin",
        "-5,2,7",
        "--truth",
        truth.to_str().unwrap(),
        "-q",
    ]);
    let ro = ReadOptions::default();
    let v = read_scalar(&out, &ro).unwrap();
    let g = read_scalar(&truth.join("g.nii.gz"), &ro).unwrap();
    let f2 = read_scalar(&truth.join("f2.nii.gz"), &ro).unwrap();
    let x = read_scalar(&truth.join("x.nii.gz"), &ro).unwrap();
    let p = read_scalar(&truth.join("p.nii.gz"), &ro).unwrap();
    let n = read(&truth.join("normal.nii.gz"), &ro).unwrap();
    assert_eq!(v.geometry.spacing, [0.5, 0.5, 1.25]);
    assert_eq!(v.geometry.origin, [-5.0, 2.0, 7.0]);
    let c = [-5.0 + 19.5 * 0.5, 2.0 + 17.5 * 0.5, 7.0 + 9.5 * 1.25];
    let a = (vmax - vmin) / (s * (2.0 * PI).sqrt());
    let mut checked = 0;
    for ((k, j, i), &val) in v.data.indexed_iter() {
        let pos = [-5.0 + i as f64 * 0.5, 2.0 + j as f64 * 0.5, 7.0 + k as f64 * 1.25];
        let d = [pos[0] - c[0], pos[1] - c[1], pos[2] - c[2]];
        let rho = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let xx = r - rho;
        let vv = vmin + (vmax - vmin) * (1.0 + libm_erf(xx / (s * SQRT_2))) / 2.0;
        let gg = a * (-xx * xx / (2.0 * s * s)).exp();
        let ff = -xx * gg / (s * s);
        let tol = |t: f64| 1e-4 * (1.0 + t.abs());
        assert!((val as f64 - vv).abs() < tol(vv) * 10.0, "v at {i},{j},{k}");
        assert!((g.data[[k, j, i]] as f64 - gg).abs() < tol(gg));
        assert!((f2.data[[k, j, i]] as f64 - ff).abs() < tol(ff));
        assert!((x.data[[k, j, i]] as f64 - xx).abs() < 1e-4);
        if xx.abs() < 3.0 * s {
            assert!((p.data[[k, j, i]] as f64 - xx).abs() < 1e-3, "p = x at {i},{j},{k}");
            // the sign of f'': negative on the high (inside) side
            if xx.abs() > 0.1 {
                assert_eq!(f2.data[[k, j, i]] < 0.0, xx > 0.0);
            }
            checked += 1;
        }
        if rho > 1e-6 {
            let nx = n.fields[0].data[[k, j, i]] as f64;
            assert!((nx + d[0] / rho).abs() < 1e-5, "normal points to the centre");
        }
    }
    assert!(checked > 1000);
}

/// erf by its own series/continued fraction, independent of the generator's libm.
fn libm_erf(x: f64) -> f64 {
    // Abramowitz-Stegun 7.1.26 is too coarse; use the Taylor series for |x| < 3
    // and the asymptotic complement beyond.
    if x.abs() < 3.0 {
        let mut sum = x;
        let mut term = x;
        for n in 1..200 {
            term *= -x * x / n as f64;
            sum += term / (2 * n + 1) as f64;
        }
        2.0 / PI.sqrt() * sum
    } else {
        let t = 1.0 / (x * x);
        let tail =
            (-x * x).exp() / (x.abs() * PI.sqrt()) * (1.0 - t / 2.0 + 3.0 * t * t / 4.0 - 15.0 * t * t * t / 8.0);
        x.signum() * (1.0 - tail)
    }
}

#[test]
fn synth_is_identical_with_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.nrrd");
    let b = dir.path().join("b.nrrd");
    for (threads, out) in [("1", &a), ("2", &b)] {
        mdtf_ok(&[
            "--threads",
            threads,
            "synth",
            "shells",
            "-o",
            out.to_str().unwrap(),
            "--size",
            "48",
            "--noise",
            "5",
            "--seed",
            "3",
        ]);
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn info_reports_geometry_range_and_non_finite_count() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("n.nrrd");
    std::fs::write(
        &p,
        [
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 2\nspacings: 0.5 1 2\nendian: little\nencoding: raw\n\n"
                .as_slice(),
            &[1.0f32, f32::NAN, 3.0, -2.0].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<_>>(),
        ]
        .concat(),
    )
    .unwrap();
    let text = mdtf_ok(&["info", p.to_str().unwrap()]);
    assert!(text.contains("dims:        2x1x2"), "{text}");
    assert!(text.contains("spacing:     0.5 1 2"), "{text}");
    assert!(text.contains("NaN/Inf:   1"), "{text}");
    assert!(text.contains("range:     -2 .. 3"), "{text}");
}

#[test]
fn convert_refuses_nan_unless_asked_and_never_overwrites_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("n.nrrd");
    std::fs::write(
        &p,
        [
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nendian: little\nencoding: raw\n\n".as_slice(),
            &[1.0f32, f32::INFINITY].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<_>>(),
        ]
        .concat(),
    )
    .unwrap();
    let out = dir.path().join("o.nii");
    let e = mdtf_err(&["convert", p.to_str().unwrap(), out.to_str().unwrap()]);
    assert!(e.contains("1 samples are NaN or infinite") && e.contains("n.nrrd"), "{e}");
    assert!(!out.exists());
    mdtf_ok(&["convert", p.to_str().unwrap(), out.to_str().unwrap(), "--nan", "zero", "-q"]);
    let v = read_scalar(&out, &ReadOptions::default()).unwrap();
    assert_eq!(v.samples(), &[1.0, 0.0]);
    let before = std::fs::read(&p).unwrap();
    let e = mdtf_err(&["convert", p.to_str().unwrap(), p.to_str().unwrap(), "--nan", "zero"]);
    assert!(e.contains("refusing to overwrite") && e.contains("an input of this run"), "{e}");
    assert_eq!(std::fs::read(&p).unwrap(), before);
}

#[test]
fn bad_inputs_fail_with_the_file_named_and_leave_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("g.nii");
    mdtf_ok(&["synth", "erf-sphere", "-o", good.to_str().unwrap(), "--size", "8", "-q"]);
    let bytes = std::fs::read(&good).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.nii", vec![], "empty"),
        ("trunc.nii", bytes[..bytes.len() - 100].to_vec(), "truncated"),
        ("zero.nrrd", b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 0 4 4\nencoding: raw\n\n".to_vec(), "at least 1"),
        (
            "huge.nrrd",
            b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 90000 90000 90000\nencoding: raw\n\n".to_vec(),
            "would need",
        ),
        ("enc.nrrd", b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nencoding: hex\n\n00".to_vec(), "encoding"),
        (
            "type.nrrd",
            b"NRRD0004\ntype: block\ndimension: 3\nsizes: 1 1 1\nencoding: raw\n\n0".to_vec(),
            "unsupported data type",
        ),
        ("gz.nii.gz", vec![0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 1, 2, 3, 4, 5], "gzip"),
    ];
    for (name, content, expect) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, &content).unwrap();
        let out = dir.path().join(format!("out-{name}.nrrd"));
        let e = mdtf_err(&["convert", p.to_str().unwrap(), out.to_str().unwrap()]);
        assert!(e.contains(name) && e.to_lowercase().contains(expect), "{name}: {e}");
        assert!(!out.exists(), "{name}: output written");
    }
    let e = mdtf_err(&["info", dir.path().join("missing.nii").to_str().unwrap()]);
    assert!(e.contains("missing.nii") && e.contains("No such file"), "{e}");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".mdtf-partial"))
        .collect();
    assert!(left.is_empty(), "temporary files left behind");
}

#[test]
fn bad_parameters_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("x.nii");
    let o = o.to_str().unwrap();
    assert!(mdtf_err(&["synth", "erf-sphere", "-o", o, "--spacing", "1,0,1"]).contains("--spacing"));
    assert!(mdtf_err(&["synth", "erf-sphere", "-o", o, "--sigma", "-1"]).contains("--sigma"));
    assert!(mdtf_err(&["synth", "erf-sphere", "-o", o, "--size", "4,4"]).contains("--size"));
    assert!(mdtf_err(&["synth", "erf-sphere", "-o", "x.png"]).contains("unknown extension"));
}

#[test]
fn derive_writes_one_file_per_item_matching_the_analytic_truth() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nrrd");
    let truth = dir.path().join("truth");
    let out = dir.path().join("d");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        s.to_str().unwrap(),
        "--size",
        "64",
        "--radius",
        "19.2",
        "--sigma",
        "3",
        "--truth",
        truth.to_str().unwrap(),
        "-q",
    ]);
    mdtf_ok(&[
        "derive",
        s.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--items",
        "g,f2,normal",
        "--format",
        "nrrd",
        "-q",
    ]);
    let ro = ReadOptions::default();
    let g = read_scalar(&out.join("g.nrrd"), &ro).unwrap();
    let tg = read_scalar(&truth.join("g.nrrd"), &ro).unwrap();
    let x = read_scalar(&truth.join("x.nrrd"), &ro).unwrap();
    let n = read(&out.join("normal.nrrd"), &ro).unwrap();
    assert_eq!(n.fields.len(), 3);
    assert_eq!(g.geometry, tg.geometry);
    let peak = 255.0 / (3.0 * (2.0 * PI).sqrt());
    let (mut err, mut count) = (0.0, 0);
    for (idx, &xv) in x.data.indexed_iter() {
        if xv.abs() < 6.0 {
            err += (g.data[idx] - tg.data[idx]).abs() as f64;
            count += 1;
        }
    }
    let mean = err / count as f64 / peak;
    assert!(mean < 1e-3, "mean g error {mean:e}");
}

#[test]
fn derive_refuses_bad_requests_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.nii");
    let b = dir.path().join("b.nii");
    mdtf_ok(&["synth", "erf-sphere", "-o", a.to_str().unwrap(), "--size", "16", "-q"]);
    mdtf_ok(&["synth", "erf-sphere", "-o", b.to_str().unwrap(), "--size", "16", "--spacing", "1,1,2", "-q"]);
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    let e = mdtf_err(&["derive", a.to_str().unwrap(), "-o", o, "--items", "g,fpp"]);
    assert!(e.contains("unknown item 'fpp'") && e.contains("f2, laplacian"), "{e}");
    // a kernel or border the library does not know is a usage error (exit 2), said before the input is read
    let missing = dir.path().join("missing.nii");
    for (flag, value, said) in [("--kernel", "cubic", "unknown kernel 'cubic'"), ("--border", "mirorr", "`mirror`")] {
        let bad = mdtf(&["derive", missing.to_str().unwrap(), "-o", o, flag, value]);
        let e = String::from_utf8_lossy(&bad.stderr);
        assert!(bad.status.code() == Some(2) && e.contains(said) && !e.contains("missing.nii"), "{e}");
    }
    let e = mdtf_err(&["derive", a.to_str().unwrap(), b.to_str().unwrap(), "-o", o, "--items", "gnorm"]);
    assert!(e.contains("spacing"), "{e}");
    let tiny = dir.path().join("t.nii");
    mdtf_ok(&["synth", "erf-sphere", "-o", tiny.to_str().unwrap(), "--size", "3,8,8", "-q"]);
    let e = mdtf_err(&["derive", tiny.to_str().unwrap(), "-o", o]);
    assert!(e.contains("needs at least 5 samples along x"), "{e}");
    assert!(!out.exists() || std::fs::read_dir(&out).unwrap().count() == 0);
}

#[test]
fn bilateral_filters_and_names_bad_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let n = dir.path().join("n.nii.gz");
    let o = dir.path().join("o.nrrd");
    mdtf_ok(&["synth", "erf-sphere", "-o", n.to_str().unwrap(), "--size", "32", "--noise", "20", "-q"]);
    mdtf_ok(&[
        "bilateral",
        n.to_str().unwrap(),
        "-o",
        o.to_str().unwrap(),
        "--sigma-r",
        "50",
        "--range-units",
        "value",
        "-q",
    ]);
    let a = read_scalar(&n, &ReadOptions::default()).unwrap();
    let b = read_scalar(&o, &ReadOptions::default()).unwrap();
    assert_eq!(a.geometry, b.geometry);
    let var = |v: &mdtf_volume::Volume| {
        // local roughness: mean squared difference of x-neighbours
        let s = v.samples();
        s.windows(2).map(|w| ((w[1] - w[0]) as f64).powi(2)).sum::<f64>() / s.len() as f64
    };
    assert!(var(&b) < var(&a) / 4.0);
    let e = mdtf_err(&["bilateral", n.to_str().unwrap(), "-o", o.to_str().unwrap(), "--sigma-r", "0"]);
    assert!(e.contains("--sigma-r must be a positive number"), "{e}");
    let e = mdtf_err(&["bilateral", n.to_str().unwrap(), "-o", o.to_str().unwrap(), "--sigma-d", "40"]);
    assert!(e.contains("--sigma-d 40 gives a radius of 100 voxels"), "{e}");
}

#[test]
fn boundary_from_a_value_volume_and_from_derived_volumes_agree() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nii.gz");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        s.to_str().unwrap(),
        "--size",
        "48",
        "--radius",
        "15",
        "--sigma",
        "2",
        "-q",
    ]);
    let a = dir.path().join("a");
    let rep = dir.path().join("rep");
    mdtf_ok(&[
        "boundary",
        s.to_str().unwrap(),
        "-o",
        a.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
        "--alpha",
        "convex:a=1,dc=3,n=3",
        "-q",
    ]);
    let d = dir.path().join("d");
    mdtf_ok(&["derive", s.to_str().unwrap(), "-o", d.to_str().unwrap(), "--items", "g,f2,normal", "-q"]);
    let b = dir.path().join("b");
    let (g, f2, n) = (d.join("g.nii.gz"), d.join("f2.nii.gz"), d.join("normal.nii.gz"));
    mdtf_ok(&[
        "boundary",
        "--g",
        g.to_str().unwrap(),
        "--f2",
        f2.to_str().unwrap(),
        "--normal",
        n.to_str().unwrap(),
        "-o",
        b.to_str().unwrap(),
        "--value-range",
        "255",
        "-q",
    ]);
    let ro = ReadOptions::default();
    for name in ["distance", "g_hit", "hit", "dot"] {
        let x = read_scalar(&a.join(format!("{name}.nii.gz")), &ro).unwrap();
        let y = read_scalar(&b.join(format!("{name}.nii.gz")), &ro).unwrap();
        assert_eq!(x.data, y.data, "{name}");
    }
    let dist = read_scalar(&a.join("distance.nii.gz"), &ro).unwrap();
    let alpha = read_scalar(&a.join("alpha_convex.nii.gz"), &ro).unwrap();
    for (d, al) in dist.samples().iter().zip(alpha.samples()) {
        let want = if *d >= 0.0 { (1.0 - (*d as f64).powi(3) / 27.0).max(0.0) } else { 0.0 };
        assert!((*al as f64 - want).abs() < 1e-6);
    }
    let csv = std::fs::read_to_string(rep.join("boundary_report.csv")).unwrap();
    assert!(csv.starts_with("# mean dot product 1.0000") || csv.starts_with("# mean dot product 0.9999"), "{csv}");
    assert!(rep.join("boundary_report.png").exists());

    let e = mdtf_err(&["boundary", s.to_str().unwrap(), "-o", a.to_str().unwrap(), "--d-max", "500"]);
    assert!(e.contains("--d-max 500 is larger than the volume"), "{e}");
    let e = mdtf_err(&["boundary", s.to_str().unwrap(), "-o", a.to_str().unwrap(), "--step", "0"]);
    assert!(e.contains("--step must be positive"), "{e}");
    let other = dir.path().join("o.nii.gz");
    mdtf_ok(&["synth", "erf-sphere", "-o", other.to_str().unwrap(), "--size", "48", "--spacing", "1,1,2", "-q"]);
    let out = dir.path().join("never");
    let e = mdtf_err(&[
        "boundary",
        "--g",
        other.to_str().unwrap(),
        "--f2",
        f2.to_str().unwrap(),
        "--normal",
        n.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(e.contains("must share one grid"), "{e}");
    assert!(!out.exists());
}

#[test]
fn histogram_writes_pictures_counts_and_the_histogram_volume() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nii.gz");
    mdtf_ok(&["synth", "erf-sphere", "-o", s.to_str().unwrap(), "--size", "64", "--radius", "19.2", "-q"]);
    let out = dir.path().join("h");
    mdtf_ok(&["histogram", s.to_str().unwrap(), "-o", out.to_str().unwrap(), "--stretched", "--hvol", "-q"]);
    for f in [
        "hist_v_g.png",
        "hist_v_g.nrrd",
        "hist_v_g.json",
        "hist_v_g_hit.png",
        "normal_vs_stretched.png",
        "hvol.nrrd",
        "opacity.png",
        "position.nrrd",
        "hvol_per_v.csv",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("hvol.json")).unwrap()).unwrap();
    let sigma = json["sigma"].as_f64().unwrap();
    assert!((sigma - 3.0).abs() < 0.06, "{sigma}");
    let counts: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("hist_v_g.json")).unwrap()).unwrap();
    assert!(counts["total"].as_u64().unwrap() > 250_000);
    let e = mdtf_err(&["histogram", s.to_str().unwrap(), "-o", out.to_str().unwrap(), "--axes", "v,gg"]);
    assert!(e.contains("unknown channel 'gg'"), "{e}");
    let e = mdtf_err(&["histogram", s.to_str().unwrap(), "-o", out.to_str().unwrap(), "--range", "0:255,3:3"]);
    assert!(e.contains("degenerate"), "{e}");
    let e = mdtf_err(&["histogram", s.to_str().unwrap(), "-o", out.to_str().unwrap(), "--bins", "0"]);
    assert!(e.contains("zero bins"), "{e}");
    // more bin counts than axes is a mistake, not something to ignore
    let e = mdtf_err(&["histogram", s.to_str().unwrap(), "-o", out.to_str().unwrap(), "--bins", "4,4,4"]);
    assert!(e.contains("--bins: give one value (for all axes) or one per axis (2 axes: v, g), got 3"), "{e}");
    // three fields: the 3D counts, the three projections, and the colour-volume picture
    let mf = dir.path().join("m.nrrd");
    mdtf_ok(&["synth", "multifield", "-o", mf.to_str().unwrap(), "--size", "24", "-q"]);
    let h3 = dir.path().join("h3");
    let args = ["histogram", mf.to_str().unwrap(), "-o", h3.to_str().unwrap(), "--axes", "a,b,c", "--bins", "32"];
    mdtf_ok(&[&args[..], &["-q"]].concat());
    for f in ["hist_a_b_c.nrrd", "hist_a_b.png", "hist_a_c.png", "hist_b_c.png", "hist_a_b_c_rgb.png"] {
        assert!(h3.join(f).exists(), "{f}");
    }
    let decoder =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(h3.join("hist_a_b_c_rgb.png")).unwrap()));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    // the three projections as one figure with axes (the bins are kept in the NRRD)
    assert_eq!((info.width, info.height, info.color_type), (1260, 470, png::ColorType::Rgb));
}

#[test]
fn pack_writes_a_manifest_that_decodes_v_and_names_missing_channels() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nii.gz");
    let pack = dir.path().join("pack");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        s.to_str().unwrap(),
        "--size",
        "24",
        "--radius",
        "7",
        "--sigma",
        "1.5",
        "-q",
    ]);
    mdtf_ok(&[
        "pack",
        "--profile",
        "distance-tf",
        s.to_str().unwrap(),
        "-o",
        pack.to_str().unwrap(),
        "--range",
        "v=0:255",
        "-q",
    ]);
    let m = mdtf_e2e::manifest(&pack);
    assert_eq!(m["schema"], "mdtf-pack/1");
    let v = m["channels"].as_array().unwrap().iter().find(|c| c["name"] == "v").unwrap();
    let (off, scale) = (v["decode"]["offset"].as_f64().unwrap(), v["decode"]["scale"].as_f64().unwrap());
    assert_eq!((off, scale), (0.0, 1.0));
    let value = read_scalar(&s, &ReadOptions::default()).unwrap();
    let raw = std::fs::read(pack.join("normal_v.raw")).unwrap();
    for (i, &x) in value.samples().iter().enumerate() {
        assert!((off + scale * raw[i * 4 + 3] as f64 - x as f64).abs() <= 0.5 + 1e-6);
    }
    assert!(m["provenance"]["input_sha256"].as_str().unwrap().len() == 64);
    let schema = mdtf_ok(&["pack", "--schema"]);
    assert!(schema.contains("\"$id\": \"mdtf-pack/1\""));
    // a folder without the boundary outputs
    let d = dir.path().join("d");
    mdtf_ok(&["derive", s.to_str().unwrap(), "-o", d.to_str().unwrap(), "--items", "g,f2,normal", "-q"]);
    std::fs::copy(&s, d.join("value.nii.gz")).unwrap();
    let e = mdtf_err(&[
        "pack",
        "--profile",
        "distance-tf",
        d.to_str().unwrap(),
        "-o",
        dir.path().join("p2").to_str().unwrap(),
    ]);
    assert!(e.contains("no g_hit file"), "{e}");
    mdtf_ok(&[
        "pack",
        "--profile",
        "slicer-3dtf",
        d.to_str().unwrap(),
        "-o",
        dir.path().join("p3").to_str().unwrap(),
        "-q",
    ]);
}

#[test]
fn pack_rasterises_a_tf_file_into_the_slicer_tables() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nii.gz");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        s.to_str().unwrap(),
        "--size",
        "24",
        "--radius",
        "7",
        "--sigma",
        "1.5",
        "-q",
    ]);
    let tf = dir.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"v_range": [0, 256], "g_range": [0, 64], "f2_range": [-8, 8], "boundary_emphasis": 0.5,
            "widgets": [{"type": "triangle", "v0": 100, "width": 40, "g_high": 60, "alpha": 0.9, "colour": [1, 0, 0]}]}"#,
    )
    .unwrap();
    let pack = dir.path().join("pack");
    mdtf_ok(&[
        "pack",
        "--profile",
        "slicer-3dtf",
        s.to_str().unwrap(),
        "-o",
        pack.to_str().unwrap(),
        "--tf",
        tf.to_str().unwrap(),
        "-q",
    ]);
    let m = mdtf_e2e::manifest(&pack);
    let names: Vec<&str> = m["luts"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["tf3d", "tf2d", "tf_f2"]);
    let t3 = read(&pack.join("tf3d_f32.nrrd"), &ReadOptions::default()).unwrap();
    assert_eq!(t3.fields.len(), 4);
    assert_eq!(t3.geometry.dims, [256, 128, 9]);
    // cell (i, j, k): v = i + 0.5, g = (j + 0.5) / 2, f2 = -8 + (k + 0.5) * 16 / 9 (k = 4: f2 = 0)
    for (i, j, k) in [(120usize, 60usize, 3usize), (100, 100, 0), (130, 30, 8), (110, 50, 4)] {
        let (v, g, f2) = (i as f64 + 0.5, (j as f64 + 0.5) * 0.5, -8.0 + (k as f64 + 0.5) * 16.0 / 9.0);
        let tri = if g <= 60.0 { 0.9 * (1.0 - (v - 100.0).abs() / (40.0 * g / 60.0)).max(0.0) } else { 0.0 };
        let emphasis = 1.0 - 0.5 * (f2.abs() / 8.0);
        let got = t3.fields[3].data[[k, j, i]] as f64;
        assert!((got - tri * emphasis).abs() < 1e-6, "({i}, {j}, {k}): {got} vs {}", tri * emphasis);
    }
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"v_range": [0, 1], "g_range": [0, 1], "widgets": [{"type": "rectangle", "centre": [0, 0], "half_size": [1, 1], "falloff": "cone", "alpha": 1, "colour": [1, 1, 1]}]}"#).unwrap();
    let e = mdtf_err(&["pack", s.to_str().unwrap(), "-o", pack.to_str().unwrap(), "--tf", bad.to_str().unwrap()]);
    assert!(e.contains("widgets[0].falloff"), "{e}");
}

#[test]
fn gaussian_and_peak_finding_profiles_pack_fields_and_tables() {
    let dir = tempfile::tempdir().unwrap();
    let mf = dir.path().join("m.nrrd");
    mdtf_ok(&["synth", "multifield", "-o", mf.to_str().unwrap(), "--size", "24", "-q"]);
    let tf = dir.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"v_range": [0, 100], "g_range": [0, 1],
            "widgets": [{"type": "gaussian", "centre": [50, 0.5], "k": [[0.1, 0], [0, 4]], "alpha_max": 0.7, "colour": [0, 1, 0]}],
            "tf1d": [[1,1,1,0], [1,0,0,3], [1,1,1,0.5], [0,0,1,1], [1,1,1,0]]}"#,
    )
    .unwrap();
    let g = dir.path().join("g");
    mdtf_ok(&[
        "pack",
        "--profile",
        "gaussian-tf",
        mf.to_str().unwrap(),
        "-o",
        g.to_str().unwrap(),
        "--tf",
        tf.to_str().unwrap(),
        "-q",
    ]);
    let m = mdtf_e2e::manifest(&g);
    assert_eq!(m["textures"][0]["component_order"], serde_json::json!(["a", "b", "c", "gnorm"]));
    assert_eq!(m["textures"][0]["dtype"], "u16");
    let gaussians: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(g.join("gaussians.json")).unwrap()).unwrap();
    assert_eq!(gaussians[0]["alpha_max"], 0.7);
    let luts: Vec<&str> = m["luts"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(luts, ["igauss", "erf_difference", "peak_table", "preintegration"]);
    // the peaks of tf1d are its samples at v = 25 (tau 3) and v = 75 (tau 1)
    let pt = read(&g.join("peak_table_f32.nrrd"), &ReadOptions::default()).unwrap();
    let values = pt.fields[0].data.iter().copied().collect::<Vec<f32>>();
    assert!(values.contains(&25.0));
    assert!(values.iter().all(|&v| v == -1.0 || v == 25.0 || v == 75.0), "peaks are sample positions");
    assert!(values.contains(&75.0) && values.contains(&-1.0));
    let p = dir.path().join("p");
    mdtf_ok(&["pack", "--profile", "peak-finding", mf.to_str().unwrap(), "-o", p.to_str().unwrap(), "-q"]);
    let m = mdtf_e2e::manifest(&p);
    assert_eq!(m["textures"][0]["component_order"], serde_json::json!(["a", "b", "c", "inv_g"]));
    // several fields: 1/g comes from ||G|| of all three (not from field a), and the manifest says so
    let inv_g = m["channels"].as_array().unwrap().iter().find(|c| c["name"] == "inv_g").unwrap().clone();
    assert!(inv_g["meaning"].as_str().unwrap().contains("sqrt(||Df^T Df||)"), "{}", inv_g["meaning"]);
    let gm = mdtf_e2e::manifest(&g);
    let gnorm = gm["channels"].as_array().unwrap().iter().find(|c| c["name"] == "gnorm").unwrap().clone();
    let decode =
        |c: &serde_json::Value| (c["decode"]["offset"].as_f64().unwrap(), c["decode"]["scale"].as_f64().unwrap());
    let ((io, is), (go, gs)) = (decode(&inv_g), decode(&gnorm));
    let codes = |pack: &std::path::Path| -> Vec<u16> {
        let nhdr = std::fs::read_to_string(pack.join("fields_0.nhdr")).unwrap();
        let raw = nhdr.lines().find_map(|l| l.strip_prefix("data file: ")).unwrap().trim().to_string();
        std::fs::read(pack.join(raw)).unwrap().chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect()
    };
    let (pc, gc) = (codes(&p), codes(&g));
    let mut compared = 0;
    for (pv, gv) in pc.chunks_exact(4).zip(gc.chunks_exact(4)) {
        let (ci, cg) = (pv[3] as f64, gv[3] as f64);
        if ci >= 65535.0 || cg < 100.0 {
            continue; // 1/g clipped at the top of its range, or ||G|| too coarse in its codes
        }
        let (got, gn) = (io + is * ci, go + gs * cg);
        let want = 1.0 / gn.sqrt();
        // one code of each: d(1/sqrt(x)) = x^-1.5 / 2 dx
        let tol = is + 0.5 * gn.powf(-1.5) * gs;
        assert!((got - want).abs() <= tol, "inv_g {got} vs 1/sqrt(gnorm) {want} (tolerance {tol})");
        compared += 1;
    }
    assert!(compared > 1000, "{compared} voxels compared");
}

#[test]
fn a_product_tf_packs_one_table_per_factor_and_previews() {
    // Kniss et al.'s meteorological TF on a three-field volume: a 2D TF over (a, b) times a ramp over ||G||
    let dir = tempfile::tempdir().unwrap();
    let mf = dir.path().join("m.nrrd");
    mdtf_ok(&["synth", "multifield", "-o", mf.to_str().unwrap(), "--size", "32", "-q"]);
    let tf = dir.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"product": [
          {"channels": ["a", "b"], "ranges": [[0, 100], [0, 100]],
           "widgets": [{"type": "rectangle", "centre": [50, 50], "half_size": [50, 50], "falloff": "constant", "alpha": 0.7, "colour": [1, 0.4, 0.1]}]},
          {"channels": ["gnorm"], "ranges": [[0, 0.02]], "ramp": [0.001, 0.004]}]}"#,
    )
    .unwrap();
    let g = dir.path().join("g");
    mdtf_ok(&[
        "pack",
        "--profile",
        "gaussian-tf",
        mf.to_str().unwrap(),
        "-o",
        g.to_str().unwrap(),
        "--tf",
        tf.to_str().unwrap(),
        "-q",
    ]);
    let m = mdtf_e2e::manifest(&g);
    let luts = m["luts"].as_array().unwrap();
    let lut = |name: &str| luts.iter().find(|l| l["name"] == name).unwrap_or_else(|| panic!("no {name}")).clone();
    let (p0, p1) = (lut("product_0"), lut("product_1"));
    assert_eq!((p0["axes"][0]["channel"].as_str(), p0["axes"][1]["channel"].as_str()), (Some("a"), Some("b")));
    assert_eq!((p0["components"].as_u64(), p0["axes"][0]["size"].as_u64()), (Some(4), Some(256)));
    assert_eq!((p1["axes"][0]["channel"].as_str(), p1["components"].as_u64()), (Some("gnorm"), Some(1)));
    assert!(p1["meaning"].as_str().unwrap().contains("product of every product_* table's opacity"));
    // the ramp: 0 up to 0.001, 1 from 0.004, linear between, at the cell centres of [0, 0.02] in 256 cells
    let ramp = read(&g.join("product_1_f32.nrrd"), &ReadOptions::default()).unwrap();
    let values: Vec<f32> = ramp.fields[0].data.iter().copied().collect();
    assert_eq!(values.len(), 256);
    for (k, &got) in values.iter().enumerate() {
        let x = (k as f64 + 0.5) * 0.02 / 256.0;
        let want = ((x - 0.001) / 0.003).clamp(0.0, 1.0);
        assert!((got as f64 - want).abs() < 1e-6, "cell {k}: {got} vs {want}");
    }
    let png = dir.path().join("g.png");
    mdtf_ok(&["preview", g.to_str().unwrap(), "-o", png.to_str().unwrap(), "--size", "64", "-q"]);
    let (_, _, buf) = mdtf_e2e::read_rgb_png(&png);
    let orange = buf.chunks_exact(3).filter(|px| px[0] > 40 && px[0] > 2 * px[2]).count();
    assert!(orange > 100, "the product shows in the preview: {orange} pixels");
    // a factor over a channel the pack does not hold is refused by name
    std::fs::write(&tf, r#"{"product": [{"channels": ["g"], "ranges": [[0, 1]], "ramp": [0, 1]}]}"#).unwrap();
    let e = mdtf_err(&[
        "pack",
        "--profile",
        "gaussian-tf",
        mf.to_str().unwrap(),
        "-o",
        dir.path().join("h").to_str().unwrap(),
        "--tf",
        tf.to_str().unwrap(),
        "-q",
    ]);
    assert!(
        e.contains("product[0] reads channel 'g', which this pack does not hold (it holds: a, b, c, gnorm)"),
        "{e}"
    );
}

#[test]
fn the_default_slicer_tf_shows_every_boundary_the_histogram_volume_finds() {
    // shells (outside 20 | enamel 230 | dentin 140 | pulp 60), clean and with noise and a smoothing kernel
    let dir = tempfile::tempdir().unwrap();
    for (name, noise, kernel) in [("clean", "0", "central4"), ("noisy", "3", "gauss:1.5")] {
        let s = dir.path().join(format!("{name}.nii.gz"));
        mdtf_ok(&["synth", "shells", "-o", s.to_str().unwrap(), "--size", "96", "--noise", noise, "-q"]);
        let pipeline = dir.path().join(format!("{name}.toml"));
        std::fs::write(
            &pipeline,
            format!(
                "[derive]\nkernel = \"{kernel}\"\n[histogram]\njoint = true\nhvol = true\n[pack]\nprofile = \"slicer-3dtf\"\n"
            ),
        )
        .unwrap();
        let out = dir.path().join(name);
        mdtf_ok(&[
            "run",
            pipeline.to_str().unwrap(),
            "--input",
            s.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-q",
        ]);
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
        // with noise and the smoothing kernel the pulp (a ball of radius 7.7 voxels, blurred by
        // sigma 2 and the kernel) holds no plateau of its own value: its boundary is not found
        let found = report["boundaries"].as_array().unwrap().len();
        assert_eq!(found, if name == "clean" { 3 } else { 2 }, "{name}: {}", report["boundaries"]);
        let m = mdtf_e2e::manifest(&out.join("pack"));
        let lut = m["luts"].as_array().unwrap().iter().find(|l| l["name"] == "tf2d_default").unwrap().clone();
        assert!(lut["meaning"].as_str().unwrap().contains("surface opacity"), "{}", lut["meaning"]);
        assert_every_boundary_colour_shows(&out.join("preview.png"), found, name);
        // the contact sheet is captioned, and its description names files in the output, not the staging folder
        let sheet = std::fs::read(out.join("contact_sheet.png")).unwrap();
        let text = String::from_utf8_lossy(&sheet);
        let at = text.find("mdtf contact sheet: ").expect("described");
        let line: String = text[at..].chars().take_while(|c| *c != '\0').collect();
        assert!(line.contains("preview.png; histogram/hist_v_g.png; histogram/opacity.png"), "{line}");
        assert!(!line.contains(dir.path().to_str().unwrap()), "{line}");
    }
}

/// Runs the shipped pipeline `name` on `input` into `out`, quietly.
fn run_shipped(name: &str, input: &Path, out: &Path) {
    let pipeline = shipped_pipeline(name);
    mdtf_ok(&[
        "run",
        pipeline.to_str().unwrap(),
        "--input",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
    ]);
}

/// Asserts that of the foreground pixels of the RGB picture `png` (|rgb| >= 30),
/// each of the first `boundaries` colours of the default TFs' palette is the
/// nearest in hue (cosine) to at least 2 %.
fn assert_every_boundary_colour_shows(png: &Path, boundaries: usize, name: &str) {
    let (_, _, px) = mdtf_e2e::read_rgb_png(png);
    let palette = &mdtf_pack::BOUNDARY_PALETTE[..boundaries];
    let mut per = vec![0usize; boundaries];
    let mut foreground = 0;
    for p in px.chunks_exact(3) {
        let c = [p[0] as f64, p[1] as f64, p[2] as f64];
        let norm = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        if norm < 30.0 {
            continue;
        }
        foreground += 1;
        let cosine = |q: &[f64; 3]| {
            (c[0] * q[0] + c[1] * q[1] + c[2] * q[2]) / (norm * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt())
        };
        let k = (0..boundaries).max_by(|&a, &b| cosine(&palette[a]).total_cmp(&cosine(&palette[b]))).unwrap();
        per[k] += 1;
    }
    eprintln!("{name}: {foreground} foreground pixels, per boundary colour {per:?}");
    assert!(foreground as f64 >= 0.02 * (px.len() / 3) as f64, "{name}: {foreground} foreground pixels");
    for (k, n) in per.iter().enumerate() {
        assert!(*n as f64 >= 0.02 * foreground as f64, "{name}: boundary {k} shows in {n} of {foreground} pixels");
    }
}

#[test]
fn a_head_ct_phantom_shows_its_skin_faintly_and_its_bone_through_it() {
    // air -1000 HU | skin (soft tissue, 40) | skull (bone, 1000) | brain (30), layers 5.6 voxels
    // thick, blurred by sigma 1 voxel, CT noise of 20 HU, stored as int16 like a scanner's output
    use mdtf_datagen::{Boundary, RadialPhantom, add_gaussian_noise, grid_centre};
    let n = 112;
    let geometry = mdtf_volume::Geometry::new([n; 3], [1.0; 3]);
    let e = n as f64;
    let head = RadialPhantom {
        centre: grid_centre(&geometry),
        geometry,
        sigma: 1.0,
        outside: -1000.0,
        boundaries: vec![
            Boundary { radius: 0.45 * e, inside: 40.0 },
            Boundary { radius: 0.40 * e, inside: 1000.0 },
            Boundary { radius: 0.35 * e, inside: 30.0 },
        ],
    };
    let mut ct = head.volume();
    add_gaussian_noise(&mut ct, 20.0, 7);
    ct.data.mapv_inplace(f32::round);
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("head-ct.nii.gz");
    mdtf_volume::write_nifti(&input, &mdtf_volume::MultiField::from(ct), mdtf_volume::SampleType::I16).unwrap();
    let out = dir.path().join("out");
    run_shipped("slicer-3dtf", &input, &out);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    let found = report["boundaries"].as_array().unwrap();
    assert_eq!(found.len(), 2, "skin and bone (bone | brain shares the bone's arch): {found:?}");
    let f = |b: &serde_json::Value, k: &str| b[k].as_f64().unwrap();
    let skin = found.iter().find(|b| b["meets_background"] == true).expect("the skin meets the air");
    let bone = found.iter().find(|b| b["meets_background"] == false).expect("the bone lies inside");
    // the materials within 5 % of the boundary's step
    for (b, low, high) in [(skin, -1000.0, 40.0), (bone, 35.0, 1000.0)] {
        let tol = 0.05 * (high - low);
        assert!((f(b, "v_low") - low).abs() < tol && (f(b, "v_high") - high).abs() < tol, "{b}");
    }
    // the skin faint, the bone opaque
    let m = mdtf_e2e::manifest(&out.join("pack"));
    let lut = m["luts"].as_array().unwrap().iter().find(|l| l["name"] == "tf2d_default").unwrap();
    let meaning = lut["meaning"].as_str().unwrap();
    assert!(meaning.contains("surface opacity 1.000") && meaning.contains("surface opacity 0.300"), "{meaning}");
    // both show in the preview, and the noise of the air and the brain shows nowhere: no lone lit pixels
    let preview = out.join("preview.png");
    assert_every_boundary_colour_shows(&preview, 2, "head CT");
    let (w, h, px) = mdtf_e2e::read_rgb_png(&preview);
    let (w, h) = (w as usize, h as usize);
    let lit = |x: usize, y: usize| px[3 * (y * w + x)..3 * (y * w + x) + 3].iter().map(|&c| c as u32).sum::<u32>() > 50;
    let (mut foreground, mut lone) = (0, 0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            if lit(x, y) {
                foreground += 1;
                let neighbours =
                    [(0, 1), (2, 1), (1, 0), (1, 2)].iter().filter(|(dx, dy)| lit(x + dx - 1, y + dy - 1)).count();
                lone += usize::from(neighbours == 0);
            }
        }
    }
    assert!(foreground > w * h / 10 && lone * 1000 < foreground, "{lone} lone of {foreground} lit pixels");
}

#[test]
fn a_two_field_head_phantom_gets_a_gaussian_per_material_and_shows_them_all() {
    // two MR-like contrasts of air | skin (r 0.45) | skull (r 0.36) | brain (r 0.27), layers of 8.6
    // voxels blurred by sigma 1 voxel, independent noise of 3 in each: in the joint histogram,
    // four blobs joined by the arcs of their partial-volume voxels
    use mdtf_datagen::{Boundary, RadialPhantom, add_gaussian_noise, grid_centre};
    let n = 96;
    let geometry = mdtf_volume::Geometry::new([n; 3], [1.0; 3]);
    let e = n as f64;
    // (skin, skull, brain) in each field; air is 0 in both
    let materials = [[60.0, 90.0], [20.0, 15.0], [100.0, 50.0]];
    let field = |a: usize, seed: u64| {
        let phantom = RadialPhantom {
            centre: grid_centre(&geometry),
            geometry: geometry.clone(),
            sigma: 1.0,
            outside: 0.0,
            boundaries: [0.45, 0.36, 0.27]
                .iter()
                .zip(&materials)
                .map(|(r, m)| Boundary { radius: r * e, inside: m[a] })
                .collect(),
        };
        let mut v = phantom.volume();
        add_gaussian_noise(&mut v, 3.0, seed);
        (format!("field{a}"), v)
    };
    let stack = mdtf_volume::MultiField::from_volumes(vec![field(0, 11), field(1, 12)]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("head-2field.nii");
    mdtf_volume::write_nifti(&input, &stack, mdtf_volume::SampleType::F32).unwrap();
    let out = dir.path().join("out");
    run_shipped("gaussian-tf", &input, &out);
    let gaussians: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("pack/gaussians.json")).unwrap()).unwrap();
    let gaussians = gaussians.as_array().unwrap();
    // the air (the background, on the volume's faces) gets none; each material one, at its values
    assert_eq!(gaussians.len(), 3, "{gaussians:?}");
    for m in materials {
        let at = |g: &&serde_json::Value| {
            let c = g["centre"].as_array().unwrap();
            (0..2).all(|a| (c[a].as_f64().unwrap() - m[a]).abs() < 2.0)
        };
        let g = gaussians.iter().find(at).unwrap_or_else(|| panic!("no Gaussian at {m:?}: {gaussians:?}"));
        assert!(g["triangular"].is_null(), "a full Gaussian: {g}");
        let a = g["alpha_max"].as_f64().unwrap();
        assert!(a > 0.0 && a <= 1.0, "{g}");
    }
    // the brain, innermost, opaque per voxel; the skin and skull around it faint enough to see through
    let alpha = |k: usize| gaussians[k]["alpha_max"].as_f64().unwrap();
    let brain = gaussians.iter().position(|g| g["centre"][0].as_f64().unwrap() > 90.0).unwrap();
    assert!((0..3).filter(|&k| k != brain).all(|k| alpha(k) < 0.3 && alpha(k) < alpha(brain)), "{gaussians:?}");
    // the colours of the palette, each shown by at least 2 % of the preview's foreground
    let colours: Vec<_> = gaussians.iter().map(|g| g["colour"].clone()).collect();
    for (k, c) in colours.iter().enumerate() {
        let want: Vec<f64> = mdtf_pack::BOUNDARY_PALETTE[k].to_vec();
        assert_eq!(c.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect::<Vec<_>>(), want);
    }
    assert_every_boundary_colour_shows(&out.join("preview.png"), 3, "two-field head");
    // drawn over the fields' joint histogram, within the figure size limit
    let (w, h, _) = mdtf_e2e::read_rgb_png(&out.join("histogram/tf_gaussians_field0_field1.png"));
    assert!(w <= 1200 && h <= 1200, "{w} x {h}");
    // the report page lists them
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(page.contains("<h2>Gaussian transfer function</h2>"));
    assert_eq!(page.matches("<td>full</td>").count(), 3);
    assert!(page.contains("field0 99.") || page.contains("field0 100."), "the brain's centre is listed");
}

/// Packs the shells phantom (96^3) as `profile` without a TF, checks that
/// its default table `lut` says `says`, and previews it (160^2): every
/// boundary's colour must show. Returns the table's manifest entry.
fn default_tf_of_the_shells(profile: &str, lut: &str, says: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("shells.nii.gz");
    mdtf_ok(&["synth", "shells", "-o", s.to_str().unwrap(), "--size", "96", "-q"]);
    let pack = dir.path().join("pack");
    mdtf_ok(&["pack", "--profile", profile, s.to_str().unwrap(), "-o", pack.to_str().unwrap(), "-q"]);
    let m = mdtf_e2e::manifest(&pack);
    let entry = m["luts"].as_array().unwrap().iter().find(|l| l["name"] == lut).unwrap().clone();
    assert!(entry["meaning"].as_str().unwrap().contains(says), "{}", entry["meaning"]);
    let png = dir.path().join("preview.png");
    mdtf_ok(&["preview", pack.to_str().unwrap(), "-o", png.to_str().unwrap(), "--size", "160", "-q"]);
    assert_every_boundary_colour_shows(&png, 3, profile);
    entry
}

#[test]
fn distance_tf_without_a_tf_colours_every_boundary_found() {
    default_tf_of_the_shells("distance-tf", "alpha_u", "from the 3 boundaries found");
}

#[test]
fn peak_finding_without_a_tf_renders_a_thin_widget_at_every_boundary_found() {
    let lut = default_tf_of_the_shells("peak-finding", "tf2d", "(3 found)");
    assert_eq!((lut["axes"][0]["size"].as_u64(), lut["axes"][1]["channel"].as_str()), (Some(1024), Some("inv_g")));
}

/// The NRRD payload of a 16-bit table as codes.
fn u16_codes(path: &std::path::Path) -> Vec<u16> {
    mdtf_e2e::nrrd_payload(path).chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect()
}

/// Simpson's rule of f over [a, b] with n (even) intervals.
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let w = |k: usize| {
        if k == 0 || k == n {
            1.0
        } else if k % 2 == 1 {
            4.0
        } else {
            2.0
        }
    };
    (0..=n).map(|k| w(k) * f(a + k as f64 * h)).sum::<f64>() * h / 3.0
}

#[test]
fn gaussian_tf_packs_scalar_data_with_the_papers_tables_and_default_or_fitted_gtfs() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nii.gz");
    mdtf_ok(&["synth", "shells", "-o", s.to_str().unwrap(), "--size", "48", "--sigma", "1.5", "-q"]);
    let g = dir.path().join("g");
    mdtf_ok(&["pack", "--profile", "gaussian-tf", s.to_str().unwrap(), "-o", g.to_str().unwrap(), "-q"]);
    let m = mdtf_e2e::manifest(&g);
    assert_eq!(m["textures"][0]["component_order"], serde_json::json!(["v", "g"]));
    // without a TF: a triangular GTF of the paper's form (width 1) at each boundary found, in its
    // colour: every GTF sits at one of the shells' three boundary centres (20|enamel,
    // enamel|140, 140|60) and each centre has one. The enamel shell (3.4 voxels thick, blurred by
    // sigma 1.5) never reaches its nominal 230: its value is the phantom's analytic peak across it
    let phantom = mdtf_datagen::RadialPhantom::tooth(mdtf_volume::Geometry::new([48; 3], [1.0; 3]), 1.5);
    let c0 = mdtf_datagen::grid_centre(&phantom.geometry);
    let enamel = (0..=200)
        .map(|k| phantom.at([c0[0] + 0.30 * 48.0 + 0.15 * 48.0 * k as f64 / 200.0, c0[1], c0[2]]).v)
        .fold(f64::MIN, f64::max);
    let gaussians: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(g.join("gaussians.json")).unwrap()).unwrap();
    let centres: Vec<f64> = gaussians.as_array().unwrap().iter().map(|p| p["centre"][0].as_f64().unwrap()).collect();
    let truth = [(20.0 + enamel) / 2.0, (140.0 + enamel) / 2.0, 100.0];
    let near = |a: f64, b: f64| (a - b).abs() < 15.0;
    assert!(centres.iter().all(|c| truth.iter().any(|t| near(*c, *t))), "{centres:?}");
    assert!(truth.iter().all(|t| centres.iter().any(|c| near(*c, *t))), "{centres:?} vs {truth:?}");
    for (k, p) in gaussians.as_array().unwrap().iter().enumerate() {
        assert_eq!((&p["triangular"], &p["k"]), (&serde_json::json!(true), &serde_json::json!([[1.0]])));
        assert_eq!(p["colour"], serde_json::json!(mdtf_pack::BOUNDARY_PALETTE[k]), "{p}");
    }
    // no boundary (noise about 100): the paper's default, one white triangular GTF at the median
    let mut flat = mdtf_volume::Volume::zeros(mdtf_volume::Geometry::new([32; 3], [1.0; 3]));
    flat.data.fill(100.0);
    mdtf_datagen::add_gaussian_noise(&mut flat, 10.0, 3);
    let noise = dir.path().join("noise.nii.gz");
    mdtf_volume::write_volume(&noise, &flat, &Default::default(), &[]).unwrap();
    let ng = dir.path().join("ng");
    mdtf_ok(&["pack", "--profile", "gaussian-tf", noise.to_str().unwrap(), "-o", ng.to_str().unwrap(), "-q"]);
    let paper: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ng.join("gaussians.json")).unwrap()).unwrap();
    assert_eq!(paper.as_array().unwrap().len(), 1, "{paper}");
    assert_eq!(
        (&paper[0]["colour"], &paper[0]["k"]),
        (&serde_json::json!([1.0, 1.0, 1.0]), &serde_json::json!([[1.0]]))
    );
    let c = paper[0]["centre"][0].as_f64().unwrap();
    assert!((c - 100.0).abs() < 2.0, "the median of the noise: {c}");

    // IGauss (eq. 16) and erf(x) - erf(y), decoded from their 16-bit codes, against quadrature
    let luts = m["luts"].as_array().unwrap();
    let table = |name: &str| luts.iter().find(|l| l["name"] == name).unwrap().clone();
    let erf = |x: f64| simpson(|t| 2.0 / PI.sqrt() * (-t * t).exp(), 0.0, x, 2000);
    let igauss = |x1: f64, x2: f64| {
        if (x1 - x2).abs() < 1e-12 { (-x1 * x1).exp() } else { simpson(|t| (-t * t).exp(), x2, x1, 4000) / (x1 - x2) }
    };
    let erf_difference = |x: f64, y: f64| erf(x) - erf(y);
    type Definition<'a> = (&'a str, usize, f64, f64, &'a dyn Fn(f64, f64) -> f64);
    let definitions: [Definition; 2] =
        [("igauss", 128, -10.0, 10.0, &igauss), ("erf_difference", 256, -3.6, 3.6, &erf_difference)];
    for (name, size, lo, hi, f) in definitions {
        let t = table(name);
        assert_eq!(t["axes"][0]["size"], size);
        assert_eq!((t["axes"][0]["min"].as_f64(), t["axes"][0]["max"].as_f64()), (Some(lo), Some(hi)));
        let (offset, scale) = (t["u16"]["offset"].as_f64().unwrap(), t["u16"]["scale"].as_f64().unwrap());
        let codes = u16_codes(&g.join(t["u16"]["file"].as_str().unwrap()));
        assert_eq!(codes.len(), size * size);
        let centre = |i: usize| lo + (i as f64 + 0.5) * (hi - lo) / size as f64;
        let mut worst = 0.0f64;
        for j in (0..size).step_by(7) {
            for i in (0..size).step_by(5) {
                let got = offset + scale * codes[j * size + i] as f64;
                worst = worst.max((got - f(centre(i), centre(j))).abs() / scale);
            }
        }
        assert!(worst <= 0.5 + 1e-3, "{name}: worst {worst} 16-bit steps");
    }

    // a GTF fitted to a probed region: the mask selects the voxels with v in [130, 150] (dentin)
    let v = read_scalar(&s, &ReadOptions::default()).unwrap();
    let mut mask = v.clone();
    mask.data.mapv_inplace(|x| if (130.0..=150.0).contains(&x) { 1.0 } else { 0.0 });
    let mpath = dir.path().join("mask.nii.gz");
    mdtf_volume::write_volume(&mpath, &mask, &Default::default(), &[]).unwrap();
    let f = dir.path().join("f");
    mdtf_ok(&[
        "pack",
        "--profile",
        "gaussian-tf",
        s.to_str().unwrap(),
        "-o",
        f.to_str().unwrap(),
        "--gtf-from-mask",
        mpath.to_str().unwrap(),
        "-q",
    ]);
    let gaussians: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(f.join("gaussians.json")).unwrap()).unwrap();
    let picked: Vec<f64> = v.samples().iter().filter(|x| (130.0..=150.0).contains(*x)).map(|&x| x as f64).collect();
    let mean = picked.iter().sum::<f64>() / picked.len() as f64;
    let var = picked.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (picked.len() - 1) as f64;
    assert!((gaussians[0]["centre"][0].as_f64().unwrap() - mean).abs() < 1e-3);
    // K^T K = 1 / (2 var)
    let k = gaussians[0]["k"][0][0].as_f64().unwrap();
    assert!((k * k * 2.0 * var - 1.0).abs() < 1e-6, "{k} {var}");
    let e = mdtf_err(&[
        "pack",
        "--profile",
        "slicer-3dtf",
        s.to_str().unwrap(),
        "-o",
        dir.path().join("x").to_str().unwrap(),
        "--gtf-from-mask",
        mpath.to_str().unwrap(),
    ]);
    assert!(e.contains("--gtf-from-mask applies to --profile gaussian-tf"), "{e}");
}

#[test]
fn a_failed_pipeline_run_changes_nothing() {
    // (tests/pipelines.rs runs every shipped pipeline and decodes its pack)
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("slicer-3dtf");
    let pipeline = shipped_pipeline("slicer-3dtf");
    mdtf_ok(&["run", pipeline.to_str().unwrap(), "-o", out.to_str().unwrap(), "--set", "input.size=40", "-q"]);
    // a failing run (unknown kernel) leaves the previous output untouched
    let before = std::fs::read(out.join("pack/manifest.json")).unwrap();
    let e = mdtf_err(&[
        "run",
        pipeline.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--set",
        "input.size=40",
        "--set",
        "derive.kernel=cubic",
    ]);
    assert!(e.contains("derive") && e.contains("unknown kernel"), "{e}");
    assert_eq!(std::fs::read(out.join("pack/manifest.json")).unwrap(), before);
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".mdtf-partial-"))
        .collect();
    assert!(left.is_empty(), "temporary run folders left behind");
    let e = mdtf_err(&["run", pipeline.to_str().unwrap(), "-o", out.to_str().unwrap(), "--set", "input.sise=4"]);
    assert!(e.contains("sise"), "{e}");
}

#[test]
fn a_pipeline_files_typos_are_reported_at_their_line_before_the_input_is_read() {
    let dir = tempfile::tempdir().unwrap();
    // the input does not exist: an error about it would mean it was read first
    let missing = dir.path().join("missing.nii.gz");
    let out = dir.path().join("out");
    let cases = [
        ("[derive]\nkernel = \"centrl4\"\n", 7, "unknown kernel 'centrl4'"),
        ("[pack]\nprofile = \"slicer3dtf\"\n", 6, "unknown profile 'slicer3dtf'"),
        ("[boundary]\ntolerence = 0.1\n", 7, "unknown field `tolerence`"),
    ];
    for (section, line, message) in cases {
        let text = if section.starts_with("[pack]") {
            format!("description = \"typo\"\n\n[input]\n\n{section}")
        } else {
            format!("description = \"typo\"\n\n[pack]\nprofile = \"slicer-3dtf\"\n\n{section}")
        };
        let file = dir.path().join("typo.toml");
        std::fs::write(&file, &text).unwrap();
        let e = mdtf_err(&[
            "run",
            file.to_str().unwrap(),
            "--input",
            missing.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(e.contains(&format!("line {line}")) && e.contains(message), "{text}\n{e}");
        assert!(!e.contains("missing.nii.gz"), "{e}");
        assert!(!out.exists());
    }
}

#[test]
fn a_bad_parameter_is_named_as_the_user_set_it_in_a_file_or_by_a_flag() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let pipeline = |section: &str| {
        let file = dir.path().join("bad.toml");
        let text = format!("[input]\nsize = 24\n\n[pack]\nprofile = \"distance-tf\"\n\n{section}");
        std::fs::write(&file, text).unwrap();
        mdtf_err(&["run", file.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"])
    };
    // a pipeline file's user sees the file's names, never a flag of another subcommand
    let e = pipeline("[boundary]\ntolerance = -1\n");
    assert!(e.contains("boundary: boundary.tolerance must be positive (voxels), got -1"), "{e}");
    assert!(!e.contains("--"), "{e}");
    let e = pipeline("[prefilter]\nsigma_d = 0.0\nsigma_r = 0.1\n");
    assert!(e.contains("prefilter: prefilter.sigma_d must be a positive number, got 0"), "{e}");
    assert!(!e.contains("--") && !e.contains("bilateral."), "{e}");
    assert!(!out.exists());

    // a stage subcommand's user sees the flag they typed
    let s = dir.path().join("s.nii");
    mdtf_ok(&["synth", "erf-sphere", "-o", s.to_str().unwrap(), "--size", "24", "-q"]);
    let o = dir.path().join("b");
    let e = mdtf_err(&["boundary", s.to_str().unwrap(), "-o", o.to_str().unwrap(), "--tolerance=-1"]);
    assert!(e.contains("--tolerance must be positive (voxels), got -1") && !e.contains("boundary."), "{e}");
    let e = mdtf_err(&["boundary", s.to_str().unwrap(), "-o", o.to_str().unwrap(), "--step", "30", "--d-max", "20"]);
    assert!(e.contains("--step 30 is larger than --d-max 20"), "{e}");
    let e = mdtf_err(&["bilateral", s.to_str().unwrap(), "-o", o.to_str().unwrap(), "--sigma-r", "0"]);
    assert!(e.contains("--sigma-r must be a positive number, got 0"), "{e}");
    assert!(!o.exists());
}

#[test]
fn kept_normals_are_derived_before_the_keep_stage() {
    // the slicer run derives normals late, just before their texture, unless a kept volume needs them
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let pipeline = shipped_pipeline("slicer-3dtf");
    mdtf_ok(&[
        "run",
        pipeline.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--set",
        "input.size=40",
        "--set",
        "keep=[\"nx\", \"ny\", \"nz\"]",
        "-q",
    ]);
    let comp = |c: &str| read(&out.join(format!("volumes/{c}.nii.gz")), &ReadOptions::default()).unwrap();
    let (nx, ny, nz) = (comp("nx"), comp("ny"), comp("nz"));
    let unit = nx.fields[0]
        .data
        .iter()
        .zip(ny.fields[0].data.iter())
        .zip(nz.fields[0].data.iter())
        .filter(|((x, y), z)| ((*x * *x + *y * *y + *z * *z) - 1.0).abs() < 1e-4)
        .count();
    assert!(unit > 40 * 40 * 40 / 4, "{unit} unit normals");
    assert!(out.join("pack/normal.raw").exists());
}

#[test]
fn validate_passes_on_a_correct_installation() {
    let dir = tempfile::tempdir().unwrap();
    let out = mdtf_ok(&["validate", "--size", "64", "-o", dir.path().to_str().unwrap()]);
    assert_eq!(out.lines().filter(|l| l.ends_with(" ok")).count(), 16, "{out}");
    for name in ["triangular GTF segment integral", "shells, least share kept per boundary"] {
        assert!(out.lines().any(|l| l.contains(name) && l.ends_with(" ok")), "{name}: {out}");
    }
    assert!(dir.path().join("boundary/boundary_report.png").exists());
    assert!(dir.path().join("histogram/normal_vs_stretched.png").exists());
    let e = mdtf_err(&["validate", "--size", "16"]);
    assert!(e.contains("at least 48"), "{e}");
    // a wrong parameter breaks its tolerance: central differences miss the g bound by 20x
    let out = mdtf(&["validate", "--size", "64", "-o", dir.path().to_str().unwrap(), "--set", "derive.kernel=central"]);
    assert!(!out.status.success(), "validate must fail with central differences");
    let table = String::from_utf8_lossy(&out.stdout);
    let g_line = table.lines().find(|l| l.starts_with("derive: mean |g error|")).unwrap_or_default();
    assert!(g_line.ends_with("OUT OF TOLERANCE"), "{table}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("out of tolerance"));
    let e = mdtf_err(&["validate", "--size", "64", "--set", "derive.kernal=central"]);
    assert!(e.contains("kernal"), "{e}");
}

#[test]
fn tetra_meshes_a_volume_and_packs_s_g_boxes_and_tables() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("s.nii.gz");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        vol.to_str().unwrap(),
        "--size",
        "24",
        "--radius",
        "7",
        "--sigma",
        "2",
        "-q",
    ]);
    let pack = dir.path().join("pack");
    mdtf_ok(&[
        "tetra",
        "--from-volume",
        vol.to_str().unwrap(),
        "--tets",
        "5",
        "-o",
        pack.to_str().unwrap(),
        "--tables",
        "gaussian,triangle",
        "-q",
    ]);
    assert!(pack.join("mesh.vtu").exists());
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(pack.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["profile"], "projected-tetrahedra");
    assert_eq!(m["mesh"]["tetrahedra"], 23 * 23 * 23 * 5);
    assert_eq!(m["mesh"]["points"], 24 * 24 * 24);
    assert_eq!(m["geometry"]["dims"], serde_json::json!([24, 24, 24]));
    let luts: Vec<&str> = m["luts"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(luts, ["pt_gaussian", "pt_triangle_rise", "pt_triangle_fall"]);
    // s is the volume's value at every point, g its gradient magnitude
    let volume = mdtf_volume::read(&vol, &mdtf_volume::ReadOptions::default()).unwrap();
    let s_g = mdtf_e2e::nrrd_f32(&pack.join("s_g.nrrd"));
    let values: Vec<f32> = volume.fields[0].data.iter().copied().collect();
    assert_eq!(s_g.len(), 2 * values.len());
    assert!(s_g.chunks_exact(2).zip(&values).all(|(sg, v)| sg[0] == *v));
    // every cell box holds its vertices' (s, g)
    let boxes = mdtf_e2e::nrrd_f32(&pack.join("cell_box.nrrd"));
    let tets = mdtf_e2e::nrrd_u32(&pack.join("tets.nrrd"));
    for (t, b) in tets.chunks_exact(4).zip(boxes.chunks_exact(4)).step_by(97) {
        for &v in t {
            let (s, g) = (s_g[2 * v as usize], s_g[2 * v as usize + 1]);
            assert!(b[0] <= s && s <= b[1] && b[2] <= g && g <= b[3]);
        }
    }
}

#[test]
fn tetra_refuses_bad_meshes_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let head =
        "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n";
    let scalars = "POINT_DATA 4\nSCALARS density float 1\nLOOKUP_TABLE default\n1 2 3 4\n";
    let cases = [
        ("tri.vtk", format!("{head}CELLS 1 4\n3 0 1 2\nCELL_TYPES 1\n5\n{scalars}"), vec!["no tetrahedra", "Triangle"]),
        (
            "idx.vtk",
            format!("{head}CELLS 1 5\n4 0 1 2 7\nCELL_TYPES 1\n10\n{scalars}"),
            vec!["uses point 7", "4 points"],
        ),
        ("flat.vtk", format!("{head}CELLS 1 5\n4 0 1 2 2\nCELL_TYPES 1\n10\n{scalars}"), vec!["zero volume"]),
        (
            "ok.vtk",
            format!("{head}CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n{scalars}"),
            vec!["pressure", "density (1 comp.)"],
        ),
    ];
    for (name, text, wanted) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let pack = dir.path().join(format!("pack-{name}"));
        let mut args = vec!["tetra", path.to_str().unwrap(), "-o", pack.to_str().unwrap()];
        if name == "ok.vtk" {
            args.extend(["--scalar", "pressure"]);
        }
        let e = mdtf_err(&args);
        for w in wanted {
            assert!(e.contains(w), "{name}: {e}");
        }
        assert!(!pack.exists(), "{name}: output written");
    }
    let left = std::fs::read_dir(dir.path())
        .unwrap()
        .filter(|e| e.as_ref().is_ok_and(|e| e.file_name().to_string_lossy().starts_with(".mdtf-partial-")));
    assert_eq!(left.count(), 0);
}

#[test]
fn preview_refuses_bad_views_steps_and_sizes_before_reading_the_pack() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("no-pack");
    let png = dir.path().join("p.png");
    for (extra, want) in [
        (["--step", "1e-6"], "--step must be 0.01 to 16 voxels"),
        (["--view", "nan,20"], "azimuth must be a finite number of degrees"),
        (["--view", "x,20"], "azimuth 'x' is not a number"),
        (["--view", "30"], "expected AZIMUTH,ELEVATION"),
        (["--size", "4"], "--size 4 must be 8 to 4096"),
    ] {
        let mut args = vec!["preview", pack.to_str().unwrap(), "-o", png.to_str().unwrap()];
        args.extend(extra);
        let e = mdtf_err(&args);
        assert!(e.contains(want), "{extra:?}: {e}");
    }
    assert!(!png.exists());
}

#[test]
fn tetra_marks_the_cells_a_tf_can_show_as_a_brute_force_box_test_does() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("s.nii.gz");
    let (size, radius, sigma) = ("20", "6", "1.5");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        vol.to_str().unwrap(),
        "--size",
        size,
        "--radius",
        radius,
        "--sigma",
        sigma,
        "-q",
    ]);
    let bare = dir.path().join("bare");
    let args = |out: &Path| {
        [
            "tetra",
            "--from-volume",
            vol.to_str().unwrap(),
            "--tets",
            "5",
            "-o",
            out.to_str().unwrap(),
            "--tables",
            "gaussian",
            "-q",
        ]
        .map(String::from)
        .to_vec()
    };
    let run = |a: Vec<String>| mdtf_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    run(args(&bare));
    // without a TF there is nothing to cull against, so no mask
    assert!(!bare.join("cell_visible.nrrd").exists());
    let s_g = mdtf_e2e::nrrd_f32(&bare.join("s_g.nrrd"));
    let tets = mdtf_e2e::nrrd_u32(&bare.join("tets.nrrd"));
    let (mut s_lo, mut s_hi, mut g_hi) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    for sg in s_g.chunks_exact(2) {
        s_lo = s_lo.min(sg[0] as f64);
        s_hi = s_hi.max(sg[0] as f64);
        g_hi = g_hi.max(sg[1] as f64);
    }
    let span = s_hi - s_lo;
    // a 2D Gaussian, a rectangle and a triangular GTF (width sigma' g), placed on the data's ranges
    let (gc, gs) = ([s_lo + 0.5 * span, 0.6 * g_hi], [0.04 * span, 0.08 * g_hi]);
    let (rc, rh) = ([s_lo + 0.1 * span, 0.05 * g_hi], [0.03 * span, 0.04 * g_hi]);
    let (tc, t_sigma) = (s_lo + 0.85 * span, 0.2);
    let k = |s: f64| 1.0 / (SQRT_2 * s);
    let tf = serde_json::json!({
        "v_range": [s_lo, s_hi], "g_range": [0.0, g_hi],
        "widgets": [
            {"type": "gaussian", "centre": gc, "k": [[k(gs[0]), 0.0], [0.0, k(gs[1])]], "alpha_max": 0.8, "colour": [1, 0, 0]},
            {"type": "rectangle", "centre": rc, "half_size": rh, "falloff": "constant", "alpha": 0.5, "colour": [0, 1, 0]},
            {"type": "gaussian", "centre": [tc], "k": [[k(t_sigma)]], "triangular": true, "alpha_max": 0.5, "colour": [0, 0, 1]},
            {"type": "rectangle", "centre": [s_lo, 0.0], "half_size": [span, g_hi], "falloff": "constant", "alpha": 0.0, "colour": [0, 0, 0]}
        ]
    });
    let tf_path = dir.path().join("tf.json");
    std::fs::write(&tf_path, tf.to_string()).unwrap();
    let pack = dir.path().join("pack");
    let mut a = args(&pack);
    a.extend(["--tf".into(), tf_path.to_str().unwrap().into()]);
    run(a);
    let mask = mdtf_e2e::nrrd_payload(&pack.join("cell_visible.nrrd"));
    assert_eq!(mask.len(), tets.len() / 4);
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(pack.join("manifest.json")).unwrap()).unwrap();
    let entry = m["mesh"]["arrays"].as_array().unwrap().iter().find(|e| e["name"] == "cell_visible").unwrap();
    assert_eq!((entry["dtype"].as_str(), entry["association"].as_str()), (Some("u8"), Some("cell")));

    let meets = |a: [f64; 2], b: [f64; 2]| a[0] <= b[1] && a[1] >= b[0];
    let density = |s: f64, g: f64| {
        let gauss = (-((s - gc[0]) / gs[0]).powi(2) / 2.0 - ((g - gc[1]) / gs[1]).powi(2) / 2.0).exp();
        let rect = ((s - rc[0]).abs() <= rh[0] && (g - rc[1]).abs() <= rh[1]) as u8 as f64;
        let tri = if g > 0.0 { (-((s - tc) / (t_sigma * g)).powi(2) / 2.0).exp() } else { 0.0 };
        gauss.max(rect).max(tri)
    };
    let (mut shown, mut checked) = (0, 0);
    for (cell, t) in tets.chunks_exact(4).enumerate() {
        let v: Vec<[f64; 2]> =
            t.iter().map(|&i| [s_g[2 * i as usize] as f64, s_g[2 * i as usize + 1] as f64]).collect();
        let lo_hi = |c: usize| {
            [
                v.iter().map(|p| p[c]).fold(f64::INFINITY, f64::min),
                v.iter().map(|p| p[c]).fold(f64::NEG_INFINITY, f64::max),
            ]
        };
        let (bs, bg) = (lo_hi(0), lo_hi(1));
        let gap = (bs[0] - tc).max(tc - bs[1]).max(0.0);
        let expected = (meets(bs, [gc[0] - 3.0 * gs[0], gc[0] + 3.0 * gs[0]])
            && meets(bg, [gc[1] - 3.0 * gs[1], gc[1] + 3.0 * gs[1]]))
            || (meets(bs, [rc[0] - rh[0], rc[0] + rh[0]]) && meets(bg, [rc[1] - rh[1], rc[1] + rh[1]]))
            || (bg[1] > 0.0 && gap <= 3.0 * t_sigma * bg[1]);
        assert_eq!(mask[cell] == 1, expected, "cell {cell}: s {bs:?}, g {bg:?}");
        shown += usize::from(expected);
        if !expected {
            // no point of a skipped cell (s and g are linear inside it) shows more than exp(-4.5) of a widget
            for w in [[1.0, 0.0, 0.0, 0.0], [0.25; 4], [0.5, 0.5, 0.0, 0.0], [0.0, 0.2, 0.3, 0.5], [0.1, 0.1, 0.1, 0.7]]
            {
                let at = |c: usize| (0..4).map(|j| w[j] * v[j][c]).sum::<f64>();
                assert!(density(at(0), at(1)) < (-4.5f64).exp(), "cell {cell} skipped but visible at {w:?}");
                checked += 1;
            }
        }
    }
    // the widgets pick some cells and leave others
    assert!(shown > 0 && checked > 0, "{shown} shown, {checked} samples of skipped cells");
}

#[test]
fn run_plan_prints_the_steps_and_the_halo_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let pipeline = shipped_pipeline("distance-tf");
    let text = mdtf_ok(&["run", pipeline.to_str().unwrap(), "--plan", "-o", out.to_str().unwrap()]);
    for line in [
        "2 derive           reads v -> g f2 nx ny nz [g, f2, normal]",
        // fast mode: the 19 neighbours within 1.5 voxels (1 + 6 + 12)
        "3 prefilter        reads g f2 [bilateral: 19 taps per voxel on each of g and f''",
        "4 boundary         reads g f2 nx ny nz -> g_hit hit distance; frees f2",
        "median of g (the noise floor: g_min, g_hit_min) -> boundary",
        // the shipped phantom: 1 mm voxels, gauss:1 (4) + the fast bilateral (2) + d_max 15 + 2 for g's
        // tricubic at the hit
        "halo of a block: x 23, y 23, z 23 voxels",
    ] {
        assert!(text.contains(line), "missing {line:?} in:\n{text}");
    }
    assert!(!out.exists(), "--plan wrote {}", out.display());
    let slicer = mdtf_ok(&["run", shipped_pipeline("slicer-3dtf").to_str().unwrap(), "--plan"]);
    assert!(slicer.contains("pack             reads v g f2 -> nx ny nz") && !slicer.contains("boundary"), "{slicer}");
}

#[test]
fn histogram_pack_and_boundary_plan_the_channels_they_compute_and_plan_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.nrrd");
    mdtf_ok(&["synth", "erf-sphere", "--size", "24", "--sigma", "2", "-o", input.to_str().unwrap()]);
    let out = dir.path().join("out");
    let (i, o) = (input.to_str().unwrap(), out.to_str().unwrap());
    // the joint (v, g) histogram derives g alone; the stretched one traces
    let joint = mdtf_ok(&["histogram", i, "-o", o, "--plan"]);
    assert!(joint.contains("2 derive           reads v -> g [g]") && !joint.contains("boundary"), "{joint}");
    let stretched = mdtf_ok(&["histogram", i, "-o", o, "--stretched", "--plan"]);
    for line in [
        "2 derive           reads v -> g f2 nx ny nz [g, f2, normal]",
        "3 boundary         reads g f2 nx ny nz -> g_hit hit; frees f2 nx ny nz",
        "channels the outputs read: v g g_hit hit",
    ] {
        assert!(stretched.contains(line), "missing {line:?} in:\n{stretched}");
    }
    // distance-tf's pack keeps the normal for its texture; slicer-3dtf's traces nothing
    let distance = mdtf_ok(&["pack", i, "--profile", "distance-tf", "--plan"]);
    assert!(distance.contains("3 boundary         reads g f2 nx ny nz -> g_hit distance; frees g f2"), "{distance}");
    // the cubic B-spline's weights at +-2 voxels are 0: it reads one voxel each side (central4: 2)
    let slicer = mdtf_ok(&["pack", i, "--plan", "--kernel", "bspline3"]);
    assert!(slicer.contains("[g, f2, normal]") && slicer.contains("halo of a block: x 1, y 1, z 1"), "{slicer}");
    // the chain: central4's 2 voxels + the pre-filter's box ceil(2.5 x 1) + d_max 6 + 2 for g's tricubic at the hit
    let chain = mdtf_ok(&["boundary", i, "-o", o, "--prefilter", "1,0.1", "--d-max", "6", "--plan"]);
    for line in ["3 prefilter        reads g f2", "halo of a block: x 13, y 13, z 13 voxels"] {
        assert!(chain.contains(line), "missing {line:?} in:\n{chain}");
    }
    // derive plans its items' channels: central differences read one voxel each side
    let derive = mdtf_ok(&["derive", i, "-o", o, "--items", "hessian,g", "--kernel", "central", "--plan"]);
    for line in [
        "2 derive           reads v -> g hxx hxy hxz hyy hyz hzz; frees v [g, hessian]",
        "halo of a block: x 1, y 1, z 1",
    ] {
        assert!(derive.contains(line), "missing {line:?} in:\n{derive}");
    }
    assert!(!out.exists(), "--plan wrote {}", out.display());
    // the plan refuses an unknown channel before any work
    let e = mdtf_err(&["histogram", i, "-o", o, "--axes", "v,gg", "--plan"]);
    assert!(e.contains("unknown channel 'gg'"), "{e}");
}

#[test]
fn run_under_a_memory_budget_matches_the_whole_run_and_explains_a_budget_it_cannot_use() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.nii");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "--size",
        "48",
        "--sigma",
        "2",
        "--type",
        "u16",
        "-o",
        input.to_str().unwrap(),
        "-q",
    ]);
    let pipeline = shipped_pipeline("distance-tf");
    let (p, i) = (pipeline.to_str().unwrap(), input.to_str().unwrap());
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    mdtf_ok(&["run", p, "--input", i, "-o", o, "--set", "preview=false", "-q"]);
    let whole: Vec<(String, Vec<u8>)> = [
        "pack/normal_v.raw",
        "pack/ghit_d.raw",
        "pack/alpha_u_u8.nrrd",
        "pack/manifest.json",
        "volumes/distance.nii.gz",
    ]
    .iter()
    .map(|f| (f.to_string(), std::fs::read(out.join(f)).unwrap_or_default()))
    .collect();
    assert!(whole.iter().all(|(_, b)| !b.is_empty()), "the whole run wrote its pack and kept volumes");
    std::fs::remove_dir_all(&out).unwrap();
    // 48 x 48 planes: the fixed 136 MiB (48 MiB, and 88 MiB for the histogram volume) and 455 planes,
    // a few slabs
    let text = mdtf_ok(&["run", p, "--input", i, "-o", o, "--set", "preview=false", "--memory-budget", "140MiB"]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    let count = report["slabs"]["count"].as_u64().unwrap();
    assert!(count >= 2, "several slabs: {report}");
    assert_eq!(report["slabs"]["budget"].as_u64(), Some(140 << 20));
    for (f, bytes) in &whole {
        assert_eq!(&std::fs::read(out.join(f)).unwrap(), bytes, "{f} differs from the whole run's\n{text}");
    }
    assert!(!out.join(".slabs").exists());
    // a size that does not parse is a usage error (exit 2), said before anything is read
    let bad = mdtf(&["run", p, "--input", i, "-o", o, "--memory-budget", "2 parsecs"]);
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(bad.status.code() == Some(2) && said.contains("unknown unit 'parsecs'"), "{said}");
    let small = mdtf_err(&["run", p, "--input", i, "-o", o, "--memory-budget", "1MiB"]);
    assert!(small.contains("too small") && small.contains("needs"), "{small}");
    let meshing = shipped_pipeline("projected-tetrahedra");
    let refused = mdtf_err(&["run", meshing.to_str().unwrap(), "--input", i, "-o", o, "--slab-planes", "4"]);
    assert!(refused.contains("does not run slab by slab: it meshes the whole volume"), "{refused}");
}

#[test]
fn print_settings_shows_every_default_and_is_itself_a_pipeline_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let missing = dir.path().join("missing.nii.gz");
    let pipeline = shipped_pipeline("distance-tf");
    let printed = mdtf_ok(&[
        "run",
        pipeline.to_str().unwrap(),
        "--input",
        missing.to_str().unwrap(),
        "--set",
        "boundary.tolerance=0.25",
        "-o",
        out.to_str().unwrap(),
        "--print-settings",
    ]);
    // nothing read, nothing written
    assert!(!out.exists());
    let table: toml::Table = toml::from_str(&printed).unwrap();
    assert_eq!(table["boundary"]["tolerance"].as_float(), Some(0.25));
    assert_eq!(table["derive"]["kernel"].as_str(), Some("gauss:1"));
    assert_eq!(table["input"]["file"].as_str(), missing.to_str());
    assert_eq!(table["pack"]["profile"].as_str(), Some("distance-tf"));
    assert!(table.get("tetra").is_none() && table["input"].get("phantom").is_none(), "{printed}");
    // the printed settings run as a pipeline file, and the run report records the same
    let again = dir.path().join("again.toml");
    let small = printed.replace(&format!("file = {:?}", missing.to_str().unwrap()), "size = 24");
    std::fs::write(&again, small).unwrap();
    mdtf_ok(&["run", again.to_str().unwrap(), "-o", out.to_str().unwrap(), "--set", "preview=false", "-q"]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    assert_eq!(report["settings"]["boundary"]["tolerance"].as_f64(), Some(0.25));
    assert_eq!(report["settings"]["input"]["size"].as_i64(), Some(24));
}

#[test]
fn derive_under_a_memory_budget_writes_the_whole_derives_files_and_says_how_it_cut() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.nii");
    let synth = ["synth", "erf-sphere", "--size", "40,36,30", "--sigma", "2", "--noise", "3", "--type", "u16"];
    mdtf_ok(&[&synth[..], &["-o", input.to_str().unwrap(), "-q"]].concat());
    let i = input.to_str().unwrap();
    let (whole, slabs) = (dir.path().join("whole"), dir.path().join("slabs"));
    let items = "g,f2,normal,hessian,value";
    for format in ["nii.gz", "nrrd"] {
        mdtf_ok(&["derive", i, "-o", whole.to_str().unwrap(), "--items", items, "--format", format, "-q"]);
        // 48 MiB of fixed costs and a few 40 x 36 planes: several slabs
        let budget = ["--memory-budget", "49MiB"];
        let args = [&["derive", i, "-o", slabs.to_str().unwrap(), "--items", items, "--format", format][..], &budget];
        let out = mdtf(&args.concat());
        let text = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && text.contains("slabs of") && text.contains("within 49.0 MiB"), "{text}");
        for item in ["g", "f2", "normal", "hessian", "value"] {
            let name = format!("{item}.{format}");
            let (a, b) = (std::fs::read(whole.join(&name)).unwrap(), std::fs::read(slabs.join(&name)).unwrap());
            assert!(a == b, "{name} differs between the whole and the slab-by-slab derive");
        }
    }
    // what cannot go by slabs is refused before anything is written
    let other = dir.path().join("other");
    let e = mdtf_err(&["derive", i, i, "-o", other.to_str().unwrap(), "--memory-budget", "1GiB"]);
    assert!(e.contains("--memory-budget derives one input file"), "{e}");
    let e = mdtf_err(&["derive", i, "-o", other.to_str().unwrap(), "--items", "shade", "--memory-budget", "1GiB"]);
    assert!(e.contains("largest g of the whole volume"), "{e}");
    let e = mdtf_err(&["derive", i, "-o", other.to_str().unwrap(), "--format", "nhdr", "--memory-budget", "1GiB"]);
    assert!(e.contains("slab by slab as .nii, .nii.gz, .nrrd"), "{e}");
    let e = mdtf_err(&["derive", i, "-o", other.to_str().unwrap(), "--memory-budget", "1MiB"]);
    assert!(e.contains("too small"), "{e}");
    assert!(!other.exists(), "a refused derive left {}", other.display());
}

#[test]
fn boundary_under_a_memory_budget_writes_the_whole_runs_files_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.nii");
    let synth = ["synth", "erf-sphere", "--size", "40,36,34", "--sigma", "2", "--noise", "3", "--type", "u16"];
    mdtf_ok(&[&synth[..], &["-o", input.to_str().unwrap(), "-q"]].concat());
    let i = input.to_str().unwrap();
    let (whole, slabs) = (dir.path().join("whole"), dir.path().join("slabs"));
    let common = ["--d-max", "5", "--flipped", "--alpha", "linear:a=1,dc=3", "--format", "nrrd"];
    let (w, s) = (whole.to_str().unwrap(), slabs.to_str().unwrap());
    mdtf_ok(&[&["boundary", i, "-o", w, "--report", w, "-q"][..], &common].concat());
    // 48 MiB of fixed costs and a few 40 x 36 planes with the tracing's halo: several slabs
    let out = mdtf(&[&["boundary", i, "-o", s, "--report", s, "--memory-budget", "49MiB"][..], &common].concat());
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && text.contains("slabs of") && text.contains("within 49.0 MiB"), "{text}");
    let names = ["distance", "g_hit", "hit", "dot", "flipped", "alpha_linear"].map(|n| format!("{n}.nrrd"));
    for name in names.iter().map(String::as_str).chain(["boundary_report.csv", "boundary_report.png"]) {
        let (a, b) = (std::fs::read(whole.join(name)).unwrap(), std::fs::read(slabs.join(name)).unwrap());
        assert!(a == b, "{name} differs between the whole and the slab-by-slab tracing");
    }
    // without --report no report is left in the output; given g, f'', normal do not go by slabs
    let other = dir.path().join("other");
    mdtf_ok(&["boundary", i, "-o", other.to_str().unwrap(), "--memory-budget", "52MiB", "-q"]);
    assert!(!other.join("boundary").exists() && other.join("distance.nii.gz").exists());
    let third = dir.path().join("third");
    let g = whole.join("g_hit.nrrd");
    let given = ["--g", g.to_str().unwrap(), "--f2", g.to_str().unwrap(), "--normal", g.to_str().unwrap()];
    let e = mdtf_err(&[&["boundary", "-o", third.to_str().unwrap(), "--memory-budget", "1GiB"][..], &given].concat());
    assert!(e.contains("--memory-budget traces from a value volume"), "{e}");
    let e = mdtf_err(&["boundary", i, "-o", third.to_str().unwrap(), "--format", "nhdr", "--memory-budget", "1GiB"]);
    assert!(e.contains("slab by slab as .nii, .nii.gz, .nrrd"), "{e}");
    assert!(!third.exists(), "a refused tracing left {}", third.display());
}

#[test]
fn slabs_of_no_planes_and_a_negative_budget_are_refused_as_sizes() {
    // clap's usage errors (exit 2), each naming the option and why, not clap's "use '-- -5'" tip
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("v.nii");
    mdtf_ok(&["synth", "erf-sphere", "-o", input.to_str().unwrap(), "--size", "8", "-q"]);
    let (i, out) = (input.to_str().unwrap(), dir.path().join("out"));
    let p = shipped_pipeline("slicer-3dtf");
    let o = out.to_str().unwrap();
    for (extra, said) in
        [(["--slab-planes", "0"], "0 is not in 1.."), (["--memory-budget", "-5"], "'-5' is not a size")]
    {
        let run = mdtf(&[&["run", p.to_str().unwrap(), "--input", i, "-o", o][..], &extra].concat());
        let text = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{text}");
        assert!(text.contains(extra[0]) && text.contains(said) && !text.contains("'-- "), "{text}");
    }
    let derive = mdtf(&["derive", i, "--items", "g", "-o", o, "--memory-budget", "-5"]);
    assert!(String::from_utf8_lossy(&derive.stderr).contains("'-5' is not a size"));
    assert!(!out.exists());
}
