//! `report.html` read as a person reads it: headless Chromium (Debian's
//! `chromium` and `chromium-driver`, driven by Selenium from
//! tests/report_check.py) loads the page from disk; every image must load,
//! the console must stay silent, and the page's tables must say what the
//! run's JSON report and the pack's manifest say. A screenshot of each page
//! is kept in `target/report-screenshots/` to look at.

use mdtf_e2e::{manifest, mdtf_ok, python, read_rgb_png, shipped_pipeline};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What the browser saw: the page's images, console messages and table texts.
fn open_in_chromium(page: &Path, shot: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("report_check.py");
    let out = Command::new(python()).arg(&script).arg(page).arg(shot).output().expect("run report_check.py");
    assert!(
        out.status.success(),
        "report_check.py failed (tests/run.sh installs chromium, chromium-driver and selenium):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("report_check.py prints JSON")
}

fn screenshot_path(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/report-screenshots");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{name}.png"))
}

/// Every PNG the run wrote (the contact sheet aside: the page replaces it), relative to `out`.
fn pngs_in(out: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![out.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "png") {
                let rel = p.strip_prefix(out).unwrap().to_string_lossy().replace('\\', "/");
                if rel != "contact_sheet.png" {
                    found.push(rel);
                }
            }
        }
    }
    found.sort();
    found
}

/// Runs `pipeline` with `sets` into a fresh folder, opens its page, and
/// checks it against the run's own files; returns the run folder and what the browser saw.
fn run_and_open(name: &str, pipeline: &str, input: Option<&Path>, sets: &[&str]) -> (tempfile::TempDir, Value) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let pipeline = shipped_pipeline(pipeline);
    let mut args = vec!["run".to_string(), pipeline.display().to_string(), "-o".into(), out.display().to_string()];
    if let Some(i) = input {
        args.extend(["--input".into(), i.display().to_string()]);
    }
    for s in sets {
        args.extend(["--set".into(), (*s).into()]);
    }
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    mdtf_ok(&refs);
    let page = out.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    let shot = screenshot_path(name);
    let seen = open_in_chromium(&page, &shot);

    // nothing from the network: every link and image is a file of the run
    for attr in ["src=\"", "href=\""] {
        for part in html.split(attr).skip(1) {
            let target = &part[..part.find('"').unwrap()];
            assert!(!target.contains("://"), "{name}: {attr}{target}");
            assert!(out.join(target).is_file(), "{name}: {attr}{target} is not a file of the run");
        }
    }
    assert!(!html.contains("<script"), "{name}: the page needs no script");

    // every figure shows, and loaded
    let images: Vec<(String, u64)> = seen["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| (i["src"].as_str().unwrap().to_string(), i["width"].as_u64().unwrap_or(0)))
        .collect();
    let mut shown: Vec<String> = images.iter().map(|(s, _)| s.clone()).collect();
    shown.sort();
    assert_eq!(shown, pngs_in(&out), "{name}: the page shows every picture of the run");
    for (src, width) in &images {
        assert!(*width > 0, "{name}: {src} did not load");
    }
    let console = seen["console"].as_array().unwrap();
    assert!(console.is_empty(), "{name}: the browser's console: {console:?}");
    let (w, h, _) = read_rgb_png(&shot);
    assert!(w >= 1000 && h > 1000, "{name}: screenshot {w} x {h}");
    (dir, seen)
}

/// The rows of the page's table whose first cell is `first`, as tab-separated cells.
fn rows_starting<'a>(seen: &'a Value, first: &str) -> Vec<Vec<&'a str>> {
    seen["tables"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|t| t.as_str().unwrap().lines())
        .map(|l| l.split('\t').map(str::trim).collect::<Vec<_>>())
        .filter(|cells| cells.first() == Some(&first))
        .collect()
}

fn number(cell: &str) -> f64 {
    cell.parse().unwrap_or_else(|_| panic!("not a number: {cell:?}"))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-3 * b.abs().max(1e-9)
}

