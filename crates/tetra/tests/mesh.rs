//! The tetra stage against analytic truth and brute force: per-vertex g on
//! the meshed erf sphere, exactness on linear fields, conforming meshes,
//! cell boxes and culling, VTK round trips and bad input.

use mdtf_datagen::erf_sphere;
use mdtf_tetra::{
    GradientMethod, MeshReport, PointArray, TetMesh, TetScheme, TetraError, cell_infos, cull, magnitudes, read_mesh,
    six_volume, tetrahedralise, vertex_gradients, write_mesh,
};
use mdtf_volume::Geometry;
use std::collections::HashMap;

/// Mean relative error of per-vertex g against the analytic g over the
/// points with |x| < 2 sigma, on a 64^3 sphere of radius 20, sigma 3.
fn sphere_g_error(scheme: TetScheme, spacing: [f64; 3], method: GradientMethod) -> f64 {
    let dims = [0, 1, 2].map(|a| (64.0 / spacing[a]).round() as usize);
    let phantom = erf_sphere(Geometry::new(dims, spacing), 20.0, 3.0, 0.0, 255.0, None);
    let mesh = tetrahedralise(&phantom.volume(), scheme, "v").unwrap();
    let g = magnitudes(&vertex_gradients(&mesh, method));
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, &gv) in mesh.points.iter().zip(&g) {
        let truth = phantom.at(*p);
        // skip the outer layer of points, whose stars are cut by the grid's edge
        let inside =
            (0..3).all(|a| p[a] > spacing[a] * 0.5 && p[a] < (dims[a] - 1) as f64 * spacing[a] - spacing[a] * 0.5);
        if truth.x.abs() < 6.0 && inside {
            sum += (gv as f64 - truth.g).abs() / truth.g;
            n += 1;
        }
    }
    assert!(n > 10_000, "{n} shell points");
    sum / n as f64
}

#[test]
fn vertex_g_on_the_meshed_erf_sphere_is_within_two_percent() {
    use GradientMethod::{LeastSquares, VolumeAverage};
    let six = sphere_g_error(TetScheme::Six, [1.0; 3], LeastSquares);
    let five = sphere_g_error(TetScheme::Five, [1.0; 3], LeastSquares);
    let average = sphere_g_error(TetScheme::Six, [1.0; 3], VolumeAverage);
    let aniso = sphere_g_error(TetScheme::Six, [1.0, 1.0, 2.0], LeastSquares);
    eprintln!(
        "mean relative g error in |x| < 2 sigma: least squares 6 tets {six:.4}, 5 tets {five:.4}, (1,1,2) voxels {aniso:.4}; volume average {average:.4}"
    );
    assert!(six <= 0.02 && five <= 0.02 && average <= 0.02, "{six} {five} {average}");
    // voxels twice as long along z sample sigma = 3 with 1.5 samples: the bound doubles
    assert!(aniso <= 0.04, "anisotropic: {aniso}");
}
/// A small irregular mesh: a jittered grid, 5 tetrahedra per cell.
fn jittered_mesh(f: impl Fn([f64; 3]) -> f64) -> TetMesh {
    let g = Geometry::new([6, 5, 4], [1.0, 1.3, 0.8]);
    let mut mesh = tetrahedralise(&mdtf_volume::Volume::zeros(g), TetScheme::Five, "s").unwrap();
    for (i, p) in mesh.points.iter_mut().enumerate() {
        let h = (i as f64 * 0.618_033_988_7).fract() - 0.5;
        let k = (i as f64 * 0.414_213_562_3).fract() - 0.5;
        *p = [p[0] + 0.2 * h, p[1] + 0.2 * k, p[2] + 0.15 * h * k];
    }
    mesh.scalar = mesh.points.iter().map(|&p| f(p) as f32).collect();
    mesh
}

#[test]
fn gradients_are_exact_for_linear_fields_on_irregular_meshes() {
    let mesh = jittered_mesh(|p| 3.0 * p[0] - 2.0 * p[1] + 0.5 * p[2] + 7.0);
    for method in [GradientMethod::LeastSquares, GradientMethod::VolumeAverage] {
        for g in vertex_gradients(&mesh, method) {
            assert!((g[0] - 3.0).abs() < 1e-4 && (g[1] + 2.0).abs() < 1e-4 && (g[2] - 0.5).abs() < 1e-4, "{g:?}");
        }
    }
}

