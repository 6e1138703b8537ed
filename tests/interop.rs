//! Cross-tool interop: files written by mdtf read by nibabel and pynrrd, and
//! files written by them read by mdtf, value for value, geometry included.
//! Also Teem's header conventions (`space directions`, `kinds`, `spacings`).

use mdtf_e2e::{mdtf_ok, run_python};
use mdtf_volume::{Field, Geometry, MultiField, ReadOptions, SampleType, WriteOptions, read, write};
use ndarray::Array3;
use serde_json::Value;
use std::path::Path;

const DUMP_NIBABEL: &str = r#"
import sys, json, nibabel as nib, numpy as np
img = nib.load(sys.argv[1])
data = np.asanyarray(img.dataobj).astype(np.float64) if img.header.get_slope_inter() == (None, None) else img.get_fdata()
if data.ndim == 3: data = data[..., None]
fields = [data[..., f].flatten(order='F').tolist() for f in range(data.shape[3])]
print(json.dumps({"shape": list(img.shape), "affine": img.affine.tolist(), "qform": img.get_qform().tolist(),
  "zooms": [float(z) for z in img.header.get_zooms()[:3]], "dtype": str(img.get_data_dtype()), "fields": fields}))
"#;

const DUMP_PYNRRD: &str = r#"
import sys, json, nrrd, numpy as np
data, h = nrrd.read(sys.argv[1])
kinds = h.get('kinds', [])
if data.ndim == 4:
    fields = [data[f].flatten(order='F').astype(np.float64).tolist() for f in range(data.shape[0])]
else:
    fields = [data.flatten(order='F').astype(np.float64).tolist()]
dirs = h.get('space directions')
dirs = None if dirs is None else [[None if np.isnan(v).any() else [float(x) for x in v]][0] for v in dirs]
print(json.dumps({"sizes": [int(s) for s in h['sizes']], "type": str(data.dtype), "space": h.get('space'),
  "directions": dirs, "origin": None if h.get('space origin') is None else [float(x) for x in h['space origin']],
  "kinds": kinds, "fields": fields}))
"#;

