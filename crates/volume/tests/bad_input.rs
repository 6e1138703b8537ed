//! Every kind of bad input is a clear, typed error naming the file; no reader panics.

use mdtf_volume::{
    Endian, Geometry, MultiField, NanPolicy, RawSpec, ReadOptions, SampleType, Volume, VolumeError, WriteOptions, read,
    read_raw, write, write_volume,
};
use ndarray::Array3;
use proptest::prelude::*;
use std::path::{Path, PathBuf};

fn small_volume() -> Volume {
    let g = Geometry::new([4, 3, 2], [1.0, 1.0, 1.0]);
    Volume::new(g, Array3::from_shape_fn((2, 3, 4), |(k, j, i)| (i + 4 * j + 12 * k) as f32)).unwrap()
}

fn written(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    write_volume(&p, &small_volume(), &WriteOptions::default(), &[]).unwrap();
    p
}

fn err_of(path: &Path) -> VolumeError {
    let e = read(path, &ReadOptions::default()).unwrap_err();
    assert!(e.to_string().contains(&path.file_name().unwrap().to_string_lossy().to_string()), "{e}");
    e
}

#[test]
fn missing_and_empty_files() {
    let dir = tempfile::tempdir().unwrap();
    assert!(matches!(err_of(&dir.path().join("nope.nii")), VolumeError::Io { .. }));
    let empty = dir.path().join("empty.nrrd");
    std::fs::write(&empty, b"").unwrap();
    assert!(matches!(err_of(&empty), VolumeError::Empty { .. }));
    let empty = dir.path().join("empty.nii");
    std::fs::write(&empty, b"").unwrap();
    assert!(matches!(err_of(&empty), VolumeError::Empty { .. }));
}

#[test]
fn truncated_data_reports_the_byte_counts() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["t.nii", "t.nrrd"] {
        let p = written(dir.path(), name);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 10]).unwrap();
        match err_of(&p) {
            VolumeError::Truncated { expected, found, .. } => assert_eq!((expected, found), (96, 86)),
            e => panic!("{name}: {e}"),
        }
    }
}

#[test]
fn header_data_size_mismatch_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = written(dir.path(), "m.nrrd");
    let mut bytes = std::fs::read(&p).unwrap();
    bytes.extend_from_slice(&[0; 8]);
    std::fs::write(&p, &bytes).unwrap();
    assert!(matches!(err_of(&p), VolumeError::SizeMismatch { expected: 96, found: 104, .. }));
}

#[test]
fn unknown_datatypes_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let p = written(dir.path(), "u.nii");
    let mut bytes = std::fs::read(&p).unwrap();
    bytes[70..72].copy_from_slice(&1536i16.to_le_bytes()); // float128
    std::fs::write(&p, &bytes).unwrap();
    let e = err_of(&p);
    assert!(matches!(e, VolumeError::UnsupportedType { .. }), "{e}");
    assert!(e.to_string().contains("1536"));

    let p = dir.path().join("u.nrrd");
    std::fs::write(
        &p,
        "NRRD0004\ntype: long long\ndimension: 3\nsizes: 1 1 1\nencoding: raw\nendian: little\n\n\0\0\0\0\0\0\0\0",
    )
    .unwrap();
    assert!(err_of(&p).to_string().contains("long long"));
}

#[test]
fn zero_and_absurd_dimensions() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("z.nrrd");
    std::fs::write(&p, "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 0 4\nencoding: raw\n\n").unwrap();
    assert!(matches!(err_of(&p), VolumeError::BadDimensions { .. }));
    let p = dir.path().join("huge.nrrd");
    std::fs::write(&p, "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 100000 100000 100000\nencoding: raw\n\n").unwrap();
    let e = err_of(&p);
    assert!(matches!(e, VolumeError::TooLarge { .. }));
    assert!(e.to_string().contains("3.6 PiB"), "{e}");

    let p = written(dir.path(), "huge.nii");
    let mut bytes = std::fs::read(&p).unwrap();
    for n in 1..4 {
        bytes[40 + 2 * n..42 + 2 * n].copy_from_slice(&30000i16.to_le_bytes());
    }
    std::fs::write(&p, &bytes).unwrap();
    assert!(matches!(err_of(&p), VolumeError::TooLarge { .. }));
}

#[test]
fn nan_and_inf_are_refused_with_a_count_unless_zeroed() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = small_volume();
    v.data[[0, 0, 1]] = f32::NAN;
    v.data[[1, 2, 3]] = f32::INFINITY;
    for name in ["n.nii", "n.nrrd"] {
        let p = dir.path().join(name);
        write_volume(&p, &v, &WriteOptions::default(), &[]).unwrap();
        assert!(matches!(err_of(&p), VolumeError::NonFinite { count: 2, .. }));
        let z = read(&p, &ReadOptions { nan: NanPolicy::Zero, ..Default::default() }).unwrap();
        assert_eq!(z.fields[0].data[[0, 0, 1]], 0.0);
        assert_eq!(z.fields[0].data[[1, 2, 3]], 0.0);
        assert_eq!(z.fields[0].data[[1, 2, 2]], 22.0);
    }
}

