//! Command-line arguments (clap derive). Every option says its unit and
//! default. This module holds the command tree, the input options every
//! reader shares and the volume, run, validate and preview subcommands;
//! [`stages`] the stage subcommands.

mod stages;

pub use stages::{BilateralArgs, BoundaryArgs, DeriveArgs, HistogramArgs, PackArgs, ScaleArg, TetraArgs};

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// mdtf prepares volume data for direct volume rendering with
/// multidimensional transfer functions: it reads CT/MRI or simulation volumes
/// (NIfTI, NRRD, MetaImage, raw), measures derivatives, filters, traces boundaries,
/// builds histograms and packs textures for renderers.
#[derive(Debug, Parser)]
#[command(
    name = "mdtf",
    version,
    propagate_version = true,
    max_term_width = 100,
    after_help = "Outputs: every file is written under a temporary name beside it and renamed into place; an \
output folder is built beside its target and swapped in in one step, so a failed or interrupted run leaves the old \
output as it was and nothing partial. mdtf replaces only folders it made (they hold a .mdtf-output list of their \
files) and never an input: a folder of yours, one holding an input, one you added files to, or the current folder \
is refused. One run at a time per output; Ctrl-C removes the partial output."
)]
pub struct Cli {
    #[command(flatten)]
    pub global: GlobalArgs,
    #[command(subcommand)]
    pub command: Command,
}

/// Options of every subcommand.
#[derive(Debug, Args)]
pub struct GlobalArgs {
    /// Worker threads (default: one per core). Results are identical for any count.
    #[arg(long, global = true, value_name = "N", value_parser = clap::value_parser!(u16).range(1..=4096))]
    pub threads: Option<u16>,
    /// No progress or summary on stderr (errors are still printed).
    #[arg(long, short, global = true)]
    pub quiet: bool,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Generate a synthetic volume with analytic ground truth (erf sphere, nested shells, multi-field).
    Synth(SynthArgs),
    /// Describe a volume file: dims, stored type, geometry, value range, NaN/Inf count, histogram.
    Info(InfoArgs),
    /// Convert a volume between formats, chosen by the file extensions (.nii, .nii.gz, .nrrd, .nhdr, .mha, .mhd, .ome.zarr).
    Convert(ConvertArgs),
    /// Measure derivatives: gradient, g, normal, Hessian, f'', Laplacian, 1/g, shading weight, multi-field ||G||.
    Derive(DeriveArgs),
    /// Edge-preserving 3D bilateral filter (exact, or fast with a truncated neighbourhood).
    Bilateral(BilateralArgs),
    /// Distance from every voxel to its nearest boundary (zero crossing of f''), g at the hit, alpha maps.
    Boundary(BoundaryArgs),
    /// Joint and stretched histograms with PNG pictures, and the Kindlmann-Durkin histogram volume (--hvol).
    Histogram(HistogramArgs),
    /// Quantised texture packs with a manifest, one layout per renderer family.
    Pack(PackArgs),
    /// Run a pipeline file: every stage in process, outputs and a run report in one folder.
    Run(RunArgs),
    /// Check this installation: every stage on the analytic erf sphere against its documented tolerance.
    Validate(ValidateArgs),
    /// Render a pack from its manifest alone (CPU ray caster), as its renderer would show it.
    Preview(PreviewArgs),
    /// Export a pack for VTK/ParaView (.vti, the TF as a 2D image, Python scripts) and 3D Slicer (.nrrd, .vp).
    Export(crate::commands::export::ExportArgs),
    /// Tetrahedral meshes (VTK .vtu/.vtk, or a meshed volume): per-vertex (s, g), cell boxes and the
    /// projected-tetrahedra pack with its bivariate pre-integration tables.
    Tetra(TetraArgs),
}