/// The page's pack tables decode as the manifest says, and its boundary
/// table and warnings are the run report's.
fn assert_page_matches_its_run(name: &str, out: &Path, seen: &Value) {
    let report: Value = serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    let m = manifest(&out.join("pack"));
    for c in m["channels"].as_array().unwrap() {
        let cname = c["name"].as_str().unwrap();
        let rows = rows_starting(seen, cname);
        let (offset, scale) = (c["decode"]["offset"].as_f64().unwrap(), c["decode"]["scale"].as_f64().unwrap());
        assert!(
            rows.iter().any(|r| r.len() == 7 && close(number(r[4]), offset) && close(number(r[5]), scale)),
            "{name}: channel {cname} (offset {offset}, scale {scale}) in {rows:?}"
        );
    }
    let boundaries = report["boundaries"].as_array().cloned().unwrap_or_default();
    // the opacities the default slicer TF was built with, as its manifest entry lists them
    let tf_meaning = m["luts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["name"] == "tf2d_default")
        .and_then(|l| l["meaning"].as_str().map(String::from));
    let gaussians: Option<Vec<Value>> = std::fs::read_to_string(out.join("pack/gaussians.json"))
        .ok()
        .map(|t| serde_json::from_str(&t).unwrap())
        .filter(|_| m["profile"] == "gaussian-tf");
    for (k, b) in boundaries.iter().enumerate() {
        let rows = rows_starting(seen, &(k + 1).to_string());
        if let (Some(meaning), Some(row)) = (&tf_meaning, rows.iter().find(|r| r.len() == 12))
            && meaning.contains("surface opacity")
        {
            let listed = meaning.split("surface opacity ").nth(k + 1).map(|t| &t[..5]);
            assert_eq!(listed, Some(row[10]), "{name}: boundary {k}'s surface opacity, {meaning}");
        }
        let centre = b["v_centre"].as_f64().unwrap();
        let g = b["g_peak"].as_f64().unwrap();
        assert!(
            rows.iter().any(|r| r.len() == 12 && close(number(r[3]), centre) && close(number(r[5]), g)),
            "{name}: boundary {k} (centre {centre}, G {g}) in {rows:?}"
        );
        // a gaussian-tf pack's k-th triangular Gaussian sits at the isovalue the page lists
        if let Some(tgtf) = gaussians.as_ref().and_then(|g| g.get(k)) {
            let at = tgtf["centre"][0].as_f64().unwrap();
            assert!(
                rows.iter().any(|r| r.len() == 12 && close(number(r[11]), at)),
                "{name}: TGTF {k} at {at} in {rows:?}"
            );
        }
    }
    let text: String = seen["tables"].as_array().unwrap().iter().map(|t| t.as_str().unwrap()).collect();
    let [nx, ny, nz] = [0, 1, 2].map(|i| report["dims"][i].as_u64().unwrap());
    assert!(text.contains(&format!("{nx} x {ny} x {nz}")), "{name}: the grid is stated");
}

#[test]
fn the_distance_tf_report_shows_every_figure_and_decodes_as_the_manifest() {
    let (dir, seen) = run_and_open(
        "distance-tf-shells",
        "distance-tf",
        None,
        // (at 80^3 the pulp, a ball of radius 6.4 voxels blurred by sigma 2, holds no plateau of its own)
        &["input.phantom=shells", "input.size=96", "histogram.hvol=true"],
    );
    let out = dir.path().join("out");
    assert_page_matches_its_run("distance-tf", &out, &seen);
    let report: Value = serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    assert_eq!(report["boundaries"].as_array().map(Vec::len), Some(3), "the shells' three boundaries");
    assert!(seen["title"].as_str().unwrap().contains("Shells phantom, 96^3"), "{}", seen["title"]);
}

#[test]
fn the_gaussian_tf_report_lists_the_isovalues_its_gaussians_sit_at() {
    // the engine's inserts (air | inserts, 0 to 229) are shown between the block's value and
    // theirs, not at their centre, 114.5, where the block's surface lies too
    let engine = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real/engine.nii.gz");
    let (dir, seen) = run_and_open("gaussian-tf-engine", "gaussian-tf", Some(&engine), &[]);
    let out = dir.path().join("out");
    assert_page_matches_its_run("engine", &out, &seen);
    let report: Value = serde_json::from_str(&std::fs::read_to_string(out.join("run_report.json")).unwrap()).unwrap();
    let gaussians: Vec<Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("pack/gaussians.json")).unwrap()).unwrap();
    let boundaries = report["boundaries"].as_array().unwrap();
    assert_eq!(gaussians.len(), boundaries.len());
    let moved = gaussians.iter().zip(boundaries).any(|(g, b)| {
        let (at, centre, high) =
            (g["centre"][0].as_f64().unwrap(), b["v_centre"].as_f64().unwrap(), b["v_high"].as_f64());
        !close(at, centre)
            && boundaries.iter().any(|o| o["v_high"].as_f64() < high && o["v_high"].as_f64().unwrap() < at)
    });
    assert!(moved, "{gaussians:?} at the centres of {boundaries:?}");
}

#[test]
fn the_slicer_report_of_a_real_mri_loads_in_the_browser() {
    let scan = mdtf_e2e::real_scan("ch2.nii.gz");
    let (dir, seen) = run_and_open("slicer-3dtf-colin27", "slicer-3dtf", Some(&scan), &[]);
    assert_page_matches_its_run("colin27", &dir.path().join("out"), &seen);
}
