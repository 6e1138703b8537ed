//! A decoder that reads only manifest.json and the texture files (through
//! serde_json::Value and raw bytes, no code shared with the encoder)
//! reproduces every channel within half a code step; 0 stays exact.

use mdtf_datagen::erf_sphere;
use mdtf_pack::{Dtype, PackParams, Profile, Provenance, pack};
use mdtf_volume::{Geometry, Volume};
use ndarray::Array3;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

fn channels() -> Vec<(String, Volume)> {
    // 37 slices: the streamed textures go in two full slabs of 16 slices and a short one
    let ph = erf_sphere(Geometry::new([24, 20, 37], [1.0, 0.8, 1.5]), 6.0, 1.5, 0.0, 255.0, None);
    let t = ph.truth();
    let mut out = vec![
        ("v".to_string(), t.v.clone()),
        ("g".to_string(), t.g.clone()),
        ("f2".to_string(), t.f2.clone()),
        ("g_hit".to_string(), t.g.clone()),
        ("distance".to_string(), Volume { geometry: t.x.geometry.clone(), data: t.x.data.mapv(f32::abs) }),
    ];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        out.push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    // stand-ins for the multi-field channels: any data decodes the same way
    out.push(("gnorm".to_string(), Volume { geometry: t.g.geometry.clone(), data: t.g.data.mapv(|g| g * g) }));
    out.push((
        "inv_g".to_string(),
        Volume { geometry: t.g.geometry.clone(), data: t.g.data.mapv(|g| 1.0 / g.max(0.5)) },
    ));
    for (name, scale) in [("a", 1.0f32), ("b", -3.0), ("c", 0.25), ("d", 7.0), ("e", 2.0)] {
        out.push((
            name.to_string(),
            Volume { geometry: t.v.geometry.clone(), data: t.v.data.mapv(|v| v * scale + 1.0) },
        ));
    }
    out
}

/// Decodes channel `name` from the pack in `dir` using the manifest alone.
fn decode(dir: &Path, name: &str) -> Vec<Vec<f64>> {
    let m: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    let dims: Vec<usize> =
        m["geometry"]["dims"].as_array().unwrap().iter().map(|d| d.as_u64().unwrap() as usize).collect();
    let n = dims.iter().product::<usize>();
    let mut all = Vec::new();
    for ch in m["channels"].as_array().unwrap().iter().filter(|c| c["name"] == name) {
        let tex = m["textures"].as_array().unwrap().iter().find(|t| t["name"] == ch["texture"]).unwrap();
        let comps = tex["components"].as_u64().unwrap() as usize;
        let size = match tex["dtype"].as_str().unwrap() {
            "u8" => 1,
            "u16" | "f16" => 2,
            _ => 4,
        };
        let bytes = std::fs::read(dir.join(tex["data"].as_str().unwrap())).unwrap();
        assert_eq!(bytes.len(), n * comps * size);
        let (off, scale) = (ch["decode"]["offset"].as_f64().unwrap(), ch["decode"]["scale"].as_f64().unwrap());
        let c = ch["component"].as_u64().unwrap() as usize;
        all.push(
            (0..n)
                .map(|i| {
                    let at = (i * comps + c) * size;
                    let code = match size {
                        1 => bytes[at] as f64,
                        2 => u16::from_le_bytes([bytes[at], bytes[at + 1]]) as f64,
                        _ => f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]) as f64,
                    };
                    off + scale * code
                })
                .collect(),
        );
    }
    all
}

