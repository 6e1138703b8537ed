//! Reading and writing VTK unstructured grids (legacy `.vtk`, ASCII or
//! binary, versions up to 5.1; XML `.vtu`, ASCII, binary or zlib-compressed)
//! through the `vtkio` crate. Only tetrahedra are kept.

use crate::TetraError;
use crate::mesh::{MeshReport, PointArray, TetMesh};
use std::path::Path;
use vtkio::model::{
    Attribute, Attributes, ByteOrder, CellType, Cells, DataArray, DataSet, ElementType, IOBuffer, Piece,
    UnstructuredGridPiece, Version, VertexNumbers, Vtk,
};

fn read_error(path: &Path, message: impl std::fmt::Display) -> TetraError {
    TetraError::Read { path: path.to_path_buf(), message: message.to_string() }
}

/// Reads a tetrahedral mesh, taking the point array `scalar` as s (None: the
/// only one-component point array). Cells other than tetrahedra and
/// zero-volume tetrahedra are skipped and counted in the report.
pub fn read_mesh(path: &Path, scalar: Option<&str>) -> Result<(TetMesh, MeshReport), TetraError> {
    piece_to_mesh(path, load_piece(path)?, scalar)
}

/// What a VTK unstructured grid holds, for `mdtf info`: no scalar chosen,
/// nothing checked beyond what reading needs.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSummary {
    /// Number of points.
    pub points: usize,
    /// Cells by VTK cell type name.
    pub cells: std::collections::BTreeMap<String, usize>,
    /// Point arrays: name, components, finite min and max over all components.
    pub arrays: Vec<(String, usize, f64, f64)>,
    /// Cell arrays, the same way.
    pub cell_arrays: Vec<(String, usize, f64, f64)>,
    /// Bounding box of the points (min, max), world units.
    pub bounds: ([f64; 3], [f64; 3]),
}

