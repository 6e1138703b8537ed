//! NIfTI-2, `.hdr`/`.img` pairs (NIfTI-1 and NIfTI-2) and Analyze 7.5,
//! both ways through nibabel: what nibabel writes mdtf reads with nibabel's
//! values and affine, and what mdtf writes nibabel reads bit for bit.

use mdtf_e2e::{mdtf, mdtf_err, run_python};
use mdtf_volume::{
    Field, Geometry, MultiField, PlaneReader, ReadOptions, SampleType, WriteOptions, read, read_with_info, write,
};
use ndarray::Array3;
use serde_json::Value;

/// Writes with nibabel into argv[1] one file per header kind, then prints for each what nibabel
/// reads back: its image class, values (x fastest, scaled) and affine.
const WRITE_WITH_NIBABEL: &str = r#"
import sys, os, json, nibabel as nib, numpy as np
out = sys.argv[1]
rng = np.random.default_rng(7)
stored = rng.integers(-3000, 3000, size=(6, 5, 4)).astype(np.int16)
oblique = np.array([[0, -0.8, 0, 10.0], [0.9, 0, 0, -20.0], [0, 0, 1.5, 5.0], [0, 0, 0, 1]])
made = {}
for name, cls in [('n2.nii', nib.Nifti2Image), ('n2.nii.gz', nib.Nifti2Image), ('n1pair.hdr', nib.Nifti1Pair),
                  ('n2pair.hdr', nib.Nifti2Pair)]:
    img = cls(stored, oblique)
    img.header.set_slope_inter(0.25, -7.5)
    img.set_qform(oblique, code=1)
    img.set_sform(oblique, code=2)
    nib.save(img, os.path.join(out, name))
    made[name] = cls.__name__
# a 4-D float NIfTI-2 (its 4th axis: fields)
four = rng.normal(size=(3, 4, 2, 3)).astype(np.float32)
nib.save(nib.Nifti2Image(four, np.diag([2.0, 3.0, 4.0, 1.0])), os.path.join(out, 'n2_4d.nii'))
made['n2_4d.nii'] = 'Nifti2Image'
# Analyze as SPM2 writes it: a slope in funused1 and an origin in 'originator' (patched into the
# header nibabel writes: its SPM writer needs scipy); and one with neither (centred). nibabel reads
# both as SPM2 Analyze.
nib.save(nib.AnalyzeImage(stored, np.diag([-2.0, 2.5, 3.0, 1.0])), os.path.join(out, 'spm.hdr'))
hdr = bytearray(open(os.path.join(out, 'spm.hdr'), 'rb').read())
hdr[112:116] = np.float32(0.5).tobytes()
hdr[253:259] = np.array([2, 3, 1], dtype=np.int16).tobytes()
open(os.path.join(out, 'spm.hdr'), 'wb').write(bytes(hdr))
made['spm.hdr'] = 'Spm2AnalyzeImage'
nib.save(nib.AnalyzeImage(stored.astype(np.float32), np.diag([-1.5, 1.5, 2.0, 1.0])), os.path.join(out, 'plain.hdr'))
made['plain.hdr'] = 'Spm2AnalyzeImage'
result = {}
for name, cls in made.items():
    img = nib.load(os.path.join(out, name))
    data = img.get_fdata()
    if data.ndim == 3: data = data[..., None]
    result[name] = {'class': type(img).__name__, 'made': cls, 'shape': list(data.shape),
                    'values': [v for f in range(data.shape[3]) for v in data[..., f].flatten(order='F').tolist()],
                    'affine': img.affine.tolist()}
print(json.dumps(result))
"#;

/// Prints what nibabel reads from argv[1]: class, on-disk dtype, shape, values (x fastest) and affine.
const NIBABEL_READS: &str = r#"
import sys, json, nibabel as nib, numpy as np
img = nib.load(sys.argv[1])
data = np.asanyarray(img.dataobj)
if data.ndim == 3: data = data[..., None]
print(json.dumps({'class': type(img).__name__, 'dtype': str(img.get_data_dtype()), 'shape': list(img.shape),
                  'values': [v for f in range(data.shape[3]) for v in data[..., f].flatten(order='F').astype(float).tolist()],
                  'affine': img.affine.tolist(), 'qform_code': int(img.header['qform_code']),
                  'sform_code': int(img.header['sform_code'])}))