fn dump(script: &str, path: &Path) -> Value {
    serde_json::from_str(&run_python(script, &[path.to_str().unwrap()])).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn test_geometry() -> Geometry {
    Geometry {
        dims: [5, 4, 3],
        spacing: [0.5, 0.75, 2.0],
        origin: [-12.5, 3.25, 100.0],
        directions: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    }
}

fn field(ty: SampleType, salt: f32) -> Array3<f32> {
    let g = test_geometry();
    Array3::from_shape_fn(g.shape(), |(k, j, i)| {
        let n = (i + 5 * j + 20 * k) as f32;
        match ty {
            SampleType::F32 => n * 0.37 - 5.125 + salt,
            SampleType::U8 => (n * 4.0 + salt) % 256.0,
            _ => (n * 1000.0 + salt) % 65536.0,
        }
    })
}

#[test]
fn nibabel_reads_what_mdtf_writes() {
    let dir = tempfile::tempdir().unwrap();
    for ty in [SampleType::F32, SampleType::U8, SampleType::U16] {
        for ext in ["nii", "nii.gz"] {
            let fields: Vec<Field> = (0..if ty == SampleType::F32 { 2 } else { 1 })
                .map(|f| Field { name: format!("f{f}"), data: field(ty, f as f32) })
                .collect();
            let mf = MultiField::new(test_geometry(), fields).unwrap();
            let p = dir.path().join(format!("m_{ty}.{ext}"));
            write(&p, &mf, &WriteOptions { ty, gzip: false }, &[]).unwrap();
            let d = dump(DUMP_NIBABEL, &p);
            assert_eq!(
                d["dtype"],
                ["float32", "uint8", "uint16"]
                    [[SampleType::F32, SampleType::U8, SampleType::U16].iter().position(|t| *t == ty).unwrap()]
            );
            assert_eq!(floats(&d["zooms"]), vec![0.5, 0.75, 2.0]);
            let aff: Vec<Vec<f64>> = d["affine"].as_array().unwrap().iter().map(floats).collect();
            assert_eq!(aff[0], vec![0.5, 0.0, 0.0, -12.5]);
            assert_eq!(aff[1], vec![0.0, 0.75, 0.0, 3.25]);
            assert_eq!(aff[2], vec![0.0, 0.0, 2.0, 100.0]);
            assert_eq!(d["qform"], d["affine"], "qform and sform agree");
            for (f, mine) in mf.fields.iter().enumerate() {
                let theirs = floats(&d["fields"][f]);
                let ours: Vec<f64> = mine.data.iter().map(|&v| v as f64).collect();
                assert_eq!(theirs, ours, "{ty} {ext} field {f}");
            }
        }
    }
}

#[test]
fn pynrrd_reads_what_mdtf_writes() {
    let dir = tempfile::tempdir().unwrap();
    for (ext, gzip) in [("nrrd", false), ("nrrd", true), ("nhdr", false), ("nhdr", true)] {
        for nfields in [1, 3] {
            let fields: Vec<Field> =
                (0..nfields).map(|f| Field { name: format!("f{f}"), data: field(SampleType::U16, f as f32) }).collect();
            let mf = MultiField::new(test_geometry(), fields).unwrap();
            let p = dir.path().join(format!("m{nfields}_{gzip}.{ext}"));
            write(&p, &mf, &WriteOptions { ty: SampleType::U16, gzip }, &[]).unwrap();
            let d = dump(DUMP_PYNRRD, &p);
            assert_eq!(d["type"], "uint16");
            assert_eq!(d["space"], "right-anterior-superior");
            assert_eq!(floats(&d["origin"]), vec![-12.5, 3.25, 100.0]);
            let dirs = d["directions"].as_array().unwrap();
            let offset = if nfields > 1 { 1 } else { 0 };
            if nfields > 1 {
                assert!(dirs[0].is_null());
                assert_eq!(d["kinds"][0], "list");
            }
            assert_eq!(floats(&dirs[offset]), vec![0.5, 0.0, 0.0]);
            assert_eq!(floats(&dirs[offset + 2]), vec![0.0, 0.0, 2.0]);
            for (f, mine) in mf.fields.iter().enumerate() {
                let ours: Vec<f64> = mine.data.iter().map(|&v| v as f64).collect();
                assert_eq!(floats(&d["fields"][f]), ours, "{ext} gzip {gzip} field {f}");
            }
        }
    }
}

const WRITE_NIBABEL: &str = r#"
import sys, nibabel as nib, numpy as np
out = sys.argv[1]
data = (np.arange(5*4*3).reshape((5, 4, 3), order='F') * 3 - 50).astype(np.int16)
aff = np.array([[0, -0.8, 0, 10.0], [0.9, 0, 0, -20.0], [0, 0, 1.5, 5.0], [0, 0, 0, 1]])
img = nib.Nifti1Image(data, aff)
img.header.set_slope_inter(0.5, 7.0)
img.set_qform(aff, code=1)
img.set_sform(aff, code=2)
nib.save(img, out)
# 4D float64 with only a qform (sform code 0)
d4 = np.random.default_rng(4).normal(size=(3, 2, 2, 3))
img4 = nib.Nifti1Image(d4, np.diag([2.0, 3.0, 4.0, 1.0]))
img4.set_sform(None, code=0)
img4.set_qform(np.diag([2.0, 3.0, 4.0, 1.0]), code=1)
nib.save(img4, out.replace('.nii', '_4d.nii'))
np.save(out.replace('.nii.gz', '_4d.npy'), d4)
"#;

#[test]
fn mdtf_reads_what_nibabel_writes() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("nib.nii.gz");
    run_python(WRITE_NIBABEL, &[p.to_str().unwrap()]);
    let v = read(&p, &ReadOptions::default()).unwrap().into_scalar().unwrap();
    assert_eq!(v.geometry.dims, [5, 4, 3]);
    for ((k, j, i), &got) in v.data.indexed_iter() {
        let stored = (i + 5 * j + 20 * k) as f32 * 3.0 - 50.0;
        assert_eq!(got, stored * 0.5 + 7.0, "scl_slope/scl_inter applied at {i},{j},{k}");
    }
    // world = affine * (i, j, k): column 0 goes to +y (0.9), column 1 to -x (0.8)
    let m = v.geometry.world_from_voxel();
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
    assert!(close(m[1][0], 0.9) && close(m[0][1], -0.8) && close(m[2][2], 1.5));
    assert!(close(m[0][3], 10.0) && close(m[1][3], -20.0) && close(m[2][3], 5.0));
    assert!(close(v.geometry.spacing[0], 0.9) && close(v.geometry.spacing[1], 0.8));

    let p4 = dir.path().join("nib_4d.nii.gz");
    let mf = read(&p4, &ReadOptions::default()).unwrap();
    assert_eq!(mf.fields.len(), 3);
    assert_eq!(mf.geometry.spacing, [2.0, 3.0, 4.0]);
    // Compare with the values numpy saved (x-fastest within each field).
    let truth = run_python(
        "import sys, numpy as np; d = np.load(sys.argv[1]); print(' '.join(repr(float(np.float32(x))) for f in range(3) for x in d[..., f].flatten(order='F')))",
        &[dir.path().join("nib_4d.npy").to_str().unwrap()],
    );
    let want: Vec<f32> = truth.split_whitespace().map(|s| s.parse().unwrap()).collect();
    let got: Vec<f32> = mf.fields.iter().flat_map(|f| f.data.iter().copied()).collect();
    assert_eq!(got, want);
}