#[test]
fn every_channel_decodes_within_half_a_step_from_the_manifest_alone() {
    let chans = channels();
    let five: Vec<String> = ["a", "b", "c", "d", "e"].iter().map(|s| s.to_string()).collect();
    for (profile, fields) in [
        (Profile::Slicer3dtf, vec![]),
        (Profile::DistanceTf, vec![]),
        (Profile::GaussianTf, five.clone()),
        (Profile::PeakFinding, vec![]),
        (Profile::PeakFinding, five),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let prov = Provenance {
            mdtf_version: "test".into(),
            input: None,
            input_sha256: None,
            stages: Value::Null,
            ..Default::default()
        };
        let params = PackParams { fields: fields.clone(), ..PackParams::new(profile) };
        let m = pack(&chans, &params, &[], dir.path(), prov, &BTreeMap::new()).unwrap();
        if profile == Profile::GaussianTf {
            // five fields and ||G||: two RGBA16 textures
            assert_eq!(m.textures.len(), 2);
            assert_eq!(m.textures[1].component_order, vec![Some("e".to_string()), Some("gnorm".to_string())]);
        }
        for name in profile.channels(&fields) {
            let name = name.as_str();
            let truth = &chans.iter().find(|(c, _)| c == name).unwrap().1;
            let entry = m.channels.iter().find(|c| c.name == name).unwrap();
            for decoded in decode(dir.path(), name) {
                assert_eq!(decoded.len(), truth.samples().len());
                for (d, &t) in decoded.iter().zip(truth.samples()) {
                    assert!(
                        (d - t as f64).abs() <= 0.5 * entry.decode.scale * (1.0 + 1e-6) + 1e-9,
                        "{profile} {name}: {t} -> {d}"
                    );
                    if t == 0.0 && matches!(name, "f2" | "nx" | "ny" | "nz") {
                        assert_eq!(*d, 0.0, "{profile} {name}: 0 must stay exact");
                    }
                }
            }
        }
        // the NRRD header points at the raw file and says what the components are
        let hdr = std::fs::read_to_string(dir.path().join(&m.textures[0].header)).unwrap();
        let ty = if matches!(profile, Profile::Slicer3dtf | Profile::DistanceTf) { "uint8" } else { "uint16" };
        assert!(
            hdr.contains(&format!("type: {ty}")) && hdr.contains(&format!("data file: {}", m.textures[0].data)),
            "{hdr}"
        );
    }
}

#[test]
fn every_dtype_decodes_within_half_a_step() {
    let chans = channels();
    for dtype in [Dtype::U8, Dtype::U16, Dtype::F16, Dtype::F32] {
        let dir = tempfile::tempdir().unwrap();
        let prov = Provenance {
            mdtf_version: "test".into(),
            input: None,
            input_sha256: None,
            stages: Value::Null,
            ..Default::default()
        };
        let params = PackParams { dtype: Some(dtype), ..PackParams::new(Profile::Slicer3dtf) };
        let m = pack(&chans, &params, &[], dir.path(), prov, &BTreeMap::new()).unwrap();
        for name in ["v", "f2", "nx"] {
            let truth = &chans.iter().find(|(c, _)| c == name).unwrap().1;
            let entry = m.channels.iter().find(|c| c.name == name).unwrap();
            let decoded = &decode_any(dir.path(), name, dtype)[0];
            for (d, &t) in decoded.iter().zip(truth.samples()) {
                let tol = match dtype {
                    Dtype::U8 | Dtype::U16 => 0.5 * entry.decode.scale * (1.0 + 1e-6) + 1e-9,
                    Dtype::F16 => (t as f64).abs() * 2f64.powi(-11) + 1e-7, // half a unit in the last place
                    Dtype::F32 => 0.0,
                };
                assert!((d - t as f64).abs() <= tol, "{dtype:?} {name}: {t} -> {d}");
            }
        }
    }
}

