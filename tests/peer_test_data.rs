//! The test files that ship inside the pinned pydicom and nibabel wheels
//! (`pydicom/data/test_files`, `nibabel/tests/data`): files no one here wrote.
//! File by file, either mdtf reads the values, dims and spacing the peer
//! reads (scaling applied), or `mdtf info` refuses with exit 1, naming the
//! file and what it does not read; never exit 0 with other values.

use mdtf_e2e::{mdtf, run_python};
use mdtf_volume::{NanPolicy, ReadOptions, read};
use serde_json::Value;
use std::path::Path;

/// Reads every file with its peer (pydicom, with pyjpegls for JPEG-LS, the rescale or dose scaling
/// applied; nibabel's get_fdata) and writes the values as little-endian f64, x fastest, into argv[1]; prints one
/// entry per file: name, path, and the peer's shape (x first) and spacing, or its error.
const PEER_READS: &str = r#"
import sys, os, glob, json, warnings
import numpy as np, pydicom, nibabel as nib
from pydicom.pixels import apply_rescale
warnings.simplefilter('ignore')
out = sys.argv[1]
dcm = sorted(glob.glob(os.path.join(os.path.dirname(pydicom.__file__), 'data', 'test_files', '*.dcm')))
nii = sorted(f for f in glob.glob(os.path.join(os.path.dirname(nib.__file__), 'tests', 'data', '*'))
             if f.endswith(('.nii', '.nii.gz', '.hdr')))
entries = []
for k, path in enumerate(dcm + nii):
    e = {'name': os.path.basename(path), 'path': path, 'dicom': path.endswith('.dcm')}
    try:
        if e['dicom']:
            ds = pydicom.dcmread(path)
            a = ds.pixel_array
            if int(getattr(ds, 'SamplesPerPixel', 1)) != 1 or ds.PhotometricInterpretation == 'PALETTE COLOR':
                raise ValueError('colour')
            v = apply_rescale(a, ds).astype(np.float64)
            if 'DoseGridScaling' in ds:
                v = v * float(ds.DoseGridScaling)
            frames = int(getattr(ds, 'NumberOfFrames', 1) or 1)
            v = v.reshape((frames, int(ds.Rows), int(ds.Columns)))
            e['shape'] = [int(ds.Columns), int(ds.Rows), frames, 1]
            ps = getattr(ds, 'PixelSpacing', None)
            e['spacing'] = None if ps is None else [float(ps[1]), float(ps[0])]
            flat = v.ravel()
        else:
            img = nib.load(path)
            v = img.get_fdata()
            while v.ndim < 3: v = v[..., None]
            v = v.reshape(v.shape[:3] + (-1,), order='F')
            e['shape'] = list(v.shape)
            e['spacing'] = [float(z) for z in img.header.get_zooms()[:3]]
            flat = np.concatenate([v[..., f].ravel(order='F') for f in range(v.shape[3])])
        e['values'] = os.path.join(out, f'{k}.f64')
        flat.astype('<f8').tofile(e['values'])
    except Exception as x:
        e['peer_error'] = f'{type(x).__name__}: {str(x).splitlines()[0] if str(x) else ""}'[:160]
    entries.append(e)
print(json.dumps(entries))
"#;

/// What a refusal must name, besides the file: the reason mdtf does not read it.
const REASONS: [&str; 11] = [
    "colour",
    "PALETTE COLOR",
    "no DICOM image",
    "not a readable DICOM file",
    "CIFTI-2",
    "which is missing",
    "mdtf cannot decode",
    "cannot decode the",
    "NumberOfFrames",
    "stored uncompressed",
    "fewer than Columns x Rows",
];

/// Files a peer reads that mdtf refuses, each for its reason (the reason must appear in the message).
const REFUSED_THOUGH_THE_PEER_READS: [(&str, &str); 1] = [
    // colour, and its data set is encoded implicit VR under an explicit-VR transfer syntax (pydicom
    // guesses; dicom-rs does not)
    ("SC_rgb_jpeg.dcm", "not a readable DICOM file"),
];