const WRITE_PYNRRD: &str = r#"
import sys, nrrd, numpy as np
d = sys.argv[1]
vol = (np.arange(4*3*2).reshape((4, 3, 2), order='F') * 1000 - 7000).astype('>i4')
# Slicer/ITK style: LPS, space directions, kinds, big endian, gzip, attached
nrrd.write(d + '/lps.nrrd', vol, {'space': 'left-posterior-superior', 'kinds': ['domain'] * 3,
  'space directions': np.array([[-0.5, 0, 0], [0, -0.5, 0], [0, 0, 1.25]]), 'space origin': np.array([4.0, 5.0, -6.0]),
  'encoding': 'gzip', 'endian': 'big'})
# Teem style detached header with spacings only, raw little endian float
f = (np.arange(4*3*2).reshape((4, 3, 2), order='F') / 8.0).astype('<f4')
nrrd.write(d + '/teem.nhdr', f, {'spacings': [0.25, 0.5, 2.0], 'kinds': ['space'] * 3, 'encoding': 'raw'}, detached_header=True)
# 4D with a leading vector axis, as Teem writes gradients
g = np.stack([f, 2 * f, 3 * f]).astype('<f4')
nrrd.write(d + '/vec.nrrd', g, {'kinds': ['3-vector', 'domain', 'domain', 'domain'], 'space': 'right-anterior-superior',
  'space directions': np.array([[np.nan] * 3, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), 'encoding': 'raw'})
"#;

#[test]
fn mdtf_reads_what_pynrrd_writes_with_teem_conventions() {
    let dir = tempfile::tempdir().unwrap();
    run_python(WRITE_PYNRRD, &[dir.path().to_str().unwrap()]);
    let ro = ReadOptions::default();
    let v = read(&dir.path().join("lps.nrrd"), &ro).unwrap().into_scalar().unwrap();
    for ((k, j, i), &got) in v.data.indexed_iter() {
        assert_eq!(got, ((i + 4 * j + 12 * k) * 1000) as f32 - 7000.0);
    }
    // LPS (-0.5 along L = +0.5 along R): RAS directions are +x, +y; origin flips x and y.
    assert_eq!(v.geometry.spacing, [0.5, 0.5, 1.25]);
    assert_eq!(v.geometry.directions[0], [1.0, 0.0, 0.0]);
    assert_eq!(v.geometry.origin, [-4.0, -5.0, -6.0]);

    let t = read(&dir.path().join("teem.nhdr"), &ro).unwrap().into_scalar().unwrap();
    assert_eq!(t.geometry.spacing, [0.25, 0.5, 2.0]);
    assert_eq!(t.data[[1, 2, 3]], (3 + 4 * 2 + 12) as f32 / 8.0);

    let g = read(&dir.path().join("vec.nrrd"), &ro).unwrap();
    assert_eq!(g.fields.len(), 3);
    for (f, field) in g.fields.iter().enumerate() {
        assert_eq!(field.data, t.data.mapv(|x| x * (f + 1) as f32), "field {f}");
    }
}

#[test]
fn synth_and_convert_output_open_in_both_python_readers() {
    let dir = tempfile::tempdir().unwrap();
    let nii = dir.path().join("s.nii.gz");
    let nrrd = dir.path().join("s.nhdr");
    mdtf_ok(&[
        "synth",
        "erf-sphere",
        "-o",
        nii.to_str().unwrap(),
        "--size",
        "12,10,8",
        "--spacing",
        "1,1,2",
        "--sigma",
        "0.5",
        "--type",
        "u8",
        "-q",
    ]);
    mdtf_ok(&["convert", nii.to_str().unwrap(), nrrd.to_str().unwrap(), "--type", "u8", "-q"]);
    let a = dump(DUMP_NIBABEL, &nii);
    let b = dump(DUMP_PYNRRD, &nrrd);
    assert_eq!(a["fields"][0], b["fields"][0]);
    let ours = read(&nii, &ReadOptions::default()).unwrap();
    let mine: Vec<f64> = ours.fields[0].data.iter().map(|&v| v as f64).collect();
    assert_eq!(floats(&a["fields"][0]), mine);
    assert!(mine.contains(&255.0) && mine.contains(&0.0));
}

#[test]
fn pynrrd_opens_pack_textures_with_values_intact() {
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
    mdtf_ok(&["pack", "--profile", "slicer-3dtf", s.to_str().unwrap(), "-o", pack.to_str().unwrap(), "-q"]);
    let d = dump(DUMP_PYNRRD, &pack.join("data.nhdr"));
    assert_eq!(d["type"], "uint8");
    assert_eq!(d["sizes"], serde_json::json!([4, 24, 24, 24]));
    let raw = std::fs::read(pack.join("data.raw")).unwrap();
    for comp in 0..4 {
        let theirs = floats(&d["fields"][comp]);
        let ours: Vec<f64> = raw.iter().skip(comp).step_by(4).map(|&b| b as f64).collect();
        assert_eq!(theirs, ours, "component {comp}");
    }
    // and mdtf's own reader agrees
    let mf = read(&pack.join("data.nhdr"), &ReadOptions::default()).unwrap();
    assert_eq!(mf.fields.len(), 4);
    assert_eq!(mf.fields[1].data.iter().map(|&v| v as f64).collect::<Vec<_>>(), floats(&d["fields"][1]));
}

/// Python shared by the meshio scripts (run as `TET_GRID_PY` + script):
/// `tet_grid(n, step, jitter, seed)` gives the points of an n^3 grid of
/// spacing `step`, each moved by up to `jitter`, and its cubes cut into six
/// tetrahedra each.
const TET_GRID_PY: &str = r#"
import sys, json, meshio, numpy as np
def tet_grid(n, step, jitter, seed):
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing='ij'), -1).reshape(-1, 3).astype(float)
    pts = g * step + rng.uniform(-jitter, jitter, g.shape)
    idx = lambda i, j, k: (i * n + j) * n + k
    tets = []
    for i in range(n - 1):
        for j in range(n - 1):
            for k in range(n - 1):
                c = [idx(i + (m >> 2 & 1), j + (m >> 1 & 1), k + (m & 1)) for m in range(8)]
                for t in ([0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]):
                    tets.append([c[v] for v in t])
    return pts, np.array(tets)
