//! Tetrahedral meshes for mdtf (Song et al., pre-integrated bivariate
//! transfer functions on unstructured grids): VTK reading and writing,
//! meshes of regular volumes, per-vertex gradients and g, per-cell (s, g)
//! boxes for conservative culling, and the `projected-tetrahedra` pack
//! (arrays + the pre-integration tables of [`mdtf_pack::TetTableParams`]).
//!
//! The tables themselves, and the derivation of each integral from the
//! paper (eq. 2-3, sections 4.2-4.4), are in `mdtf_pack`'s `tet_tables`
//! module ([`mdtf_pack::front_back_tables`] and its siblings): they are pure
//! functions of the transfer-function widgets, not of the mesh.
//!
//! Units: positions and lengths in world units, s in the input's units, g
//! in s units per world unit.

mod budget;
mod cells;
mod from_volume;
mod gradient;
mod legacy_binary_check;
mod legacy_check;
mod mesh;
mod pack_mesh;
mod vtk_io;
pub mod vtu_writer;

pub use budget::{Coarsened, DEFAULT_MAX_TETRAHEDRA, block_average, coarsening, tetrahedra_of, tetrahedralise_within};
pub use cells::{CellInfo, cell_infos, cull, visible_cells};
pub use from_volume::{TetScheme, tetrahedralise};
pub use gradient::{GradientMethod, VertexStars, magnitudes, tet_gradient, vertex_gradients};
pub use mesh::{DEGENERATE_RATIO, MeshReport, PointArray, TetMesh, cell_to_points, max_edge, six_volume};
pub use pack_mesh::write_pack;
pub use vtk_io::{MeshSummary, mesh_summary, read_mesh, write_mesh};

