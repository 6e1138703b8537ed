//! Reading by planes gives the planes of the whole-volume read, for every
//! format and encoding it takes, with overlapping (halo) requests; it refuses
//! going backwards and reports a truncated file.

use mdtf_volume::{Geometry, PlaneReader, ReadOptions, SampleType, Volume, WriteOptions, read_scalar, write_volume};

fn volume() -> Volume {
    let geo = Geometry::new([7, 5, 11], [1.0, 0.5, 2.0]).with_origin([3.0, -2.0, 10.0]);
    let mut v = Volume::zeros(geo);
    for (i, x) in v.data.iter_mut().enumerate() {
        *x = ((i * 37) % 1000) as f32;
    }
    v
}

#[test]
fn planes_equal_the_whole_reads_planes_in_every_streamable_format() {
    let dir = tempfile::tempdir().unwrap();
    let v = volume();
    for (name, ty, gzip) in [
        ("a.nii", SampleType::U16, false),
        ("b.nii.gz", SampleType::F32, false),
        ("c.nrrd", SampleType::U16, false),
        ("d.nrrd", SampleType::F32, true),
        ("e.nhdr", SampleType::U16, false),
        ("f.nhdr", SampleType::U16, true),
        ("g.ome.zarr", SampleType::U16, false),
    ] {
        let path = dir.path().join(name);
        write_volume(&path, &v, &WriteOptions { ty, gzip }, &[]).unwrap();
        let whole = read_scalar(&path, &ReadOptions::default()).unwrap();
        assert_eq!(whole.data, v.data, "{name}: the writer and the whole read agree");
        let mut r = PlaneReader::open(&path, &ReadOptions::default()).unwrap().expect(name);
        assert!(r.geometry().same_grid(&v.geometry), "{name}");
        // overlapping slabs with halos, as a slab-by-slab run asks for them, and a skip
        for z in [0..3, 1..6, 4..9, 4..9, 10..14] {
            let got = r.read(z.clone()).unwrap();
            let want = whole.z_slab(z.clone());
            assert_eq!(got.data, want.data, "{name} planes {z:?}");
            assert_eq!(got.geometry, want.geometry, "{name} planes {z:?}");
        }
        if name.ends_with(".zarr") {
            // read by chunks: any planes, in any order
            assert_eq!(r.read(2..4).unwrap().data, whole.z_slab(2..4).data);
        } else {
            let back = r.read(2..4).unwrap_err().to_string();
            assert!(back.contains("front to back"), "{back}");
        }
    }
}

#[test]
fn files_read_only_whole_are_declined_and_truncation_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let v = volume();
    let mha = dir.path().join("v.mha");
    write_volume(&mha, &v, &WriteOptions::default(), &[]).unwrap();
    assert!(PlaneReader::open(&mha, &ReadOptions::default()).unwrap().is_none(), "MetaImage is read whole");
    // a raw NRRD cut short: the planes before the cut read, the one across it fails with the counts
    let path = dir.path().join("t.nrrd");
    write_volume(&path, &v, &WriteOptions { ty: SampleType::U16, gzip: false }, &[]).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 7 * 5 * 2 * 3]).unwrap();
    let mut r = PlaneReader::open(&path, &ReadOptions::default()).unwrap().unwrap();
    assert_eq!(r.read(0..8).unwrap().data, v.z_slab(0..8).data);
    let e = r.read(6..11).unwrap_err().to_string();
    assert!(e.contains("truncated") || e.contains("short") || e.contains("expected"), "{e}");
}

#[test]
fn a_nifti_written_slab_by_slab_has_the_whole_writes_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let v = volume();
    for name in ["w.nii", "w.nii.gz"] {
        let whole = dir.path().join(format!("whole-{name}"));
        mdtf_volume::write_nifti(&whole, &mdtf_volume::MultiField::from(v.clone()), SampleType::F32).unwrap();
        let slabs = [0..1, 1..8, 8..11];
        let path = dir.path().join(name);
        mdtf_volume::write_slabs(&path, &v.geometry, SampleType::F32, &slabs, &mut |z, out| {
            *out = v.z_slab(z).data.iter().copied().collect();
            Ok(())
        })
        .unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&whole).unwrap(), "{name}");
    }
    // a text format cannot be written by slabs: refused by name before any slab
    let whole_slab = [std::ops::Range { start: 0, end: 11 }];
    let e =
        mdtf_volume::write_slabs(&dir.path().join("t.mha"), &v.geometry, SampleType::F32, &whole_slab, &mut |_, _| {
            panic!("no slab is asked for")
        });
    assert!(e.unwrap_err().to_string().contains(".nii, .nii.gz, .nrrd"));
    // a slab gap, and a value u8 cannot hold, are refused, leaving no file
    let path = dir.path().join("bad.nii");
    let gap = [0..3, 4..11];
    let e = mdtf_volume::write_slabs(&path, &v.geometry, SampleType::F32, &gap, &mut |z, out| {
        *out = v.z_slab(z).data.iter().copied().collect();
        Ok(())
    });
    assert!(e.unwrap_err().to_string().contains("do not cover"));
    let all = [std::ops::Range { start: 0, end: 11 }];
    let e = mdtf_volume::write_slabs(&path, &v.geometry, SampleType::U8, &all, &mut |z, out| {
        *out = v.z_slab(z).data.iter().copied().collect();
        Ok(())
    });
    assert!(e.is_err() && !path.exists());
}

