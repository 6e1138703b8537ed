//! What a pack says it was made from: the manifest's provenance names the
//! input given with `--input` (its path, format, grid and SHA-256, checked
//! against coreutils' `sha256sum`), the pipeline file and the settings the
//! run used, and no built-in phantom: for every shipped pipeline, whole and
//! slab by slab, and for a DICOM folder (whose digest is the one of its
//! files' names and digests, recomputed here).

use mdtf_e2e::{EXPLICIT_LE, dicom_slice, mdtf_ok, shipped_pipeline};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// `sha256sum`'s digest of `data`, hex.
fn sha256sum(data: &[u8]) -> String {
    use std::io::Write;
    let mut child = Command::new("sha256sum")
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("coreutils' sha256sum");
    child.stdin.take().unwrap().write_all(data).unwrap();
    let out = child.wait_with_output().unwrap();
    String::from_utf8(out.stdout).unwrap().split_whitespace().next().unwrap().to_string()
}

/// The provenance of the pack a run of `pipeline` on `input` writes into `out`.
fn provenance(pipeline: &str, input: &Path, out: &Path, extra: &[&str]) -> Value {
    let p = shipped_pipeline(pipeline);
    let mut args = vec!["run", p.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    args.push("-q");
    mdtf_ok(&args);
    let m: Value = serde_json::from_slice(&std::fs::read(out.join("pack/manifest.json")).unwrap()).unwrap();
    m["provenance"].clone()
}

/// The checks every run's provenance passes: the input named as given, its
/// format, grid and digest; the pipeline file; the input settings without a phantom.
fn assert_names_the_input(prov: &Value, pipeline: &str, input: &Path, format: &str, dims: [u64; 3], digest: &str) {
    let what = format!("{pipeline}: {prov}");
    assert_eq!(prov["input"], input.to_str().unwrap(), "{what}");
    assert_eq!(prov["input_sha256"], digest, "{what}");
    assert_eq!(prov["input_format"], format, "{what}");
    assert_eq!(prov["input_dims"], serde_json::json!(dims), "{what}");
    assert_eq!(prov["pipeline"], shipped_pipeline(pipeline).to_str().unwrap(), "{what}");
    let stages_input = &prov["stages"]["input"];
    assert_eq!(stages_input["file"], input.to_str().unwrap(), "{what}");
    for phantom_key in ["phantom", "size", "sigma", "noise"] {
        assert!(stages_input.get(phantom_key).is_none(), "{what}");
    }
    assert_eq!(prov["stages"]["pack"]["profile"], pipeline, "{what}");
}

#[test]
fn every_pipeline_names_the_file_it_read_whole_and_by_slabs() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.nii.gz");
    mdtf_ok(&["synth", "erf-sphere", "-o", input.to_str().unwrap(), "--size", "24", "-q"]);
    let digest = sha256sum(&std::fs::read(&input).unwrap());
    for pipeline in ["slicer-3dtf", "distance-tf", "gaussian-tf", "peak-finding", "projected-tetrahedra"] {
        let prov = provenance(pipeline, &input, &dir.path().join(pipeline), &[]);
        assert_names_the_input(&prov, pipeline, &input, "NIfTI", [24, 24, 24], &digest);
    }
    let by_slabs = provenance("distance-tf", &input, &dir.path().join("slabs"), &["--slab-planes", "8"]);
    assert_names_the_input(&by_slabs, "distance-tf", &input, "NIfTI", [24, 24, 24], &digest);
}

#[test]
fn a_dicom_folder_is_named_with_the_digest_of_its_files() {
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    std::fs::create_dir(&series).unwrap();
    let mut lines = String::new();
    for k in 0..12 {
        let name = format!("slice{k:02}.dcm");
        let mut bytes = dicom_slice(EXPLICIT_LE, 20, 20, Some(k as f64), 20 * 20 * 2);
        // a ball of 1000 in 0 (the pixel data closes the file)
        let pixels = bytes.len() - 20 * 20 * 2;
        for (i, px) in bytes[pixels..].chunks_exact_mut(2).enumerate() {
            let (x, y, z) = ((i % 20) as f64 - 9.5, (i / 20) as f64 - 9.5, k as f64 - 5.5);
            let value: i16 = if x * x + y * y + z * z < 36.0 { 1000 } else { 0 };
            px.copy_from_slice(&value.to_le_bytes());
        }
        lines.push_str(&format!("{name} {}\n", sha256sum(&bytes)));
        std::fs::write(series.join(&name), bytes).unwrap();
    }
    let prov = provenance("slicer-3dtf", &series, &dir.path().join("out"), &[]);
    assert_names_the_input(&prov, "slicer-3dtf", &series, "DICOM", [20, 20, 12], &sha256sum(lines.as_bytes()));
}

#[test]
fn a_phantom_run_names_its_phantom_and_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = shipped_pipeline("slicer-3dtf");
    let out = dir.path().join("out");
    mdtf_ok(&["run", p.to_str().unwrap(), "-o", out.to_str().unwrap(), "--set", "input.size=24", "-q"]);
    let m: Value = serde_json::from_slice(&std::fs::read(out.join("pack/manifest.json")).unwrap()).unwrap();
    let prov = &m["provenance"];
    assert!(prov["input"].is_null() && prov["input_sha256"].is_null(), "{prov}");
    assert_eq!(prov["stages"]["input"]["phantom"], "erf-sphere", "{prov}");
    assert_eq!(prov["stages"]["input"]["size"], 24, "{prov}");
    assert_eq!(prov["input_dims"], serde_json::json!([24, 24, 24]), "{prov}");
}