"#;

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn assert_affine(got: &Geometry, want: &Value, what: &str) {
    let m = got.world_from_voxel();
    for (r, row) in want.as_array().unwrap().iter().take(3).enumerate() {
        for (c, w) in floats(row).iter().enumerate() {
            assert!((m[r][c] - w).abs() < 1e-5, "{what}: affine[{r}][{c}] {} vs nibabel's {w}", m[r][c]);
        }
    }
}

#[test]
fn mdtf_reads_nifti2_pairs_and_analyze_as_nibabel_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let theirs: Value = serde_json::from_str(&run_python(WRITE_WITH_NIBABEL, &[dir.path().to_str().unwrap()])).unwrap();
    let formats = [
        ("n2.nii", "NIfTI-2"),
        ("n2.nii.gz", "NIfTI-2"),
        ("n1pair.hdr", "NIfTI-1 pair"),
        ("n2pair.hdr", "NIfTI-2 pair"),
        ("n2_4d.nii", "NIfTI-2"),
        ("spm.hdr", "Analyze 7.5"),
        ("plain.hdr", "Analyze 7.5"),
    ];
    for (name, format) in formats {
        let t = &theirs[name];
        assert_eq!(t["class"], t["made"], "{name}: nibabel reads back the class it wrote");
        let (mf, info) =
            read_with_info(&dir.path().join(name), &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(info.format.starts_with(format), "{name}: {}", info.format);
        let shape: Vec<usize> = t["shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
        assert_eq!(mf.geometry.dims.to_vec(), shape[..3], "{name}: dims");
        assert_eq!(mf.fields.len(), shape[3], "{name}: fields");
        let got: Vec<f64> = mf.fields.iter().flat_map(|f| f.data.iter().map(|&v| v as f64)).collect();
        let want = floats(&t["values"]);
        assert_eq!(got.len(), want.len(), "{name}");
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(*g as f32, *w as f32, "{name}: sample {i}");
        }
        assert_affine(&mf.geometry, &t["affine"], name);
    }
    // the data file's name reads the pair too
    let by_img = read(&dir.path().join("n1pair.img"), &ReadOptions::default()).unwrap();
    let by_hdr = read(&dir.path().join("n1pair.hdr"), &ReadOptions::default()).unwrap();
    assert_eq!(by_img.fields[0].data, by_hdr.fields[0].data);
    // a pair without its data file, or a data file without its header, is refused by name
    std::fs::remove_file(dir.path().join("n2pair.img")).unwrap();
    let err = mdtf_err(&["info", dir.path().join("n2pair.hdr").to_str().unwrap()]);
    assert!(err.contains("n2pair.img, which is missing"), "{err}");
    std::fs::remove_file(dir.path().join("spm.hdr")).unwrap();
    let err = mdtf_err(&["info", dir.path().join("spm.img").to_str().unwrap()]);
    assert!(err.contains("the header of this .img is missing") && err.contains("spm.hdr"), "{err}");
}

fn ramp(dims: [usize; 3], ty: SampleType) -> MultiField {
    let g = Geometry {
        dims,
        spacing: [0.5, 0.75, 2.0],
        origin: [-12.5, 3.25, 100.0],
        directions: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
    };
    let data = Array3::from_shape_fn((dims[2], dims[1], dims[0]), |(k, j, i)| {
        let n = (i * 7 + j * 13 + k * 29) as f32;
        match ty {
            SampleType::U8 => n % 256.0,
            SampleType::U16 => (n * 3.0) % 65536.0,
            _ => n * 0.37 - 5.125,
        }
    });
    MultiField::new(g, vec![Field { name: "value".into(), data }]).unwrap()
}