"#;

/// Writes a mesh with meshio: tetrahedra, one triangle, a linear scalar s, a
/// second scalar and a vector array, in the format and options given.
const MESHIO_WRITE: &str = r#"
pts, tets = tet_grid(4, [1.0, 1.5, 0.75], 0.1, 7)
s = 2.0 * pts[:, 0] - 3.0 * pts[:, 1] + 0.5 * pts[:, 2] + 10.0
m = meshio.Mesh(pts, [("tetra", np.array(tets)), ("triangle", np.array([[0, 1, 2]]))],
                point_data={"s": s, "temperature": s * 0 + 1.0, "velocity": pts * 2.0})
kw = {}
if sys.argv[2] == "ascii": kw["binary"] = False
if sys.argv[2] == "raw": kw["compression"] = None
m.write(sys.argv[1], **kw)
"#;

/// Reads a mesh with meshio and prints points, tetra cells and point arrays as JSON.
const MESHIO_DUMP: &str = r#"
import sys, json, meshio, numpy as np
m = meshio.read(sys.argv[1])
tets = [c.data.tolist() for c in m.cells if c.type == "tetra"]
print(json.dumps({"points": m.points.tolist(), "tets": tets[0] if tets else [],
  "arrays": {k: np.asarray(v).tolist() for k, v in m.point_data.items()}}))
