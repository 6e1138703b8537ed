//! The stage subcommands' arguments (derive, bilateral, boundary,
//! histogram, pack, tetra): each flag says its unit and default, and takes
//! the stage library's own types where it can.

use super::{InputArgs, OutFormat};
use crate::values::named;
use clap::{Args, ValueEnum};
use mdtf_pipeline::stages::bilateral::{BilateralParams, Mode, RangeUnits};
use mdtf_pipeline::stages::boundary::BoundaryParams;
use mdtf_pipeline::stages::derive::{Border, Kernel};
use std::path::PathBuf;

/// `mdtf derive`.
#[derive(Debug, Args)]
#[command(
    after_help = "Items (one file each, named after the item; several components become fields of one file):\n  \
    value      reconstructed value\n  \
    grad       gradient gx, gy, gz along the grid axes (value units per world unit)\n  \
    g          gradient magnitude |grad f|\n  \
    normal     unit gradient nx, ny, nz (0 where g < epsilon)\n  \
    hessian    hxx, hxy, hxz, hyy, hyz, hzz (per world unit squared)\n  \
    f2         second derivative along the gradient, (grad f)^T H (grad f) / g^2 (0 where g < epsilon)\n  \
    laplacian  hxx + hyy + hzz\n  \
    curvature  mean curvature of the isosurface, (f2 - laplacian) / (2 g), per world unit\n             \
(positive where the brighter side is convex: 1/r on a bright sphere of radius r)\n  \
    inv_g      1 / max(g, epsilon); several fields: 1 / max(sqrt(gnorm), epsilon)\n  \
    shade      surface-shading weight 1 - (1 - g/g_max)^2\n  \
    gnorm      multi-field: ||Df^T Df|| (Frobenius) of the fields normalised to [0,1]\n  \
    jacobian   multi-field: Df of the normalised fields, 3 components per field\n\n\
Kernels (all evaluated at the grid points; derivatives in world units):\n  \
    central4     4th-order 5-point differences (default: the most accurate on the erf sphere,\n               \
    mean g error 2.6e-4 and f'' error 6.0e-4 of their peaks at sigma = 3 voxels)\n  \
    central      central differences (the distance paper's; = numpy.gradient, ITK, VTK)\n  \
    bspline3     smoothing cubic B-spline (Teem cubic:1,0; for noisy data)\n  \
    catmull-rom  interpolating cubic\n  \
    gauss:S      Gaussian derivatives of scale S (world units), cut at 4 S\n\n\
Examples:\n  mdtf derive ct.nii.gz -o derived/ --items g,f2,normal\n  \
    mdtf derive noisy.nrrd -o d/ --items g,f2 --kernel gauss:1.5 --format nrrd\n  \
    mdtf derive t1.nii t2.nii pd.nii -o mf/ --items gnorm\n  \
    mdtf derive big.nii -o d/ --items g,f2,normal --memory-budget 4GiB"
)]
pub struct DeriveArgs {
    /// Input volume(s). Several files (or one multi-field file) form a multi-field volume; their grids must match.
    #[arg(required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// Output folder (created if missing); one file per item, named after it.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Items to compute, comma-separated (see below). All are computed in one pass.
    #[arg(long, value_delimiter = ',', default_value = "g,f2", value_name = "ITEMS")]
    pub items: Vec<String>,
    /// Kernel family: central4, central, bspline3, catmull-rom, gauss:SIGMA.
    #[arg(long, default_value_t = mdtf_pipeline::stages::derive::DEFAULT_KERNEL, value_name = "K")]
    pub kernel: Kernel,
    /// Border policy: `clamp` (repeat the edge, ITK's; the default), `mirror`, or `wrap` (periodic).
    #[arg(long, value_parser = named::<Border>, value_name = "B")]
    pub border: Option<Border>,
    /// g below this counts as 0 for normal, f2 and inv_g (value units per world unit).
    /// Default: 1e-6 x value range / smallest spacing.
    #[arg(long, value_name = "E")]
    pub epsilon: Option<f32>,
    /// Use only this field of a multi-field input (by name, or by index 0, 1, ...).
    #[arg(long, value_name = "NAME")]
    pub field: Option<String>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = OutFormat::NiiGz)]
    pub format: OutFormat,
    /// Print the plan instead of deriving: the derive passes with the items and channels each
    /// makes, the whole-volume reductions and the halo a block needs (the kernel's support).
    /// Reads the inputs and writes nothing.
    #[arg(long)]
    pub plan: bool,
    /// Derive slab by slab within this much memory (e.g. 2GiB, 512MiB): the input is read by
    /// planes into a file in the output's staging folder (disk: 4 bytes a voxel), each z-slab
    /// is derived over its planes grown by the kernel's support, and every item's file is
    /// written slab by slab (.nii, .nii.gz, .nrrd or .ome.zarr). The files are byte-identical
    /// to a whole-volume derive's. One input file with one field; not shade (it divides by
    /// the whole volume's largest g). Without it, a volume whose whole derive would not fit in
    /// three quarters of the available memory goes this way within that.
    #[arg(long, value_name = "SIZE", value_parser = mdtf_volume::parse_size, allow_hyphen_values = true)]
    pub memory_budget: Option<u64>,
    #[command(flatten)]
    pub read: InputArgs,
}

