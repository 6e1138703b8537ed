//! What a run reads: its input file or built-in phantom, how the input is
//! to be read, the TF file, the list of files it reads (so that no output
//! replaces one), and the settings and provenance it records.

use crate::error::{RunError, at, fail};
use crate::file::{PhantomKind, Pipeline};
use crate::plan::Plan;
use crate::run::RunOptions;
use mdtf_datagen::{MultiFieldPhantom, RadialPhantom, add_gaussian_noise, erf_sphere, min_extent};
use mdtf_pack::{Profile, Provenance, parse_tf};
use mdtf_volume::dicom::DicomOptions;
use mdtf_volume::{Geometry, Inputs, MultiField, ReadOptions, Units, Volume};
use std::path::{Path, PathBuf};

/// The plan [`run`](crate::run::run) follows for `p`, with the input's name and grid. It reads
/// the input (or builds the phantom) to learn its fields and grid, and
/// writes nothing.
pub fn plan(p: &Pipeline, opts: &RunOptions) -> Result<(Plan, String, Geometry), RunError> {
    let base = opts.base();
    let (input, meta) = load_input(p, opts, &base)?;
    let fields: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let plan = Plan::resolve(p, &fields, &input.geometry).map_err(at("plan"))?;
    Ok((plan, meta.name, input.geometry))
}

/// The settings of a run of `p` with every default filled in, as the run
/// uses them: `--input` in place of the pipeline's input (and then no phantom
/// keys), and no meshing section unless the profile meshes. `mdtf run
/// --print-settings` prints them; the run report and report.html record them.
pub fn resolved_settings(p: &Pipeline, opts: &RunOptions) -> Result<toml::Table, String> {
    let mut resolved = p.clone();
    if let Some(f) = &opts.input {
        resolved.input.file = Some(f.clone());
    }
    let mut table = toml::Table::try_from(&resolved).map_err(|e| e.to_string())?;
    if resolved.pack.profile != Profile::ProjectedTetrahedra {
        table.remove("tetra");
    }
    if let Some(toml::Value::Table(input)) = table.get_mut("input")
        && input.contains_key("file")
    {
        for k in ["phantom", "size", "sigma", "noise"] {
            input.remove(k);
        }
    }
    Ok(table)
}

/// The pack's provenance: mdtf's version, the input (file or folder, its
/// format, grid `dims`, `units` and digest; or the phantom), the pipeline file and
/// the settings the run used ([`resolved_settings`]).
pub(crate) fn provenance(p: &Pipeline, opts: &RunOptions, base: &Path, dims: [usize; 3], units: &Units) -> Provenance {
    let file = input_file(p, opts, base);
    let stages =
        resolved_settings(p, opts).ok().and_then(|t| serde_json::to_value(t).ok()).unwrap_or(serde_json::Value::Null);
    Provenance {
        mdtf_version: env!("CARGO_PKG_VERSION").into(),
        input: file.as_ref().map(|f| f.display().to_string()),
        input_sha256: file.as_ref().and_then(|f| mdtf_pack::sha256_path(f).ok()),
        input_format: file.as_ref().and_then(|f| mdtf_volume::Format::of_input(f)).map(|f| f.name().to_string()),
        input_dims: Some(dims),
        input_units: units.clone(),
        pipeline: Some(opts.pipeline_path.display().to_string()),
        stages,
    }
}

/// The pack's TF file, read and parsed, when the pipeline names one.
pub(crate) fn read_tf(p: &Pipeline, base: &Path) -> Result<Option<mdtf_pack::TfFile>, RunError> {
    let err = |e: String| fail("pack")(e);
    match &p.pack.tf {
        Some(f) => {
            let path = base.join(f);
            let text = std::fs::read_to_string(&path).map_err(|e| err(format!("{}: {e}", path.display())))?;
            Ok(Some(parse_tf(&text).map_err(|e| err(format!("{}: {e}", path.display())))?))
        }
        None => Ok(None),
    }
}

/// Every file a run reads: the pipeline file, the input, the TF file and the mask.
pub(crate) fn run_inputs(p: &Pipeline, opts: &RunOptions, base: &Path) -> Inputs {
    let mut inputs = Inputs::of(&[&opts.pipeline_path]);
    if let Some(f) = input_file(p, opts, base) {
        inputs.add(&f);
    }
    if let Some(tf) = &p.pack.tf {
        inputs.add(&base.join(tf));
    }
    if let Some(mask) = &p.pack.gtf_from_mask {
        inputs.add(&base.join(mask));
    }
    inputs
}

/// The input file of a run: `--input` as given, else the pipeline's, relative to its folder.
pub(crate) fn input_file(p: &Pipeline, opts: &RunOptions, base: &Path) -> Option<PathBuf> {
    opts.input.clone().or_else(|| p.input.file.as_ref().map(|f| base.join(f)))
}

/// How the pipeline's `[input]` asks for its file to be read.
pub(crate) fn read_options(p: &Pipeline) -> ReadOptions {
    ReadOptions {
        nan: p.input.nan,
        dicom: DicomOptions { series: p.input.series.clone(), resample: p.input.resample },
        level: p.input.level,
    }
}