#[test]
fn the_peers_own_test_files_read_as_the_peers_read_them_or_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let entries: Value = serde_json::from_str(&run_python(PEER_READS, &[dir.path().to_str().unwrap()])).unwrap();
    let entries = entries.as_array().unwrap();
    assert!(entries.len() > 80, "the wheels' test files: {}", entries.len());
    let (mut equal, mut refused_colour, mut refused_both) = (Vec::new(), Vec::new(), Vec::new());
    for e in entries {
        let name = e["name"].as_str().unwrap();
        let path = Path::new(e["path"].as_str().unwrap());
        let peer_reads = e.get("values").is_some();
        let colour = e["peer_error"].as_str() == Some("ValueError: colour");
        // NaN kept, to compare with the peer's (mdtf refuses them by default, and info counts them)
        match read(path, &ReadOptions { nan: NanPolicy::Keep, ..Default::default() }) {
            Ok(mf) => {
                assert!(peer_reads, "{name}: mdtf reads what the peer refuses ({})", e["peer_error"]);
                let shape: Vec<usize> =
                    e["shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
                assert_eq!(mf.geometry.dims.to_vec(), shape[..3], "{name}: dims");
                assert_eq!(mf.fields.len(), shape[3], "{name}: fields");
                let bytes = std::fs::read(e["values"].as_str().unwrap()).unwrap();
                let want: Vec<f64> = bytes.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap())).collect();
                let got: Vec<f32> = mf.fields.iter().flat_map(|f| f.data.iter().copied()).collect();
                assert_eq!(got.len(), want.len(), "{name}: samples");
                for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                    let same = *g == *w as f32 || (g.is_nan() && w.is_nan());
                    assert!(same, "{name}: sample {i}: mdtf {g}, the peer {w}");
                }
                if let Some(spacing) = e["spacing"].as_array() {
                    for (a, s) in spacing.iter().enumerate() {
                        let (ours, theirs) = (mf.geometry.spacing[a], s.as_f64().unwrap());
                        assert!(
                            (ours - theirs).abs() <= 1e-5 * theirs.abs(),
                            "{name}: spacing {a}: {ours} vs {theirs}"
                        );
                    }
                }
                equal.push(name);
            }
            Err(err) => {
                let out = mdtf(&["info", path.to_str().unwrap()]);
                let text = String::from_utf8_lossy(&out.stderr);
                assert_eq!(out.status.code(), Some(1), "{name}: {text}");
                assert!(text.contains(name), "{name}: the message names the file: {text}");
                assert!(REASONS.iter().any(|r| text.contains(r)), "{name}: a named reason: {text}");
                if let Some((_, reason)) = REFUSED_THOUGH_THE_PEER_READS.iter().find(|(n, _)| *n == name) {
                    assert!(text.contains(reason), "{name}: {text}");
                    refused_both.push(name);
                } else if peer_reads {
                    panic!("{name}: the peer reads it, mdtf refuses: {err}");
                } else if colour {
                    assert!(text.contains("colour"), "{name}: refused as colour: {text}");
                    refused_colour.push(name);
                } else {
                    refused_both.push(name);
                }
            }
        }
    }
    println!("equal to the peer ({}): {}", equal.len(), equal.join(" "));
    println!("colour, refused ({}): {}", refused_colour.len(), refused_colour.join(" "));
    println!("refused, the peer fails too or as listed ({}): {}", refused_both.len(), refused_both.join(" "));
    for must in [
        "rtdose_expb.dcm",
        "rtdose_rle.dcm",
        "image_dfl.dcm",
        "liver_1frame.dcm",
        "MR_small_jpeg_ls_lossless.dcm",
        "JPEGLSNearLossless_16.dcm",
        "example_nifti2.nii.gz",
    ] {
        assert!(equal.contains(&must), "{must} reads as its peer reads it");
    }
}