use mdtf_pack::{Lut, TetTable, TetTableParams, Tf1d, TfFile};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Errors of the tetra stage.
#[derive(Debug, thiserror::Error)]
pub enum TetraError {
    /// The file could not be read as a VTK unstructured grid.
    #[error("{path}: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// No tetrahedra to work on.
    #[error("{what}: no tetrahedra ({detail})")]
    NoTetrahedra {
        /// The source.
        what: String,
        /// Why.
        detail: String,
    },
    /// A cell refers to a point that does not exist.
    #[error("{what}: tetrahedron {cell} uses point {index}, but the mesh has {points} points")]
    IndexOutOfRange {
        /// The source.
        what: String,
        /// Cell index (among the file's tetrahedra).
        cell: usize,
        /// The bad point index.
        index: u64,
        /// Number of points.
        points: usize,
    },
    /// The scalar array asked for is not there.
    #[error("{what}: no one-component point array {name} (point arrays present: {present})")]
    MissingArray {
        /// The source.
        what: String,
        /// The name asked for.
        name: String,
        /// The arrays the file has.
        present: String,
    },
    /// Anything else wrong with the input or the parameters.
    #[error("{0}")]
    Invalid(String),
    /// Writing failed.
    #[error(transparent)]
    Volume(#[from] mdtf_volume::VolumeError),
    /// Writing the pack failed.
    #[error(transparent)]
    Pack(#[from] mdtf_pack::PackError),
}

/// Parameters of the tetra stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TetraParams {
    /// Point array used as the scalar s (default: the only one-component point array).
    #[serde(default)]
    pub scalar: Option<String>,
    /// Tetrahedra per grid cell when meshing a volume (5 or 6; default 6, whose
    /// symmetric vertex stars make the per-vertex gradients second-order accurate).
    #[serde(default = "six")]
    pub tets: TetScheme,
    /// How per-vertex gradients are estimated.
    #[serde(default = "least_squares")]
    pub gradient: GradientMethod,
    /// The pre-integration tables and their sizes.
    #[serde(default)]
    pub tables: TetTableParams,
    /// Most tetrahedra a volume is meshed into: above it the volume is
    /// averaged over blocks of k x k x k voxels first (see [`coarsening`]);
    /// 0 meshes every voxel. Meshes read from files are kept as they are.
    #[serde(default = "default_max_tetrahedra")]
    pub max_tetrahedra: u64,
}

fn default_max_tetrahedra() -> u64 {
    DEFAULT_MAX_TETRAHEDRA
}

fn least_squares() -> GradientMethod {
    GradientMethod::LeastSquares
}

fn six() -> TetScheme {
    TetScheme::Six
}

impl Default for TetraParams {
    fn default() -> Self {
        TetraParams {
            scalar: None,
            tets: TetScheme::Six,
            gradient: GradientMethod::LeastSquares,
            tables: TetTableParams::default(),
            max_tetrahedra: DEFAULT_MAX_TETRAHEDRA,
        }
    }
}

/// Everything the tetra stage computes for one mesh.
#[derive(Debug, Clone)]
pub struct TetraOutput {
    /// Per-vertex gradient of s (s units per world unit).
    pub gradients: Vec<[f32; 3]>,
    /// Per-vertex g = |gradient|.
    pub g: Vec<f32>,
    /// Per-cell boxes, longest edges and smallest value differences.
    pub cells: Vec<CellInfo>,
    /// Longest edge of the mesh (world units).
    pub max_edge_length: f64,
    /// The pre-integration tables asked for.
    pub luts: Vec<Lut>,
    /// Longest segment D covered by the tables (world units).
    pub d_max: f64,
    /// Largest extinction on the F/B tables (per world unit).
    pub tau_max: f64,
    /// Per cell, 1 when it may be visible under the TF's widgets and 0 when
    /// the renderer can skip it ([`visible_cells`]); None without a TF with widgets.
    pub visible: Option<Vec<u8>>,
    /// The gradient method used.
    pub gradient: GradientMethod,
    /// What was asked for and left out, one sentence each (for stderr and run reports).
    pub notes: Vec<String>,
}

/// Runs the stage on a mesh: gradients, g, cells, tables and, given a TF
/// with widgets, the visible-cell mask. The classic 1D
/// table needs `tf`'s `tf1d` (over its `v_range`); without one it is left
/// out, with a note: a 1D TF the user did not give would be a picture of
/// nothing in the data.
pub fn run(mesh: &TetMesh, params: &TetraParams, tf: Option<&TfFile>) -> Result<TetraOutput, TetraError> {
    run_with_progress(mesh, params, tf, &|_| {})
}

/// [`run`], calling `on_step` with the name of each step as it starts
/// (gradients, cells, then each table), for progress on large meshes.
pub fn run_with_progress(
    mesh: &TetMesh,
    params: &TetraParams,
    tf: Option<&TfFile>,
    on_step: &dyn Fn(&str),
) -> Result<TetraOutput, TetraError> {
    on_step("per-vertex gradients");
    let gradients = vertex_gradients(mesh, params.gradient);
    let g = magnitudes(&gradients);
    on_step("cell boxes");
    let cells = cell_infos(mesh, &g);
    let max_edge_length = cells.iter().map(|c| c.max_edge as f64).fold(0.0, f64::max);
    let t = &params.tables;
    let d_max = t.d_max.unwrap_or(max_edge_length);
    let tau_max = t.tau_max.unwrap_or(16.0 / d_max);
    for (name, x) in [("d_max", d_max), ("tau_max", tau_max), ("p_max", t.p_max), ("t_max", t.t_max)] {
        if !(x.is_finite() && x > 0.0) {
            return Err(TetraError::Invalid(format!("tables.{name} must be a positive number, not {x}")));
        }
    }
    for (name, x) in [("kappa_max", t.kappa_max), ("lambda_max", t.lambda_max)] {
        if !(x.is_finite() && x >= 0.0) {
            return Err(TetraError::Invalid(format!("tables.{name} must be >= 0, not {x}")));
        }
    }
    let sizes: [(&str, &[usize]); 5] = [
        ("fb_size", &t.fb_size),
        ("gaussian_size", &t.gaussian_size),
        ("triangle_size", &t.triangle_size),
        ("sinusoid_size", &t.sinusoid_size),
        ("preint_size", &t.preint_size),
    ];
    for (name, s) in sizes {
        if s.iter().any(|&n| !(2..=4096).contains(&n)) || s.iter().product::<usize>() > 1 << 26 {
            return Err(TetraError::Invalid(format!(
                "tables.{name} {s:?}: every size must be in 2..=4096 and the table at most 2^26 cells"
            )));
        }
    }
    let mut luts = Vec::new();
    let mut notes = Vec::new();
    for table in &t.tables {
        on_step(&format!(
            "{} table",
            serde_json::to_value(table).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default()
        ));
        match table {
            TetTable::FrontBack => luts.extend(mdtf_pack::front_back_tables(t.fb_size, tau_max, d_max)),
            TetTable::Gaussian => luts.push(mdtf_pack::gaussian_table(t.gaussian_size, t.p_max, t.t_max)),
            TetTable::Triangle => luts.extend(mdtf_pack::triangle_tables(t.triangle_size, t.kappa_max)),
            TetTable::Sinusoid => luts.push(mdtf_pack::sinusoid_table(t.sinusoid_size, t.lambda_max)),
            TetTable::Preintegration1d => match tf.and_then(|f| f.tf1d.clone().map(|s| (s, f.v_range))) {
                Some((samples, range)) => {
                    luts.push(mdtf_pack::preintegration_1d_table(&Tf1d { samples }, range, t.preint_size, d_max));
                }
                None => notes.push(
                    "the classic 1D pre-integration table (preintegration-1d) is left out: it needs a TF file \
                     with tf1d (pack.tf)"
                        .into(),
                ),
            },
        }
    }
    let visible = tf.filter(|f| !f.widgets.is_empty()).map(|f| {
        on_step("visible cells");
        let mask = visible_cells(&cells, f);
        let shown = mask.iter().filter(|&&m| m == 1).count();
        if shown == 0 {
            notes.push(format!(
                "no cell is visible under the TF's widgets: none of the {} cells' (s, g) ranges meets one",
                cells.len()
            ));
        }
        mask
    });
    Ok(TetraOutput {
        gradients,
        g,
        cells,
        max_edge_length,
        luts,
        d_max,
        tau_max,
        visible,
        gradient: params.gradient,
        notes,
    })
}
