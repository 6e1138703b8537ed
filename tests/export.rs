//! `mdtf export` against the tools it exports for: VTK renders the exported
//! pack (with the shipped render_vtk.py) as `mdtf preview` renders the pack,
//! ParaView too (open_in_paraview.py under pvbatch), the `.vti` reads back
//! in vtk and by the format's documented layout as the pack decodes, and
//! Slicer's `.vp` parses by its documented layout and holds the TF's marginals.

use mdtf_datagen::erf_sphere;
use mdtf_e2e::{mdtf, mdtf_err, mdtf_ok, python, shipped_pipeline};
use mdtf_volume::{Geometry, MultiField, SampleType, write_nifti};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Grid of the phantoms and pixels of the pictures compared.
const SIZE: usize = 96;
const PIXELS: usize = 256;
/// The issue's agreement: foreground IoU and mean colour difference over the overlap (of 255).
const MIN_IOU: f64 = 0.9;
const MAX_MEAN_DIFFERENCE: f64 = 10.0;

/// Semi-transparent coloured triangles on the shells' inner boundaries.
const SHELLS_TF: &str = r#"{
  "v_range": [0, 255],
  "g_range": [0, 40],
  "widgets": [
    {"type": "triangle", "v0": 185, "width": 30, "g_low": 2, "g_high": 12, "alpha": 0.25, "colour": [1.0, 0.6, 0.2]},
    {"type": "triangle", "v0": 100, "width": 30, "g_low": 2, "g_high": 11, "alpha": 0.5, "colour": [0.3, 0.5, 1.0]}
  ]
}"#;

struct Packs {
    dir: tempfile::TempDir,
}

impl Packs {
    fn pack(&self, case: &str) -> PathBuf {
        self.dir.path().join(case).join("pack")
    }
    fn export(&self, case: &str) -> PathBuf {
        self.dir.path().join(case).join("export")
    }
    fn preview(&self, case: &str) -> PathBuf {
        self.dir.path().join(case).join("preview.png")
    }
}

/// The rendered cases, each a slicer-3dtf pack, its export and its preview:
/// `sphere` and `shells` with the default TF (for the shells, three
/// coloured semi-transparent boundaries); `shells` and `shells-tf` (with
/// SHELLS_TF) without their normal texture and previewed `--no-shading`
/// (so that neither side shades their semi-transparent layers: the preview
/// weights shading by g, VTK does not); `oblique`, the sphere on a rotated anisotropic grid.
fn packs() -> &'static Packs {
    static P: OnceLock<Packs> = OnceLock::new();
    P.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let pipeline = shipped_pipeline("slicer-3dtf");
        let size = format!("input.size={SIZE}");
        let tf = dir.path().join("shells-tf.json");
        std::fs::write(&tf, SHELLS_TF).unwrap();
        let oblique = dir.path().join("oblique.nii");
        write_oblique_sphere(&oblique);
        let cases: [(&str, Vec<String>); 4] = [
            ("sphere", vec!["--set".into(), size.clone()]),
            ("shells", vec!["--set".into(), size.clone(), "--set".into(), "input.phantom=shells".into()]),
            (
                "shells-tf",
                vec![
                    "--set".into(),
                    size.clone(),
                    "--set".into(),
                    "input.phantom=shells".into(),
                    "--set".into(),
                    format!("pack.tf={}", tf.display()),
                ],
            ),
            ("oblique", vec!["--input".into(), oblique.to_str().unwrap().into()]),
        ];
        for (case, extra) in &cases {
            let out = dir.path().join(case);
            let mut args = vec!["run", pipeline.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"];
            args.extend(extra.iter().map(String::as_str));
            mdtf_ok(&args);
            let pack = out.join("pack");
            // semi-transparent layers are compared unshaded (the preview weights shading by g, VTK does not)
            if *case == "shells-tf" || *case == "shells" {
                strip_normals(&pack);
            }
            let export = out.join("export");
            mdtf_ok(&["export", pack.to_str().unwrap(), "-o", export.to_str().unwrap(), "-q"]);
            let preview = out.join("preview.png");
            let size = PIXELS.to_string();
            let mut args = vec!["preview", pack.to_str().unwrap(), "-o", preview.to_str().unwrap(), "--size", &size];
            // (without normals the preview would shade by the value's gradient: off, as in VTK)
            if *case == "shells-tf" || *case == "shells" {
                args.push("--no-shading");
            }
            mdtf_ok(&args);
        }
        Packs { dir }
    })
}