"#;

#[test]
fn meshio_meshes_round_trip_through_mdtf_tetra() {
    let dir = tempfile::tempdir().unwrap();
    for (name, mode) in [
        ("m.vtu", "default"),
        ("m_raw.vtu", "raw"),
        ("m_ascii.vtu", "ascii"),
        ("m.vtk", "default"),
        ("m_ascii.vtk", "ascii"),
    ] {
        let input = dir.path().join(name);
        run_python(&format!("{TET_GRID_PY}{MESHIO_WRITE}"), &[input.to_str().unwrap(), mode]);
        let pack = dir.path().join(format!("pack_{name}"));
        mdtf_ok(&[
            "tetra",
            input.to_str().unwrap(),
            "-o",
            pack.to_str().unwrap(),
            "--scalar",
            "s",
            "--tables",
            "front-back",
            "--fb-size",
            "8,8,8",
            "-q",
        ]);
        let theirs = dump(MESHIO_DUMP, &input);
        let ours = dump(MESHIO_DUMP, &pack.join("mesh.vtu"));
        assert_eq!(ours["points"], theirs["points"], "{name}: points");
        assert_eq!(ours["tets"], theirs["tets"], "{name}: tetrahedra");
        for array in ["s", "temperature", "velocity"] {
            assert_eq!(ours["arrays"][array], theirs["arrays"][array], "{name}: {array}");
        }
        // the added arrays: s is linear, so every vertex gradient is exactly (2, -3, 0.5)
        let g = floats(&ours["arrays"]["g"]);
        let expected = (4.0f64 + 9.0 + 0.25).sqrt();
        assert_eq!(g.len(), 64, "{name}");
        assert!(g.iter().all(|x| (x - expected).abs() < 1e-4), "{name}: g {g:?}");
        let grad = ours["arrays"]["gradient"].as_array().unwrap();
        assert!((grad[5][1].as_f64().unwrap() + 3.0).abs() < 1e-4, "{name}: gradient {:?}", grad[5]);
        // the manifest says what was skipped
        let manifest: Value = serde_json::from_slice(&std::fs::read(pack.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(manifest["profile"], "projected-tetrahedra");
        assert_eq!(manifest["mesh"]["tetrahedra"], 162, "{name}");
        assert_eq!(manifest["mesh"]["skipped_cells"]["Triangle"], 1, "{name}");
    }
}

/// Writes a mesh with meshio whose only scalar is a cell array (a material
/// id per tetrahedron, as FE and CFD meshes carry), and prints with numpy the
/// volume-weighted mean of the cells around each point, the reference.
const MESHIO_CELL_DATA: &str = r#"
pts, tets = tet_grid(5, 2.0, 0.2, 3)
centres = pts[tets].mean(axis=1)
material = np.where(np.linalg.norm(centres - 4.0, axis=1) < 3.0, 7.0, 1.0)
m = meshio.Mesh(pts, [("tetra", tets)], cell_data={"material": [material]})
m.write(sys.argv[1], **({"binary": False} if sys.argv[1].endswith(".vtk") else {}))
a, b, c, d = (pts[tets[:, q]] for q in range(4))
vol = np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))) / 6.0
num, den = np.zeros(len(pts)), np.zeros(len(pts))
for q in range(4):
    np.add.at(num, tets[:, q], vol * material)
    np.add.at(den, tets[:, q], vol)