/// `mdtf bilateral`.
#[derive(Debug, Args)]
#[command(
    after_help = "f~(x) = sum W_d W_r f(x_i) / sum W_d W_r with W_d = exp(-|x_i - x|^2 / (2 sigma_d^2)) (world units)\n\
and W_r = exp(-(f(x_i) - f(x))^2 / (2 sigma_r^2)); borders clamp to the edge. For noise of standard\n\
deviation s, sigma_r of 2 to 3 s removes most of it and keeps edges (on the erf sphere with noise 20,\n\
--sigma-r 50 --range-units value cuts the RMSE 4x and moves the f'' zero crossing by < 0.1 voxel).\n\n\
Examples:\n  mdtf bilateral noisy.nii.gz -o smooth.nii.gz\n  \
    mdtf bilateral ct.nrrd -o ct-bf.nrrd --sigma-d 0.8 --sigma-r 40 --range-units value --mode fast"
)]
pub struct BilateralArgs {
    /// Input volume (one field).
    pub input: PathBuf,
    /// Output volume; its extension picks the format.
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
    /// Spatial standard deviation, world units.
    #[arg(long, default_value_t = BilateralParams::default().sigma_d, value_name = "S", allow_negative_numbers = true)]
    pub sigma_d: f64,
    /// Range standard deviation, in --range-units.
    #[arg(long, default_value_t = BilateralParams::default().sigma_r, value_name = "S", allow_negative_numbers = true)]
    pub sigma_r: f64,
    /// Units of --sigma-r: `fraction` of the input's value range (max - min; the default) or `value`
    /// (the input's value units).
    #[arg(long, value_parser = named::<RangeUnits>, value_name = "UNITS")]
    pub range_units: Option<RangeUnits>,
    /// `exact` (the default): every neighbour in the box of radius ceil(2.5 sigma_d / spacing), ITK's
    /// BilateralImageFilter neighbourhood; `fast`: the neighbours within 1.5 sigma_d only, about 10x
    /// faster, 43.6 dB PSNR from exact on the noisy erf sphere.
    #[arg(long, value_parser = named::<Mode>, value_name = "MODE")]
    pub mode: Option<Mode>,
    /// Gzip NRRD data.
    #[arg(long)]
    pub gzip: bool,
    #[command(flatten)]
    pub read: InputArgs,
}

