//! OME-Zarr interop: stores written by mdtf read back bit-exactly in
//! zarr-python and validate with ome-zarr-models; stores written by
//! zarr-python (Zarr v2 with NGFF 0.4, v3 with 0.5, sharded or not, chunks
//! that do not divide the shape, several levels) read correctly in mdtf,
//! geometry included; the CLI converts both ways and never replaces a store
//! it did not make; a run reads a store by slabs with the same outputs.

use mdtf_e2e::{mdtf, mdtf_ok, run_python, shipped_pipeline};
use mdtf_volume::{Field, Geometry, MultiField, ReadOptions, SampleType, WriteOptions, read_with_info, write};
use ndarray::Array3;
use serde_json::Value;
use std::path::Path;

/// Validates a store with ome-zarr-models and dumps its level 0 as zarr-python reads it.
const DUMP_ZARR_PYTHON: &str = r#"
import sys, json, zarr, numpy as np, ome_zarr_models
g = zarr.open_group(sys.argv[1], mode='r')
model = ome_zarr_models.open_ome_zarr(g)
ms = g.attrs['ome']['multiscales'][0]
a = g[ms['datasets'][0]['path']]
data = a[:]
print(json.dumps({"model": type(model).__name__, "version": g.attrs['ome']['version'],
  "shape": list(data.shape), "dtype": str(data.dtype), "dims": list(a.metadata.dimension_names),
  "axes": [x['name'] for x in ms['axes']], "transforms": ms['datasets'][0]['coordinateTransformations'],
  "shards": list(a.shards or []), "data": data.astype(np.float64).ravel().tolist()}))
"#;

/// Writes stores as zarr-python users do, into argv[1]; prints each one's samples.
const WRITE_ZARR_PYTHON: &str = r#"
import sys, os, json, numpy as np, zarr, numcodecs
root = sys.argv[1]
rng = np.random.default_rng(7)
kinds = {'t': 'time', 'c': 'channel', 'z': 'space', 'y': 'space', 'x': 'space'}
def axes(names):
    return [dict(name=n, type=kinds[n], **({'unit': 'micrometer'} if kinds[n] == 'space' else {})) for n in names]
out = {}

# NGFF 0.4 on Zarr v2: two channels of u16, two levels, blosc, chunks that do not divide the shape
g = zarr.open_group(os.path.join(root, 'v04.zarr'), mode='w', zarr_format=2)
full = rng.integers(0, 4000, size=(2, 9, 13, 11), dtype=np.uint16)
half = full[:, ::2, ::2, ::2].copy()
for path, arr in [('0', full), ('1', half)]:
    a = g.create_array(path, shape=arr.shape, dtype=arr.dtype, chunks=(1, 4, 5, 6),
                       compressors=numcodecs.Blosc(cname='lz4', clevel=5, shuffle=numcodecs.Blosc.SHUFFLE))
    a[:] = arr
g.attrs['multiscales'] = [{'version': '0.4', 'name': 'v04', 'axes': axes('czyx'), 'datasets': [
    {'path': '0', 'coordinateTransformations': [{'type': 'scale', 'scale': [1, 2.5, 0.7, 0.7]},
                                                {'type': 'translation', 'translation': [0, 10.0, -3.5, 4.0]}]},
    {'path': '1', 'coordinateTransformations': [{'type': 'scale', 'scale': [1, 5.0, 1.4, 1.4]},
                                                {'type': 'translation', 'translation': [0, 11.25, -3.15, 4.35]}]}]}]
out['v04'] = [full.astype(np.float64).ravel().tolist(), half.astype(np.float64).ravel().tolist()]

# NGFF 0.5 on Zarr v3, sharded, i16, a time axis of one point, an image-wide scale
g = zarr.open_group(os.path.join(root, 'v05_sharded.zarr'), mode='w', zarr_format=3)
arr = rng.integers(-1000, 1000, size=(1, 9, 13, 11), dtype=np.int16)
a = g.create_array('s0', shape=arr.shape, dtype=arr.dtype, shards=(1, 8, 8, 8), chunks=(1, 4, 4, 4),
                   dimension_names=list('tzyx'))