print(json.dumps((num / den).tolist()))
"#;

#[test]
fn a_mesh_with_only_a_cell_scalar_is_meshed_from_its_volume_weighted_point_means_and_previewed() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["cells.vtu", "cells.vtk"] {
        let input = dir.path().join(name);
        let want = floats(
            &serde_json::from_str(&run_python(&format!("{TET_GRID_PY}{MESHIO_CELL_DATA}"), &[input.to_str().unwrap()]))
                .unwrap(),
        );
        // info lists the cell array; run points to mdtf tetra
        let info = mdtf_ok(&["info", input.to_str().unwrap()]);
        assert!(info.contains("cell arrays: 1") && info.contains("material: 1 component(s)"), "{info}");
        let pipeline = mdtf_e2e::shipped_pipeline("projected-tetrahedra");
        let out = dir.path().join(format!("run_{name}"));
        let run = ["run", pipeline.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        let err = mdtf_e2e::mdtf_err(&run);
        assert!(err.contains("is a mesh") && err.contains("mdtf tetra"), "{err}");
        let pack = dir.path().join(format!("pack_{name}"));
        let said =
            mdtf_e2e::mdtf(&["tetra", input.to_str().unwrap(), "-o", pack.to_str().unwrap(), "--fb-size", "8,8,8"]);
        assert!(said.status.success(), "{}", String::from_utf8_lossy(&said.stderr));
        assert!(String::from_utf8_lossy(&said.stderr).contains("cell array 'material'"), "{name}: says so");
        let got = floats(&dump(MESHIO_DUMP, &pack.join("mesh.vtu"))["arrays"]["material"]);
        assert_eq!(got.len(), want.len(), "{name}");
        for (p, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!((g - w).abs() <= 1e-5 * w.abs().max(1.0), "{name}: point {p}: {g} vs numpy's {w}");
        }
        // the pack previews with the default (s, g) TF written beside it
        let picture = dir.path().join(format!("{name}.png"));
        mdtf_ok(&["preview", pack.to_str().unwrap(), "-o", picture.to_str().unwrap(), "-q"]);
        let (_, _, rgb) = mdtf_e2e::read_rgb_png(&picture);
        let lit = rgb.chunks_exact(3).filter(|p| p.iter().any(|&c| c > 10)).count();
        assert!(lit * 50 >= rgb.len() / 3, "{name}: {lit} pixels lit");
    }
}

/// Writes with nibabel into argv[1] `oblique.nii.gz` (axes rotated 30 degrees about z and 20 about
/// x, spacing 1 x 1.2 x 1.5) and `flipped.nii.gz` (x reversed) holding one volume without symmetry:
/// an off-centre ellipsoid and a small ball beside it.
const ORIENTED_VOLUMES_PY: &str = r#"
import sys, math
import numpy as np, nibabel as nib
erf = np.vectorize(math.erf)
n = 48
z, y, x = np.meshgrid(np.arange(32), np.arange(40), np.arange(n), indexing='ij')
# an off-centre ellipsoid and a small ball beside it: no symmetry
d = np.sqrt(((x - 30) / 14.0) ** 2 + ((y - 18) / 7.0) ** 2 + ((z - 14) / 6.0) ** 2)
v = 255 * 0.5 * (1 + erf((1 - d) * 6 / np.sqrt(2) / 1.5))
b = np.sqrt((x - 10) ** 2 + (y - 30) ** 2 + (z - 20) ** 2)
v = np.maximum(v, 255 * 0.5 * (1 + erf((5 - b) / np.sqrt(2) / 1.2)))
data = np.transpose(v, (2, 1, 0)).astype(np.float32)
def rot(ax, deg):
    t = np.radians(deg); c, s = np.cos(t), np.sin(t)
    m = np.eye(3); i, j = [(1, 2), (0, 2), (0, 1)][ax]
    m[i, i] = c; m[j, j] = c; m[i, j] = -s; m[j, i] = s
    return m
