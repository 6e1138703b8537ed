//! What a run says it was made from and in which units: the manifest's
//! provenance names the input given with `--input` (its path, format, grid
//! and SHA-256, checked against coreutils' `sha256sum`), the pipeline file
//! and the settings the run used, and no built-in phantom: for every
//! shipped pipeline, whole and slab by slab, and for a DICOM folder (whose
//! digest is the one of its files' names and digests, recomputed here).
//! The units the input states (a CT's HU and DICOM's mm, NIfTI's
//! `xyzt_units`, NRRD's `sample units` and `space units`) label the figures'
//! axes (the PNG's Description text and the histogram's JSON) and the report.

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

/// A CT series of 12 slices of 20 x 20 (1 mm, modality CT): a ball of 1000
/// HU in 0, written into `series`; each file's name with its digest, one
/// `name sha256` line each in name order.
fn write_ct_series(series: &Path) -> String {
    std::fs::create_dir(series).unwrap();
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
    lines
}

#[test]
fn a_dicom_folder_is_named_with_the_digest_of_its_files() {
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    let lines = write_ct_series(&series);
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

/// The Description text of a PNG.
fn png_description(path: &Path) -> String {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    info.uncompressed_latin1_text
        .iter()
        .find(|t| t.keyword == "Description")
        .map(|t| t.text.clone())
        .unwrap_or_default()
}

/// The units of the (v, g) histogram's axes, as its JSON and its figure's Description state them.
fn vg_units(out: &Path) -> (Vec<Value>, String) {
    let json: Value = serde_json::from_slice(&std::fs::read(out.join("histogram/hist_v_g.json")).unwrap()).unwrap();
    let units = json["axes"].as_array().unwrap().iter().map(|a| a["unit"].clone()).collect();
    (units, png_description(&out.join("histogram/hist_v_g.png")))
}

#[test]
fn the_units_an_input_states_label_the_figures_and_the_report() {
    let dir = tempfile::tempdir().unwrap();
    // a CT series: values in HU (modality CT), lengths in mm (DICOM's)
    let series = dir.path().join("series");
    write_ct_series(&series);
    let out = dir.path().join("ct");
    let prov = provenance("slicer-3dtf", &series, &out, &[]);
    assert_eq!(prov["input_units"], serde_json::json!({"value": "HU", "length": "mm"}));
    let (units, text) = vg_units(&out);
    assert_eq!(units, [serde_json::json!("HU"), serde_json::json!("HU/mm")]);
    assert!(text.contains("v (HU)") && text.contains("g = |grad v| (HU/mm)"), "{text}");
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    let g_row = "<tr><td>g</td><td>gradient magnitude |grad f|</td><td>HU/mm</td>";
    assert!(page.contains("values in HU; lengths in mm") && page.contains(g_row), "report.html: {page}");
    // a NIfTI whose xyzt_units say mm (mdtf synth writes NIFTI_UNITS_MM), no value unit
    let nifti = dir.path().join("sphere.nii.gz");
    mdtf_ok(&["synth", "erf-sphere", "-o", nifti.to_str().unwrap(), "--size", "24", "-q"]);
    let mut header = vec![0u8; 348];
    let gz = flate2::read::GzDecoder::new(std::fs::File::open(&nifti).unwrap());
    std::io::Read::read_exact(&mut std::io::BufReader::new(gz), &mut header).unwrap();
    assert_eq!(header[123] & 7, 2, "xyzt_units of the synth output");
    let out = dir.path().join("nifti");
    provenance("slicer-3dtf", &nifti, &out, &[]);
    let (units, text) = vg_units(&out);
    assert_eq!(units, [serde_json::json!("input units"), serde_json::json!("input units/mm")]);
    assert!(text.contains("g = |grad v| (input units/mm)"), "{text}");
    // a NRRD stating both: sample units and space units
    let nrrd = dir.path().join("sphere.nrrd");
    mdtf_ok(&["convert", nifti.to_str().unwrap(), nrrd.to_str().unwrap(), "-q"]);
    let mut header_and_data = std::fs::read(&nrrd).unwrap();
    let end = header_and_data.windows(2).position(|w| w == b"\n\n").unwrap() + 1;
    header_and_data.splice(end..end, b"sample units: HU\nspace units: \"mm\" \"mm\" \"mm\"\n".iter().copied());
    std::fs::write(&nrrd, header_and_data).unwrap();
    let out = dir.path().join("nrrd");
    provenance("distance-tf", &nrrd, &out, &[]);
    let (units, _) = vg_units(&out);
    assert_eq!(units, [serde_json::json!("HU"), serde_json::json!("HU/mm")]);
}

#[test]
fn a_one_value_profile_says_which_of_several_fields_it_read() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("three.nii.gz");
    mdtf_ok(&["synth", "multifield", "-o", input.to_str().unwrap(), "--size", "24", "-q"]);
    let warnings = |pipeline: &str| {
        let out = dir.path().join(pipeline);
        provenance(pipeline, &input, &out, &[]);
        let report: Value = serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap();
        report["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap().to_string()).collect::<Vec<_>>()
    };
    let slicer = warnings("slicer-3dtf");
    assert!(slicer.iter().any(|w| w.contains("3 fields") && w.contains("uses the first, 'field0'")), "{slicer:?}");
    let gaussian = warnings("gaussian-tf");
    assert!(!gaussian.iter().any(|w| w.contains("3 fields")), "{gaussian:?}");
}