a[:] = arr
g.attrs['ome'] = {'version': '0.5', 'multiscales': [{'axes': axes('tzyx'), 'datasets': [
    {'path': 's0', 'coordinateTransformations': [{'type': 'scale', 'scale': [1.0, 0.5, 0.25, 0.125]}]}],
    'coordinateTransformations': [{'type': 'scale', 'scale': [1.0, 2.0, 2.0, 2.0]}]}]}
out['v05_sharded'] = [arr.astype(np.float64).ravel().tolist()]

# NGFF 0.5 on Zarr v3, not sharded, f64 (zstd, zarr-python's default)
g = zarr.open_group(os.path.join(root, 'v05_f64.zarr'), mode='w', zarr_format=3)
arr = rng.normal(100.0, 30.0, size=(9, 13, 11))
a = g.create_array('0', shape=arr.shape, dtype=arr.dtype, chunks=(4, 5, 6))
a[:] = arr
g.attrs['ome'] = {'version': '0.5', 'multiscales': [{'axes': axes('zyx'), 'datasets': [
    {'path': '0', 'coordinateTransformations': [{'type': 'scale', 'scale': [1.25, 0.5, 0.75]},
                                                {'type': 'translation', 'translation': [-7.0, 2.0, 0.5]}]}]}]}
out['v05_f64'] = [arr.ravel().tolist()]

# a plain Zarr v3 array, no OME metadata
a = zarr.create_array(os.path.join(root, 'plain.zarr'), shape=(5, 6, 7), dtype='float32', chunks=(2, 4, 4))
plain = rng.normal(0.0, 1.0, size=(5, 6, 7)).astype(np.float32)
a[:] = plain
out['plain'] = [plain.astype(np.float64).ravel().tolist()]

# a time series: three points in time
g = zarr.open_group(os.path.join(root, 'time.zarr'), mode='w', zarr_format=3)
a = g.create_array('0', shape=(3, 4, 5, 6), dtype='uint8', chunks=(1, 4, 5, 6))
a[:] = 1
g.attrs['ome'] = {'version': '0.5', 'multiscales': [{'axes': axes('tzyx'), 'datasets': [
    {'path': '0', 'coordinateTransformations': [{'type': 'scale', 'scale': [1.0, 1.0, 1.0, 1.0]}]}]}]}
print(json.dumps(out))
"#;

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn samples(mf: &MultiField) -> Vec<f64> {
    mf.fields.iter().flat_map(|f| f.data.iter().map(|&v| v as f64)).collect()
}