#[test]
fn nibabel_reads_the_nifti2_and_pairs_mdtf_writes_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        // an axis beyond NIfTI-1's 32767 voxels: NIfTI-2
        ("long.nii", [40000, 2, 1], SampleType::U8, "Nifti2Image"),
        ("long.nii.gz", [40000, 2, 1], SampleType::F32, "Nifti2Image"),
        ("pair.hdr", [5, 4, 3], SampleType::U16, "Nifti1Pair"),
        ("pair_gz.hdr.gz", [5, 4, 3], SampleType::F32, "Nifti1Pair"),
        ("longpair.img", [2, 33000, 1], SampleType::U8, "Nifti2Pair"),
        ("small.nii", [5, 4, 3], SampleType::F32, "Nifti1Image"),
    ];
    for (name, dims, ty, class) in cases {
        let mf = ramp(dims, ty);
        let path = dir.path().join(name);
        write(&path, &mf, &WriteOptions { ty, gzip: false }, &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
        let d: Value = serde_json::from_str(&run_python(NIBABEL_READS, &[path.to_str().unwrap()])).unwrap();
        assert_eq!(d["class"], class, "{name}");
        assert_eq!(
            d["dtype"],
            ty.to_string().replace("f32", "float32").replace("u8", "uint8").replace("u16", "uint16")
        );
        assert_eq!((d["qform_code"].as_i64(), d["sform_code"].as_i64()), (Some(1), Some(1)), "{name}");
        let ours: Vec<f64> = mf.fields[0].data.iter().map(|&v| v as f64).collect();
        assert_eq!(floats(&d["values"]), ours, "{name}: values");
        assert_affine(&mf.geometry, &d["affine"], name);
        // and back through mdtf
        let back = read(&path, &ReadOptions::default()).unwrap();
        assert_eq!(back.fields[0].data, mf.fields[0].data, "{name}: read back");
    }
    // a pair's two files exist, nothing else is left beside them
    let mut names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(
        names,
        [
            "long.nii",
            "long.nii.gz",
            "longpair.hdr",
            "longpair.img",
            "pair.hdr",
            "pair.img",
            "pair_gz.hdr.gz",
            "pair_gz.img.gz",
            "small.nii"
        ]
    );
    // the command says when it writes NIfTI-2
    let out = mdtf(&[
        "convert",
        dir.path().join("long.nii").to_str().unwrap(),
        dir.path().join("copy.nii.gz").to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && text.contains("written as NIfTI-2"), "{text}");
    // a pair is never written over its own input
    let err = mdtf_err(&[
        "convert",
        dir.path().join("pair.hdr").to_str().unwrap(),
        dir.path().join("pair.img").to_str().unwrap(),
    ]);
    assert!(err.contains("pair.img") && err.contains("input"), "{err}");
}

/// Writes with nibabel a float32 ramp of 9 x 7 x 6 into argv[1] as a NIfTI-2 file and as a NIfTI-1 pair.
const RAMP_WITH_NIBABEL: &str = r#"
import sys, os, nibabel as nib, numpy as np
ramp = np.arange(9 * 7 * 6, dtype=np.float32).reshape((9, 7, 6), order='F') * 0.5
nib.save(nib.Nifti2Image(ramp, np.diag([1.0, 2.0, 3.0, 1.0])), os.path.join(sys.argv[1], 'ramp2.nii'))
nib.save(nib.Nifti1Pair(ramp, np.diag([1.0, 2.0, 3.0, 1.0])), os.path.join(sys.argv[1], 'ramp1.hdr'))
"#;

#[test]
fn nifti2_files_and_pairs_are_read_plane_by_plane_as_they_are_read_whole() {
    let dir = tempfile::tempdir().unwrap();
    run_python(RAMP_WITH_NIBABEL, &[dir.path().to_str().unwrap()]);
    for name in ["ramp2.nii", "ramp1.hdr"] {
        let path = dir.path().join(name);
        let whole = read(&path, &ReadOptions::default()).unwrap();
        let mut planes = PlaneReader::open(&path, &ReadOptions::default()).unwrap().expect("streams");
        assert_eq!(planes.geometry(), &whole.geometry, "{name}");
        let mut got = Vec::new();
        for z in [0..2, 2..5, 5..6] {
            got.extend(planes.read(z).unwrap().data.iter().copied());
        }
        let want: Vec<f32> = whole.fields[0].data.iter().copied().collect();
        assert_eq!(got, want, "{name}");
        assert_eq!(want[9 * 7 * 6 - 1], (9 * 7 * 6 - 1) as f32 * 0.5);
    }
}
