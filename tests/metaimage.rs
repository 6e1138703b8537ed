//! MetaImage against ITK itself (SimpleITK): what mdtf writes opens in ITK
//! with the same values, spacing, origin and direction, and what ITK writes
//! (every pixel type, compressed or not, vectors, detached data) opens in
//! mdtf the same way. ITK's world is LPS, mdtf's RAS.

use mdtf_e2e::run_python;
use mdtf_volume::{Field, Geometry, MultiField, ReadOptions, SampleType, WriteOptions, read, write};
use ndarray::Array3;
use serde_json::Value;

const DUMP_ITK: &str = r#"
import sys, json, SimpleITK as sitk, numpy as np
img = sitk.ReadImage(sys.argv[1])
a = sitk.GetArrayFromImage(img)  # (z, y, x[, c])
comps = img.GetNumberOfComponentsPerPixel()
fields = [a[..., c].astype(np.float64).ravel().tolist() for c in range(comps)] if comps > 1 else [a.astype(np.float64).ravel().tolist()]
print(json.dumps({"size": list(img.GetSize()), "spacing": list(img.GetSpacing()), "origin": list(img.GetOrigin()),
  "direction": list(img.GetDirection()), "type": img.GetPixelIDTypeAsString(), "fields": fields}))
"#;

const WRITE_ITK: &str = r#"
import sys, json, os, SimpleITK as sitk, numpy as np
folder, kinds, variants = sys.argv[1], sys.argv[2].split(","), sys.argv[3].split(",")
shape = (3, 4, 5)  # z, y, x
n = np.arange(60, dtype=np.float64).reshape(shape)
truth = {}
for kind in kinds:
    if kind == "vector":
        a = np.stack([n * 0.5, n - 7.0, n * n / 9.0], axis=-1).astype(np.float32)
        img = sitk.GetImageFromArray(a, isVector=True)
        fields = [a[..., c].astype(np.float64).ravel().tolist() for c in range(3)]
    else:
        vals = {"uint8": n * 4 % 256, "int8": n - 30, "uint16": n * 1000, "int16": n * 500 - 15000,
                "uint32": n * 70000, "int32": n * -70000, "float32": n * 0.37 - 5.125, "float64": n / 3.0 - 1e-9}[kind]
        img = sitk.GetImageFromArray(vals.astype(kind))
        fields = [vals.astype(kind).astype(np.float64).ravel().tolist()]
    img.SetSpacing((0.5, 0.75, 2.0))
    img.SetOrigin((10.0, -20.0, 30.5))
    c, s = np.cos(0.3), np.sin(0.3)
    img.SetDirection((c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0))
    for v in variants:
        compress, ext = v.split(".")
        name = f"{kind}-{compress}.{ext}"
        sitk.WriteImage(img, os.path.join(folder, name), compress == "z")
        truth[name] = fields
print(json.dumps(truth))
"#;