/// `mdtf boundary`.
#[derive(Debug, Args)]
#[command(
    after_help = "From every voxel with g >= --g-min, one ray along n or -n (n = grad f / g): the direction in\n\
which g increases, picked by the sign of f'' at the voxel (f'' is the derivative of g along n). The\n\
paper traces both rays and keeps that one; the result is the same. The ray steps by --step up to\n\
--d-max, sampling f'' trilinearly; at the first sign change of f'' the zero crossing is refined to\n\
--tolerance and g is read there (tricubic). Crossings whose g is below --g-hit-min are rejected.\n\n\
Thresholds: by default from the data. The noise floor is max(2 x median g, 1e-3 x value range /\n\
L_min); --g-min defaults to it, --g-hit-min to twice it (mdtf run lowers that to half the least\n\
peak g of the boundaries its (v, g) histogram shows, and scales the Fig. 2 thresholds by the span of\n\
their materials). The paper's 5 and 20 (8-bit data, scaled by\n\
value range / 255) filter the --report statistics only: as output thresholds they cut real, weaker\n\
boundaries. Voxels above the noise floor are traced whatever the thresholds, and a boundary whose\n\
crossings all fall below them is named in a warning.\n\n\
Outputs in DIR, named after them: distance (world units; -1 where no boundary was kept), g_hit\n\
(g at the zero crossing; the stretched-histogram axis), hit (0 not traced, 1 hit, 2 no zero\n\
crossing within d_max, 3 rejected: g at the crossing below --g-hit-min), dot (unit gradient at the\n\
voxel . at the hit), with --flipped the display image d_max - d, and with --alpha the alpha maps\n\
of distance (0 where no hit; dc omitted or dc=d_max: the map spans d_max, the paper's domain\n\
0 < dc <= d_max):\n  \
linear:a=1,dc=3       max(-a d / dc + a, 0)                      (eq. 9)\n  \
concave:a=0.4,dc=3,n=9  a / dc^n |d - dc|^n for d < dc, else 0    (eq. 10)\n  \
convex:a=1,dc=3,n=3   max(-a d^n / dc^n + a, 0)                  (eq. 11)\n\n\
Examples:\n  mdtf boundary sphere.nii.gz -o bnd/ --report bnd/\n  \
    mdtf boundary noisy.nrrd -o bnd/ --kernel gauss:1 --prefilter 1,0.1 --alpha linear:a=1,dc=3\n  \
    mdtf boundary --g d/g.nii.gz --f2 d/f2.nii.gz --normal d/normal.nii.gz -o bnd/ --value-range 255\n  \
    mdtf boundary big.nii -o bnd/ --memory-budget 4GiB"
)]
pub struct BoundaryArgs {
    /// Value volume: derive (g, f'', normal) runs in process first. Omit when giving --g, --f2 and --normal.
    pub input: Option<PathBuf>,
    /// Output folder (created if missing).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Precomputed gradient magnitude (with --f2 and --normal instead of a value volume).
    #[arg(long, value_name = "FILE", requires_all = ["f2", "normal"], conflicts_with = "input")]
    pub g: Option<PathBuf>,
    /// Precomputed f''.
    #[arg(long, value_name = "FILE", requires_all = ["g", "normal"])]
    pub f2: Option<PathBuf>,
    /// Precomputed unit normal (3 fields).
    #[arg(long, value_name = "FILE", requires_all = ["g", "f2"])]
    pub normal: Option<PathBuf>,
    /// Value range of the data behind --g/--f2 (scales the noise floor's lower bound and the Fig. 2
    /// thresholds). Default 255; with a value volume, its range.
    #[arg(long, value_name = "R")]
    pub value_range: Option<f64>,
    /// Derivative kernel when deriving from a value volume (gauss:1 or bspline3 for noisy data).
    #[arg(long, value_name = "K")]
    pub kernel: Option<Kernel>,
    /// Bilateral pre-filter of g and f'': SIGMA_D (world units),SIGMA_R (fraction of each channel's range).
    #[arg(long, value_name = "SD,SR")]
    pub prefilter: Option<String>,
    /// Print the plan of the chain from a value volume instead of running it: the derive items,
    /// the pre-filter and the tracing with what each reads and makes, and the halo a block needs
    /// (d_max plus the interpolation's support). Reads the input and writes nothing.
    #[arg(long, requires = "input")]
    pub plan: bool,
    /// Trace voxels with g at least this. Default: the noise floor, max(2 x median g, 1e-3 x value range / L_min).
    #[arg(long, value_name = "G")]
    pub g_min: Option<f64>,
    /// Keep hits with g at least this. Default: twice the noise floor.
    #[arg(long, value_name = "G")]
    pub g_hit_min: Option<f64>,
    /// Step along the ray, world units. Default: L_min / 5.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub step: Option<f64>,
    /// Longest traced distance, world units. Default: 15 L_min.
    #[arg(long, value_name = "D", allow_negative_numbers = true)]
    pub d_max: Option<f64>,
    /// Zero-crossing tolerance, voxels.
    #[arg(long, default_value_t = BoundaryParams::default().tolerance, value_name = "T", allow_negative_numbers = true)]
    pub tolerance: f64,
    /// Also write `flipped` = d_max - d (the paper's display image).
    #[arg(long)]
    pub flipped: bool,
    /// Alpha map(s) of distance to write (repeatable), e.g. linear:a=1,dc=3.
    #[arg(long, value_name = "SPEC")]
    pub alpha: Vec<String>,
    /// Write the Fig. 2 validation report (boundary_report.csv and .png) into this folder: per bin of
    /// log10(1 - dot) and per the paper's dot x 100, over the hits passing the paper's thresholds.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = OutFormat::NiiGz)]
    pub format: OutFormat,
    /// Trace slab by slab within this much memory (e.g. 2GiB, 512MiB), from a value volume: the
    /// input is read by planes, each pass (derive, pre-filter, tracing) works on z-slabs grown by
    /// its halo (the tracing's: d_max plus the interpolation's support), the channels wait in
    /// files in the output's staging folder (disk: about 30 bytes a voxel), and every output is
    /// written slab by slab (.nii, .nii.gz or .ome.zarr). The outputs and the report are
    /// byte-identical to a whole-volume run's. Without it, a volume whose whole run would not
    /// fit in three quarters of the available memory goes this way within that.
    #[arg(long, value_name = "SIZE", value_parser = mdtf_volume::parse_size, allow_hyphen_values = true)]
    pub memory_budget: Option<u64>,
    #[command(flatten)]
    pub read: InputArgs,
}

