//! Textures written slab by slab ([`PackWriter::add_slabs`]), one at a time
//! or all from one pass, have the bytes
//! and manifest entries of the same texture written whole, for slabs of one
//! plane, of uneven heights and of the whole volume.

use mdtf_datagen::erf_sphere;
use mdtf_pack::{PackParams, PackWriter, Profile, texture_layouts};
use mdtf_volume::{Geometry, Volume};
use std::collections::BTreeMap;

fn channels() -> Vec<(String, Volume)> {
    let ph = erf_sphere(Geometry::new([20, 18, 23], [1.0, 0.8, 1.5]), 6.0, 1.5, 0.0, 255.0, None);
    let t = ph.truth();
    let mut out = vec![("v".to_string(), t.v.clone()), ("g".to_string(), t.g.clone()), ("f2".to_string(), t.f2)];
    for (i, name) in ["nx", "ny", "nz"].iter().enumerate() {
        out.push((name.to_string(), Volume { geometry: t.v.geometry.clone(), data: t.normal.fields[i].data.clone() }));
    }
    out
}

fn params(chans: &[(String, Volume)]) -> PackParams {
    // every channel's range given, as a slab-by-slab run's first pass gives them
    let ranges: BTreeMap<String, [f64; 2]> = chans
        .iter()
        .filter(|(c, _)| !c.starts_with('n'))
        .map(|(c, v)| {
            let (lo, hi) = v.finite_range().unwrap();
            (c.clone(), [lo as f64, hi as f64 * 0.9])
        })
        .collect();
    PackParams { profile: Profile::Slicer3dtf, ranges, fields: vec![], dtype: None, nifti: false }
}

/// The files of a pack and its manifest's channel entries.
fn written(dir: &std::path::Path) -> (Vec<(String, Vec<u8>)>, serde_json::Value) {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "raw" || x == "nhdr"))
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect();
    files.sort();
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    (files, manifest["channels"].clone())
}

#[test]
fn a_texture_written_slab_by_slab_equals_the_whole_one() {
    let chans = channels();
    let params = params(&chans);
    let geo = chans[0].1.geometry.clone();
    let sources = BTreeMap::new();
    let provenance = || mdtf_pack::Provenance {
        mdtf_version: "test".into(),
        input: None,
        input_sha256: None,
        stages: serde_json::Value::Null,
        ..Default::default()
    };
    let whole_dir = tempfile::tempdir().unwrap();
    let mut w = PackWriter::new(whole_dir.path(), &params, geo.clone(), &sources);
    for layout in texture_layouts(&params) {
        w.add(&layout, &|c| chans.iter().find(|(n, _)| n == c).map(|(_, v)| v)).unwrap();
    }
    w.finish(&[], provenance()).unwrap();
    let whole = written(whole_dir.path());
    assert!(whole.0.len() >= 4, "two textures with headers: {:?}", whole.0.iter().map(|f| &f.0).collect::<Vec<_>>());

    for heights in [vec![1usize; 23], vec![7, 7, 7, 2], vec![5, 1, 17], vec![23]] {
        let mut slabs = Vec::new();
        let mut z = 0;
        for h in &heights {
            slabs.push(z..z + h);
            z += h;
        }
        // each texture on its own, then all of them from one pass over the slabs
        let layouts = texture_layouts(&params);
        for together in [false, true] {
            let groups: Vec<&[mdtf_pack::TextureLayout]> = match together {
                false => layouts.chunks(1).collect(),
                true => vec![&layouts[..]],
            };
            let dir = tempfile::tempdir().unwrap();
            let mut w = PackWriter::new(dir.path(), &params, geo.clone(), &sources);
            for group in groups {
                let mut seen = Vec::new();
                w.add_slabs(group, &slabs, &mut |z, _| {
                    seen.push(z.clone());
                    Ok(chans.iter().map(|(c, v)| (c.clone(), v.z_slab(z.clone()))).collect())
                })
                .unwrap();
                assert_eq!(seen, slabs, "each slab asked for once, in order");
            }
            w.finish(&[], provenance()).unwrap();
            assert_eq!(written(dir.path()), whole, "slab heights {heights:?}, together {together}");
        }
    }
}

#[test]
fn slab_writing_refuses_gaps_missing_ranges_and_wrong_slabs() {
    let chans = channels();
    let mut params = params(&chans);
    let geo = chans[0].1.geometry.clone();
    let sources = BTreeMap::new();
    let layout =
        texture_layouts(&params).into_iter().find(|l| l.components.iter().flatten().any(|c| c == "v")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let all = |z: std::ops::Range<usize>| Ok(chans.iter().map(|(c, v)| (c.clone(), v.z_slab(z.clone()))).collect());
    let mut w = PackWriter::new(dir.path(), &params, geo.clone(), &sources);
    let gap = w.add_slabs(std::slice::from_ref(&layout), &[0..5, 6..23], &mut |z, _| all(z)).unwrap_err().to_string();
    assert!(gap.contains("do not cover"), "{gap}");
    // a slab of the wrong height
    let layouts = texture_layouts(&params);
    let wrong = w.add_slabs(&layouts, &[0..5, 5..23], &mut |z, _| all(0..z.len() + 1)).unwrap_err().to_string();
    assert!(wrong.contains("voxels, not"), "{wrong}");
    // a failure on the second slab: no texture and no partial file is left
    let mut slab = 0;
    let failing = w.add_slabs(&layouts, &[0..5, 5..23], &mut |z, _| {
        slab += 1;
        if slab == 2 { Err(mdtf_pack::PackError::Geometry("made to fail".into())) } else { all(z) }
    });
    assert!(failing.unwrap_err().to_string().contains("made to fail"));
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "no texture and no partial file is left: {left:?}");
    params.ranges.remove("v");
    let mut w = PackWriter::new(dir.path(), &params, geo, &sources);
    let whole = vec![std::ops::Range { start: 0, end: 23 }];
    let unranged = w.add_slabs(std::slice::from_ref(&layout), &whole, &mut |z, _| all(z)).unwrap_err().to_string();
    assert!(unranged.contains("channel v") && unranged.contains("no code range"), "{unranged}");
}
