//! Round trips through every writer and reader: values exact, geometry kept.

use mdtf_volume::nrrd::read_nrrd;
use mdtf_volume::{
    Field, Geometry, MultiField, ReadOptions, SampleType, Volume, WriteOptions, read, read_scalar, write,
};
use ndarray::Array3;
use std::path::Path;

fn geometry() -> Geometry {
    Geometry {
        dims: [5, 4, 3],
        spacing: [0.5, 0.75, 2.0],
        origin: [-12.5, 3.25, 100.0],
        directions: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// Distinct integer-valued samples within the range of `ty`.
fn samples(ty: SampleType, g: &Geometry) -> Array3<f32> {
    let (lo, hi) = ty.range();
    let (lo, hi) = (lo.max(-30000.0), hi.min(60000.0));
    Array3::from_shape_fn(g.shape(), |(k, j, i)| {
        let n = (i + 5 * j + 20 * k) as f64;
        (lo + (n * 7919.0) % (hi - lo + 1.0)) as f32
    })
}

fn assert_same(a: &MultiField, b: &MultiField) {
    assert!(a.geometry.same_grid(&b.geometry), "{:?} vs {:?}", a.geometry, b.geometry);
    assert_eq!(a.fields.len(), b.fields.len());
    for (fa, fb) in a.fields.iter().zip(&b.fields) {
        assert_eq!(fa.data, fb.data, "field {}", fa.name);
    }
}

#[test]
fn every_writer_round_trips_its_types_value_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let g = geometry();
    for ty in [SampleType::F32, SampleType::U8, SampleType::U16] {
        let mut data = samples(ty, &g);
        if ty == SampleType::F32 {
            data.mapv_inplace(|v| v * 0.001 + 1e-7);
        }
        let mf = MultiField::from(Volume::new(g.clone(), data).unwrap());
        for ext in ["nii", "nii.gz", "nrrd", "nhdr"] {
            for gzip in [false, true] {
                let path = dir.path().join(format!("v_{ty}_{gzip}.{ext}"));
                write(&path, &mf, &WriteOptions { ty, gzip }, &[]).unwrap();
                let back = read(&path, &ReadOptions::default()).unwrap();
                assert_same(&mf, &back);
            }
        }
    }
}

#[test]
fn multi_field_volumes_round_trip_with_their_names() {
    let dir = tempfile::tempdir().unwrap();
    let g = geometry();
    let fields = (0..3)
        .map(|f| Field { name: ["v", "g", "f2"][f].into(), data: samples(SampleType::U16, &g).mapv(|v| v + f as f32) })
        .collect();
    let mf = MultiField::new(g, fields).unwrap();
    for ext in ["nii.gz", "nrrd", "nhdr"] {
        let path = dir.path().join(format!("m.{ext}"));
        write(&path, &mf, &WriteOptions::default(), &[]).unwrap();
        let back = read(&path, &ReadOptions::default()).unwrap();
        assert_same(&mf, &back);
        if ext != "nii.gz" {
            assert_eq!(back.fields[2].name, "f2");
        }
    }
}

#[test]
fn rotated_and_flipped_geometry_survives_nifti_and_nrrd() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry { directions: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], ..geometry() };
    let v = Volume::new(g.clone(), samples(SampleType::U8, &g)).unwrap();
    for ext in ["nii", "nrrd"] {
        let path = dir.path().join(format!("r.{ext}"));
        mdtf_volume::write_volume(&path, &v, &WriteOptions::default(), &[]).unwrap();
        let back = read_scalar(&path, &ReadOptions::default()).unwrap();
        assert!(back.geometry.same_grid(&g), "{ext}: {:?}", back.geometry);
    }
}

#[test]
fn conversion_chain_keeps_spacing_and_origin() {
    let dir = tempfile::tempdir().unwrap();
    let g = geometry();
    let v = MultiField::from(Volume::new(g.clone(), samples(SampleType::I16, &g)).unwrap());
    let chain = ["a.nii.gz", "b.nhdr", "c.nrrd", "d.nii", "e.nrrd"];
    let mut current = v.clone();
    for name in chain {
        let p = dir.path().join(name);
        write(&p, &current, &WriteOptions::default(), &[]).unwrap();
        current = read(&p, &ReadOptions::default()).unwrap();
    }
    assert_same(&v, &current);
    assert_eq!(current.geometry.spacing, [0.5, 0.75, 2.0]);
    assert_eq!(current.geometry.origin, [-12.5, 3.25, 100.0]);
}

