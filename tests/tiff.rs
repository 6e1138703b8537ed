//! TIFF stacks written by tifffile (the reference writer of the microscopy
//! world): ImageJ hyperstacks with their spacing, OME-TIFF with physical
//! sizes, BigTIFF, Deflate and LZW pages, every sample type, and folders of
//! numbered slices, read by mdtf value for value.

use mdtf_e2e::{mdtf, mdtf_err, run_python};
use mdtf_volume::{ReadOptions, read};
use serde_json::Value;

const WRITE: &str = r#"
import sys, os, json, numpy as np, tifffile
d = sys.argv[1]
z, y, x = 3, 4, 5
n = np.arange(z * y * x, dtype=np.float64).reshape(z, y, x)
out = {}
def save(name, a, **kw):
    if not kw.get("imagej"):
        kw["photometric"] = "minisblack"
    tifffile.imwrite(os.path.join(d, name), a, **kw)
    out[name] = a.astype(np.float64).ravel().tolist()
for t in ["uint8", "int8", "uint16", "int16", "uint32", "int32", "float32", "float64"]:
    save(f"plain-{t}.tif", (n * 3 - (40 if t[0] == "i" else 0)).astype(t))
save("imagej.tif", (n * 100).astype("uint16"), imagej=True, resolution=(1 / 0.25, 1 / 0.5), metadata={"spacing": 2.5, "unit": "um", "axes": "ZYX"})
save("ome.ome.tif", (n / 7).astype("float32"), metadata={"axes": "ZYX", "PhysicalSizeX": 0.125, "PhysicalSizeY": 0.375, "PhysicalSizeZ": 1.5})
save("big.tif", (n * 7).astype("uint16"), bigtiff=True)
save("deflate.tif", (n * 11).astype("uint16"), compression="zlib")
save("lzw.tif", (n * 13).astype("uint16"), compression="lzw")
save("zstd.tif", (n * 17).astype("float32"), compression="zstd")
save("tiled-float64.tif", (n / 3).astype("float64"), tile=(16, 16))
# a stack of 4 float slices written without photometric='minisblack': tifffile stores one planar RGBA image
tifffile.imwrite(os.path.join(d, "four-planes.tif"), np.zeros((4, 6, 7), "float32"))
# several channels or time points: refused, not read as z-slices with the axes mixed
h = np.zeros((2, 3, 2, 4, 5), "uint16")
tifffile.imwrite(os.path.join(d, "tzcyx.tif"), h, imagej=True, metadata={"axes": "TZCYX"})
tifffile.imwrite(os.path.join(d, "czyx.ome.tif"), h[0].transpose(1, 0, 2, 3), metadata={"axes": "CZYX"})
os.makedirs(os.path.join(d, "slices"))
for k in range(z):
    tifffile.imwrite(os.path.join(d, "slices", f"z{k * 5 + 2}.tif"), (n[k] + 1000 * k).astype("uint16"))
out["slices"] = np.stack([n[k] + 1000 * k for k in range(z)]).ravel().tolist()
tifffile.imwrite(os.path.join(d, "rgb.tif"), np.zeros((4, 5, 3), "uint8"), photometric="rgb")
print(json.dumps(out))
"#;

#[test]
fn tifffile_stacks_read_value_for_value_with_their_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let truth: Value = serde_json::from_str(&run_python(WRITE, &[dir.path().to_str().unwrap()])).unwrap();
    let spacing = |name: &str| match name {
        "imagej.tif" => [0.25, 0.5, 2.5],
        "ome.ome.tif" => [0.125, 0.375, 1.5],
        _ => [1.0, 1.0, 1.0],
    };
    for (name, values) in truth.as_object().unwrap() {
        // (tiles of 16 x 16 over 5 x 4 pages: tifffile pads them, mdtf crops them)
        let mf = read(&dir.path().join(name), &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(mf.geometry.dims, [5, 4, 3], "{name}");
        let s = mf.geometry.spacing;
        let want = spacing(name);
        assert!((0..3).all(|a| (s[a] - want[a]).abs() < 1e-6), "{name}: spacing {s:?}, want {want:?}");
        let got: Vec<f64> = mf.fields[0].data.iter().map(|&v| v as f64).collect();
        let want: Vec<f64> = values.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(got.len(), want.len(), "{name}");
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{name} sample {i}: {a} vs {b}");
        }
    }
    // no recorded spacing is a warning, not a guess kept silent
    let out = mdtf(&["info", dir.path().join("plain-uint8.tif").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("no ImageJ or OME spacing"), "{err}");
    // a hyperstack names its channels and time points
    for (name, said) in [("tzcyx.tif", "2 channel(s) and 2 time point(s)"), ("czyx.ome.tif", "2 channel(s) and 1")] {
        let out = mdtf(&["info", dir.path().join(name).to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(name) && err.contains(said), "{name}: {err}");
    }
    // colour is not a volume
    let out = mdtf(&["info", dir.path().join("rgb.tif").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("rgb.tif") && err.contains("not grayscale"), "{err}");
    // tifffile's 4-slice trap is named, with the way out
    let err = mdtf_err(&["info", dir.path().join("four-planes.tif").to_str().unwrap()]);
    assert!(err.contains("RGBA") && err.contains("photometric='minisblack'"), "{err}");
}