#[test]
fn a_store_written_by_slabs_of_any_height_equals_the_one_written_whole() {
    use mdtf_volume::ome_zarr::ZarrWriter;
    let dir = tempfile::tempdir().unwrap();
    // 70 planes: shards of 64 planes, so slabs straddle a shard's edge
    let geo = Geometry::new([9, 6, 70], [0.5, 0.5, 1.0]);
    let mut v = Volume::zeros(geo.clone());
    for (i, x) in v.data.iter_mut().enumerate() {
        *x = ((i * 7919) % 65536) as f32;
    }
    let whole = dir.path().join("whole.ome.zarr");
    write_volume(&whole, &v, &WriteOptions { ty: SampleType::U16, gzip: false }, &[]).unwrap();
    for height in [1, 7, 33, 64] {
        let path = dir.path().join(format!("slabs{height}.ome.zarr"));
        let mut w = ZarrWriter::create(&path, &geo, &["value".into()], SampleType::U16).unwrap();
        for z0 in (0..70).step_by(height) {
            let slab = v.z_slab(z0..(z0 + height).min(70));
            w.write_planes(z0, &[slab.samples()]).unwrap();
        }
        let got = read_scalar(&path, &ReadOptions::default()).unwrap();
        assert_eq!(got.data, v.data, "slabs of {height}");
        assert!(got.geometry.same_grid(&geo));
    }
    assert_eq!(read_scalar(&whole, &ReadOptions::default()).unwrap().data, v.data);
    // a value u16 cannot hold is refused with its index, as by every writer
    let mut w = ZarrWriter::create(&dir.path().join("bad.ome.zarr"), &geo, &["value".into()], SampleType::U16).unwrap();
    let mut plane = vec![0.0f32; 54];
    plane[5] = 2.5;
    let e = w.write_planes(3, &[&plane]).unwrap_err().to_string();
    assert!(e.contains("2.5 at index 167") && e.contains("u16"), "{e}");
    let e = w.write_planes(70, &[&plane]).unwrap_err().to_string();
    assert!(e.contains("do not fit"), "{e}");
}

/// Every file under `dir` (a file: itself), by its path below `dir`, with its bytes.
fn tree_bytes(dir: &std::path::Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(p) = todo.pop() {
        if p.is_dir() {
            todo.extend(std::fs::read_dir(&p).unwrap().map(|e| e.unwrap().path()));
        } else {
            let rel = p.strip_prefix(dir).unwrap().to_path_buf();
            // the marker lists the folder's files in the order they were written
            if !rel.to_string_lossy().contains(mdtf_volume::output::MARKER_NAME) {
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn several_fields_written_slab_by_slab_have_the_whole_writes_bytes_in_every_format() {
    use mdtf_volume::{MultiField, SlabWriter, write};
    let dir = tempfile::tempdir().unwrap();
    let geo = Geometry::new([7, 5, 70], [1.0, 0.5, 2.0]).with_origin([3.0, -2.0, 10.0]);
    let names: Vec<String> = ["gx", "gy", "gz"].map(String::from).to_vec();
    let fields: Vec<(String, Volume)> = names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let mut v = Volume::zeros(geo.clone());
            for (i, x) in v.data.iter_mut().enumerate() {
                *x = ((i * 37 + k * 101) % 1000) as f32 - 300.0;
            }
            (n.clone(), v)
        })
        .collect();
    let mf = MultiField::from_volumes(fields.clone()).unwrap();
    let one = MultiField::from_volumes(vec![("g".into(), fields[0].1.clone())]).unwrap();
    for ext in [".nii", ".nii.gz", ".nrrd", ".ome.zarr"] {
        for (what, mf) in [("three", &mf), ("one", &one)] {
            let whole = dir.path().join(format!("whole-{what}{ext}"));
            write(&whole, mf, &WriteOptions::default(), &[]).unwrap();
            let names: Vec<String> = mf.fields.iter().map(|f| f.name.clone()).collect();
            for height in [1, 7, 33, 70] {
                let path = dir.path().join(format!("slabs{height}-{what}{ext}"));
                let mut w = SlabWriter::create(&path, &geo, &names, SampleType::F32).unwrap();
                for z0 in (0..70).step_by(height) {
                    let z = z0..(z0 + height).min(70);
                    let slabs: Vec<Volume> =
                        (0..names.len()).map(|i| mf.field_volume(i).unwrap().z_slab(z.clone())).collect();
                    let samples: Vec<&[f32]> = slabs.iter().map(Volume::samples).collect();
                    w.put(z0, &samples).unwrap();
                }
                w.finish().unwrap();
                assert_eq!(tree_bytes(&path), tree_bytes(&whole), "{what}{ext}, slabs of {height}");
                // no field's partial file is left beside it
                let left: Vec<_> = std::fs::read_dir(dir.path())
                    .unwrap()
                    .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                    .filter(|n| n.contains(".field"))
                    .collect();
                assert!(left.is_empty(), "{left:?}");
            }
        }
    }
    // out of order, short of planes, or dropped unfinished: an error and no file, no partial files
    let path = dir.path().join("bad.nii.gz");
    let mut w = SlabWriter::create(&path, &geo, &names, SampleType::F32).unwrap();
    let z = fields.iter().map(|(_, v)| v.z_slab(0..2)).collect::<Vec<_>>();
    let s: Vec<&[f32]> = z.iter().map(Volume::samples).collect();
    let e = w.put(3, &s).unwrap_err().to_string();
    assert!(e.contains("does not follow plane 0"), "{e}");
    w.put(0, &s).unwrap();
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains("only planes 0..2 of 70"), "{e}");
    let mut w = SlabWriter::create(&path, &geo, &names, SampleType::F32).unwrap();
    w.put(0, &s).unwrap();
    drop(w);
    let names_left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(!path.exists() && !names_left.iter().any(|n| n.contains("bad.nii")), "{names_left:?}");
}