fn dump(path: &std::path::Path) -> Value {
    serde_json::from_str(&run_python(DUMP_ITK, &[path.to_str().unwrap()])).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

/// An oblique grid: rotated 0.3 rad about z, off the origin.
fn oblique() -> Geometry {
    let (c, s) = (0.3f64.cos(), 0.3f64.sin());
    Geometry {
        dims: [5, 4, 3],
        spacing: [0.5, 0.75, 2.0],
        origin: [-10.0, 20.0, 30.5],
        directions: [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

#[test]
fn itk_reads_what_mdtf_writes_with_values_and_lps_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let g = oblique();
    for (ty, name, itk) in [
        (SampleType::F32, "f.mha", "32-bit float"),
        (SampleType::U8, "b.mhd", "8-bit unsigned integer"),
        (SampleType::U16, "s.mha", "16-bit unsigned integer"),
        (SampleType::F32, "v.mhd", "vector of 32-bit float"),
    ] {
        let nf = if name.starts_with('v') { 3 } else { 1 };
        let fields: Vec<Field> = (0..nf)
            .map(|f| Field {
                name: format!("c{f}"),
                data: Array3::from_shape_fn(g.shape(), |(k, j, i)| {
                    let n = (i + 5 * j + 20 * k) as f32;
                    if ty == SampleType::F32 { n * 0.37 - 5.125 + f as f32 } else { (n * 3.0 + f as f32) % 200.0 }
                }),
            })
            .collect();
        let mf = MultiField::new(g.clone(), fields).unwrap();
        let path = dir.path().join(name);
        write(&path, &mf, &WriteOptions { ty, gzip: false }, &[]).unwrap();
        let d = dump(&path);
        assert_eq!(d["type"], itk, "{name}");
        assert_eq!(floats(&d["size"]), vec![5.0, 4.0, 3.0]);
        assert_eq!(floats(&d["spacing"]), vec![0.5, 0.75, 2.0]);
        assert_eq!(floats(&d["origin"]), vec![10.0, -20.0, 30.5], "{name}: RAS (-10, 20) is LPS (10, -20)");
        // ITK's direction matrix, row-major: column a is axis a's direction, in LPS
        let m = floats(&d["direction"]);
        for a in 0..3 {
            let lps = [-g.directions[a][0], -g.directions[a][1], g.directions[a][2]];
            for r in 0..3 {
                assert!(close(m[r * 3 + a], lps[r]), "{name}: direction {m:?}");
            }
        }
        for (f, field) in mf.fields.iter().enumerate() {
            let got = floats(&d["fields"][f]);
            let want: Vec<f64> = field.data.iter().map(|&v| v as f64).collect();
            assert_eq!(got, want, "{name} field {f}");
        }
    }
}

#[test]
fn mdtf_reads_what_itk_writes_for_every_pixel_type() {
    let dir = tempfile::tempdir().unwrap();
    let (c, s) = (0.3f64.cos(), 0.3f64.sin());
    let kinds = "uint8,int8,uint16,int16,uint32,int32,float32,float64,vector";
    let truth: Value =
        serde_json::from_str(&run_python(WRITE_ITK, &[dir.path().to_str().unwrap(), kinds, "raw.mha,z.mha,raw.mhd"]))
            .unwrap();
    for (name, fields) in truth.as_object().unwrap() {
        let path = dir.path().join(name);
        let mf = read(&path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let g = &mf.geometry;
        assert_eq!(g.dims, [5, 4, 3]);
        assert_eq!(g.spacing, [0.5, 0.75, 2.0]);
        assert_eq!(g.origin, [-10.0, 20.0, 30.5], "{name}: LPS (10, -20) is RAS (-10, 20)");
        // ITK direction (c, -s; s, c) in LPS: axis x along (c, s) LPS = (-c, -s) RAS
        let want = [[-c, -s, 0.0], [s, -c, 0.0], [0.0, 0.0, 1.0]];
        for a in 0..3 {
            for r in 0..3 {
                assert!(close(g.directions[a][r], want[a][r]), "{name}: {:?}", g.directions);
            }
        }
        assert_eq!(mf.fields.len(), fields.as_array().unwrap().len(), "{name}");
        for (f, field) in mf.fields.iter().enumerate() {
            let want = floats(&fields[f]);
            let got: Vec<f64> = field.data.iter().map(|&v| v as f64).collect();
            assert_eq!(got.len(), want.len());
            // mdtf holds f32: float64 and 32-bit integers compare at f32 precision
            for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{name} field {f} sample {i}: {a} vs {b}");
            }
        }
    }
    assert_eq!(truth.as_object().unwrap().len(), 27);
}

#[test]
fn a_metaimage_round_trips_through_mdtf_convert_and_keeps_its_pair_whole() {
    let dir = tempfile::tempdir().unwrap();
    run_python(WRITE_ITK, &[dir.path().to_str().unwrap(), "int16", "z.mha"]);
    let src = dir.path().join("int16-z.mha");
    let before = read(&src, &ReadOptions::default()).unwrap();
    let nii = dir.path().join("x.nii");
    let mhd = dir.path().join("y.mhd");
    mdtf_e2e::mdtf_ok(&["convert", src.to_str().unwrap(), nii.to_str().unwrap(), "-q"]);
    mdtf_e2e::mdtf_ok(&["convert", nii.to_str().unwrap(), mhd.to_str().unwrap(), "-q"]);
    mdtf_e2e::mdtf_ok(&["convert", src.to_str().unwrap(), mhd.to_str().unwrap(), "-q"]);
    let after = read(&mhd, &ReadOptions::default()).unwrap();
    assert!(after.geometry.same_grid(&before.geometry));
    assert_eq!(after.fields[0].data, before.fields[0].data);
    // the data file of an .mhd input is never overwritten
    let e = mdtf_e2e::mdtf_err(&["convert", mhd.to_str().unwrap(), dir.path().join("y.mhd").to_str().unwrap()]);
    assert!(e.contains("input"), "{e}");
    assert_eq!(read(&mhd, &ReadOptions::default()).unwrap().fields[0].data, before.fields[0].data);
}

#[test]
fn list_slices_compressed_data_and_bad_headers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let head = "ObjectType = Image\nNDims = 3\nDimSize = 2 2 3\nElementType = MET_USHORT\nElementSpacing = 1 1 2.5\n";
    for z in 0..3u16 {
        let bytes: Vec<u8> = (0..4u16).flat_map(|i| (z * 100 + i).to_le_bytes()).collect();
        std::fs::write(d.join(format!("s{z}.raw")), bytes).unwrap();
    }
    std::fs::write(d.join("list.mhd"), format!("{head}ElementDataFile = LIST\ns0.raw\ns1.raw\ns2.raw\n")).unwrap();
    let mf = read(&d.join("list.mhd"), &ReadOptions::default()).unwrap();
    let want: Vec<f32> = (0..3).flat_map(|z| (0..4).map(move |i| (z * 100 + i) as f32)).collect();
    assert_eq!(mf.fields[0].data.iter().copied().collect::<Vec<_>>(), want);
    assert_eq!(mf.geometry.spacing, [1.0, 1.0, 2.5]);
    // the slices are inputs: converting onto one of them is refused
    let s0 = std::fs::read(d.join("s0.raw")).unwrap();
    let e = mdtf_e2e::mdtf_err(&["convert", d.join("list.mhd").to_str().unwrap(), d.join("s0.nhdr").to_str().unwrap()]);
    assert!(e.contains("s0.raw") && e.contains("an input of this run"), "{e}");
    assert_eq!(std::fs::read(d.join("s0.raw")).unwrap(), s0);
    let inputs = mdtf_volume::Inputs::of(&[&d.join("list.mhd")]);
    assert!(inputs.find(&d.join("s2.raw")).is_some());
    // zlib-compressed samples
    let raw: Vec<u8> = want.iter().flat_map(|&v| (v as u16).to_be_bytes()).collect();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut z, &raw).unwrap();
    let packed = z.finish().unwrap();
    let text = format!(
        "{head}BinaryDataByteOrderMSB = True\nCompressedData = True\nCompressedDataSize = {}\nElementDataFile = LOCAL\n",
        packed.len()
    );
    std::fs::write(d.join("z.mha"), [text.into_bytes(), packed].concat()).unwrap();
    let mf = read(&d.join("z.mha"), &ReadOptions::default()).unwrap();
    assert_eq!(mf.fields[0].data.iter().copied().collect::<Vec<_>>(), want);
    // bad headers are named
    for (text, words) in [
        (format!("{head}ElementDataFile = LIST\ns0.raw\n"), "names 1 slice files for 3 slices"),
        (head.replace("MET_USHORT", "MET_LONG_LONG") + "ElementDataFile = LOCAL\n", "MET_LONG_LONG"),
        (head.replace("DimSize = 2 2 3", "DimSize = 2 2") + "ElementDataFile = LOCAL\n", "DimSize has 2 sizes"),
        (head.replace("NDims = 3", "NDims = 4") + "ElementDataFile = LOCAL\n", "NDims = 4"),
        (head.replace("1 1 2.5", "1 -1 2.5") + "ElementDataFile = LOCAL\n", "ElementSpacing"),
        (head.to_string(), "no ElementDataFile"),
        (format!("{head}ElementDataFile = gone.raw\n"), "gone.raw"),
        (format!("{head}ElementDataFile = LOCAL\n"), "truncated"),
    ] {
        std::fs::write(d.join("bad.mha"), &text).unwrap();
        let e = read(&d.join("bad.mha"), &ReadOptions::default()).unwrap_err().to_string();
        assert!(e.contains(words) && e.contains("bad.mha") || e.contains("gone.raw"), "{words}: {e}");
    }
}
