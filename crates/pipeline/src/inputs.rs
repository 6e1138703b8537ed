//! What a run reads: its input file or built-in phantom, how the input is
//! to be read, the TF file, the list of files it reads (so that no output
//! replaces one), and the settings and provenance it records.

use crate::error::{RunError, at, fail};
use crate::file::{PackSection, PhantomKind};
use crate::plan::Plan;
use crate::settings::{InputSettings, InputSource, Settings};
use mdtf_datagen::{MultiFieldPhantom, RadialPhantom, add_gaussian_noise, erf_sphere, min_extent};
use mdtf_pack::{Provenance, parse_tf};
use mdtf_volume::{Geometry, Inputs, MultiField, Units, Volume};
use std::path::Path;

/// The plan [`run`](crate::run::run) follows for `s`, with the input's name and grid. It reads
/// the input (or builds the phantom) to learn its fields and grid, and
/// writes nothing.
pub fn plan(s: &Settings) -> Result<(Plan, String, Geometry), RunError> {
    let (input, meta) = load_input(&s.input)?;
    let fields: Vec<String> = input.fields.iter().map(|f| f.name.clone()).collect();
    let plan = Plan::resolve(s, &fields, &input.geometry).map_err(at("plan"))?;
    Ok((plan, meta.name, input.geometry))
}

/// The pack's provenance: mdtf's version, the input (file or folder, its
/// format, grid `dims`, `units` and digest; or the phantom), the pipeline file and
/// the settings the run used ([`Settings::to_table`]).
pub(crate) fn provenance(s: &Settings, dims: [usize; 3], units: &Units) -> Provenance {
    let file = s.input.file();
    let stages = s.to_table().ok().and_then(|t| serde_json::to_value(t).ok()).unwrap_or(serde_json::Value::Null);
    Provenance {
        mdtf_version: env!("CARGO_PKG_VERSION").into(),
        input: file.map(|f| f.display().to_string()),
        input_sha256: file.and_then(|f| mdtf_pack::sha256_path(f).ok()),
        input_format: file.and_then(mdtf_volume::Format::of_input).map(|f| f.name().to_string()),
        input_dims: Some(dims),
        input_units: units.clone(),
        pipeline: Some(s.pipeline_path.display().to_string()),
        stages,
    }
}

/// The pack's TF file, read and parsed, when the pack names one.
pub(crate) fn read_tf(pack: &PackSection) -> Result<Option<mdtf_pack::TfFile>, RunError> {
    let err = |e: String| fail("pack")(e);
    match &pack.tf {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| err(format!("{}: {e}", path.display())))?;
            Ok(Some(parse_tf(&text).map_err(|e| err(format!("{}: {e}", path.display())))?))
        }
        None => Ok(None),
    }
}

/// Every file a run reads: the pipeline file, the input, the TF file and the mask.
pub(crate) fn run_inputs(s: &Settings) -> Inputs {
    let mut inputs = Inputs::of(&[&s.pipeline_path]);
    let pack = &s.outputs.pack;
    for f in [s.input.file(), pack.tf.as_deref(), pack.gtf_from_mask.as_deref()].into_iter().flatten() {
        inputs.add(f);
    }
    inputs
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
pub(crate) fn padding_of(input: &InputSettings, file: Option<[f64; 2]>) -> (Option<[f64; 2]>, &'static str) {
    match (input.padding, file) {
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
pub(crate) fn load_input(input: &InputSettings) -> Result<(MultiField, InputMeta), RunError> {
    let (kind, size, sigma, noise) = match &input.source {
        &InputSource::Phantom { kind, size, sigma, noise } => (kind, size, sigma, noise),
        InputSource::File(f) => return load_file(input, f),
    };
    if !(8..=1024).contains(&size) {
        return Err(fail("input")(format!("phantom size {size} must be 8 to 1024")));
    }
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(fail("input")(format!("phantom sigma {sigma} must be a positive number of voxels")));
    }
    if !(noise.is_finite() && noise >= 0.0) {
        return Err(fail("input")(format!("phantom noise {noise} must be zero or a positive standard deviation")));
    }
    let geo = Geometry::new([size; 3], [1.0; 3]);
    let name = format!("built-in {kind:?} phantom, {size}^3, sigma {sigma}");
    let mut mf = match kind {
        PhantomKind::ErfSphere => {
            let r = 0.3 * min_extent(&geo);
            MultiField::from(erf_sphere(geo, r, sigma, 0.0, 255.0, None).volume())
        }
        PhantomKind::Shells => MultiField::from(RadialPhantom::tooth(geo, sigma).volume()),
        PhantomKind::Multifield => MultiFieldPhantom::new(geo, sigma).volume(),
    };
    if noise > 0.0 {
        let g = mf.geometry.clone();
        for (k, f) in mf.fields.iter_mut().enumerate() {
            let mut v = Volume { geometry: g.clone(), data: std::mem::take(&mut f.data) };
            add_gaussian_noise(&mut v, noise, 1 + k as u64);
            f.data = v.data;
        }
    }
    let (padding, padding_source) = padding_of(input, None);
    Ok((mf, InputMeta { name, padding, padding_source, ..Default::default() }))
}

/// The volume in the file `f` and what its reader said of it.
fn load_file(input: &InputSettings, f: &Path) -> Result<(MultiField, InputMeta), RunError> {
    let extension = f.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if extension == "vtu" || extension == "vtk" {
        return Err(fail("input")(format!(
            "{} is a mesh: `mdtf run` reads volumes; make a projected-tetrahedra pack of the mesh's own \
             tetrahedra with `mdtf tetra {} -o PACK` (and `mdtf preview PACK` to look at it)",
            f.display(),
            f.display()
        )));
    }
    let (mf, info) = mdtf_volume::read_with_info(f, &input.read).map_err(at("input"))?;
    let (padding, padding_source) = padding_of(input, info.padding);
    let meta = InputMeta {
        name: f.display().to_string(),
        warnings: info.warnings,
        units: info.units,
        padding,
        padding_source,
    };
    Ok((mf, meta))
}