/// A grid that is not axis-aligned (x runs along world -y, y along world x).
fn oriented() -> Geometry {
    Geometry {
        dims: [70, 45, 9],
        spacing: [0.7, 0.45, 2.5],
        origin: [-12.5, 3.25, 100.0],
        directions: [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
    }
}

fn field(geo: &Geometry, ty: SampleType, salt: f32) -> Array3<f32> {
    Array3::from_shape_fn(geo.shape(), |(k, j, i)| {
        let n = (i + 70 * j + 3150 * k) as f32;
        match ty {
            SampleType::F32 => (n * 0.37 + salt).sin() * 1000.0 + 0.1,
            _ => (n * 7.0 + salt) % 65536.0,
        }
    })
}

#[test]
fn zarr_python_reads_what_mdtf_writes_bit_exactly_and_ome_zarr_models_validates_it() {
    let dir = tempfile::tempdir().unwrap();
    let axis_aligned = Geometry::new([33, 20, 70], [0.5, 0.5, 1.25]).with_origin([1.0, -2.0, 3.5]);
    for (name, geo, ty, fields) in [
        ("oriented_f32", oriented(), SampleType::F32, 1),
        ("aligned_u16", axis_aligned.clone(), SampleType::U16, 1),
        ("two_fields", axis_aligned, SampleType::F32, 2),
    ] {
        let fields: Vec<Field> = (0..fields)
            .map(|f| Field { name: format!("channel_{f}"), data: field(&geo, ty, f as f32 * 3.0) })
            .collect();
        let mf = MultiField::new(geo.clone(), fields).unwrap();
        let store = dir.path().join(format!("{name}.ome.zarr"));
        write(&store, &mf, &WriteOptions { ty, gzip: false }, &[]).unwrap();
        let d: Value = serde_json::from_str(&run_python(DUMP_ZARR_PYTHON, &[store.to_str().unwrap()])).unwrap();
        assert_eq!(d["model"], "Image", "{name}: ome-zarr-models sees an image");
        assert_eq!(d["version"], "0.5");
        let [nx, ny, nz] = geo.dims.map(|n| n as u64);
        let (shape, names): (Vec<u64>, Vec<&str>) = match mf.fields.len() {
            1 => (vec![nz, ny, nx], vec!["z", "y", "x"]),
            n => (vec![n as u64, nz, ny, nx], vec!["c", "z", "y", "x"]),
        };
        assert_eq!(d["shape"], serde_json::json!(shape), "{name}");
        assert_eq!(d["dims"], serde_json::json!(names), "{name}");
        assert_eq!(d["axes"], serde_json::json!(names), "{name}");
        assert_eq!(d["dtype"], if ty == SampleType::U16 { "uint16" } else { "float32" });
        assert!(!d["shards"].as_array().unwrap().is_empty(), "{name}: sharded");
        assert_eq!(floats(&d["data"]), samples(&mf), "{name}: zarr-python reads every sample as written");
        // scale and translation: the spacing, and the origin in the grid's own axes
        let t = &d["transforms"];
        let (scale, translation) = (floats(&t[0]["scale"]), floats(&t[1]["translation"]));
        let c = shape.len() - 3;
        assert_eq!(scale[c..], [geo.spacing[2], geo.spacing[1], geo.spacing[0]], "{name}");
        let grid_origin: Vec<f64> =
            (0..3).rev().map(|a| (0..3).map(|r| geo.directions[a][r] * geo.origin[r]).sum()).collect();
        assert_eq!(translation[c..], grid_origin[..], "{name}");
        // and back in mdtf, orientation included
        let (back, info) = read_with_info(&store, &ReadOptions::default()).unwrap();
        assert!(back.geometry.same_grid(&geo), "{name}: {:?} vs {geo:?}", back.geometry);
        assert_eq!(back.geometry.directions, geo.directions);
        assert_eq!(samples(&back), samples(&mf));
        assert_eq!(
            back.fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(),
            ["channel_0", "channel_1"][..mf.fields.len()]
        );
        assert_eq!(info.sample_type, ty);
    }
}

#[test]
fn mdtf_reads_stores_written_by_zarr_python_with_their_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let expected: Value =
        serde_json::from_str(&run_python(WRITE_ZARR_PYTHON, &[dir.path().to_str().unwrap()])).unwrap();
    let read = |name: &str, level: usize| {
        let opts = ReadOptions { level, ..Default::default() };
        read_with_info(&dir.path().join(format!("{name}.zarr")), &opts).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12);

    // v2 / NGFF 0.4: two channels, blosc, both levels with their own transforms
    let (mf, info) = read("v04", 0);
    assert_eq!((mf.geometry.dims, mf.fields.len()), ([11, 13, 9], 2));
    assert!(
        close(mf.geometry.spacing, [0.7, 0.7, 2.5]) && close(mf.geometry.origin, [4.0, -3.5, 10.0]),
        "{:?}",
        mf.geometry
    );
    assert_eq!(samples(&mf), floats(&expected["v04"][0]));
    assert_eq!((info.sample_type, info.format.as_str()), (SampleType::U16, "OME-Zarr 0.4 (Zarr v2)"));
    assert!(info.details.iter().any(|(k, v)| k == "levels" && v == "0: 11x13x9x2, 1: 6x7x5x2"), "{:?}", info.details);
    assert!(info.details.iter().any(|(k, v)| k == "space unit" && v.starts_with("micrometer")), "{:?}", info.details);
    let (coarse, _) = read("v04", 1);
    assert_eq!(coarse.geometry.dims, [6, 7, 5]);
    assert!(close(coarse.geometry.spacing, [1.4, 1.4, 5.0]) && close(coarse.geometry.origin, [4.35, -3.15, 11.25]));
    assert_eq!(samples(&coarse), floats(&expected["v04"][1]));

    // v3 / NGFF 0.5, sharded, a time axis of one point, the image-wide scale applied after the level's
    let (mf, info) = read("v05_sharded", 0);
    assert_eq!((mf.geometry.dims, mf.fields.len()), ([11, 13, 9], 1));
    assert!(close(mf.geometry.spacing, [0.25, 0.5, 1.0]), "{:?}", mf.geometry);
    assert_eq!(samples(&mf), floats(&expected["v05_sharded"][0]));
    assert_eq!((info.sample_type, info.format.as_str()), (SampleType::I16, "OME-Zarr 0.5 (Zarr v3)"));

    // f64 samples become f32
    let (mf, _) = read("v05_f64", 0);
    assert!(close(mf.geometry.spacing, [0.75, 0.5, 1.25]) && close(mf.geometry.origin, [0.5, 2.0, -7.0]));
    let want: Vec<f64> = floats(&expected["v05_f64"][0]).iter().map(|&v| v as f32 as f64).collect();
    assert_eq!(samples(&mf), want);

    // a plain array: spacing 1, said so
    let (mf, info) = read("plain", 0);
    assert_eq!((mf.geometry.dims, mf.geometry.spacing), ([7, 6, 5], [1.0; 3]));
    assert_eq!(samples(&mf), floats(&expected["plain"][0]));
    assert!(info.warnings.iter().any(|w| w.contains("without OME metadata")), "{:?}", info.warnings);

    // what mdtf cannot read is named
    let e = read_with_info(&dir.path().join("time.zarr"), &ReadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("axis t (time) has 3 points"), "{e}");
    let e = read_with_info(&dir.path().join("v04.zarr"), &ReadOptions { level: 2, ..Default::default() })
        .unwrap_err()
        .to_string();
    assert!(e.contains("input.level 2: the image has 2 level(s), 0 to 1"), "{e}");
}