/// `--scale` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ScaleArg {
    /// 255 log(1 + count) / log(1 + max).
    Log,
    /// 255 count / max.
    Linear,
}

/// `mdtf histogram`.
#[derive(Debug, Args)]
#[command(
    after_help = "Channels: v (the value; field 0), g and f2 (derived in process, --kernel), g_hit, hit and distance\n\
(traced in process by the boundary stage), or the field names of a multi-field input.\n\n\
Bins: value exactly at an axis maximum goes to the last bin; values outside the range are not counted.\n\
Automatic ranges clip 0 / 0.002 / 0.004 percent at each end of v / g / f2 (Teem qbert's defaults);\n\
integer data spanning at most 4096 values get one bin per value.\n\n\
Outputs in DIR: hist_A_B.png (A to the right, B upward; axis ranges in the PNG text chunk), hist_A_B.nrrd\n\
(counts), hist_A_B.exr (counts, f32), hist_A_B.json (axes, total); 3 axes add the three projections. --stretched adds hist_v_g_hit.*\n\
(traced voxels only) and normal_vs_stretched.png (the distance paper's Fig. 5). --hvol writes hvol.nrrd,\n\
hvol_per_v.csv (mean g and f'' per v bin), position.nrrd (p(v,g)), opacity.png/.nrrd and hvol.json (sigma).\n\n\
Examples:\n  mdtf histogram ct.nii.gz -o hist/ --axes v,g\n  mdtf histogram sphere.nii.gz -o hist/ --stretched\n  \
    mdtf histogram sphere.nii.gz -o hist/ --hvol\n  mdtf histogram fields.nii.gz -o hist/ --axes a,b,c --bins 64,64,64"
)]
pub struct HistogramArgs {
    /// Input volume (value, or a multi-field volume whose fields are channels).
    pub input: PathBuf,
    /// Output folder.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Channels on the axes, 1 to 3, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "v,g", value_name = "A,B[,C]")]
    pub axes: Vec<String>,
    /// Bins per axis (one number for all). Default: automatic (256, or one per integer).
    #[arg(long, value_delimiter = ',', value_name = "N[,N..]")]
    pub bins: Vec<usize>,
    /// Range per axis: MIN:MAX or auto, comma-separated.
    #[arg(long, value_delimiter = ',', value_name = "R[,R..]", allow_hyphen_values = true)]
    pub range: Vec<String>,
    /// Count only voxels where this volume is non-zero.
    #[arg(long, value_name = "FILE")]
    pub mask: Option<PathBuf>,
    /// Grey-level mapping of the PNGs.
    #[arg(long, value_enum, default_value_t = ScaleArg::Log)]
    pub scale: ScaleArg,
    /// Also the stretched (v, g_hit) histogram of traced voxels, and normal | stretched side by side.
    #[arg(long)]
    pub stretched: bool,
    /// The histogram volume (v, g, f'') with sigma, p(v, g) and the default opacity.
    #[arg(long)]
    pub hvol: bool,
    /// g threshold of p(v, g). Default: 4% of the largest mean g.
    #[arg(long, value_name = "G")]
    pub g_thresh: Option<f64>,
    /// Half-width of the opacity tent in p, world units. Default: the estimated sigma.
    #[arg(long, value_name = "W")]
    pub tent_width: Option<f64>,
    /// Derivative kernel for g and f2.
    #[arg(long, value_name = "K")]
    pub kernel: Option<Kernel>,
    /// Print the plan of the channels instead of computing them: the derive items, whether the
    /// tracing runs, what each step reads and makes, and a block's halo. Reads the input (to
    /// learn its fields and grid) and writes nothing.
    #[arg(long)]
    pub plan: bool,
    #[command(flatten)]
    pub read: InputArgs,
}