/// Which phantom to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Phantom {
    /// One erf-blurred sphere: v = vmin + (vmax - vmin)(1 + erf(x / (sigma sqrt 2)))/2, x = radius - |P - centre|.
    ErfSphere,
    /// Tooth-like nested shells: enamel 230 (radius 0.40 E), dentin 140 (0.33 E), pulp 60 (0.16 E) in
    /// background 20, where E is the smallest grid extent.
    Shells,
    /// Three overlapping erf spheres as a 3-field volume (for multi-field gradients, ||G||).
    Multifield,
    /// A head CT in HU: skin 40, fat -90, galea 40, skull (tables 1400, diploe 600), CSF 8, brain
    /// 35, a frontal sinus (air) in bone, a head holder 250, 5 mm layers, 1 mm blur (--sigma), 20 HU
    /// noise (--noise), int16 values and -2000 padding outside the circular field of view (--size
    /// 200,200,48 for a head of radius 80). Boundaries: air|skin, air|holder, air|bone, soft
    /// tissue|bone, diploe|bone, fat|skin (6.5 noise sds); padding|air is a hard edge, no arch.
    CtHead,
}

/// Sample type of written volumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutType {
    /// 32-bit float (exact).
    F32,
    /// 8-bit unsigned; values are rounded and clamped to 0..255.
    U8,
    /// 16-bit unsigned; values are rounded and clamped to 0..65535.
    U16,
}

/// `mdtf synth`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:\n  mdtf synth erf-sphere -o sphere.nii.gz --truth truth/\n  \
    mdtf synth erf-sphere -o noisy.nrrd --size 128 --radius 38.4 --sigma 3 --noise 20 --seed 7\n  \
    mdtf synth shells -o tooth.nhdr --spacing 0.5,0.5,1.0\n\n\
    With --truth DIR the analytic fields are written next to each other in DIR, with OUT's extension:\n  \
    erf-sphere, shells: v (noise-free), g, f2 (f''), x (signed distance, + on the high side), normal (3 fields), p\n  \
    multifield: jacobian (9 fields, of the [0,1]-normalised fields), gnorm (||Df^T Df||, Frobenius)")]
pub struct SynthArgs {
    /// Which phantom.
    #[arg(value_enum)]
    pub phantom: Phantom,
    /// Output volume (.nii, .nii.gz, .nrrd, .nhdr, .mha or .mhd).
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
    /// Grid size: N for N^3, or NX,NY,NZ.
    #[arg(long, default_value = "128", value_name = "N|NX,NY,NZ")]
    pub size: String,
    /// Sphere radius in world units (erf-sphere only). Default: 0.3 of the smallest extent (38.4 at 128^3).
    #[arg(long, value_name = "R", allow_negative_numbers = true)]
    pub radius: Option<f64>,
    /// Boundary blur: standard deviation of the Gaussian, world units.
    /// Default: 3 (ct-head: 1, a scanner's).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub sigma: Option<f64>,
    /// Value outside the sphere (erf-sphere only).
    #[arg(long, default_value_t = 0.0, value_name = "A", allow_negative_numbers = true)]
    pub vmin: f64,
    /// Value inside the sphere (erf-sphere only).
    #[arg(long, default_value_t = 255.0, value_name = "B", allow_negative_numbers = true)]
    pub vmax: f64,
    /// Voxel spacing SX,SY,SZ in world units.
    #[arg(long, default_value = "1,1,1", value_name = "SX,SY,SZ")]
    pub spacing: String,
    /// World position of voxel (0,0,0).
    #[arg(long, default_value = "0,0,0", value_name = "OX,OY,OZ", allow_hyphen_values = true)]
    pub origin: String,
    /// Sphere centre in world units (erf-sphere only). Default: the grid centre, index (n-1)/2.
    #[arg(long, value_name = "CX,CY,CZ", allow_hyphen_values = true)]
    pub centre: Option<String>,
    /// Add Gaussian noise of this standard deviation (value units).
    #[arg(long, value_name = "STD", allow_negative_numbers = true)]
    pub noise: Option<f64>,
    /// Seed of the noise (same seed, same noise on every machine).
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub seed: u64,
    /// Write the analytic fields into this folder (see below).
    #[arg(long, value_name = "DIR")]
    pub truth: Option<PathBuf>,
    /// Sample type of the written volume (truth is always f32; ct-head is always int16).
    #[arg(long = "type", value_enum, default_value_t = OutType::F32)]
    pub out_type: OutType,
    /// Gzip NRRD data (NIfTI is compressed by naming it .nii.gz).
    #[arg(long)]
    pub gzip: bool,
}