/// Reads a `.vtk`/`.vtu` file and summarises it.
pub fn mesh_summary(path: &Path) -> Result<MeshSummary, TetraError> {
    let piece = load_piece(path)?;
    let coords: Vec<f64> =
        piece.points.cast_into::<f64>().ok_or_else(|| read_error(path, "point coordinates are not numbers"))?;
    let points = coords.len() / 3;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in coords.chunks_exact(3) {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let mut cells = std::collections::BTreeMap::new();
    for t in &piece.cells.types {
        *cells.entry(format!("{t:?}")).or_insert(0) += 1;
    }
    let summarise = |arrays: Vec<PointArray>| -> Vec<(String, usize, f64, f64)> {
        arrays
            .into_iter()
            .map(|a| {
                let (mn, mx) = a
                    .values
                    .iter()
                    .filter(|v| v.is_finite())
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
                (a.name, a.components, mn, mx)
            })
            .collect()
    };
    let arrays = summarise(point_arrays(path, &piece.data, points)?);
    let cell_arrays = summarise(data_arrays(path, &piece.data.cell, piece.cells.types.len(), "cell")?);
    Ok(MeshSummary { points, cells, arrays, cell_arrays, bounds: (lo, hi) })
}

thread_local! {
    /// Set while this thread runs the VTK parser inside [`catch_quietly`].
    static PARSING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f`, turning a panic into `Err` without the panic message reaching
/// the user's terminal (other threads' panics are reported as before).
fn catch_quietly<R>(f: impl FnOnce() -> R + std::panic::UnwindSafe) -> std::thread::Result<R> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !PARSING.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    PARSING.with(|p| p.set(true));
    let result = std::panic::catch_unwind(f);
    PARSING.with(|p| p.set(false));
    result
}

/// What is wrong with the point and cell counts of a VTU's `Piece` tags
/// (each a whole number that fits 64 bits), if anything.
fn piece_counts_problem(text: &str) -> Option<String> {
    for key in ["NumberOfPoints", "NumberOfCells"] {
        for (at, _) in text.match_indices(&format!("{key}=\"")) {
            let value = &text[at + key.len() + 2..];
            let value = &value[..value.find('"').unwrap_or(value.len())];
            if value.trim().parse::<u64>().is_err() {
                let shown: String = value.chars().take(40).collect();
                return Some(format!("{key}=\"{shown}\" is not a count (a whole number below 2^64)"));
            }
        }
    }
    None
}

/// The single unstructured-grid piece of a `.vtk`/`.vtu` file.
fn load_piece(path: &Path) -> Result<UnstructuredGridPiece, TetraError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "vtk" && ext != "vtu" {
        return Err(read_error(path, "not a VTK unstructured grid: expected a .vtk (legacy) or .vtu (XML) file"));
    }
    if !path.is_file() {
        return Err(read_error(path, "no such file"));
    }
    // what is wrong, in the file's own terms, when the parser fails
    let explained = || {
        let bytes = std::fs::read(path).ok()?;
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let binary = text.lines().nth(2).is_some_and(|l| l.trim().eq_ignore_ascii_case("BINARY"));
        match ext.as_str() {
            "vtk" if binary => {
                crate::legacy_binary_check::explain(&bytes).map(|why| format!("malformed legacy VTK (binary): {why}"))
            }
            "vtk" => crate::legacy_check::explain(&text).map(|why| format!("malformed legacy VTK: {why}")),
            _ => piece_counts_problem(&text).map(|why| format!("malformed VTU: {why}")),
        }
    };
    // vtkio asserts on some malformed inputs; a panic there is a bad file, not a bug of ours
    let imported = catch_quietly(|| Vtk::import(path)).map_err(|_| {
        read_error(path, explained().unwrap_or_else(|| "malformed VTK file (the parser gave up)".into()))
    })?;
    let mut vtk = imported.map_err(|e| match explained() {
        Some(why) => read_error(path, why),
        None => read_error(
            path,
            format!(
                "cannot parse: {e} (the parser's words; check that the file is complete and that \
                     its point and cell counts match the data)"
            ),
        ),
    })?;
    vtk.load_all_pieces().map_err(|e| read_error(path, format!("cannot load pieces: {e}")))?;
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        return Err(read_error(path, "the file holds no UNSTRUCTURED_GRID (only unstructured grids are meshes here)"));
    };
    let mut pieces_in = Vec::new();
    for piece in pieces {
        match piece {
            Piece::Inline(p) => pieces_in.push(*p),
            Piece::Loaded(ds) => match *ds {
                DataSet::UnstructuredGrid { pieces, .. } => {
                    for p in pieces {
                        if let Piece::Inline(p) = p {
                            pieces_in.push(*p);
                        }
                    }
                }
                _ => return Err(read_error(path, "a loaded piece is not an unstructured grid")),
            },
            Piece::Source(src, _) => return Err(read_error(path, format!("piece in another file ({src}) not loaded"))),
        }
    }
    if pieces_in.len() != 1 {
        return Err(read_error(path, format!("{} pieces; mdtf reads single-piece grids", pieces_in.len())));
    }
    Ok(pieces_in.remove(0))
}

fn piece_to_mesh(
    path: &Path,
    piece: UnstructuredGridPiece,
    scalar: Option<&str>,
) -> Result<(TetMesh, MeshReport), TetraError> {
    let coords: Vec<f64> =
        piece.points.cast_into::<f64>().ok_or_else(|| read_error(path, "point coordinates are not numbers"))?;
    if !coords.len().is_multiple_of(3) {
        return Err(read_error(path, format!("{} point coordinates is not a multiple of 3", coords.len())));
    }
    let points: Vec<[f64; 3]> = coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let types = &piece.cells.types;
    let cells = cell_lists(path, piece.cells.cell_verts, types.len())?;
    let mut report = MeshReport::default();
    let mut raw = Vec::new();
    for (c, (kind, verts)) in types.iter().zip(&cells).enumerate() {
        if *kind == CellType::Tetra {
            if verts.len() != 4 {
                return Err(read_error(path, format!("tetrahedron {c} has {} points", verts.len())));
            }
            raw.push([verts[0], verts[1], verts[2], verts[3]]);
        } else {
            *report.skipped_cells.entry(format!("{kind:?}")).or_insert(0) += 1;
        }
    }
    let mut arrays = point_arrays(path, &piece.data, points.len())?;
    // no point scalar (or not the one asked for) but a cell scalar: carried to the points
    let wanted_point = |a: &PointArray| a.components == 1 && scalar.is_none_or(|s| s == a.name);
    if !arrays.iter().any(wanted_point) {
        let cells_arrays = data_arrays(path, &piece.data.cell, types.len(), "cell")?;
        let singles: Vec<&PointArray> =
            cells_arrays.iter().filter(|a| a.components == 1 && scalar.is_none_or(|s| s == a.name)).collect();
        if let [one] = singles.as_slice() {
            let tet_values: Vec<f64> =
                types.iter().zip(&one.values).filter(|(k, _)| **k == CellType::Tetra).map(|(_, &v)| v).collect();
            let values = crate::cell_to_points(&points, &raw, &tet_values);
            arrays.push(PointArray { name: one.name.clone(), components: 1, values });
            report.scalar_from_cells = Some(one.name.clone());
        }
    }
    let present = || {
        let names: Vec<String> = arrays.iter().map(|a| format!("{} ({} comp.)", a.name, a.components)).collect();
        if names.is_empty() { "none".to_string() } else { names.join(", ") }
    };
    let chosen = match scalar {
        Some(name) => arrays.iter().position(|a| a.name == name && a.components == 1).ok_or_else(|| {
            TetraError::MissingArray { what: path.display().to_string(), name: name.into(), present: present() }
        })?,
        None => {
            let singles: Vec<usize> = (0..arrays.len()).filter(|&i| arrays[i].components == 1).collect();
            match singles.as_slice() {
                [one] => *one,
                [] => {
                    return Err(TetraError::MissingArray {
                        what: path.display().to_string(),
                        name: "(any one-component scalar)".into(),
                        present: present(),
                    });
                }
                _ => {
                    return Err(TetraError::Invalid(format!(
                        "{}: several scalar point arrays; choose one with tetra.scalar: {}",
                        path.display(),
                        present()
                    )));
                }
            }
        }
    };
    let (name, values) = (arrays[chosen].name.clone(), &arrays[chosen].values);
    if raw.is_empty() {
        let kinds = report.summary();
        return Err(TetraError::NoTetrahedra {
            what: path.display().to_string(),
            detail: if kinds.is_empty() { "the grid has no cells".into() } else { kinds },
        });
    }
    let scalar_values: Vec<f32> = values.iter().map(|&v| v as f32).collect();
    let (mesh, degenerate) =
        TetMesh::from_parts(&path.display().to_string(), points, raw, name, scalar_values, arrays)?;
    report.degenerate_tets = degenerate;
    Ok((mesh, report))
}

/// Point lists of every cell, from either connectivity layout.
fn cell_lists(path: &Path, verts: VertexNumbers, n_cells: usize) -> Result<Vec<Vec<u64>>, TetraError> {
    let mut out = Vec::with_capacity(n_cells);
    match verts {
        VertexNumbers::Legacy { vertices, .. } => {
            let mut i = 0;
            while i < vertices.len() {
                let n = vertices[i] as usize;
                let end = i + 1 + n;
                if end > vertices.len() {
                    return Err(read_error(path, "CELLS list ends inside a cell"));
                }
                out.push(vertices[i + 1..end].iter().map(|&v| v as u64).collect());
                i = end;
            }
        }
        VertexNumbers::XML { connectivity, mut offsets } => {
            // legacy 5.x files carry a leading 0, XML files do not
            if offsets.len() == n_cells + 1 && offsets.first() == Some(&0) {
                offsets.remove(0);
            }
            let mut start = 0usize;
            for &end in &offsets {
                let end = end as usize;
                if end < start || end > connectivity.len() {
                    return Err(read_error(path, format!("cell offset {end} outside the connectivity array")));
                }
                out.push(connectivity[start..end].to_vec());
                start = end;
            }
        }
    }
    if out.len() != n_cells {
        return Err(read_error(path, format!("{} cell point lists for {n_cells} cell types", out.len())));
    }
    Ok(out)
}

/// Every numeric point array (legacy attributes and FIELD arrays alike).
fn point_arrays(path: &Path, data: &Attributes, n_points: usize) -> Result<Vec<PointArray>, TetraError> {
    data_arrays(path, &data.point, n_points, "point")
}

/// The numeric arrays of one attribute list (`what`: "point" or "cell"), `n` tuples each.
fn data_arrays(path: &Path, list: &[Attribute], n: usize, what: &str) -> Result<Vec<PointArray>, TetraError> {
    let mut out = Vec::new();
    let mut push = |name: &str, components: usize, buf: &IOBuffer| -> Result<(), TetraError> {
        let values: Vec<f64> =
            buf.cast_into::<f64>().ok_or_else(|| read_error(path, format!("{what} array {name} is not numeric")))?;
        if components == 0 || values.len() != components * n {
            return Err(read_error(
                path,
                format!("{what} array {name} has {} values for {n} {what}s x {components}", values.len()),
            ));
        }
        out.push(PointArray { name: name.into(), components, values });
        Ok(())
    };
    for attr in list {
        match attr {
            Attribute::DataArray(DataArray { name, elem, data }) => {
                if matches!(elem, ElementType::LookupTable) {
                    continue;
                }
                push(name, elem.num_comp() as usize, data)?;
            }
            Attribute::Field { data_array, .. } => {
                for a in data_array {
                    push(&a.name, a.elem as usize, &a.data)?;
                }
            }
        }
    }
    Ok(out)
}

/// Writes the mesh with its scalar, its input arrays, `added` point arrays
/// (f64) and `added_f32` ones (name, components, values): VTK XML (`.vtu`,
/// streamed, see [`crate::vtu_writer`]) or legacy binary (`.vtk`, built in
/// memory by vtkio: for small meshes) by the extension. Atomic.
pub fn write_mesh(
    path: &Path,
    mesh: &TetMesh,
    added: &[PointArray],
    added_f32: &[(&str, usize, &[f32])],
) -> Result<(), TetraError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "vtu" => {
            mdtf_volume::write_file_atomically(path, |w| {
                let mut w = std::io::BufWriter::new(w);
                crate::vtu_writer::write_vtu(&mut w, mesh, added, added_f32)?;
                std::io::Write::flush(&mut w)
            })?;
            return Ok(());
        }
        "vtk" => {}
        _ => return Err(TetraError::Invalid(format!("{}: write a .vtu or .vtk file", path.display()))),
    }
    let mut point_data = Vec::new();
    if !mesh.arrays.iter().any(|a| a.name == mesh.scalar_name) {
        point_data.push(data_array(&mesh.scalar_name, 1, mesh.scalar.iter().map(|&v| v as f64).collect()));
    }
    for a in mesh.arrays.iter().chain(added) {
        point_data.push(data_array(&a.name, a.components, a.values.clone()));
    }
    for (name, components, values) in added_f32 {
        point_data.push(data_array(name, *components, values.iter().map(|&v| v as f64).collect()));
    }
    let n = mesh.tets.len();
    let piece = UnstructuredGridPiece {
        points: IOBuffer::F64(mesh.points.iter().flatten().copied().collect()),
        cells: Cells {
            cell_verts: VertexNumbers::XML {
                connectivity: mesh.tets.iter().flatten().map(|&i| i as u64).collect(),
                offsets: (1..=n as u64).map(|c| 4 * c).collect(),
            },
            types: vec![CellType::Tetra; n],
        },
        data: Attributes { point: point_data, cell: Vec::new() },
    };
    let vtk = Vtk {
        version: Version::new_legacy(5, 1),
        title: "mdtf tetrahedral mesh".into(),
        byte_order: ByteOrder::BigEndian,
        data: DataSet::inline(piece),
        file_path: None,
    };
    mdtf_volume::write_file_atomically(path, |w| {
        use vtkio::writer::WriteVtk;
        vtkio::writer::BinaryWriter(w).write_vtk(vtk).map(|_| ()).map_err(|e| std::io::Error::other(e.to_string()))
    })?;
    Ok(())
}

fn data_array(name: &str, components: usize, values: Vec<f64>) -> Attribute {
    let elem = if components == 1 {
        ElementType::Scalars { num_comp: 1, lookup_table: None }
    } else {
        ElementType::Generic(components as u32)
    };
    Attribute::DataArray(DataArray { name: name.into(), elem, data: IOBuffer::F64(values) })
}