/// `mdtf pack`.
#[derive(Debug, Args)]
#[command(after_help = "Profiles:\n  \
    slicer-3dtf  data.raw RGBA8 (v, g, f2, unused) and normal.raw RGBA8 (nx, ny, nz, g) (Kniss et al.)\n  \
    distance-tf  normal_v.raw RGBA8 (nx, ny, nz, v) and ghit_d.raw 2 x u8 (g_hit, distance) (distance-based TFs)\n  \
    gaussian-tf  fields_k.raw RGBA16: the fields and gnorm, or v and g for scalar data; gaussians.json\n  \
    peak-finding fields_k.raw RGBA16: the fields and inv_g (several fields: 1 / sqrt(gnorm))\n\n\
Each texture is raw little-endian samples (components fastest, then x, y, z) with a detached NRRD\n\
header (.nhdr) that Teem, ParaView and 3D Slicer open; manifest.json says for every channel\n\
value = offset + scale * code, its meaning, units and source. Signed channels (f2, normals) keep 0\n\
exact. Ranges default to the data with Teem qbert's percentile clipping (g 0.002 %, f2 0.004 %).\n\n\
Lookup tables (NRRD, uint8 and float, listed under \"luts\" in the manifest): slicer-3dtf writes tf3d\n\
(256 x 128 x 9 over v, g, f2) and the separable tf2d (256 x 256) + tf_f2 (256) from --tf, or\n\
tf2d_default (the boundaries found in the histogram volume, coloured); distance-tf writes alpha_d (256 over [0, d_max]) and, with\n\
--tf, alpha_u; gaussian-tf writes igauss (128^2 over [-10, 10]^2, eq. 16) and erf_difference (256^2\n\
over [-3.6, 3.6]^2), each also as uint16 with its decode in the manifest.\n\
TF widgets: triangle (v0, width, g_low, g_high, shear), rectangle (centre, half_size, falloff:\n\
constant|ellipsoid|ramp|tent|pyramid), gaussian (centre, k, alpha_max, triangular); each with\n\
alpha/colour. gaussian-tf's primitives (gaussians.json) come from --tf, else --gtf-from-mask, else\n\
the Gaussian-TF paper's default: a triangular GTF (width sigma' g) at the median of each field.\n\
A TF's \"product\" (any profile) is a separable TF over the pack's channels, opacity the product of\n\
its factors, colour the first's: 2D widget factors ({\"channels\": [a, b], \"ranges\": [[..], [..]],\n\
\"widgets\": [..]}) and 1D ramps ({\"channels\": [gnorm], \"ranges\": [[..]], \"ramp\": [begin, end]});\n\
Kniss et al.'s meteorological TF (fields x a ramp over ||G||) or the peak-finding paper's 4D TF\n\
v(a, b) mu(c, d). Each factor is a table product_k (256 per axis; peak-finding 1024).\n\n\
Examples:\n  mdtf pack --profile slicer-3dtf ct.nii.gz -o pack/\n  mdtf pack --profile slicer-3dtf ct.nii.gz -o pack/ --tf tf.json\n  \
    mdtf pack --profile distance-tf sphere.nii.gz -o pack/ --range v=0:255\n  mdtf pack --schema")]