#[test]
fn meshes_of_grids_are_conforming_and_fill_the_box() {
    for scheme in [TetScheme::Five, TetScheme::Six] {
        let geometry = Geometry::new([5, 4, 6], [0.5, 1.0, 2.0]);
        let mesh = tetrahedralise(&mdtf_volume::Volume::zeros(geometry), scheme, "v").unwrap();
        let total: f64 = mesh
            .tets
            .iter()
            .map(|t| {
                six_volume(
                    mesh.points[t[0] as usize],
                    mesh.points[t[1] as usize],
                    mesh.points[t[2] as usize],
                    mesh.points[t[3] as usize],
                )
                .abs()
                    / 6.0
            })
            .sum();
        assert!((total - 2.0 * 3.0 * 10.0).abs() < 1e-9, "{scheme:?}: volume {total}");
        // every face is shared by two tetrahedra, or lies on the box surface
        let mut faces: HashMap<[u32; 3], usize> = HashMap::new();
        for t in &mesh.tets {
            for skip in 0..4 {
                let mut f: Vec<u32> = (0..4).filter(|&i| i != skip).map(|i| t[i]).collect();
                f.sort();
                *faces.entry([f[0], f[1], f[2]]).or_default() += 1;
            }
        }
        let on_surface = |f: &[u32; 3]| {
            (0..3).any(|a| {
                let c: Vec<f64> = f.iter().map(|&i| mesh.points[i as usize][a]).collect();
                let hi = [2.0, 3.0, 10.0][a];
                c.iter().all(|&x| x.abs() < 1e-12) || c.iter().all(|&x| (x - hi).abs() < 1e-12)
            })
        };
        for (f, n) in &faces {
            assert!(*n == 2 || (*n == 1 && on_surface(f)), "{scheme:?}: face {f:?} used {n} times");
        }
    }
}

#[test]
fn cell_boxes_hold_their_vertices_and_culling_keeps_every_touched_cell() {
    let mesh = jittered_mesh(|p| (p[0] * 1.7).sin() * 50.0 + p[1] * p[2] * 10.0);
    let g = magnitudes(&vertex_gradients(&mesh, GradientMethod::LeastSquares));
    let cells = cell_infos(&mesh, &g);
    for (t, c) in mesh.tets.iter().zip(&cells) {
        for &v in t {
            let (s, gv) = (mesh.scalar[v as usize], g[v as usize]);
            assert!(c.s_range[0] <= s && s <= c.s_range[1] && c.g_range[0] <= gv && gv <= c.g_range[1]);
        }
    }
    let (s_lo, s_hi) = cells.iter().fold((f32::MAX, f32::MIN), |(a, b), c| (a.min(c.s_range[0]), b.max(c.s_range[1])));
    let (g_lo, g_hi) = cells.iter().fold((f32::MAX, f32::MIN), |(a, b), c| (a.min(c.g_range[0]), b.max(c.g_range[1])));
    for w in 0..200 {
        let r = |k: f32| (w as f32 * k).sin() * 0.5 + 0.5;
        let s0 = s_lo + (s_hi - s_lo) * r(1.3);
        let g0 = g_lo + (g_hi - g_lo) * r(2.9);
        let widget_s = [s0, s0 + (s_hi - s_lo) * 0.1 * r(0.7)];
        let widget_g = [g0, g0 + (g_hi - g_lo) * 0.1 * r(5.1)];
        let kept = cull(&cells, widget_s, widget_g);
        for (c, t) in mesh.tets.iter().enumerate() {
            let touched = t.iter().any(|&v| {
                let (s, gv) = (mesh.scalar[v as usize], g[v as usize]);
                widget_s[0] <= s && s <= widget_s[1] && widget_g[0] <= gv && gv <= widget_g[1]
            });
            if touched {
                assert!(
                    kept.binary_search(&(c as u32)).is_ok(),
                    "widget {w}: cell {c} has a vertex inside but was culled"
                );
            }
        }
    }
}

