//! Boundary detection and the default transfer function on real volumes of
//! `../shared/data/real` (see its README), with the same defaults for all.
//!
//! The references were read off each volume's (v, g) histogram, drawn with
//! every v column scaled to its own maximum (so that each column's typical
//! g shows), before the detection was tuned:
//! - engine (industrial CT, u8): air at v = 0 and the cast block at about
//!   144 (the two dips of the columns' typical g), one clear arch between
//!   them peaking near g = 45 at v = 70; denser inserts near 230.
//! - bonsai (CT, u8): still values near 0, 40, 134 and 203, arches between
//!   40 and 134 and between 134 and 203 (two humps, g up to about 30-40).
//! - heptane (a simulated gas jet): soft fronts, no plateau but the ambient
//!   value 0: no boundary.

use mdtf_e2e::{mdtf_ok, read_rgb_png, shipped_pipeline};
use std::path::{Path, PathBuf};

/// A volume of `../shared/data/real`.
fn real(name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real").join(name);
    assert!(path.is_file(), "{} is missing (the shared real volumes)", path.display());
    path
}

/// Runs `pipeline` on `input` into `out`; returns the run report.
fn run(pipeline: &str, input: &Path, out: &Path) -> serde_json::Value {
    let p = shipped_pipeline(pipeline);
    mdtf_ok(&["run", p.to_str().unwrap(), "--input", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
    serde_json::from_slice(&std::fs::read(out.join("run_report.json")).unwrap()).unwrap()
}

/// (v_low, v_high) of every boundary of a run report.
fn boundaries(report: &serde_json::Value) -> Vec<(f64, f64)> {
    // (a report leaves the list out when it is empty)
    report["boundaries"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|b| (b["v_low"].as_f64().unwrap(), b["v_high"].as_f64().unwrap()))
        .collect()
}

/// The shares of the lit preview pixels whose hue is orange, blue and green
/// (the default TF's first three boundary colours), and the lit share.
fn colour_shares(preview: &Path) -> ([f64; 3], f64) {
    let (w, h, px) = read_rgb_png(preview);
    let mut counts = [0usize; 3];
    let mut lit = 0usize;
    for c in px.chunks_exact(3) {
        let (r, g, b) = (c[0] as i32, c[1] as i32, c[2] as i32);
        if r + g + b < 30 {
            continue;
        }
        lit += 1;
        if r > b + 40 && r >= g {
            counts[0] += 1;
        } else if b > r + 20 {
            counts[1] += 1;
        } else if g > r + 20 && g > b + 20 {
            counts[2] += 1;
        }
    }
    (counts.map(|n| n as f64 / lit.max(1) as f64), lit as f64 / (w * h) as f64)
}

/// Runs the default slicer-3dtf on the real volume `name`, asserts that each
/// of `pairs` (low, high) is found (both materials within 10), and that two
/// boundary colours each cover at least 5 % of the lit preview.
fn shows_in_their_own_colours(name: &str, pairs: &[(f64, f64)]) {
    let dir = tempfile::tempdir().unwrap();
    let found = boundaries(&run("slicer-3dtf", &real(name), dir.path()));
    eprintln!("{name}: {found:?}");
    for &(low, high) in pairs {
        let near = |&(a, b): &(f64, f64)| (a - low).abs() < 10.0 && (b - high).abs() < 10.0;
        assert!(found.iter().any(near), "{name}: {low} | {high} in {found:?}");
    }
    let (shares, lit) = colour_shares(&dir.path().join("preview.png"));
    eprintln!("{name} preview: {shares:?} of {lit}");
    assert!(shares.iter().filter(|&&s| s >= 0.05).count() >= 2, "{name}: {shares:?}");
}

#[test]
fn the_engine_block_and_its_inserts_show_in_their_own_colours() {
    // air | cast block
    shows_in_their_own_colours("engine.nii.gz", &[(0.0, 144.0)]);
}

#[test]
fn the_bonsai_shows_its_materials_in_their_own_colours() {
    shows_in_their_own_colours("bonsai.nii.gz", &[(134.0, 203.0), (40.0, 134.0)]);
}

#[test]
fn a_smooth_simulation_field_has_no_boundary_and_its_fallback_still_shows_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("slicer");
    let report = run("slicer-3dtf", &real("heptane.nii.gz"), &out);
    assert!(boundaries(&report).is_empty(), "{:?}", boundaries(&report));
    let warnings = report["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("no boundary found")), "{warnings:?}");
    let (_, lit) = colour_shares(&out.join("preview.png"));
    assert!(lit >= 0.02, "{lit}");
    // peak finding writes its TF, its tables and its preview even so
    let out = dir.path().join("peak");
    run("peak-finding", &real("heptane.nii.gz"), &out);
    assert!(out.join("pack/tf2d_u8.nrrd").is_file());
    let (_, lit) = colour_shares(&out.join("preview.png"));
    assert!(lit >= 0.02, "{lit}");
}