pub struct PackArgs {
    /// Input: a value volume (channels are computed in process) or a folder of stage outputs
    /// (value/v, g, f2, normal, g_hit, distance files).
    #[arg(required_unless_present = "schema")]
    pub input: Option<PathBuf>,
    /// Output pack folder.
    #[arg(short, long, value_name = "DIR", required_unless_present_any = ["schema", "plan"])]
    pub output: Option<PathBuf>,
    /// Layout: slicer-3dtf, distance-tf, gaussian-tf or peak-finding (meshes: `mdtf tetra`).
    #[arg(long, default_value = "slicer-3dtf")]
    pub profile: String,
    /// Range of a channel, NAME=MIN:MAX (repeatable).
    #[arg(long, value_name = "NAME=MIN:MAX", allow_hyphen_values = true)]
    pub range: Vec<String>,
    /// Derivative kernel when computing channels from a value volume.
    #[arg(long, value_name = "K")]
    pub kernel: Option<Kernel>,
    /// Print the plan of the channels instead of computing them: the derive items, whether the
    /// tracing runs, what each step reads and makes, and a block's halo. Reads the input (a
    /// value volume, to learn its fields and grid) and writes nothing.
    #[arg(long)]
    pub plan: bool,
    /// Transfer-function file (JSON: v_range, g_range, f2_range, boundary_emphasis, widgets, tf1d,
    /// product) rasterised into the profile's lookup tables. Without it, slicer-3dtf gets a default TF
    /// from the boundaries found in the histogram volume: each its own colour on its arch in (v, g),
    /// opacity the tent of p(v, g), larger surfaces more transparent so the ones behind show.
    #[arg(long, value_name = "TF.json")]
    pub tf: Option<PathBuf>,
    /// Storage type of every texture instead of the profile's: u8, u16, f16 (IEEE half bits; NRRD
    /// header says uint16, the manifest f16) or f32.
    #[arg(long, value_name = "T")]
    pub dtype: Option<String>,
    /// gaussian-tf without --tf: fit the Gaussian to the voxels where this mask volume is positive
    /// (centre: their mean; width: their covariance).
    #[arg(long, value_name = "MASK")]
    pub gtf_from_mask: Option<PathBuf>,
    /// distance-tf: the alpha map of distance written as the 1D table alpha_d(d) over [0, d_max]
    /// (dc omitted: d_max, the paper's domain).
    #[arg(long, default_value = "linear:a=1", value_name = "SPEC")]
    pub alpha: String,
    /// Also write every texture as NIfTI-1 (`<name>.nii`, one volume per component, the codes as
    /// stored) for tools without NRRD.
    #[arg(long)]
    pub nifti: bool,
    /// Print the manifest's JSON Schema and exit.
    #[arg(long)]
    pub schema: bool,
    #[command(flatten)]
    pub read: InputArgs,
}

