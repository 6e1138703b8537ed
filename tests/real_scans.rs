//! Every shipped pipeline on real scans from a registry package: Colin27's
//! T1 MRI (ch2.nii.gz, Debian mricron-data) and a real two-field stack of
//! it with its brain-extracted copy (ch2bet.nii.gz), stacked by nibabel.
//! Each run must write a preview that shows something (at least 2 % of its
//! pixels lit) and its (v, g) figure, within the figure size limit.

use mdtf_e2e::{mdtf_ok, read_rgb_png, real_scan, run_python, shipped_pipeline};
use std::path::{Path, PathBuf};

/// The pipelines that run on any volume (every shipped one).
const PIPELINES: [&str; 5] = ["slicer-3dtf", "distance-tf", "peak-finding", "gaussian-tf", "projected-tetrahedra"];

/// Runs `pipeline` on `input` into `out` and checks its preview and figures.
fn run_shows_something(pipeline: &str, input: &Path, out: &Path) {
    let p = shipped_pipeline(pipeline);
    mdtf_ok(&["run", p.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    let (w, h, px) = read_rgb_png(&out.join("preview.png"));
    let lit = px.chunks_exact(3).filter(|c| c.iter().map(|&x| x as u32).sum::<u32>() >= 30).count();
    let share = lit as f64 / (w * h) as f64;
    eprintln!("{pipeline} on {}: {:.1} % of the preview lit", input.display(), 100.0 * share);
    assert!(share >= 0.02, "{pipeline}: {lit} of {} preview pixels lit", w * h);
    let figures: Vec<_> = std::fs::read_dir(out.join("histogram"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|f| f.extension().is_some_and(|e| e == "png"))
        .collect();
    assert!(figures.iter().any(|f| f.ends_with("hist_v_g.png")), "{pipeline}: {figures:?}");
    // the TF drawn over a histogram (a mesh's (s, g) TF over the (v, g) histogram)
    let tf_figure = |f: &PathBuf| f.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("tf_"));
    assert!(figures.iter().any(tf_figure), "{pipeline}: {figures:?}");
    for f in &figures {
        let (w, h, _) = read_rgb_png(f);
        assert!(w <= 1260 && h <= 1200, "{}: {w} x {h}", f.display());
    }
    // peak finding's (v, 1/g) histogram holds the voxels near boundaries (a
    // 1/g axis in the wrong units leaves it all but empty)
    if pipeline == "peak-finding" {
        // named by the value, or by the first field of a stack
        let file = std::fs::read_dir(out.join("histogram"))
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .find(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.ends_with("_inv_g.json")))
            .unwrap_or_else(|| panic!("{pipeline}: no (value, 1/g) histogram in {}", out.display()));
        let counts: serde_json::Value = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap();
        let voxels: f64 = report["dims"].as_array().unwrap().iter().map(|d| d.as_f64().unwrap()).product();
        let share = counts["total"].as_f64().unwrap() / voxels;
        eprintln!("{pipeline}: {:.1} % of the voxels in the (v, 1/g) histogram", 100.0 * share);
        assert!(share > 0.1, "{pipeline}: {share}");
    }
}

#[test]
fn every_shipped_pipeline_shows_a_real_mri() {
    let scan = real_scan("ch2.nii.gz");
    let dir = tempfile::tempdir().unwrap();
    // meshing the full scan (43 M tetrahedra) is the slowest case by far: it meshes every
    // second voxel of each axis (nibabel keeps the affine right), still the real head
    let half = dir.path().join("ch2-half.nii.gz");
    run_python(
        "import sys, nibabel as nb\nnb.save(nb.load(sys.argv[1]).slicer[::2, ::2, ::2], sys.argv[2])\n",
        &[scan.to_str().unwrap(), half.to_str().unwrap()],
    );
    for p in PIPELINES {
        let input = if p == "projected-tetrahedra" { &half } else { &scan };
        run_shows_something(p, input, &dir.path().join(p));
    }
    // the projected-tetrahedra preview draws the TF the run wrote beside the mesh
    let g: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("projected-tetrahedra/pack/gaussians.json")).unwrap(),
    )
    .unwrap();
    assert!(!g.as_array().unwrap().is_empty());
}

#[test]
fn the_pipelines_show_a_real_two_field_stack() {
    let (t1, brain) = (real_scan("ch2.nii.gz"), real_scan("ch2bet.nii.gz"));
    let dir = tempfile::tempdir().unwrap();
    let stack = dir.path().join("stack.nii.gz");
    run_python(
        "import sys, nibabel as nb, numpy as np\n\
         a, b = nb.load(sys.argv[1]), nb.load(sys.argv[2])\n\
         assert a.shape == b.shape and np.allclose(a.affine, b.affine)\n\
         d = np.stack([np.asarray(a.dataobj), np.asarray(b.dataobj)], axis=-1)\n\
         img = nb.Nifti1Image(d, a.affine)\n\
         img.header.set_xyzt_units('mm')\n\
         nb.save(img, sys.argv[3])\n",
        &[t1.to_str().unwrap(), brain.to_str().unwrap(), stack.to_str().unwrap()],
    );
    // (projected tetrahedra meshes the first field only, as on the scan above, and is the slowest)
    for p in PIPELINES.iter().filter(|&&p| p != "projected-tetrahedra") {
        run_shows_something(p, &stack, &dir.path().join(p));
    }
    assert!(dir.path().join("gaussian-tf/histogram/hist_field0_field1.png").is_file());
}
