//! A pack loses nothing that shows: rendering the decoded pack and rendering
//! the float fields it was made from differ by at most 2/255 per pixel on average.

use mdtf_datagen::erf_sphere;
use mdtf_pack::{PackParams, Profile, Provenance, pack, parse_tf};
use mdtf_preview::{Camera, classifier, load, render};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

#[test]
fn decoded_pack_renders_like_the_float_fields() {
    let n = 64;
    let t = erf_sphere(Geometry::new([n; 3], [1.0; 3]), 19.2, 2.0, 0.0, 255.0, None).truth();
    let mut chans =
        vec![("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone()), ("f2".to_string(), t.f2.clone())];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        chans
            .push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    let a = 255.0 / (2.0 * (2.0 * std::f64::consts::PI).sqrt());
    let tf = parse_tf(&format!(
        r#"{{"v_range": [0, 255], "g_range": [0, {gmax}], "f2_range": [-20, 20], "boundary_emphasis": 0.5,
            "widgets": [{{"type": "triangle", "v0": 128, "width": 60, "g_high": {a}, "alpha": 0.6, "colour": [1, 0.7, 0.4]}}]}}"#,
        gmax = 1.1 * a
    ))
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let prov = Provenance {
        mdtf_version: "t".into(),
        input: None,
        input_sha256: None,
        stages: serde_json::Value::Null,
        ..Default::default()
    };
    let params = PackParams::new(Profile::Slicer3dtf);
    pack(&chans, &params, &tf.slicer_luts(), dir.path(), prov, &BTreeMap::new()).unwrap();
    let loaded = load(dir.path()).unwrap();
    let c = classifier(&loaded, true).unwrap();
    let cam = Camera { azimuth: 30.0, elevation: 20.0, size: 96, step: 0.5, shaded: true };
    let from_pack = render(&loaded.channels, &c, &cam);
    let floats: BTreeMap<String, Volume> = chans.into_iter().collect();
    let from_floats = render(&floats, &c, &cam);
    let mean = from_pack.iter().zip(&from_floats).map(|(p, q)| (*p as f64 - *q as f64).abs()).sum::<f64>()
        / from_pack.len() as f64;
    let lit = from_floats.iter().filter(|&&x| x > 20).count();
    eprintln!("mean |pack - float| = {mean:.3} / 255 over {} values ({lit} lit)", from_pack.len());
    assert!(lit > 1000, "the sphere is visible");
    assert!(mean <= 2.0, "{mean}");
    // empty-space skipping changes no pixel
    assert_eq!(mdtf_preview::render_without_skipping(&loaded.channels, &c, &cam), from_pack);
    // decoding only the channels the renderer reads (as `preview` does, streamed) changes no pixel
    let read = mdtf_preview::channels_read(&c);
    let some = mdtf_preview::load_channels(dir.path(), &|n| read.iter().any(|r| r == n) && n != "v").unwrap();
    assert!(some.channels.contains_key("nx") && !some.channels.contains_key("v"));
    let some = mdtf_preview::load_channels(dir.path(), &|n| read.iter().any(|r| r == n)).unwrap();
    assert_eq!(some.channels.get("g"), loaded.channels.get("g"));
    assert_eq!(render(&some.channels, &c, &cam), from_pack);
    // the textures read in place (codes looked up, as `preview` renders) give the decoded pack's pixels
    let textures = mdtf_preview::PackTextures::read(dir.path(), &loaded.manifest, n * n * n, &|_| true).unwrap();
    let geometry = &loaded.channels["v"].geometry;
    assert_eq!(mdtf_preview::render_samples(&textures.samples(), geometry, &c, &cam), from_pack);
    let png = dir.path().join("preview.png");
    mdtf_preview::preview(dir.path(), &png, &cam, true).unwrap();
    let mut reader =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap())).read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut pixels).unwrap();
    assert_eq!(pixels, from_pack, "mdtf preview's picture is the decoded pack's");
}

#[test]
fn malformed_manifests_are_refused_not_a_panic() {
    let t = erf_sphere(Geometry::new([12; 3], [1.0; 3]), 4.0, 1.5, 0.0, 255.0, None).truth();
    let mut chans =
        vec![("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone()), ("f2".to_string(), t.f2.clone())];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        chans
            .push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    let tf = parse_tf(
        r#"{"v_range": [0, 255], "g_range": [0, 80], "f2_range": [-20, 20],
            "widgets": [{"type": "triangle", "v0": 128, "width": 60, "g_high": 60, "alpha": 0.6, "colour": [1, 0.7, 0.4]}]}"#,
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let prov = Provenance {
        mdtf_version: "t".into(),
        input: None,
        input_sha256: None,
        stages: serde_json::Value::Null,
        ..Default::default()
    };
    pack(&chans, &PackParams::new(Profile::Slicer3dtf), &tf.slicer_luts(), dir.path(), prov, &BTreeMap::new()).unwrap();
    let path = dir.path().join("manifest.json");
    let good: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let broken = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut manifest = good.clone();
        edit(&mut manifest);
        std::fs::write(&path, manifest.to_string()).unwrap();
        load(dir.path()).unwrap_err().to_string()
    };
    let e = broken(&|m| m["luts"][0]["axes"][0]["size"] = serde_json::json!(0));
    assert!(e.contains("each must be at least 1"), "{e}");
    let e = broken(&|m| m["channels"][0]["component"] = serde_json::json!(9));
    assert!(e.contains("component 9 of texture"), "{e}");
    let e = broken(&|m| m["geometry"]["dims"] = serde_json::json!([1usize << 22, 1usize << 22, 1usize << 22]));
    assert!(e.contains("more voxels than this machine can count"), "{e}");
    let e = broken(&|m| m["geometry"]["dims"] = serde_json::json!([12, 0, 12]));
    assert!(e.contains("hold no voxel"), "{e}");
    let e = broken(&|m| m["geometry"]["dims"] = serde_json::json!([13, 12, 12]));
    assert!(e.contains("bytes, the manifest describes"), "{e}");
}

#[test]
fn a_camera_out_of_range_is_refused_before_the_pack_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-pack");
    let png = dir.path().join("p.png");
    let good = Camera { azimuth: 30.0, elevation: 20.0, size: 64, step: 0.5, shaded: true };
    for (cam, want) in [
        (Camera { step: 1e-6, ..good }, "preview.step must be 0.01 to 16 voxels"),
        (Camera { elevation: f64::INFINITY, ..good }, "elevation must be a finite number"),
        (Camera { size: 4, ..good }, "preview.size 4 must be 8 to 4096"),
    ] {
        let e = mdtf_preview::preview(&missing, &png, &cam, true).unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
    assert!(good.check().is_ok());
}