/// Writes a NRRD by hand so the reader is tested against the format, not against our writer.
fn handmade_nrrd(dir: &Path, name: &str, header: &str, data: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    let mut bytes = header.as_bytes().to_vec();
    bytes.extend_from_slice(data);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn nrrd_reader_handles_big_endian_spacings_lps_and_ascii() {
    let dir = tempfile::tempdir().unwrap();
    let values: Vec<i16> = (0..24).map(|i| i * 100 - 1000).collect();
    let be: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let p = handmade_nrrd(
        dir.path(),
        "be.nrrd",
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 3 2\nspacings: 0.5 1 2.5\nendian: big\nencoding: raw\n\n",
        &be,
    );
    let v = read_scalar(&p, &ReadOptions::default()).unwrap();
    assert_eq!(v.geometry.spacing, [0.5, 1.0, 2.5]);
    assert_eq!(v.data[[1, 2, 3]], values[3 + 4 * 2 + 12] as f32);

    // Slicer / ITK write LPS: x and y flip into mdtf's RAS world.
    let p = handmade_nrrd(
        dir.path(),
        "lps.nrrd",
        "NRRD0004\ntype: uchar\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 2\n\
         space directions: (-1,0,0) (0,-1,0) (0,0,3)\nkinds: domain domain domain\nencoding: raw\n\
         space origin: (10,20,30)\n\n",
        &[1, 2, 3, 4, 5, 6, 7, 8],
    );
    let v = read_scalar(&p, &ReadOptions::default()).unwrap();
    assert_eq!(v.geometry.origin, [-10.0, -20.0, 30.0]);
    assert_eq!(v.geometry.directions[0], [1.0, 0.0, 0.0]);
    assert_eq!(v.geometry.spacing, [1.0, 1.0, 3.0]);

    let p = handmade_nrrd(
        dir.path(),
        "a.nrrd",
        "NRRD0001\ntype: float\ndimension: 3\nsizes: 2 1 2\nencoding: ascii\n\n",
        b"1.5 -2\n3e2 4\n",
    );
    let v = read_scalar(&p, &ReadOptions::default()).unwrap();
    assert_eq!(v.samples(), &[1.5, -2.0, 300.0, 4.0]);
}

#[test]
fn nrrd_with_trailing_field_axis_and_detached_byte_skip() {
    let dir = tempfile::tempdir().unwrap();
    // 2 fields slowest: field 0 = 0..8, field 1 = 100..108
    let data: Vec<u8> = (0..8).chain(100..108).collect();
    let mut raw = vec![0xAB; 5];
    raw.extend_from_slice(&data);
    std::fs::write(dir.path().join("d.bin"), &raw).unwrap();
    let hdr = dir.path().join("t.nhdr");
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 2\nkinds: domain domain domain list\nencoding: raw\n\
         data file: d.bin\nbyte skip: 5\n",
    )
    .unwrap();
    let mf = read_nrrd(&hdr, &ReadOptions::default()).unwrap();
    assert_eq!(mf.fields.len(), 2);
    assert_eq!(mf.fields[1].data[[1, 1, 1]], 107.0);
    // byte skip -1: the samples end the file
    std::fs::write(&hdr, "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 2\nkinds: domain domain domain list\nencoding: raw\ndata file: d.bin\nbyte skip: -1\n").unwrap();
    let mf2 = read_nrrd(&hdr, &ReadOptions::default()).unwrap();
    assert_eq!(mf, mf2);
}

#[test]
fn nifti_scaling_and_every_datatype_are_applied_on_read() {
    // A NIfTI-1 file written byte by byte from the nifti1.h layout.
    let dir = tempfile::tempdir().unwrap();
    let cases: [(i16, i16, &[f64]); 8] = [
        (2, 8, &[0.0, 255.0]),
        (256, 8, &[-128.0, 127.0]),
        (512, 16, &[0.0, 65535.0]),
        (4, 16, &[-32768.0, 32767.0]),
        (768, 32, &[0.0, 4294967295.0]),
        (8, 32, &[-2147483648.0, 2147483647.0]),
        (16, 32, &[-1.5, 3.25]),
        (64, 64, &[-1e-3, 1e10]),
    ];
    for (code, bitpix, vals) in cases {
        for scaled in [false, true] {
            let mut h = vec![0u8; 352];
            h[0..4].copy_from_slice(&348i32.to_le_bytes());
            let dims: [i16; 8] = [3, 2, 1, 1, 1, 1, 1, 1];
            for (n, d) in dims.iter().enumerate() {
                h[40 + 2 * n..42 + 2 * n].copy_from_slice(&d.to_le_bytes());
            }
            h[70..72].copy_from_slice(&code.to_le_bytes());
            h[72..74].copy_from_slice(&bitpix.to_le_bytes());
            for (n, p) in [1.0f32, 0.8, 0.9, 1.1].iter().enumerate() {
                h[76 + 4 * n..80 + 4 * n].copy_from_slice(&p.to_le_bytes());
            }
            h[108..112].copy_from_slice(&352f32.to_le_bytes());
            let (slope, inter) = if scaled { (0.5f32, -3.0f32) } else { (0.0, 0.0) };
            h[112..116].copy_from_slice(&slope.to_le_bytes());
            h[116..120].copy_from_slice(&inter.to_le_bytes());
            h[344..348].copy_from_slice(b"n+1\0");
            for v in vals {
                match code {
                    2 => h.push(*v as u8),
                    256 => h.push(*v as i8 as u8),
                    512 => h.extend((*v as u16).to_le_bytes()),
                    4 => h.extend((*v as i16).to_le_bytes()),
                    768 => h.extend((*v as u32).to_le_bytes()),
                    8 => h.extend((*v as i32).to_le_bytes()),
                    16 => h.extend((*v as f32).to_le_bytes()),
                    _ => h.extend(v.to_le_bytes()),
                }
            }
            let p = dir.path().join(format!("t{code}_{scaled}.nii"));
            std::fs::write(&p, &h).unwrap();
            let v = read_scalar(&p, &ReadOptions::default()).unwrap();
            for (n, want) in vals.iter().enumerate() {
                let want = if scaled { want * 0.5 - 3.0 } else { *want };
                assert_eq!(v.data[[0, 0, n]], want as f32, "code {code} scaled {scaled}");
            }
            assert_eq!(v.geometry.spacing, [0.800000011920929, 0.8999999761581421, 1.100000023841858]);
        }
    }
}