#[test]
fn the_cli_converts_both_ways_and_never_replaces_a_store_it_did_not_make() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    mdtf_ok(&["synth", "erf-sphere", "--size", "24", "--type", "u16", "-o", &p("s.nii.gz"), "-q"]);
    mdtf_ok(&["convert", &p("s.nii.gz"), &p("s.ome.zarr"), "--type", "u16", "-q"]);
    mdtf_ok(&["convert", &p("s.ome.zarr"), &p("back.nii.gz"), "--type", "u16", "-q"]);
    let read = |n: &str| mdtf_volume::read(Path::new(&p(n)), &ReadOptions::default()).unwrap();
    let (a, b) = (read("s.nii.gz"), read("back.nii.gz"));
    assert!(a.geometry.same_grid(&b.geometry));
    assert_eq!(samples(&a), samples(&b));
    let info = mdtf_ok(&["info", &p("s.ome.zarr")]);
    assert!(info.contains("OME-Zarr 0.5 (Zarr v3)") && info.contains("levels:") && info.contains("24x24x24"), "{info}");
    // written again over its own store: replaced, in the input's own u16 without --type
    mdtf_ok(&["convert", &p("s.nii.gz"), &p("s.ome.zarr"), "-q"]);
    assert_eq!(read("s.ome.zarr").fields.len(), 1);
    let dtype =
        run_python("import sys, zarr; print(zarr.open_group(sys.argv[1], mode='r')['0'].dtype)", &[&p("s.ome.zarr")]);
    assert_eq!(dtype.trim(), "uint16", "the input's type kept");
    assert_eq!(samples(&read("s.ome.zarr")), samples(&read("s.nii.gz")));

    // a store another tool wrote is refused as an output, and left as it was
    run_python(WRITE_ZARR_PYTHON, &[dir.path().to_str().unwrap()]);
    let before = read("v05_f64.zarr");
    let out = mdtf(&["convert", &p("s.nii.gz"), &p("v05_f64.zarr")]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("v05_f64.zarr"), "{err}");
    assert_eq!(samples(&read("v05_f64.zarr")), samples(&before));

    // a level that does not exist is a clear error
    let e = String::from_utf8_lossy(&mdtf(&["info", &p("v04.zarr"), "--level", "3"]).stderr).into_owned();
    assert!(e.contains("the image has 2 level(s)"), "{e}");
}