/// `mdtf tetra`.
#[derive(Debug, Args)]
#[command(
    after_help = "Reads a tetrahedral mesh with a point scalar s (VTK legacy .vtk, ASCII or binary up to version 5.1,\n\
or VTK XML .vtu; other cell types and zero-volume tetrahedra are skipped and counted), or meshes a regular\n\
volume (--from-volume, 5 or 6 tetrahedra per cell, conforming). Computes per-vertex gradients and\n\
g = |grad s| (least-squares fit over the edge neighbours by default), per-cell (s, g) boxes for\n\
conservative culling, longest edges and smallest vertex value differences, and the pre-integration\n\
tables of Song et al.: front-back (F, B of the approximated mode, eq. 3), gaussian (T(P, t), section\n\
4.2), triangle (rising/falling flank integrals, 4.3), sinusoid (4.4) and preintegration-1d (the\n\
classic (s_f, s_b, D) table of --tf's tf1d; left out, with a note, without one). Given --tf with\n\
widgets, cell_visible.nrrd marks (1 per cell, uint8) the cells whose (s, g) box meets a widget\n\
(Gaussians reach +-3 sigma), so a renderer may skip the rest (section 3.1). The pack folder\n\
gets mesh.vtu (with g and gradient added), the arrays as NRRD, the tables as NRRD and manifest.json;\n\
it is written to a temporary folder and renamed at the end.\n\n\
Examples:\n  mdtf tetra blunt_fin.vtu -o blunt-pack --scalar density\n  \
    mdtf tetra --from-volume ct.nii.gz --tets 6 -o ct-mesh-pack\n  \
    mdtf tetra mesh.vtk -o pack --tables front-back,gaussian --fb-size 64,64,128"
)]
pub struct TetraArgs {
    /// Input mesh (.vtu or .vtk).
    #[arg(required_unless_present = "from_volume", conflicts_with = "from_volume")]
    pub input: Option<PathBuf>,
    /// Mesh this volume instead (NIfTI, NRRD or raw): one point per voxel, the value as s.
    #[arg(long, value_name = "VOLUME")]
    pub from_volume: Option<PathBuf>,
    /// Output pack folder.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Tetrahedra per grid cell with --from-volume: 5 or 6.
    #[arg(long, default_value = "6", value_name = "5|6")]
    pub tets: String,
    /// With --from-volume, the most tetrahedra to make: a larger grid is
    /// averaged over k x k x k blocks first (the least k that fits), and the
    /// run says so; 0 meshes every voxel.
    #[arg(long, default_value_t = mdtf_pipeline::stages::tetra::DEFAULT_MAX_TETRAHEDRA, value_name = "N")]
    pub max_tetrahedra: u64,
    /// Point array to use as s (default: the only one-component point array).
    #[arg(long, value_name = "NAME")]
    pub scalar: Option<String>,
    /// Per-vertex gradients: least-squares or volume-average.
    #[arg(long, default_value = "least-squares", value_name = "METHOD")]
    pub gradient: String,
    /// Tables to build, comma-separated: front-back, gaussian, triangle, sinusoid, preintegration-1d.
    #[arg(long, value_delimiter = ',', default_value = "front-back,gaussian,triangle,sinusoid,preintegration-1d")]
    pub tables: Vec<String>,
    /// Cells of the F/B tables along a_front, a_back, D.
    #[arg(long, default_value = "128,128,256", value_name = "NA,NB,ND")]
    pub fb_size: String,
    /// Cells of the classic 1D table along s_front, s_back, D.
    #[arg(long, default_value = "128,128,64", value_name = "NF,NB,ND")]
    pub preint_size: String,
    /// Largest extinction on the F/B axes, per world unit (default 16 / d_max).
    #[arg(long, value_name = "TAU")]
    pub tau_max: Option<f64>,
    /// Longest segment on the D axes, world units (default: the mesh's longest edge).
    #[arg(long, value_name = "D")]
    pub d_max: Option<f64>,
    /// Transfer-function file; its tf1d (over v_range) feeds the classic 1D table
    /// (without one that table is left out, with a note), and its widgets (over (s, g))
    /// the visible-cell mask cell_visible.nrrd.
    #[arg(long, value_name = "TF.json")]
    pub tf: Option<PathBuf>,
    #[command(flatten)]
    pub read: InputArgs,
}