#[test]
fn min_value_difference_and_longest_edge_match_brute_force() {
    let mesh = jittered_mesh(|p| p[0] * 10.0 + p[1] * p[1]);
    let g = magnitudes(&vertex_gradients(&mesh, GradientMethod::LeastSquares));
    for (t, c) in mesh.tets.iter().zip(cell_infos(&mesh, &g)) {
        let mut diff = f32::MAX;
        let mut edge = 0.0f64;
        for a in 0..4 {
            for b in 0..4 {
                if a != b {
                    diff = diff.min((mesh.scalar[t[a] as usize] - mesh.scalar[t[b] as usize]).abs());
                    let (p, q) = (mesh.points[t[a] as usize], mesh.points[t[b] as usize]);
                    edge = edge.max(((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt());
                }
            }
        }
        assert_eq!(c.s_min_diff, diff);
        assert!((c.max_edge as f64 - edge).abs() < 1e-5);
    }
}

#[test]
fn vtu_and_vtk_round_trips_keep_points_cells_and_arrays() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = jittered_mesh(|p| p[0] - p[2]);
    mesh.arrays.push(PointArray {
        name: "velocity".into(),
        components: 3,
        values: (0..mesh.points.len() * 3).map(|i| i as f64 * 0.25).collect(),
    });
    let extra = [PointArray { name: "g".into(), components: 1, values: vec![1.5; mesh.points.len()] }];
    for name in ["m.vtu", "m.vtk"] {
        let path = dir.path().join(name);
        write_mesh(&path, &mesh, &extra, &[("h", 1, &vec![0.5f32; mesh.points.len()])]).unwrap();
        let (back, report) = read_mesh(&path, Some("s")).unwrap();
        assert_eq!(report, MeshReport::default());
        assert_eq!(back.points, mesh.points, "{name}");
        assert_eq!(back.tets, mesh.tets, "{name}");
        assert_eq!(back.scalar, mesh.scalar, "{name}");
        let names: Vec<&str> = back.arrays.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["s", "velocity", "g", "h"], "{name}");
        assert_eq!(back.arrays[1], mesh.arrays[0], "{name}");
    }
}

fn write_text(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const HEAD: &str = "# vtk DataFile Version 4.2\nbad\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 5 float\n0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\n";

#[test]
fn bad_meshes_are_refused_with_clear_messages() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // only triangles
    let p = write_text(
        d,
        "tri.vtk",
        &format!(
            "{HEAD}CELLS 1 4\n3 0 1 2\nCELL_TYPES 1\n5\nPOINT_DATA 5\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4 5\n"
        ),
    );
    let e = read_mesh(&p, None).unwrap_err().to_string();
    assert!(e.contains("no tetrahedra") && e.contains("1 Triangle cell(s) skipped"), "{e}");
    // index out of range
    let p = write_text(
        d,
        "idx.vtk",
        &format!(
            "{HEAD}CELLS 1 5\n4 0 1 2 9\nCELL_TYPES 1\n10\nPOINT_DATA 5\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4 5\n"
        ),
    );
    let e = read_mesh(&p, None).unwrap_err();
    assert!(matches!(e, TetraError::IndexOutOfRange { index: 9, points: 5, .. }), "{e}");
    // missing scalar: the message lists what is there
    let p = write_text(
        d,
        "miss.vtk",
        &format!(
            "{HEAD}CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\nPOINT_DATA 5\nSCALARS density float 1\nLOOKUP_TABLE default\n1 2 3 4 5\n"
        ),
    );
    let e = read_mesh(&p, Some("temperature")).unwrap_err().to_string();
    assert!(e.contains("temperature") && e.contains("density (1 comp.)"), "{e}");
    // one good and one flat tetrahedron, plus a triangle: counted and said
    let p = write_text(
        d,
        "flat.vtk",
        &format!(
            "{HEAD}CELLS 3 14\n4 0 1 2 3\n4 0 1 2 1\n3 0 1 2\nCELL_TYPES 3\n10\n10\n5\nPOINT_DATA 5\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4 5\n"
        ),
    );
    let (mesh, report) = read_mesh(&p, None).unwrap();
    assert_eq!(mesh.tets.len(), 1);
    assert_eq!(report.degenerate_tets, 1);
    assert_eq!(report.summary(), "1 Triangle cell(s) skipped (not tetrahedra); 1 zero-volume tetrahedra skipped");
    // all degenerate
    let p = write_text(
        d,
        "allflat.vtk",
        &format!(
            "{HEAD}CELLS 1 5\n4 0 1 2 1\nCELL_TYPES 1\n10\nPOINT_DATA 5\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4 5\n"
        ),
    );
    assert!(read_mesh(&p, None).unwrap_err().to_string().contains("zero volume"));
    // not VTK at all, wrong extension, missing file
    let p = write_text(d, "junk.vtu", "<VTKFile type=\"UnstructuredGrid\"><garbage");
    assert!(matches!(read_mesh(&p, None), Err(TetraError::Read { .. })));
    let p = write_text(
        d,
        "junk.vtk",
        "# vtk DataFile Version 4.2\nx\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 99 float\n\x01\x02",
    );
    assert!(matches!(read_mesh(&p, None), Err(TetraError::Read { .. })));
    assert!(read_mesh(&d.join("mesh.stl"), None).unwrap_err().to_string().contains(".vtk"));
    assert!(read_mesh(&d.join("none.vtu"), None).unwrap_err().to_string().contains("no such file"));
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let phantom = erf_sphere(Geometry::new([24, 24, 24], [1.0; 3]), 8.0, 2.0, 0.0, 100.0, None);
    let mesh = tetrahedralise(&phantom.volume(), TetScheme::Six, "v").unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| vertex_gradients(&mesh, GradientMethod::LeastSquares));
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap()
        .install(|| vertex_gradients(&mesh, GradientMethod::LeastSquares));
    assert_eq!(one, two);
}