/// What a run knows of its input besides the samples.
#[derive(Debug, Clone, Default)]
pub(crate) struct InputMeta {
    /// Its name for figures and reports: the path as given, or the phantom's description.
    pub(crate) name: String,
    /// What its reader assumed or repaired.
    pub(crate) warnings: Vec<String>,
    /// The units it states for its values and lengths (none for a phantom).
    pub(crate) units: Units,
    /// Values that are scanner padding, not data (inclusive range, input
    /// units): the pipeline's `input.padding`, else the file's (DICOM's
    /// Pixel Padding Value).
    pub(crate) padding: Option<[f64; 2]>,
    /// Where the padding values come from, in words.
    pub(crate) padding_source: &'static str,
}

impl InputMeta {
    /// The sentence for the run report on `padded` of `voxels` voxels being
    /// padding (None without padding values).
    pub(crate) fn padding_note(&self, padded: u64, voxels: usize) -> Option<String> {
        let [lo, hi] = self.padding?;
        let values = if lo == hi { format!("{lo}") } else { format!("{lo} to {hi}") };
        Some(format!(
            "input: {padded} of {voxels} voxels ({:.1} %) are scanner padding (value {values}, {}): left out of the \
             derivatives, histograms, statistics and tracing, with every voxel within the derivative kernel's \
             reach of them",
            100.0 * padded as f64 / voxels.max(1) as f64,
            self.padding_source
        ))
    }
}

/// The padding values of a run (the pipeline's, else the file's) and where they come from.
pub(crate) fn padding_of(p: &Pipeline, file: Option<[f64; 2]>) -> (Option<[f64; 2]>, &'static str) {
    match (p.input.padding, file) {
        (Some(given), _) => (Some(given.range()), "input.padding"),
        (None, Some(range)) => (Some(range), "the DICOM Pixel Padding Value"),
        (None, None) => (None, ""),
    }
}

/// How many of `samples` lie in the padding `range` (inclusive).
pub(crate) fn count_padding(samples: &[f32], range: [f64; 2]) -> u64 {
    use rayon::prelude::*;
    let [lo, hi] = range.map(|x| x as f32);
    samples.par_iter().filter(|&&v| v >= lo && v <= hi).count() as u64
}

/// The input volume and what its reader said of it.
pub(crate) fn load_input(p: &Pipeline, opts: &RunOptions, base: &Path) -> Result<(MultiField, InputMeta), RunError> {
    if let Some(f) = input_file(p, opts, base) {
        let extension = f.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if extension == "vtu" || extension == "vtk" {
            return Err(fail("input")(format!(
                "{} is a mesh: `mdtf run` reads volumes; make a projected-tetrahedra pack of the mesh's own \
                 tetrahedra with `mdtf tetra {} -o PACK` (and `mdtf preview PACK` to look at it)",
                f.display(),
                f.display()
            )));
        }
        let (mf, info) = mdtf_volume::read_with_info(&f, &read_options(p)).map_err(at("input"))?;
        let (padding, padding_source) = padding_of(p, info.padding);
        let meta = InputMeta {
            name: f.display().to_string(),
            warnings: info.warnings,
            units: info.units,
            padding,
            padding_source,
        };
        return Ok((mf, meta));
    }
    let i = &p.input;
    if i.size < 8 || i.size > 1024 {
        return Err(fail("input")(format!("phantom size {} must be 8 to 1024", i.size)));
    }
    if !(i.sigma.is_finite() && i.sigma > 0.0) {
        return Err(fail("input")(format!("phantom sigma {} must be a positive number of voxels", i.sigma)));
    }
    if !(i.noise.is_finite() && i.noise >= 0.0) {
        return Err(fail("input")(format!("phantom noise {} must be zero or a positive standard deviation", i.noise)));
    }
    let geo = Geometry::new([i.size; 3], [1.0; 3]);
    let name = format!("built-in {:?} phantom, {}^3, sigma {}", i.phantom, i.size, i.sigma);
    let mut mf = match i.phantom {
        PhantomKind::ErfSphere => {
            let r = 0.3 * min_extent(&geo);
            MultiField::from(erf_sphere(geo, r, i.sigma, 0.0, 255.0, None).volume())
        }
        PhantomKind::Shells => MultiField::from(RadialPhantom::tooth(geo, i.sigma).volume()),
        PhantomKind::Multifield => MultiFieldPhantom::new(geo, i.sigma).volume(),
    };
    if i.noise > 0.0 {
        let g = mf.geometry.clone();
        for (k, f) in mf.fields.iter_mut().enumerate() {
            let mut v = Volume { geometry: g.clone(), data: std::mem::take(&mut f.data) };
            add_gaussian_noise(&mut v, i.noise, 1 + k as u64);
            f.data = v.data;
        }
    }
    let (padding, padding_source) = padding_of(p, None);
    Ok((mf, InputMeta { name, padding, padding_source, ..Default::default() }))
}