#[test]
fn a_run_reads_a_store_by_slabs_with_the_outputs_of_the_nifti_input() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    mdtf_ok(&["synth", "erf-sphere", "--size", "40", "--sigma", "2", "--type", "u16", "-o", &p("s.nii"), "-q"]);
    mdtf_ok(&["convert", &p("s.nii"), &p("s.ome.zarr"), "--type", "u16", "-q"]);
    let pipeline = shipped_pipeline("slicer-3dtf");
    let pl = pipeline.to_str().unwrap();
    let keep = ["--set", "preview=false", "--set", "keep=[\"g\", \"f2\"]", "--set", "keep_format=\"ome-zarr\"", "-q"];
    let run = |input: &str, out: &str, extra: &[&str]| {
        let mut args = vec!["run", pl, "--input", input, "-o", out];
        args.extend(keep);
        args.extend(extra);
        mdtf_ok(&args);
    };
    run(&p("s.nii"), &p("whole"), &[]);
    run(&p("s.ome.zarr"), &p("slabs"), &["--slab-planes", "7"]);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("slabs/run_report.json")).unwrap()).unwrap();
    assert_eq!(report["slabs"]["count"].as_u64(), Some(6), "{report}");
    let pack = dir.path().join("whole/pack");
    let mut compared = 0;
    for entry in std::fs::read_dir(&pack).unwrap() {
        let name = entry.unwrap().file_name();
        if name == "manifest.json" {
            continue; // names its input
        }
        let a = std::fs::read(pack.join(&name)).unwrap();
        let b = std::fs::read(dir.path().join("slabs/pack").join(&name)).unwrap();
        assert!(a == b, "{name:?} differs");
        compared += 1;
    }
    assert!(compared >= 2, "the pack's textures were compared");
    // the kept channels, as OME-Zarr stores written whole and by slabs: the same samples, valid for ome-zarr-models
    for c in ["g", "f2"] {
        let stores = ["whole", "slabs"].map(|run| dir.path().join(format!("{run}/volumes/{c}.ome.zarr")));
        let [a, b] = stores.clone().map(|s| mdtf_volume::read(&s, &ReadOptions::default()).unwrap());
        assert!(a.geometry.same_grid(&b.geometry));
        assert_eq!(samples(&a), samples(&b), "{c}");
        let d: Value = serde_json::from_str(&run_python(DUMP_ZARR_PYTHON, &[stores[1].to_str().unwrap()])).unwrap();
        assert_eq!((d["model"].as_str(), floats(&d["data"])), (Some("Image"), samples(&b)), "{c}");
    }
}

#[test]
fn every_single_bit_flip_in_a_written_shard_is_caught_and_its_chunk_named() {
    // zstd's frame checksum covers each chunk's content, the shard index has its CRC32C: 40 flips
    // at positions spread over the shard (a fixed LCG, no rand crate), each read refused
    let dir = tempfile::tempdir().unwrap();
    let (input, store) = (dir.path().join("v.nii"), dir.path().join("s.ome.zarr"));
    let (i, s) = (input.to_str().unwrap(), store.to_str().unwrap());
    mdtf_ok(&["synth", "erf-sphere", "-o", i, "--size", "24", "--noise", "3", "-q"]);
    mdtf_ok(&["convert", i, s, "-q"]);
    let meta = std::fs::read_to_string(store.join("0/zarr.json")).unwrap();
    assert!(meta.contains("\"checksum\": true") || meta.contains("\"checksum\":true"), "{meta}");
    let shard = store.join("0/c/0/0/0");
    let original = std::fs::read(&shard).unwrap();
    let mut state = 12345u64;
    for k in 0..40 {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let (at, bit) = ((state >> 33) as usize % original.len(), (state >> 13) % 8);
        let mut flipped = original.clone();
        flipped[at] ^= 1 << bit;
        std::fs::write(&shard, &flipped).unwrap();
        let out = mdtf(&["info", s]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "flip {k} at byte {at} bit {bit} read back: {err}");
        assert!(err.contains("s.ome.zarr") && err.contains("chunk 0/c/0/0/0"), "flip {k}: {err}");
    }
    std::fs::write(&shard, &original).unwrap();
    mdtf_ok(&["info", s]);
}