/// Like `decode`, reading f16 bit patterns where the manifest says f16.
fn decode_any(dir: &Path, name: &str, dtype: Dtype) -> Vec<Vec<f64>> {
    if dtype != Dtype::F16 {
        return decode(dir, name);
    }
    let m: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    let ch = m["channels"].as_array().unwrap().iter().find(|c| c["name"] == name).unwrap();
    let tex = m["textures"].as_array().unwrap().iter().find(|t| t["name"] == ch["texture"]).unwrap();
    assert_eq!(tex["dtype"], "f16");
    let comps = tex["components"].as_u64().unwrap() as usize;
    let c = ch["component"].as_u64().unwrap() as usize;
    let bytes = std::fs::read(dir.join(tex["data"].as_str().unwrap())).unwrap();
    let n = bytes.len() / (2 * comps);
    vec![
        (0..n)
            .map(|i| {
                half::f16::from_bits(u16::from_le_bytes([bytes[(i * comps + c) * 2], bytes[(i * comps + c) * 2 + 1]]))
                    .to_f64()
            })
            .collect(),
    ]
}

#[test]
fn missing_channels_are_named_with_their_stage() {
    let chans: Vec<(String, Volume)> = channels().into_iter().filter(|(c, _)| c != "g_hit" && c != "f2").collect();
    let dir = tempfile::tempdir().unwrap();
    let prov = Provenance {
        mdtf_version: "t".into(),
        input: None,
        input_sha256: None,
        stages: Value::Null,
        ..Default::default()
    };
    let e = pack(&chans, &PackParams::new(Profile::DistanceTf), &[], dir.path(), prov.clone(), &BTreeMap::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("g_hit (made by the boundary stage)"), "{e}");
    let mut flat = channels();
    flat[0].1 = Volume::new(flat[0].1.geometry.clone(), Array3::from_elem(flat[0].1.data.dim(), 3.0)).unwrap();
    let e = pack(&flat, &PackParams::new(Profile::Slicer3dtf), &[], dir.path(), prov, &BTreeMap::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("would lose all precision"), "{e}");
}

#[test]
fn texture_by_texture_writing_equals_encoding_in_memory() {
    // `pack` writes one texture at a time through PackWriter; `encode` holds
    // them all. Same bytes, same manifest entries, for every profile.
    let chans = channels();
    for profile in [Profile::Slicer3dtf, Profile::DistanceTf] {
        let params = PackParams::new(profile);
        let dir = tempfile::tempdir().unwrap();
        let prov = Provenance {
            mdtf_version: "test".into(),
            input: None,
            input_sha256: None,
            stages: Value::Null,
            ..Default::default()
        };
        let manifest = pack(&chans, &params, &[], dir.path(), prov, &BTreeMap::new()).unwrap();
        let encoded = mdtf_pack::encode(&chans, &params, &BTreeMap::new()).unwrap();
        assert_eq!(manifest.textures.len(), encoded.textures.len(), "{profile}");
        for ((layout, bytes), entry) in encoded.textures.iter().zip(&manifest.textures) {
            assert_eq!(layout.name, entry.name);
            assert_eq!(&std::fs::read(dir.path().join(&entry.data)).unwrap(), bytes, "{profile} {}", entry.name);
        }
        assert_eq!(
            serde_json::to_value(&manifest.channels).unwrap(),
            serde_json::to_value(&encoded.channels).unwrap(),
            "{profile}"
        );
        // and streamed to a sink, slab by slab: the same bytes in the same order
        let mut streamed: Vec<(String, Vec<u8>)> = Vec::new();
        let entries = mdtf_pack::encode_streamed(&chans, &params, &BTreeMap::new(), &mut |layout, bytes| {
            match streamed.last_mut() {
                Some((name, b)) if *name == layout.name => b.extend_from_slice(bytes),
                _ => streamed.push((layout.name.clone(), bytes.to_vec())),
            }
            Ok(())
        })
        .unwrap();
        assert_eq!(serde_json::to_value(&entries).unwrap(), serde_json::to_value(&encoded.channels).unwrap());
        let whole: Vec<(String, Vec<u8>)> = encoded.textures.iter().map(|(l, b)| (l.name.clone(), b.clone())).collect();
        assert_eq!(streamed, whole, "{profile}");
    }
}