#[test]
fn mesh_summary_counts_cells_by_type_and_ranges_arrays() {
    let dir = tempfile::tempdir().unwrap();
    let head = "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 5 float\n0 0 0 1 0 0 0 1 0 0 0 1 2 2 3\n";
    let text = format!(
        "{head}CELLS 3 14\n4 0 1 2 3\n4 1 2 3 4\n3 0 1 2\nCELL_TYPES 3\n10\n10\n5\nPOINT_DATA 5\nSCALARS density float 1\nLOOKUP_TABLE default\n1 2 3 4 -5\n"
    );
    let path = dir.path().join("m.vtk");
    std::fs::write(&path, text).unwrap();
    let m = mdtf_tetra::mesh_summary(&path).unwrap();
    assert_eq!(m.points, 5);
    assert_eq!(m.cells.get("Tetra"), Some(&2));
    assert_eq!(m.cells.get("Triangle"), Some(&1));
    assert_eq!(m.arrays, vec![("density".to_string(), 1, -5.0, 4.0)]);
    assert_eq!(m.bounds, ([0.0, 0.0, 0.0], [2.0, 2.0, 3.0]));
}

#[test]
fn the_classic_1d_table_comes_from_the_users_tf_or_is_left_out_with_a_note() {
    let phantom = erf_sphere(Geometry::new([12, 12, 12], [1.0; 3]), 4.0, 1.5, 0.0, 100.0, None);
    let mesh = tetrahedralise(&phantom.volume(), TetScheme::Six, "v").unwrap();
    let mut params = mdtf_tetra::TetraParams::default();
    params.tables.tables = vec![mdtf_pack::TetTable::Preintegration1d];
    params.tables.preint_size = [8, 8, 4];
    let without = mdtf_tetra::run(&mesh, &params, None).unwrap();
    assert!(
        without.luts.is_empty(),
        "no TF given, no table: {:?}",
        without.luts.iter().map(|l| &l.name).collect::<Vec<_>>()
    );
    assert!(without.notes[0].contains("needs a TF file with tf1d"), "{:?}", without.notes);
    let tf = mdtf_pack::parse_tf(r#"{"v_range": [0, 100], "g_range": [0, 1], "tf1d": [[1, 1, 1, 0], [1, 0, 0, 2]]}"#)
        .unwrap();
    let with = mdtf_tetra::run(&mesh, &params, Some(&tf)).unwrap();
    assert_eq!(with.luts.len(), 1);
    assert_eq!(with.luts[0].name, "pt_preintegration_1d");
    assert_eq!((with.luts[0].axes[0].min, with.luts[0].axes[0].max), (0.0, 100.0), "over the TF's v_range");
    assert!(with.notes.is_empty());
}