/// The erf sphere on a grid rotated 30 degrees about z, spacings 0.8, 1, 1.2 mm, origin off zero.
fn write_oblique_sphere(path: &Path) {
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let mut g = Geometry::new([SIZE, SIZE, 80], [0.8, 1.0, 1.2]).with_origin([10.0, -20.0, 5.0]);
    g.directions = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]];
    let v = erf_sphere(g, 26.0, 2.0, 0.0, 255.0, None).volume();
    write_nifti(path, &MultiField::from(v), SampleType::F32).unwrap();
}

/// Removes the normal texture from a pack's manifest (the pack stays valid: g is in its data texture too).
fn strip_normals(pack: &Path) {
    let path = pack.join("manifest.json");
    let mut m: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    m["channels"].as_array_mut().unwrap().retain(|c| c["texture"] != "normal");
    m["textures"].as_array_mut().unwrap().retain(|t| t["name"] != "normal");
    std::fs::write(&path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
}

/// RGB8 pixels of a PNG.
fn rgb(path: &Path) -> (usize, Vec<[u8; 3]>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let pixels = buf[..info.width as usize * info.height as usize * channels]
        .chunks_exact(channels)
        .map(|p| if channels >= 3 { [p[0], p[1], p[2]] } else { [p[0]; 3] })
        .collect();
    (info.width as usize, pixels)
}

/// Foreground IoU (a pixel is foreground above 10 of 255 in any channel) and
/// the mean absolute colour difference over the overlap, of 255.
fn agreement(a: &Path, b: &Path) -> (f64, f64) {
    let ((wa, pa), (wb, pb)) = (rgb(a), rgb(b));
    assert_eq!((wa, pa.len()), (wb, pb.len()), "{} and {} differ in size", a.display(), b.display());
    let fg = |p: &[u8; 3]| p.iter().any(|&c| c > 10);
    let (mut both, mut either, mut diff) = (0usize, 0usize, 0f64);
    for (x, y) in pa.iter().zip(&pb) {
        match (fg(x), fg(y)) {
            (true, true) => {
                both += 1;
                either += 1;
                diff += (0..3).map(|k| (x[k] as f64 - y[k] as f64).abs()).sum::<f64>() / 3.0;
            }
            (false, false) => {}
            _ => either += 1,
        }
    }
    assert!(both > 1000, "{} and {} hardly show anything ({both} pixels in common)", a.display(), b.display());
    (both as f64 / either as f64, diff / both as f64)
}

/// Runs the exported render_vtk.py offscreen; returns the PNG.
fn render_vtk(case: &str, extra: &[&str]) -> PathBuf {
    let p = packs();
    let out = p.dir.path().join(case).join(format!("vtk{}.png", extra.len()));
    let size = PIXELS.to_string();
    let mut args = vec!["render_vtk.py", "-o", out.to_str().unwrap(), "--size", &size];
    args.extend(extra);
    let run = Command::new(python())
        .args(&args)
        .current_dir(p.export(case))
        .env("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        .output()
        .expect("run python");
    assert!(
        run.status.success(),
        "render_vtk.py failed for {case} (needs the vtk wheel of tests/requirements.txt and Mesa's EGL: \
         bash tests/run.sh installs both):\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    out
}

fn export_json(case: &str) -> Value {
    serde_json::from_slice(&std::fs::read(packs().export(case).join("export.json")).unwrap()).unwrap()
}

#[test]
fn vtk_renders_the_exported_pack_as_mdtf_preview_does() {
    for case in ["sphere", "shells", "shells-tf", "oblique"] {
        let (iou, diff) = agreement(&render_vtk(case, &[]), &packs().preview(case));
        eprintln!("{case}: IoU {iou:.4}, mean colour difference {diff:.2}/255");
        assert!(iou >= MIN_IOU && diff <= MAX_MEAN_DIFFERENCE, "{case}: IoU {iou:.4}, mean difference {diff:.2}");
    }
}

#[test]
fn a_wrong_y_axis_scaling_is_caught_by_the_same_comparison() {
    // the table stretched over twice g's range, as an uncalibrated Y axis would be. (Not on the
    // sphere: its default TF follows the boundary's arch in (v, g), so a factor 2 in g changes which
    // voxels show, not the silhouette; the shells' widgets select by g.)
    let case = "shells-tf";
    let g_max = export_json(case)["tf"]["y_range"][1].as_f64().unwrap();
    let wrong = format!("0,{}", 2.0 * g_max);
    let (iou, diff) = agreement(&render_vtk(case, &["--y-range", &wrong]), &packs().preview(case));
    eprintln!("{case} with Y over [{wrong}]: IoU {iou:.4}, mean colour difference {diff:.2}/255");
    assert!(
        iou < MIN_IOU || diff > MAX_MEAN_DIFFERENCE,
        "{case}: a Y axis twice too long still passed (IoU {iou:.4}, mean difference {diff:.2})"
    );
}

/// pvbatch (Debian's python3-paraview) and xvfb-run, which tests/run.sh
/// installs as root; attempt `attempt` looks for a free X display from a
/// number of its own (this process's and the attempt's), so that two test
/// runs on one machine do not race for display 99.
fn pvbatch(attempt: u32) -> Command {
    let found = |tool: &str| Command::new("sh").args(["-c", &format!("command -v {tool}")]).output();
    for tool in ["pvbatch", "xvfb-run"] {
        assert!(
            found(tool).is_ok_and(|o| o.status.success()),
            "{tool} is missing: the ParaView test needs ParaView's pvbatch under xvfb-run (Debian: apt-get install \
             python3-paraview xvfb xauth; bash tests/run.sh does it as root)"
        );
    }
    let mut c = Command::new("xvfb-run");
    let first_display = 100 + (std::process::id() % 300) * 3 + attempt;
    c.args(["-a", "-n", &first_display.to_string(), "-s", "-screen 0 1024x768x24", "pvbatch"]);
    c
}

#[test]
fn paraview_renders_the_exported_pack_as_mdtf_preview_does() {
    for case in ["sphere", "shells-tf", "oblique"] {
        let p = packs();
        let out = p.dir.path().join(case).join("paraview.png");
        let size = PIXELS.to_string();
        let args = ["open_in_paraview.py", "--screenshot", out.to_str().unwrap(), "--size", &size];
        // xvfb-run -a can lose the race for a display number to another X server starting: try again
        let mut run = pvbatch(0).args(args).current_dir(p.export(case)).output().expect("run pvbatch");
        for attempt in 1..3 {
            if run.status.success() || !String::from_utf8_lossy(&run.stderr).contains("bad X server connection") {
                break;
            }
            run = pvbatch(attempt).args(args).current_dir(p.export(case)).output().expect("run pvbatch");
        }
        assert!(
            run.status.success(),
            "open_in_paraview.py failed for {case}:\n{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let (iou, diff) = agreement(&out, &p.preview(case));
        eprintln!("{case} in ParaView: IoU {iou:.4}, mean colour difference {diff:.2}/255");
        assert!(iou >= MIN_IOU && diff <= MAX_MEAN_DIFFERENCE, "{case}: IoU {iou:.4}, mean difference {diff:.2}");
    }
}

fn check(what: &str, case: &str) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("export_check.py");
    let p = packs();
    let out = Command::new(python())
        .args([script.to_str().unwrap(), what, p.pack(case).to_str().unwrap(), p.export(case).to_str().unwrap()])
        .output()
        .expect("run python");
    assert!(out.status.success(), "export_check.py {what} {case}:\n{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn the_vti_reads_back_in_vtk_and_by_its_documented_layout_as_the_pack_decodes() {
    for case in ["sphere", "oblique"] {
        let r = check("vti", case);
        for reader in ["vtk", "layout"] {
            let x = &r[reader];
            // every channel, within half a quantisation step of the pack's decode
            assert_eq!(x["channels"], serde_json::json!(["f2", "g", "nx", "ny", "nz", "v"]), "{case} {reader}");
            assert_eq!(x["arrays"], serde_json::json!(["f2", "g", "normal", "v"]), "{case} {reader}");
            assert!(x["worst_steps"].as_f64().unwrap() <= 0.5, "{case} {reader}: {x}");
            assert!(x["geometry_error"].as_f64().unwrap() < 1e-9, "{case} {reader}: {x}");
        }
        let dims = if case == "oblique" { [SIZE, SIZE, 80] } else { [SIZE; 3] };
        assert_eq!(r["vtk"]["dims"], serde_json::json!(dims));
    }
}

#[test]
fn the_slicer_files_parse_by_slicers_layout_and_hold_the_tfs_marginals() {
    for case in ["sphere", "shells"] {
        let r = check("vp", case);
        // (the shells pack's normals are stripped: it is not shaded)
        let shade = if case == "shells" { 0.0 } else { 1.0 };
        assert_eq!(r["settings"], serde_json::json!([1.0, shade, 0.75, 0.25, 0.3, 32.0]), "{case}");
        for f in ["scalar_error", "gradient_error", "colour_error"] {
            assert!(r[f].as_f64().unwrap() < 1e-6, "{case} {f}: {r}");
        }
        assert_eq!(r["points"], serde_json::json!([256, 256, 256]), "{case}");
        // the default opacity makes the boundary nearly opaque somewhere
        assert!(r["peak_scalar_opacity"].as_f64().unwrap() > 0.5, "{case}: {r}");
        let n = check("nrrd", case);
        assert!(n["worst_steps"].as_f64().unwrap() < 1e-3, "{case}: {n}");
        assert!(n["geometry_error"].as_f64().unwrap() < 1e-9, "{case}: {n}");
        assert_eq!(n["encoding"], "gzip", "{case}");
    }
}

/// Runs the shipped pipeline `name` at 40^3 into `dir/name`.
fn small_run(name: &str, dir: &Path) -> PathBuf {
    let out = dir.join(name);
    let pipeline = shipped_pipeline(name);
    mdtf_ok(&["run", pipeline.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q", "--set", "input.size=40"]);
    out
}

#[test]
fn what_cannot_be_exported_is_said_and_the_pack_is_never_written_over() {
    let dir = tempfile::tempdir().unwrap();
    let pack = packs().pack("sphere");
    // the pack itself as the output
    for target in [pack.clone(), pack.parent().unwrap().to_path_buf()] {
        let err = mdtf_err(&["export", pack.to_str().unwrap(), "-o", target.to_str().unwrap()]);
        assert!(err.contains("an input of this run"), "{err}");
    }
    assert!(pack.join("manifest.json").is_file() && pack.join("data.raw").is_file());
    // a projected-tetrahedra pack already is VTK (mesh.vtu)
    let tet = small_run("projected-tetrahedra", dir.path());
    let err = mdtf_err(&["export", tet.join("pack").to_str().unwrap(), "-o", dir.path().join("x").to_str().unwrap()]);
    assert!(err.contains("mesh.vtu"), "{err}");
    assert!(!dir.path().join("x").exists(), "a failed export left its folder");
    // a gaussian-tf pack has no table: the data is exported and the note says so
    let gtf = small_run("gaussian-tf", dir.path());
    let out = mdtf(&["export", gtf.join("pack").to_str().unwrap(), "-o", dir.path().join("g").to_str().unwrap()]);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no 2D or 3D transfer-function table"), "{stderr}");
    assert!(dir.path().join("g/volume.vti").is_file() && !dir.path().join("g/render_vtk.py").exists());
    // a TF over (v, inv_g) has no separable form over v and its gradient: no .vp, and the note says why
    let pf = small_run("peak-finding", dir.path());
    let out = mdtf(&[
        "export",
        pf.join("pack").to_str().unwrap(),
        "--to",
        "slicer",
        "-o",
        dir.path().join("p").to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && stderr.contains("no volume_property.vp: the TF is over (v, inv_g)"), "{stderr}");
    assert!(dir.path().join("p/v.nrrd").is_file() && !dir.path().join("p/volume.vti").exists());
}
