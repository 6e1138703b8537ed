//! DICOM series in: series written by pydicom (oblique, shuffled, rescale
//! varying per slice, two series in a folder, a missing slice, a duplicate,
//! a copy, a gantry tilt, 12-bit samples with overlay bits, an enhanced
//! multi-frame CT), checked against the values written and against
//! SimpleITK's ImageSeriesReader (GDCM); pydicom's own test files; and the
//! MR image of ../shared/data/dicom-ts in nine transfer syntaxes.

use mdtf_e2e::{mdtf, mdtf_err, mdtf_ok, run_python};
use mdtf_volume::dicom::DicomOptions;
use mdtf_volume::{Geometry, MultiField, ReadOptions, read, read_with_info};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

struct Written {
    dir: tempfile::TempDir,
    json: Value,
}

/// The series of tests/dicom_series.py, written once for every test here.
fn written() -> &'static Written {
    static W: OnceLock<Written> = OnceLock::new();
    W.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let script = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("dicom_series.py")).unwrap();
        let json = serde_json::from_str(&run_python(&script, &[dir.path().to_str().unwrap()])).unwrap();
        Written { dir, json }
    })
}

fn case(name: &str) -> PathBuf {
    written().dir.path().join(name)
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn read_opts(series: Option<&str>, resample: bool) -> ReadOptions {
    ReadOptions { dicom: DicomOptions { series: series.map(String::from), resample }, ..Default::default() }
}

fn values(mf: &MultiField) -> Vec<f64> {
    mf.fields[0].data.iter().map(|&v| v as f64).collect()
}

fn assert_close(got: &[f64], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: sample count");
    for (i, (a, b)) in got.iter().zip(want).enumerate() {
        assert!((a - b).abs() <= tol * b.abs().max(1.0), "{what}: sample {i}: {a} vs {b}");
    }
}

/// Origin and axis directions in DICOM's LPS.
fn lps(g: &Geometry) -> ([f64; 3], [[f64; 3]; 3]) {
    let flip = |v: [f64; 3]| [-v[0], -v[1], v[2]];
    (flip(g.origin), [flip(g.directions[0]), flip(g.directions[1]), flip(g.directions[2])])
}

/// Geometry and values equal SimpleITK's reading of the same files.
fn assert_same_as_sitk(mf: &MultiField, sitk: &Value, what: &str) {
    let g = &mf.geometry;
    let size: Vec<usize> = sitk["size"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
    assert_eq!(g.dims.to_vec(), size, "{what}: dims");
    let (origin, dirs) = lps(g);
    assert_close(&origin, &numbers(&sitk["origin"]), 1e-6, &format!("{what}: origin"));
    assert_close(&g.spacing, &numbers(&sitk["spacing"]), 1e-6, &format!("{what}: spacing"));
    let d = numbers(&sitk["direction"]);
    for r in 0..3 {
        for a in 0..3 {
            assert!(
                (dirs[a][r] - d[r * 3 + a]).abs() < 1e-6,
                "{what}: direction[{r}][{a}] {} vs {}",
                dirs[a][r],
                d[r * 3 + a]
            );
        }
    }
    assert_close(&values(mf), &numbers(&sitk["values"]), 1e-6, &format!("{what}: values"));
}

#[test]
fn an_oblique_shuffled_series_matches_simpleitk_and_the_values_written() {
    let w = written();
    let mf = read(&case("oblique"), &ReadOptions::default()).unwrap();
    assert_same_as_sitk(&mf, &w.json["oblique"]["sitk"], "oblique");
    assert_close(&values(&mf), &numbers(&w.json["oblique"]["truth"]), 1e-6, "oblique truth");
    // the same files named by a list, in another order, give the same volume
    let listed = read(&case("oblique.txt"), &ReadOptions::default()).unwrap();
    assert_eq!(listed, mf);
    // and the geometry is written through to another format
    let out = tempfile::tempdir().unwrap();
    let nii = out.path().join("ct.nii.gz");
    mdtf_ok(&["convert", case("oblique").to_str().unwrap(), nii.to_str().unwrap()]);
    let back = read(&nii, &ReadOptions::default()).unwrap();
    assert!(back.geometry.same_grid(&mf.geometry), "{:?} vs {:?}", back.geometry, mf.geometry);
    assert_eq!(values(&back), values(&mf));
}

#[test]
fn info_shows_the_series_but_never_the_patient() {
    let out = mdtf(&["info", case("oblique").to_str().unwrap()]);
    assert!(out.status.success());
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    for shown in [
        "DICOM series of 9 files",
        "modality:    CT",
        "\"test\"",
        "Explicit VR Little Endian",
        "rescale:     per slice",
    ] {
        assert!(text.contains(shown), "missing {shown}:\n{text}");
    }
    for secret in ["Doe", "Jane", "PID-93731", "19230417"] {
        assert!(!text.contains(secret), "{secret} printed:\n{text}");
    }
    // the listing of several series prints no patient attribute either
    let err = mdtf_err(&["info", case("two").to_str().unwrap()]);
    assert!(!err.contains("Doe") && !err.contains("PID-93731"), "{err}");
}

#[test]
fn several_series_are_listed_and_chosen_by_number_or_uid() {
    let w = written();
    let err = mdtf_err(&["info", case("two").to_str().unwrap()]);
    assert!(err.contains("2 DICOM series") && err.contains("--series"), "{err}");
    assert!(err.contains("series 7: \"first\", CT, 10x12 pixels, 3 images"), "{err}");
    assert!(err.contains("series 9: \"second\", CT, 10x12 pixels, 4 images"), "{err}");
    let nine = read(&case("two"), &read_opts(Some("9"), false)).unwrap();
    assert_close(&values(&nine), &numbers(&w.json["two"]["truth9"]), 1e-6, "series 9");
    let uid = w.json["two"]["uid9"].as_str().unwrap();
    assert_eq!(read(&case("two"), &read_opts(Some(uid), false)).unwrap(), nine);
    let seven = read(&case("two"), &read_opts(Some("7"), false)).unwrap();
    assert_close(&values(&seven), &numbers(&w.json["two"]["truth7"]), 1e-6, "series 7");
    let err = read(&case("two"), &read_opts(Some("8"), false)).unwrap_err().to_string();
    assert!(err.contains("no DICOM series has the number or UID '8'") && err.contains("series 9"), "{err}");
    // the command line takes the same choice
    let text = mdtf_ok(&["info", case("two").to_str().unwrap(), "--series", "9"]);
    assert!(text.contains("10x12x4"), "{text}");
}

#[test]
fn a_missing_slice_is_refused_or_interpolated_on_request() {
    let w = written();
    // described by info as resampling would make it; refused where it would be read as data
    let said = mdtf_ok(&["info", case("missing").to_str().unwrap()]);
    assert!(said.contains("slice spacing varies: 2.0 mm x5, 4.0 mm") && said.contains("10x12x8"), "{said}");
    let out = tempfile::tempdir().unwrap();
    let err = mdtf_err(&["convert", case("missing").to_str().unwrap(), out.path().join("m.nrrd").to_str().unwrap()]);
    assert!(err.contains("slice spacing varies: 2.0 mm x5, 4.0 mm") && err.contains("--resample"), "{err}");
    let (mf, info) = read_with_info(&case("missing"), &read_opts(None, true)).unwrap();
    assert_eq!(mf.geometry.dims, [10, 12, 8]);
    assert_eq!(mf.geometry.spacing[2], 2.0);
    // values are linear along z, so linear interpolation restores the slice exactly
    assert_close(&values(&mf), &numbers(&w.json["missing"]["truth_full"]), 1e-6, "resampled");
    assert!(
        info.warnings.iter().any(|m| m.contains("resampled onto a regular grid of 8 slices at 2.0 mm")),
        "{:?}",
        info.warnings
    );
    let full = read(&case("missing-full"), &ReadOptions::default()).unwrap();
    assert!(full.geometry.same_grid(&mf.geometry));
}

#[test]
fn two_images_at_one_place_are_refused_and_a_copied_file_is_read_once() {
    let w = written();
    let err = mdtf_err(&["info", case("dup").to_str().unwrap()]);
    assert!(err.contains("two images lie at the same position") && err.contains("another-at-2.dcm"), "{err}");
    let out = mdtf(&["info", case("copy").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    // which of the two is named first follows path order, and the original's name is random
    let said = err.lines().find(|l| l.contains("holds the same image as")).unwrap_or_default();
    assert!(out.status.success() && said.contains("copy-of-1.dcm") && said.contains("read once"), "{err}");
    assert_eq!(err.matches("holds the same image as").count(), 1, "{err}");
    let mf = read(&case("copy"), &ReadOptions::default()).unwrap();
    assert_close(&values(&mf), &numbers(&w.json["copy"]["truth"]), 1e-6, "copy");
}

#[test]
fn a_gantry_tilt_is_refused_or_shifted_back_onto_the_slice_normal() {
    let w = written();
    // refused where it would be read as data, with the option named as each command takes it
    let p = mdtf_e2e::shipped_pipeline("slicer-3dtf");
    let (tilt, out) = (case("tilt"), tempfile::tempdir().unwrap());
    let run = ["run", p.to_str().unwrap(), "--input", tilt.to_str().unwrap(), "-o", out.path().to_str().unwrap()];
    let err = mdtf_err(&[&run[..], &["-q"]].concat());
    assert!(err.contains("gantry tilt 14.0 degrees") && err.contains("--set input.resample=true"), "{err}");
    // described by info, as resampling would make it
    let said = mdtf_ok(&["info", tilt.to_str().unwrap()]);
    assert!(said.contains("gantry tilt 14.0 degrees") && said.contains("dims:        16x12x6"), "{said}");
    let mf = read(&case("tilt"), &read_opts(None, true)).unwrap();
    let g = &mf.geometry;
    assert_eq!(g.dims, [16, 12, 6]);
    // the output axes are the image plane and its normal, whatever the tilt
    let (origin, dirs) = lps(g);
    let rot: Vec<Vec<f64>> = w.json["tilt"]["rot"].as_array().unwrap().iter().map(numbers).collect();
    for a in 0..3 {
        for r in 0..3 {
            assert!((dirs[a][r] - rot[r][a]).abs() < 1e-9, "axis {a}");
        }
    }
    // the written values are 10x + 4y - 3z + 100 of the LPS position (rounded
    // to integers), so every interpolated voxel inside the stack shows it
    let data = &mf.fields[0].data;
    for k in 0..6 {
        for j in 0..12 {
            for i in 5..15 {
                let p: Vec<f64> = (0..3)
                    .map(|r| {
                        origin[r]
                            + i as f64 * g.spacing[0] * dirs[0][r]
                            + j as f64 * g.spacing[1] * dirs[1][r]
                            + k as f64 * g.spacing[2] * dirs[2][r]
                    })
                    .collect();
                let want = 10.0 * p[0] + 4.0 * p[1] - 3.0 * p[2] + 100.0;
                let got = data[[k, j, i]] as f64;
                assert!((got - want).abs() <= 0.5 + 1e-3, "voxel ({i},{j},{k}): {got} vs {want}");
            }
        }
    }
}

#[test]
fn stored_bits_enhanced_frames_and_pydicoms_files_read_as_pydicom_decodes_them() {
    let w = written();
    let mf = read(&case("bits12"), &ReadOptions::default()).unwrap();
    assert_eq!(values(&mf), numbers(&w.json["bits12"]["truth"]));

    let e = &w.json["enhanced"];
    let mf = read(&case("enhanced.dcm"), &ReadOptions::default()).unwrap();
    assert_eq!(mf.geometry.dims, [3, 4, 5]);
    assert_close(&mf.geometry.spacing, &[0.9, 0.7, 1.25], 1e-9, "enhanced spacing");
    let (origin, dirs) = lps(&mf.geometry);
    assert_close(&origin, &numbers(&e["origin_lps"]), 1e-9, "enhanced origin");
    for (a, want) in e["dirs_lps"].as_array().unwrap().iter().enumerate() {
        assert_close(&dirs[a], &numbers(want), 1e-9, "enhanced axis");
    }
    assert_eq!(values(&mf), numbers(&e["truth"]));

    let data = PathBuf::from(w.json["pydicom_data"].as_str().unwrap());
    for name in ["CT_small.dcm", "MR_small.dcm", "rtdose.dcm"] {
        let mf = read(&data.join(name), &ReadOptions::default()).unwrap();
        assert_close(&values(&mf), &numbers(&w.json[name]["values"]), 1e-6, name);
    }
    let mr = read(&data.join("MR_small.dcm"), &ReadOptions::default()).unwrap();
    for variant in [
        "MR_small_RLE.dcm",
        "MR_small_jp2klossless.dcm",
        "MR_small_bigendian.dcm",
        "MR_small_implicit.dcm",
        "MR_small_jpeg_ls_lossless.dcm",
    ] {
        assert_eq!(read(&data.join(variant), &ReadOptions::default()).unwrap(), mr, "{variant}");
    }
    let err = mdtf_err(&["info", data.join("MR_truncated.dcm").to_str().unwrap()]);
    assert!(err.contains("MR_truncated.dcm"), "{err}");
}

#[test]
fn a_dicomdir_names_its_series_as_simpleitk_reads_them() {
    let w = written();
    let dicomdir = PathBuf::from(w.json["pydicom_data"].as_str().unwrap()).join("dicomdirtests/DICOMDIR");
    let uid = w.json["dicomdir"]["uid"].as_str().unwrap();
    let mf = read(&dicomdir, &read_opts(Some(uid), false)).unwrap();
    assert_same_as_sitk(&mf, &w.json["dicomdir"]["sitk"], "DICOMDIR");
    // its "Routine Brain" series has a gap of 202.5 mm between slices 1.25 mm apart
    let brain = "1.3.6.1.4.1.5962.1.1.0.0.0.1196530851.28319.0.2";
    let err = read(&dicomdir, &read_opts(Some(brain), false)).unwrap_err().to_string();
    assert!(err.contains("slice spacing varies: 1.25 mm x2, 202.5 mm"), "{err}");
}

#[test]
fn the_mr_image_reads_the_same_in_every_decodable_transfer_syntax() {
    let dir = mdtf_e2e::shared_data("dicom-ts/In");
    assert!(
        dir.is_dir(),
        "{} is missing: the shared test data sits in ../shared/data beside the checkout (or set MDTF_SHARED_DATA)",
        dir.display()
    );
    let reference = read(&dir.join("1.dcm"), &ReadOptions::default()).unwrap();
    // a Siemens MOSAIC of 35 slices of 64 x 64, untiled
    assert_eq!(reference.geometry.dims, [64, 64, 35]);
    // the tiles hold what pydicom decodes, tile by tile
    let pydicom = run_python(
        "import sys, json, pydicom; a = pydicom.dcmread(sys.argv[1]).pixel_array.reshape(6, 64, 6, 64).transpose(0, 2, 1, 3).reshape(36, 64, 64)[:35]; print(json.dumps(a.ravel().tolist()))",
        &[dir.join("1.dcm").to_str().unwrap()],
    );
    assert_eq!(values(&reference), numbers(&serde_json::from_str(&pydicom).unwrap()), "1.dcm vs pydicom");
    // and every voxel lies where dcm2niix puts it, with its value
    let dcm2niix = read(&dir.join("../Ref/1.nii"), &ReadOptions::default()).unwrap();
    assert_same_in_world(&reference, &dcm2niix, "1.dcm vs dcm2niix's Ref/1.nii");
    // 7 and 8 are JPEG-LS (CharLS)
    for n in 2..=9 {
        let mf = read(&dir.join(format!("{n}.dcm")), &ReadOptions::default()).unwrap();
        assert_eq!(mf, reference, "{n}.dcm");
    }
}

#[test]
fn a_pipeline_reads_a_chosen_resampled_series_and_reports_the_resampling() {
    let out = tempfile::tempdir().unwrap();
    let run = out.path().join("run");
    let pipeline = Path::new(env!("CARGO_MANIFEST_DIR")).join("../pipelines/slicer-3dtf.toml");
    let input = case("missing");
    let args = |extra: &[&'static str]| -> Vec<String> {
        let mut a: Vec<String> =
            ["run", pipeline.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"]
                .iter()
                .map(|s| s.to_string())
                .collect();
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let refused = args(&[]);
    let err = mdtf_err(&refused.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(err.contains("slice spacing varies") && err.contains("resample = true"), "{err}");
    let ok = args(&["--set", "input.resample=true", "--set", "input.series=1"]);
    mdtf_ok(&ok.iter().map(String::as_str).collect::<Vec<_>>());
    let report: Value = serde_json::from_str(&std::fs::read_to_string(run.join("run_report.json")).unwrap()).unwrap();
    assert_eq!(report["dims"], serde_json::json!([10, 12, 8]));
    let warnings = report["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("resampled onto a regular grid")), "{warnings:?}");
}

/// The value of `b` at the world position of each voxel of `a`: the grids
/// must coincide up to the order and sign of their axes.
fn assert_same_in_world(a: &MultiField, b: &MultiField, what: &str) {
    let (ga, gb) = (&a.geometry, &b.geometry);
    let mb = gb.world_from_voxel();
    // b's voxel of a world point: solve the 3x3 system by Cramer's rule
    let m = [[mb[0][0], mb[0][1], mb[0][2]], [mb[1][0], mb[1][1], mb[1][2]], [mb[2][0], mb[2][1], mb[2][2]]];
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    let ma = ga.world_from_voxel();
    let (mut checked, data_a, data_b) = (0, &a.fields[0].data, &b.fields[0].data);
    for ((k, j, i), &va) in data_a.indexed_iter() {
        let p: Vec<f64> = (0..3)
            .map(|r| ma[r][0] * i as f64 + ma[r][1] * j as f64 + ma[r][2] * k as f64 + ma[r][3] - mb[r][3])
            .collect();
        let mut idx = [0usize; 3];
        for c in 0..3 {
            let mut mc = m;
            for r in 0..3 {
                mc[r][c] = p[r];
            }
            let x = det(mc) / d;
            assert!(
                (x - x.round()).abs() < 1e-3,
                "{what}: voxel ({i},{j},{k}) falls between voxels of the reference ({x})"
            );
            idx[c] = x.round() as usize;
        }
        let vb = data_b[[idx[2], idx[1], idx[0]]];
        assert!((va - vb).abs() <= 1e-3 * vb.abs().max(1.0), "{what}: voxel ({i},{j},{k}): {va} vs {vb}");
        checked += 1;
    }
    assert_eq!(checked, ga.voxel_count());
    assert_eq!(ga.voxel_count(), gb.voxel_count(), "{what}");
}

#[test]
fn an_oblique_series_matches_dcm2niix_in_world_space() {
    let w = written();
    let dcm2niix = std::process::Command::new("dcm2niix").arg("-h").output();
    assert!(
        dcm2niix.is_ok(),
        "dcm2niix is missing: install it (Debian: apt-get install dcm2niix; tests/run.sh does so as root)"
    );
    let out = tempfile::tempdir().unwrap();
    let status = std::process::Command::new("dcm2niix")
        .args([
            "-o",
            out.path().to_str().unwrap(),
            "-f",
            "ct",
            "-z",
            "n",
            "-b",
            "n",
            case("oblique-uniform").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(status.status.success(), "dcm2niix: {}", String::from_utf8_lossy(&status.stderr));
    let theirs = read(&out.path().join("ct.nii"), &ReadOptions::default()).unwrap();
    let ours = read(&case("oblique-uniform"), &ReadOptions::default()).unwrap();
    assert_close(&values(&ours), &numbers(&w.json["oblique-uniform"]["truth"]), 1e-6, "truth");
    assert_same_in_world(&ours, &theirs, "dcm2niix");
    for a in 0..3 {
        assert!((ours.geometry.spacing[a] - theirs.geometry.spacing[a]).abs() < 1e-4, "spacing {a}");
    }
}

/// Python shared by the pydicom scripts (run as `PYDICOM_CT_PY` + script):
/// `ct_dataset(syntax, series, study)` gives a CT image's dataset with its
/// file meta, identifiers and modality; pixels and geometry are the script's.
const PYDICOM_CT_PY: &str = r#"
import json, os, sys
import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRBigEndian, ExplicitVRLittleEndian, ImplicitVRLittleEndian, generate_uid
def ct_dataset(syntax, series, study):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = syntax
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
    ds.Modality, ds.SeriesInstanceUID, ds.StudyInstanceUID = "CT", series, study
    return ds
def grey_frames(ds, rows, cols, frames, bits, signed):
    """Sets the pixel module of a grayscale image of `frames` frames (stored as all `bits`)."""
    ds.Rows, ds.Columns, ds.NumberOfFrames, ds.SamplesPerPixel, ds.PhotometricInterpretation = rows, cols, frames, 1, "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = bits, bits, bits - 1, signed
"#;

/// Writes one CT image per (transfer syntax, bits allocated, pixel representation) with pydicom
/// (values spanning the stored range, RescaleSlope 0.5 and RescaleIntercept -3) into argv[1], and
/// prints {file: values pydicom decodes, scaled} as JSON.
const SAMPLE_LAYOUTS_PY: &str = r#"
out, result = sys.argv[1], {}
for syntax, little in [(ExplicitVRLittleEndian, True), (ImplicitVRLittleEndian, True), (ExplicitVRBigEndian, False)]:
    for bits in (8, 16, 32):
        for signed in (0, 1):
            kind = {8: 'i1', 16: 'i2', 32: 'i4'}[bits] if signed else {8: 'u1', 16: 'u2', 32: 'u4'}[bits]
            info = np.iinfo(np.dtype(kind))
            # values near both ends of the stored range and between, in every byte
            lo, hi = max(info.min, -(2**31) + 1), min(info.max, 2**31 - 1)
            values = np.linspace(lo, hi, 5 * 7).round().astype(kind).reshape(5, 7)
            ds = ct_dataset(syntax, generate_uid(), generate_uid())
            ds.Rows, ds.Columns, ds.SamplesPerPixel, ds.PhotometricInterpretation = 5, 7, 1, "MONOCHROME2"
            ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = bits, bits, bits - 1, signed
            ds.PixelSpacing, ds.RescaleSlope, ds.RescaleIntercept = [1, 1], 0.5, -3
            ds.PixelData = values.astype(values.dtype.newbyteorder('<' if little else '>')).tobytes()
            name = f"{syntax.name.replace(' ', '_')}_{bits}_{'signed' if signed else 'unsigned'}.dcm"
            ds.save_as(os.path.join(out, name), implicit_vr=syntax == ImplicitVRLittleEndian, little_endian=little, enforce_file_format=True)
            back = pydicom.dcmread(os.path.join(out, name))
            result[name] = (back.pixel_array.astype(np.float64) * 0.5 - 3).ravel().tolist()
print(json.dumps(result))
"#;

#[test]
fn every_sample_width_byte_order_and_sign_reads_as_pydicom_decodes_it() {
    let dir = tempfile::tempdir().unwrap();
    let written: Value = serde_json::from_str(&run_python(
        &format!("{PYDICOM_CT_PY}{SAMPLE_LAYOUTS_PY}"),
        &[dir.path().to_str().unwrap()],
    ))
    .unwrap();
    let files = written.as_object().unwrap();
    assert_eq!(files.len(), 18, "3 transfer syntaxes x 3 widths x 2 signs");
    for (name, want) in files {
        let mf = read(&dir.path().join(name), &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        // f32 holds 24 bits: 32-bit values agree to f32's rounding
        let (got, want) = (values(&mf), numbers(want));
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= w.abs() * 1e-7 + 1e-9, "{name}: {g} vs pydicom's {w}");
        }
        assert_eq!(got.len(), want.len(), "{name}");
    }
}

/// Writes multi-frame RLE Lossless images (3 frames of 6 x 5) with pydicom's own RLE encoder into
/// argv[1], one per bits allocated (8, 16: the encoder refuses 32, which pydicom's 15-frame
/// rtdose_rle.dcm covers in tests/peer_test_data.rs) and sign, and prints {file: values pydicom decodes}.
const RLE_FRAMES_PY: &str = r#"
from pydicom.uid import RLELossless
out, result = sys.argv[1], {}
rng = np.random.default_rng(5)
for bits in (8, 16):
    for signed in (0, 1):
        kind = ('i' if signed else 'u') + str(bits // 8)
        info = np.iinfo(np.dtype(kind))
        values = rng.integers(info.min, info.max, size=(3, 5, 6), dtype=np.int64, endpoint=True).astype(kind)
        values[:, :2, :] = values[0, 0, 0]  # runs, as well as literals
        ds = ct_dataset(ExplicitVRLittleEndian, generate_uid(), generate_uid())
        grey_frames(ds, 5, 6, 3, bits, signed)
        # frames placed along the normal by offsets, as RT dose grids place theirs
        ds.PixelSpacing, ds.ImageOrientationPatient, ds.ImagePositionPatient = [1, 1], [1, 0, 0, 0, 1, 0], [0, 0, 0]
        ds.GridFrameOffsetVector = [0, 1, 2]
        ds.compress(RLELossless, values, encoding_plugin='pydicom')
        name = f"rle_{bits}_{'signed' if signed else 'unsigned'}.dcm"
        ds.save_as(os.path.join(out, name), enforce_file_format=True)
        back = pydicom.dcmread(os.path.join(out, name))
        assert back.file_meta.TransferSyntaxUID == RLELossless
        result[name] = back.pixel_array.astype(np.float64).ravel().tolist()
print(json.dumps(result))
"#;

#[test]
fn rle_frames_of_8_and_16_bits_either_sign_read_as_pydicom_decodes_them() {
    let dir = tempfile::tempdir().unwrap();
    let written: Value =
        serde_json::from_str(&run_python(&format!("{PYDICOM_CT_PY}{RLE_FRAMES_PY}"), &[dir.path().to_str().unwrap()]))
            .unwrap();
    let files = written.as_object().unwrap();
    assert_eq!(files.len(), 4, "2 widths x 2 signs");
    for (name, want) in files {
        let mf = read(&dir.path().join(name), &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(mf.geometry.dims, [6, 5, 3], "{name}");
        let want: Vec<f32> = numbers(want).iter().map(|&w| w as f32).collect();
        let got: Vec<f32> = mf.fields[0].data.iter().copied().collect();
        assert_eq!(got, want, "{name}");
    }
}

/// Writes into argv[1] a multi-frame image with no geometry at all (no position, orientation or
/// pixel spacing, as a cine or a secondary capture has): 4 frames of 6 x 5, SliceThickness 2.5 in
/// `thick.dcm` and none in `bare.dcm`; prints the values pydicom decodes, frame after frame.
const BARE_FRAMES_PY: &str = r#"
out = sys.argv[1]
values = (np.arange(4 * 5 * 6).reshape(4, 5, 6) * 7 % 1000).astype(np.uint16)
for name, thickness in [("thick.dcm", 2.5), ("bare.dcm", None)]:
    ds = ct_dataset(ExplicitVRLittleEndian, generate_uid(), generate_uid())
    grey_frames(ds, 5, 6, 4, 16, 0)
    if thickness is not None:
        ds.SliceThickness = thickness
    ds.PixelData = values.tobytes()
    ds.save_as(os.path.join(out, name), enforce_file_format=True)
print(json.dumps(pydicom.dcmread(os.path.join(out, "bare.dcm")).pixel_array.astype(float).ravel().tolist()))
"#;

#[test]
fn a_multi_frame_image_without_geometry_stacks_its_frames_in_file_order_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let want: Value =
        serde_json::from_str(&run_python(&format!("{PYDICOM_CT_PY}{BARE_FRAMES_PY}"), &[dir.path().to_str().unwrap()]))
            .unwrap();
    for (name, gap, said) in
        [("thick.dcm", 2.5, "2.5 mm apart (SliceThickness)"), ("bare.dcm", 1.0, "1 mm apart (assumed)")]
    {
        let path = dir.path().join(name);
        let (mf, info) = read_with_info(&path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(mf.geometry.dims, [6, 5, 4], "{name}");
        assert_eq!(mf.geometry.spacing, [1.0, 1.0, gap], "{name}");
        assert_eq!(values(&mf), numbers(&want), "{name}: frames in file order");
        let warned = info.warnings.join("\n");
        assert!(warned.contains("the 4 frames are stacked in file order") && warned.contains(said), "{name}: {warned}");
    }
}

#[test]
fn pydicoms_big_endian_dose_grids_read_as_pydicom_decodes_them() {
    let script = "import json, sys, pydicom, os; d = os.path.join(os.path.dirname(pydicom.__file__), 'data', 'test_files'); \
                  print(json.dumps({f: os.path.join(d, f) for f in ['rtdose.dcm', 'rtdose_expb.dcm', 'rtdose_1frame.dcm', 'rtdose_expb_1frame.dcm']}))";
    let files: Value = serde_json::from_str(&run_python(script, &[])).unwrap();
    for (name, path) in files.as_object().unwrap() {
        let path = path.as_str().unwrap();
        let want = run_python(
            "import json, sys, pydicom; d = pydicom.dcmread(sys.argv[1]); print(json.dumps((d.pixel_array * float(d.DoseGridScaling)).ravel().tolist()))",
            &[path],
        );
        let mf = read(Path::new(path), &ReadOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let (got, want) = (values(&mf), numbers(&serde_json::from_str(&want).unwrap()));
        assert_eq!(got.len(), want.len(), "{name}");
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= w.abs() * 1e-6, "{name}: {g} vs pydicom's {w}");
        }
    }
}

/// Writes a CT series (12 slices of 40 x 40, 1 mm) with pydicom into argv[1]: a blurred ball of
/// 1000 HU in air (-1000 HU) inside a circular field of view, -1500 (Pixel Padding Value) outside
/// it; prints the number of padded voxels, then for kernel radii 1 to 6 the number of voxels
/// within that many voxels of a padded one along each axis (a box): those whose derivatives read
/// padding.
const PADDED_SERIES_PY: &str = r#"
from math import erf
out = sys.argv[1]
nx, ny, nz = 40, 40, 12
z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
r = np.sqrt((x - 19.5) ** 2 + (y - 19.5) ** 2 + (z - 5.5) ** 2)
verf = np.vectorize(erf)
hu = -1000 + 2000 * 0.5 * (1 + verf((8.0 - r) / (np.sqrt(2) * 1.5)))
padded = np.hypot(x - 19.5, y - 19.5) > 18.0
hu = np.where(padded, -1500, np.round(hu)).astype(np.int16)
series, study = generate_uid(), generate_uid()
for k in range(nz):
    ds = ct_dataset(ExplicitVRLittleEndian, series, study)
    ds.SeriesNumber = 1
    ds.InstanceNumber, ds.ImagePositionPatient, ds.ImageOrientationPatient = k + 1, [0, 0, float(k)], [1, 0, 0, 0, 1, 0]
    ds.Rows, ds.Columns, ds.SamplesPerPixel, ds.PhotometricInterpretation = ny, nx, 1, "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
    ds.PixelSpacing, ds.SliceThickness, ds.RescaleSlope, ds.RescaleIntercept = [1, 1], 1, 1, 0
    ds.add_new(0x00280120, "SS", -1500)
    ds.PixelData = hu[k].tobytes()
    ds.save_as(os.path.join(out, f"{k:02d}.dcm"), enforce_file_format=True)
# the same scan as a scanner with no field of view would store it: air where the padding is
import nibabel as nib
air = np.where(padded, -1000, hu).astype(np.int16)
nib.save(nib.Nifti1Image(np.transpose(air, (2, 1, 0)), np.diag([-1.0, -1.0, 1.0, 1.0])), os.path.join(out, "..", "air.nii.gz"))
counts = [int(padded.sum())]
for r in range(1, 7):
    near = np.zeros_like(padded)
    for dz in range(-r, r + 1):
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                src = padded[max(dz, 0):nz + min(dz, 0), max(dy, 0):ny + min(dy, 0), max(dx, 0):nx + min(dx, 0)]
                near[max(-dz, 0):nz + min(-dz, 0), max(-dy, 0):ny + min(-dy, 0), max(-dx, 0):nx + min(-dx, 0)] |= src
    counts.append(int(near.sum()))
print(*counts)
"#;

#[test]
fn a_ct_series_pixel_padding_is_left_out_of_the_histograms_and_the_tracing() {
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    std::fs::create_dir(&series).unwrap();
    let counts = run_python(&format!("{PYDICOM_CT_PY}{PADDED_SERIES_PY}"), &[series.to_str().unwrap()]);
    let counts: Vec<u64> = counts.split_whitespace().map(|n| n.parse().unwrap()).collect();
    let padded = counts[0];
    let info = mdtf_ok(&["info", series.to_str().unwrap()]);
    assert!(info.contains("pixel padding:") && info.contains("stored -1500"), "{info}");
    for (pipeline, extra) in [("slicer-3dtf", &[][..]), ("distance-tf", &["--slab-planes", "5"][..])] {
        let out = dir.path().join(pipeline);
        let p = mdtf_e2e::shipped_pipeline(pipeline);
        let mut args =
            vec!["run", p.to_str().unwrap(), "--input", series.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        args.push("-q");
        mdtf_ok(&args);
        // the kernel's radius, as the plan states it ("kernel [r, r, r]")
        let plan =
            mdtf_ok(&["run", p.to_str().unwrap(), "--input", series.to_str().unwrap(), "-o", "unused", "--plan"]);
        let radius: usize = plan.split("(kernel [").nth(1).and_then(|r| r.split(',').next()).unwrap().parse().unwrap();
        let near = counts[radius];
        let report: Value = serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap();
        let said = format!("{padded} of 19200 voxels");
        let warnings = report["warnings"].as_array().unwrap();
        assert!(warnings.iter().any(|w| w.as_str().unwrap().contains(&said)), "{pipeline}: {warnings:?}");
        // 19200 voxels, so the g axis clips none (0.002 % of them is less than one): exact
        let hist: Value = serde_json::from_slice(&std::fs::read(out.join("histogram/hist_v_g.json")).unwrap()).unwrap();
        assert_eq!(hist["total"].as_u64().unwrap(), 19200 - near, "{pipeline}: voxels counted");
        if pipeline == "slicer-3dtf" {
            // the preview shows the ball, not the field of view: as it does where the padding is air
            let air = dir.path().join("air");
            let input = dir.path().join("air.nii.gz");
            mdtf_ok(&[
                "run",
                p.to_str().unwrap(),
                "--input",
                input.to_str().unwrap(),
                "-o",
                air.to_str().unwrap(),
                "-q",
            ]);
            // the lit pixels' box (a shaded surface's speckle differs pixel by pixel; the field of view's
            // cylinder would widen the box to the picture's width)
            let lit_box = |picture: &Path| -> [usize; 4] {
                let (w, _, rgb) = mdtf_e2e::read_rgb_png(picture);
                let lit = rgb.chunks_exact(3).enumerate().filter(|(_, p)| p.iter().any(|&c| c > 10));
                lit.fold([usize::MAX, usize::MAX, 0, 0], |[x0, y0, x1, y1], (i, _)| {
                    let (x, y) = (i % w as usize, i / w as usize);
                    [x0.min(x), y0.min(y), x1.max(x), y1.max(y)]
                })
            };
            let (padded_box, air_box) = (lit_box(&out.join("preview.png")), lit_box(&air.join("preview.png")));
            let apart = padded_box.iter().zip(&air_box).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
            assert!(apart <= 8, "lit box {padded_box:?} with padding, {air_box:?} with air there");
        }
        if pipeline == "distance-tf" {
            // no voxel whose derivatives read padding is traced
            let traced = report["boundary"]["counts"]["not_traced"].as_u64().unwrap();
            assert!(traced >= near, "{pipeline}: {traced} not traced");
        }
    }
}

#[test]
fn pydicoms_deflated_image_reads_as_pydicom_decodes_it() {
    let script = "import json, sys, pydicom, os; f = os.path.join(os.path.dirname(pydicom.__file__), 'data', 'test_files', 'image_dfl.dcm'); \
                  d = pydicom.dcmread(f); print(json.dumps({'path': f, 'syntax': str(d.file_meta.TransferSyntaxUID), 'values': d.pixel_array.ravel().tolist()}))";
    let theirs: Value = serde_json::from_str(&run_python(script, &[])).unwrap();
    assert_eq!(theirs["syntax"], "1.2.840.10008.1.2.1.99", "Deflated Explicit VR Little Endian");
    let mf = read(Path::new(theirs["path"].as_str().unwrap()), &ReadOptions::default()).unwrap();
    assert_eq!(mf.geometry.dims, [512, 512, 1]);
    assert_eq!(values(&mf), numbers(&theirs["values"]));
}

#[test]
fn pydicoms_one_bit_segmentations_read_as_0_and_1_as_pydicom_decodes_them() {
    for name in ["liver_1frame.dcm", "liver_expb_1frame.dcm"] {
        let script = "import json, sys, pydicom, os; f = os.path.join(os.path.dirname(pydicom.__file__), 'data', 'test_files', sys.argv[1]); \
                      d = pydicom.dcmread(f); print(json.dumps({'path': f, 'bits': d.BitsAllocated, 'values': d.pixel_array.ravel().tolist()}))";
        let theirs: Value = serde_json::from_str(&run_python(script, &[name])).unwrap();
        assert_eq!(theirs["bits"], 1, "{name}");
        let mf = read(Path::new(theirs["path"].as_str().unwrap()), &ReadOptions::default()).unwrap();
        let want = numbers(&theirs["values"]);
        assert!(want.contains(&1.0) && want.contains(&0.0), "{name}: a mask of both values");
        assert_eq!(values(&mf), want, "{name}");
    }
}

#[test]
fn a_series_folder_says_how_many_files_it_left_out_and_why() {
    // pydicom's CT_small beside an empty .dcm, a text note and pydicom's structured report
    let script = "import json, pydicom, os; d = os.path.join(os.path.dirname(pydicom.__file__), 'data', 'test_files'); \
                  print(json.dumps([os.path.join(d, 'CT_small.dcm'), os.path.join(d, 'test-SR.dcm')]))";
    let files: Vec<String> = serde_json::from_str(&run_python(script, &[])).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    std::fs::create_dir(&series).unwrap();
    std::fs::copy(&files[0], series.join("ct.dcm")).unwrap();
    std::fs::copy(&files[1], series.join("report.dcm")).unwrap();
    std::fs::write(series.join("empty.dcm"), b"").unwrap();
    std::fs::write(series.join("notes.txt"), b"scanned on Monday").unwrap();
    let out = mdtf(&["info", series.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("left out 2 files not DICOM") && text.contains("1 DICOM file without pixel data"), "{text}");
    // with nothing to leave out, nothing is said
    std::fs::remove_file(series.join("report.dcm")).unwrap();
    std::fs::remove_file(series.join("empty.dcm")).unwrap();
    std::fs::remove_file(series.join("notes.txt")).unwrap();
    let out = mdtf(&["info", series.to_str().unwrap()]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("left out"));
}