/// Writes with zarr-python into argv[1] an OME-Zarr 0.5 store claiming 800^3 float32 voxels in
/// chunks of 64^3 of which it holds two (a constant 5 and a ramp from -20), fill value 0; runs `argv[2] info`
/// on it and prints its peak RSS (KiB), its output, and the statistics numpy computes of the whole
/// grid from what the store holds.
const SPARSE_STORE_PYTHON: &str = r#"
import sys, os, json, resource, subprocess, numpy as np, zarr
path = os.path.join(sys.argv[1], 'sparse.ome.zarr')
g = zarr.open_group(path, mode='w', zarr_format=3)
a = g.create_array('0', shape=(800, 800, 800), dtype='float32', chunks=(64, 64, 64), fill_value=0.0,
                   dimension_names=['z', 'y', 'x'])
a[0:64, 0:64, 0:64] = 5.0
ramp = np.arange(64 ** 3, dtype=np.float32).reshape(64, 64, 64) / 1000.0 - 20.0
a[64:128, 0:64, 64:128] = ramp
g.attrs['ome'] = {'version': '0.5', 'multiscales': [{'axes': [{'name': n, 'type': 'space', 'unit': 'micrometer'} for n in 'zyx'],
    'datasets': [{'path': '0', 'coordinateTransformations': [{'type': 'scale', 'scale': [1.0, 1.0, 1.0]}]}]}]}
size = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(path) for f in fs)
run = subprocess.run([sys.argv[2], 'info', path, '--bins', '4'], capture_output=True, text=True)
rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
total = 800 ** 3
s = 5.0 * 64 ** 3 + float(ramp.astype(np.float64).sum())
lo, hi = float(ramp.min()), float(ramp.max())
print(json.dumps({'bytes': size, 'rss_kib': rss, 'code': run.returncode, 'out': run.stdout, 'err': run.stderr,
                  'mean': s / total, 'min': lo, 'max': hi}))
"#;

#[test]
fn a_small_store_claiming_800_cubed_is_described_from_the_chunks_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let mdtf_bin = mdtf_e2e::mdtf_path();
    let r: Value = serde_json::from_str(&run_python(
        SPARSE_STORE_PYTHON,
        &[dir.path().to_str().unwrap(), mdtf_bin.to_str().unwrap()],
    ))
    .unwrap();
    let out = r["out"].as_str().unwrap();
    assert_eq!(r["code"], 0, "{}", r["err"]);
    assert!(r["bytes"].as_u64().unwrap() < 2 << 20, "a small store: {} bytes", r["bytes"]);
    assert!(out.contains("800x800x800 (512000000 voxels)"), "{out}");
    assert!(out.contains("chunks held: 0.1 % of the grid; the rest is the fill value 0"), "{out}");
    // the statistics of the whole claimed grid: fill value included
    let line = |key: &str| out.lines().find(|l| l.trim_start().starts_with(key)).unwrap().to_string();
    let (lo, hi) = (r["min"].as_f64().unwrap() as f32, r["max"].as_f64().unwrap() as f32);
    assert_eq!(line("range:"), format!("  range:     {lo} .. {hi}"));
    let mean: f64 = line("mean:").split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!((mean - r["mean"].as_f64().unwrap()).abs() < 1e-6, "{mean} vs {}", r["mean"]);
    let counted: u64 = out
        .lines()
        .filter(|l| l.contains(" | "))
        .map(|l| l.split('|').nth(1).unwrap().split_whitespace().next().unwrap().parse::<u64>().unwrap())
        .sum();
    assert_eq!(counted, 512_000_000, "every voxel of the grid in the histogram");
    // and at the cost of what it holds, not of the grid it claims (2 GB as f32)
    let rss_mib = r["rss_kib"].as_u64().unwrap() / 1024;
    assert!(rss_mib < 64, "peak RSS {rss_mib} MiB");
}