a = np.eye(4); a[:3, :3] = rot(2, 30) @ rot(0, 20) @ np.diag([1.0, 1.2, 1.5]); a[:3, 3] = [-20, 5, 7]
nib.save(nib.Nifti1Image(data, a), sys.argv[1] + '/oblique.nii.gz')
f = np.eye(4); f[:3, :3] = np.diag([-1.0, 1.0, 1.0]); f[:3, 3] = [47, 0, 0]
nib.save(nib.Nifti1Image(data, f), sys.argv[1] + '/flipped.nii.gz')
"#;

#[test]
fn the_mesh_preview_of_a_volume_sees_it_as_the_volume_preview_does_on_oblique_and_flipped_grids() {
    let dir = tempfile::tempdir().unwrap();
    run_python(ORIENTED_VOLUMES_PY, &[dir.path().to_str().unwrap()]);
    let foreground = |pipeline: &str, input: &Path| -> Vec<bool> {
        let out = dir.path().join(format!("{pipeline}-{}", input.file_name().unwrap().to_str().unwrap()));
        let p = mdtf_e2e::shipped_pipeline(pipeline);
        mdtf_ok(&["run", p.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
        let (_, _, rgb) = mdtf_e2e::read_rgb_png(&out.join("preview.png"));
        rgb.chunks_exact(3).map(|p| p.iter().any(|&c| c > 10)).collect()
    };
    for name in ["oblique.nii.gz", "flipped.nii.gz"] {
        let input = dir.path().join(name);
        // gaussian-tf draws the same TGTF at the same boundary as the mesh's default (s, g) TF
        let (volume, mesh) = (foreground("gaussian-tf", &input), foreground("projected-tetrahedra", &input));
        let both = volume.iter().zip(&mesh).filter(|(a, b)| **a && **b).count();
        let either = volume.iter().zip(&mesh).filter(|(a, b)| **a || **b).count();
        let iou = both as f64 / either.max(1) as f64;
        assert!(iou >= 0.9, "{name}: foreground IoU {iou} of the volume and mesh previews");
    }
}

#[test]
fn nibabel_opens_the_nifti_copies_of_pack_textures() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.nii.gz");
    let pack = dir.path().join("pack");
    let (s_str, pack_str) = (s.to_str().unwrap(), pack.to_str().unwrap());
    mdtf_ok(&["synth", "erf-sphere", "-o", s_str, "--size", "20", "--radius", "6", "--sigma", "1.5", "-q"]);
    mdtf_ok(&["pack", "--profile", "slicer-3dtf", s_str, "-o", pack_str, "--nifti", "-q"]);
    let manifest: Value = serde_json::from_slice(&std::fs::read(pack.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["textures"][0]["nifti"], "data.nii");
    let d = dump(DUMP_NIBABEL, &pack.join("data.nii"));
    assert_eq!(d["shape"], serde_json::json!([20, 20, 20, 4]));
    assert_eq!(d["dtype"], "uint8");
    let raw = std::fs::read(pack.join("data.raw")).unwrap();
    for comp in 0..4 {
        let ours: Vec<f64> = raw.iter().skip(comp).step_by(4).map(|&b| b as f64).collect();
        assert_eq!(floats(&d["fields"][comp]), ours, "component {comp}");
    }
    // the geometry is the volume's
    let src = dump(DUMP_NIBABEL, &s);
    assert_eq!(d["affine"], src["affine"]);
    let e = mdtf_volume::read(&pack.join("data.nii"), &ReadOptions::default()).unwrap();
    assert_eq!(e.fields.len(), 4);
}