#[test]
fn corrupt_gzip_is_reported_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let v = Volume::new(
        Geometry::new([32, 32, 32], [1.0; 3]),
        Array3::from_shape_fn((32, 32, 32), |(k, j, i)| ((i * j + k) % 251) as f32),
    )
    .unwrap();
    for name in ["c.nii.gz", "c.nrrd"] {
        let p = dir.path().join(name);
        write(&p, &MultiField::from(v.clone()), &WriteOptions { ty: SampleType::F32, gzip: true }, &[]).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        let n = bytes.len();
        for b in &mut bytes[n - 600..n - 500] {
            *b ^= 0x5A;
        }
        std::fs::write(&p, &bytes).unwrap();
        let e = err_of(&p);
        assert!(matches!(e, VolumeError::Gzip { .. }), "{name}: {e}");
    }
}

#[test]
fn unsupported_nrrd_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("b.nrrd");
    std::fs::write(&p, "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nencoding: bzip2\n\nxx").unwrap();
    assert!(matches!(err_of(&p), VolumeError::UnsupportedEncoding { .. }));
}

#[test]
fn raw_reader_checks_the_size_the_caller_gave() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.raw");
    let bytes: Vec<u8> = (0u16..24).flat_map(|v| v.to_be_bytes()).collect();
    std::fs::write(&p, &bytes).unwrap();
    let spec = RawSpec {
        dims: [4, 3, 2],
        ty: SampleType::U16,
        endian: Endian::Big,
        spacing: [1.0, 2.0, 3.0],
        origin: [0.0; 3],
        byte_skip: 0,
    };
    let v = read_raw(&p, &spec, &ReadOptions::default()).unwrap();
    assert_eq!(v.data[[1, 2, 3]], 23.0);
    assert_eq!(v.geometry.spacing, [1.0, 2.0, 3.0]);
    let wrong = RawSpec { dims: [4, 3, 1], ..spec.clone() };
    assert!(matches!(read_raw(&p, &wrong, &ReadOptions::default()), Err(VolumeError::SizeMismatch { .. })));
    let wrong = RawSpec { dims: [4, 3, 3], ..spec };
    assert!(matches!(read_raw(&p, &wrong, &ReadOptions::default()), Err(VolumeError::Truncated { .. })));
}

#[test]
fn writing_over_an_input_is_refused_and_leaves_it_intact() {
    let dir = tempfile::tempdir().unwrap();
    let p = written(dir.path(), "in.nrrd");
    let before = std::fs::read(&p).unwrap();
    let e = write_volume(&p, &small_volume(), &WriteOptions::default(), &[&p]).unwrap_err();
    assert!(matches!(e, VolumeError::WouldOverwriteInput { .. }));
    assert_eq!(std::fs::read(&p).unwrap(), before);
}

#[test]
fn integer_writes_refuse_values_they_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = small_volume();
    v.data[[0, 0, 3]] = 300.0;
    let p = dir.path().join("q.nii");
    let e = write_volume(&p, &v, &WriteOptions { ty: SampleType::U8, gzip: false }, &[]).unwrap_err();
    assert!(matches!(e, VolumeError::NotRepresentable { index: 3, .. }));
    assert!(!p.exists());
}

fn corpus() -> Vec<(String, Vec<u8>)> {
    let dir = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    for name in ["s.nii", "s.nii.gz", "s.nrrd"] {
        let p = written(dir.path(), name);
        out.push((name.to_string(), std::fs::read(&p).unwrap()));
    }
    let p = dir.path().join("g.nrrd");
    write(&p, &MultiField::from(small_volume()), &WriteOptions { ty: SampleType::U16, gzip: true }, &[]).unwrap();
    out.push(("g.nrrd".into(), std::fs::read(&p).unwrap()));
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, .. ProptestConfig::default() })]

    /// Mutating any bytes of a valid file (header or data) gives Ok or Err, never a panic.
    #[test]
    fn mutated_files_never_panic(which in 0usize..4, edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8), cut in any::<prop::sample::Index>(), truncate in any::<bool>()) {
        let files = corpus();
        let (name, mut bytes) = files[which].clone();
        for (at, b) in edits {
            let i = at.index(bytes.len());
            bytes[i] = b;
        }
        if truncate {
            let n = cut.index(bytes.len());
            bytes.truncate(n);
        }
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(&name);
        std::fs::write(&p, &bytes).unwrap();
        let _ = read(&p, &ReadOptions::default());
    }

    /// Mutating the text of a NRRD header line by line never panics.
    #[test]
    fn mutated_nrrd_headers_never_panic(line in 1usize..9, text in "[ -~]{0,40}") {
        let mut lines: Vec<String> = "NRRD0004\ntype: float\ndimension: 3\nsizes: 4 3 2\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nkinds: domain domain domain\nendian: little\nencoding: raw\nspace origin: (0,0,0)".lines().map(String::from).collect();
        let l = line.min(lines.len() - 1);
        lines[l] = text;
        let mut bytes = (lines.join("\n") + "\n\n").into_bytes();
        bytes.extend(std::iter::repeat_n(0u8, 96));
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.nrrd");
        std::fs::write(&p, &bytes).unwrap();
        let _ = read(&p, &ReadOptions::default());
    }

    /// Random bytes are an error for every reader.
    #[test]
    fn random_bytes_are_an_error(bytes in prop::collection::vec(any::<u8>(), 0..2000), ext in prop::sample::select(vec!["nii", "nii.gz", "nrrd", "nhdr"])) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(format!("r.{ext}"));
        std::fs::write(&p, &bytes).unwrap();
        prop_assert!(read(&p, &ReadOptions::default()).is_err());
        let spec = RawSpec { dims: [7, 7, 7], ty: SampleType::F64, endian: Endian::Little, spacing: [1.0; 3], origin: [0.0; 3], byte_skip: 0 };
        prop_assert!(read_raw(&p, &spec, &ReadOptions::default()).is_err());
    }
}