/// How to read an input: format by extension, or raw with an explicit layout.
#[derive(Debug, Args)]
pub struct InputArgs {
    /// What to do with NaN/Inf samples: refuse the file (default) or replace them with 0.
    #[arg(long, value_enum, default_value_t = NanArg::Refuse)]
    pub nan: NanArg,
    /// Read the input as raw samples of this grid size NX,NY,NZ (no header).
    #[arg(long, value_name = "NX,NY,NZ", help_heading = "Raw input")]
    pub raw_dims: Option<String>,
    /// Raw sample type: u8, i8, u16, i16, u32, i32, f32, f64.
    #[arg(long, default_value = "u8", value_name = "TYPE", help_heading = "Raw input")]
    pub raw_type: String,
    /// Raw byte order.
    #[arg(long, value_enum, default_value_t = EndianArg::Little, help_heading = "Raw input")]
    pub raw_endian: EndianArg,
    /// Raw voxel spacing SX,SY,SZ in world units.
    #[arg(long, default_value = "1,1,1", value_name = "SX,SY,SZ", help_heading = "Raw input")]
    pub raw_spacing: String,
    /// Bytes to skip at the start of a raw file.
    #[arg(long, default_value_t = 0, value_name = "BYTES", help_heading = "Raw input")]
    pub raw_skip: u64,
    /// The DICOM series to read when the input holds several, by its
    /// SeriesNumber or SeriesInstanceUID (without it, mdtf lists them).
    #[arg(long, value_name = "N|UID", help_heading = "DICOM input")]
    pub series: Option<String>,
    /// Interpolate a DICOM stack whose slice gaps vary (a missing slice) or
    /// that is tilted (gantry tilt) onto a regular grid, instead of refusing
    /// it: linear between slices, tilt undone by shifting each slice in-plane.
    /// The run prints what it found and did.
    #[arg(long, help_heading = "DICOM input")]
    pub resample: bool,
    /// The multiscale level of an OME-Zarr input: 0 is full resolution, each
    /// level after it coarser (`mdtf info` lists them).
    #[arg(long, default_value_t = 0, value_name = "N", help_heading = "OME-Zarr input")]
    pub level: usize,
}

/// `--nan` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum NanArg {
    /// Refuse a file with NaN or infinite samples, reporting how many.
    Refuse,
    /// Replace NaN and infinite samples with 0.
    Zero,
}

/// `--raw-endian` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EndianArg {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

/// `mdtf info`.
#[derive(Debug, Args)]
#[command(
    after_help = "Example:\n  mdtf info sphere.nii.gz\n  mdtf info scan.raw --raw-dims 256,256,128 --raw-type u16 --raw-spacing 0.5,0.5,1\n  mdtf info dicom-export/                 (lists the series if there are several)\n  mdtf info dicom-export/DICOMDIR --series 3\n  mdtf info cells.ome.zarr --level 1       (a store's levels, axes, units, chunks, codecs)"
)]
pub struct InfoArgs {
    /// The volume: a file (NIfTI, NRRD, MetaImage, TIFF, DICOM; the content
    /// picks the reader), a folder (an OME-Zarr store, a DICOM series or
    /// export, or TIFF slices), a DICOMDIR, or a .txt list of DICOM files.
    pub input: PathBuf,
    /// Bins of the text histogram.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=200))]
    pub bins: u32,
    #[command(flatten)]
    pub read: InputArgs,
}

/// `mdtf convert`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:\n  mdtf convert scan.nii.gz scan.nrrd\n  mdtf convert ct.nhdr ct.nii --type u16\n  \
    mdtf convert scan.nii.gz scan.ome.zarr --type u16      (OME-Zarr 0.5: sharded, zstd)\n  \
    mdtf convert cells.ome.zarr cells.nii.gz --level 1    (from NGFF 0.4 or 0.5, any level)\n  \
    mdtf convert scan.raw scan.nii.gz --raw-dims 256,256,128 --raw-type i16 --raw-endian big")]
pub struct ConvertArgs {
    /// Input volume.
    pub input: PathBuf,
    /// Output volume; its extension picks the format. Never the input itself.
    pub output: PathBuf,
    /// Sample type to write. Default: the input's own when it stores u8 or u16 without
    /// rescaling (the values are then those integers), else f32. Integer types need integer
    /// values in range (they are refused otherwise; quantisation is the pack stage's job).
    #[arg(long = "type", value_enum)]
    pub out_type: Option<OutType>,
    /// Gzip NRRD data.
    #[arg(long)]
    pub gzip: bool,
    #[command(flatten)]
    pub read: InputArgs,
}

/// Output format of stage results.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutFormat {
    /// NIfTI-1, uncompressed (.nii).
    Nii,
    /// NIfTI-1, gzip (.nii.gz).
    #[value(name = "nii.gz")]
    NiiGz,
    /// NRRD with attached header (.nrrd).
    Nrrd,
    /// NRRD with detached header (.nhdr + .raw).
    Nhdr,
    /// OME-Zarr 0.5 store (.ome.zarr folder; napari, zarr-python, Dask).
    #[value(name = "ome-zarr")]
    OmeZarr,
}

impl OutFormat {
    /// File extension including the dot.
    pub fn extension(self) -> &'static str {
        match self {
            OutFormat::Nii => ".nii",
            OutFormat::NiiGz => ".nii.gz",
            OutFormat::Nrrd => ".nrrd",
            OutFormat::Nhdr => ".nhdr",
            OutFormat::OmeZarr => ".ome.zarr",
        }
    }
}

/// `mdtf run`.
#[derive(Debug, Args)]
#[command(
    after_help = "A pipeline file (TOML) names the input (a file, or a built-in phantom), the stage parameters\n\
([derive], [prefilter], [boundary], [histogram], [pack]) and the channels to keep as volumes.\n\
The run writes into a temporary folder beside OUT and swaps it in at the end, so a failed run\n\
leaves OUT as it was. OUT must be new, empty or an earlier mdtf output holding no input\n\
(mdtf --help says why). OUT holds pack/ (textures + manifest.json), histogram/, boundary/ (the\n\
Fig. 2 report), volumes/ (kept channels) and run_report.json (per stage: wall time, voxels/s,\n\
peak memory, outputs).\n\n\
Examples:\n  mdtf run pipelines/slicer-3dtf.toml\n  mdtf run pipelines/distance-tf.toml --input ct.nii.gz -o ct-pack\n  \
    mdtf run pipelines/slicer-3dtf.toml --set input.size=64 --set derive.kernel=central"
)]
pub struct RunArgs {
    /// Pipeline file.
    pub pipeline: PathBuf,
    /// Input volume replacing the pipeline's input.
    #[arg(long, value_name = "FILE")]
    pub input: Option<PathBuf>,
    /// Output folder.
    #[arg(short, long, default_value = "out", value_name = "DIR")]
    pub output: PathBuf,
    /// Override a pipeline parameter, SECTION.KEY=VALUE (repeatable; VALUE is TOML, else a string).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
    /// Print the plan instead of running it: the derive items, whether the tracing runs, what each
    /// step reads, makes and frees, the whole-volume reductions and a block's halo. Reads the input
    /// (to learn its fields and grid) and writes nothing.
    #[arg(long)]
    pub plan: bool,
    /// With --plan: plan for a grid of this size (N or NX,NY,NZ voxels, spacing 1) instead of the
    /// input's, without reading it, and size a run of it by slabs or on a cluster (with
    /// --memory-budget, a task's memory, or --slab-planes; default: three quarters of this
    /// machine's memory): each pass's tasks, memory, bytes read and written, the shared disk it
    /// needs, and the time it takes per voxel (timed on a small phantom run of the pipeline here).
    #[arg(long, value_name = "N|NX,NY,NZ", requires = "plan")]
    pub dims: Option<String>,
    /// Print the settings the run would use, as a pipeline file with every default filled in
    /// (after --set and --input), and stop. Reads neither the input nor writes anything; the
    /// output is itself a valid pipeline file.
    #[arg(long, conflicts_with = "plan")]
    pub print_settings: bool,
    /// Run slab by slab within this much memory (e.g. 2GiB, 512MiB): the input is read by planes,
    /// each stage works on z-slabs grown by its halo, and the channels wait between stages in
    /// files inside the output's staging folder (disk: about 40 bytes a voxel). The outputs are
    /// byte-identical to a whole-volume run. One-field inputs, every profile but projected-tetrahedra.
    /// Without it, a volume whose whole run would not fit in three quarters of the available
    /// memory runs this way within that.
    #[arg(long, value_name = "SIZE", value_parser = mdtf_volume::parse_size, allow_hyphen_values = true)]
    pub memory_budget: Option<u64>,
    /// Run slab by slab with slabs of this many z-planes (for checks and benchmarks; see
    /// --memory-budget).
    #[arg(long, value_name = "N", conflicts_with = "memory_budget",
          value_parser = clap::value_parser!(u32).range(1..))]
    pub slab_planes: Option<u32>,
}

/// `mdtf validate`.
#[derive(Debug, Args)]
#[command(
    after_help = "Builds an erf sphere (radius 0.3 N, sigma 3 voxels, values 0..255) with its analytic truth, runs\n\
derive, boundary, histogram and the pack quantisation and tables on it, and prints each measured error\n\
next to its tolerance; exits with 1 if any is out of tolerance. Also writes the boundary report and the\n\
histogram pictures into --output."
)]
pub struct ValidateArgs {
    /// Grid size N of the N^3 phantom (at least 48).
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Folder for the boundary report and histogram pictures.
    #[arg(short, long, default_value = "out/validate", value_name = "DIR")]
    pub output: PathBuf,
    /// Change a stage parameter, SECTION.KEY=VALUE as in pipeline files (sections derive,
    /// boundary, tetra; repeatable): e.g. `--set derive.kernel=central` shows what a cruder
    /// kernel costs against the same tolerances.
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
}

/// `mdtf preview`.
#[derive(Debug, Args)]
#[command(
    after_help = "Orthographic ray casting with emission-absorption compositing front to back, opacity corrected\n\
for the step; slicer-3dtf classifies with its 3D (or 2D) TF LUT, distance-tf with alpha_u(v, g_hit) x alpha_d(d),\n\
gaussian-tf with the pack's Gaussian primitives (gaussians.json), peak-finding with its peak and\n\
pre-integration tables (1D peak finding on v), projected-tetrahedra with the primitives of its\n\
gaussians.json over the mesh's (s, g) resampled onto a grid (at most 192 nodes a side);\n\
Blinn-Phong shading from the normal channel (without one, from the value's gradient by central\n\
differences), weighted by 1 - (1 - g/g_max)^2.\n\n\
Example:\n  mdtf preview out/pack -o preview.png --view 30,20 --size 512"
)]
pub struct PreviewArgs {
    /// Pack folder (with manifest.json).
    pub pack: PathBuf,
    /// Output PNG.
    #[arg(short, long, default_value = "preview.png", value_name = "PNG")]
    pub output: PathBuf,
    /// View direction AZIMUTH,ELEVATION in degrees. Default: the `mdtf run` preview's, 30,20.
    #[arg(long, value_name = "AZ,EL", allow_hyphen_values = true)]
    pub view: Option<String>,
    /// Image size in pixels (square).
    #[arg(long, default_value_t = mdtf_pipeline::stages::preview::Camera::default().size)]
    pub size: usize,
    /// Sample spacing along rays, voxels (0.01 to 16).
    #[arg(long, default_value_t = mdtf_pipeline::stages::preview::Camera::default().step)]
    pub step: f64,
    /// Between-sample classification: gaussian-tf integrates the primitives along each segment
    /// analytically (eq. 11), peak-finding classifies at the TF peak crossed between samples;
    /// `riemann` classifies both at the samples only.
    #[arg(long, value_enum, default_value_t = IntegrationArg::Analytic)]
    pub integration: IntegrationArg,
    /// Composite the TF's colours unlit (as a renderer without shading shows them).
    #[arg(long)]
    pub no_shading: bool,
}

/// `--integration` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum IntegrationArg {
    /// Analytic segment integral (gaussian-tf) or peak finding (peak-finding).
    Analytic,
    /// Classify at the samples (Riemann sum / post-classification).
    Riemann,
}
