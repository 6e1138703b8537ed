//! A run's settings, resolved once from its pipeline file and options
//! ([`Settings::new`]): the input as the run opens it (a file's path, or a
//! phantom), how it is read, the measuring chain (kernel, pre-filter,
//! tracing), the outputs (histograms, pack, kept volumes, preview) and how
//! the run is cut into slabs ([`Settings::slabs`]). Every executor (the
//! whole-volume run, the slab run, the tasks, `mdtf boundary`'s slab
//! tracing), the CLI, the Python package, `--print-settings`, the report and
//! the pack's provenance take them from here.
//!
//! Defaults live in the stage libraries (the kernel in `mdtf_derive`, the
//! tracing's step, d_max and thresholds in `mdtf_boundary::resolve`, the
//! pre-filter's in `mdtf_bilateral`); those that need the grid or the
//! samples (d_max, the noise floor) are resolved when the run has them and
//! recorded in the report's `boundary` section.

use crate::blocks::SlabSize;
use crate::boundary_chain::BoundaryChainParams;
use crate::file::{
    DeriveSection, HistogramSection, InputSection, KeepFormat, PackSection, Padding, PhantomKind, Pipeline,
};
use crate::run::RunOptions;
use mdtf_pack::Profile;
use mdtf_volume::dicom::DicomOptions;
use mdtf_volume::{Geometry, ReadOptions};
use std::path::{Path, PathBuf};

/// Where a run's input comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum InputSource {
    /// A volume file or folder, its path as the run opens it (`--input` as
    /// given, else the pipeline's, relative to the pipeline file's folder).
    File(PathBuf),
    /// A built-in phantom.
    Phantom {
        /// Which phantom.
        kind: PhantomKind,
        /// Grid size (a cube of this many voxels a side, unit spacing).
        size: usize,
        /// Boundary blur, world units.
        sigma: f64,
        /// Standard deviation of the Gaussian noise added, value units (0: none).
        noise: f64,
    },
}

/// The input of a run and how it is read.
#[derive(Debug, Clone, PartialEq)]
pub struct InputSettings {
    /// The file or phantom.
    pub source: InputSource,
    /// How the file is read (NaN policy, DICOM series, OME-Zarr level).
    pub read: ReadOptions,
    /// The scanner padding values the pipeline gives; without them a
    /// file's own (DICOM's Pixel Padding Value) are used.
    pub padding: Option<Padding>,
}

impl InputSettings {
    /// The input file, if the input is one.
    pub fn file(&self) -> Option<&Path> {
        match &self.source {
            InputSource::File(f) => Some(f),
            InputSource::Phantom { .. } => None,
        }
    }

    /// A file read as `read` says, with no padding values of its own.
    pub fn of_file(file: &Path, read: &ReadOptions) -> InputSettings {
        InputSettings { source: InputSource::File(file.to_path_buf()), read: read.clone(), padding: None }
    }
}

/// Which histograms a run makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Histograms {
    /// The histogram stage runs (the pipeline has a `[histogram]` section):
    /// the 1D value histogram at least.
    pub counted: bool,
    /// The joint (v, g) histogram.
    pub joint: bool,
    /// The stretched (v, g_hit) histogram and the normal | stretched figure.
    pub stretched: bool,
    /// The histogram volume and the default opacity.
    pub hvol: bool,
}

/// What a run writes besides the store of its channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Outputs {
    /// The histograms.
    pub histograms: Histograms,
    /// The pack: profile, TF file and mask (paths as the run opens them), alpha map.
    pub pack: PackSection,
    /// The projected-tetrahedra profile's meshing and tables.
    pub tetra: mdtf_tetra::TetraParams,
    /// Channels written as volumes too, by their table names.
    pub keep: Vec<String>,
    /// How the kept channels are written.
    pub keep_format: KeepFormat,
    /// preview.png is asked for (rendered when the pack can be previewed).
    pub preview: bool,
}

/// A pipeline run's settings with every default filled in that does not
/// need the grid or the samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The pipeline file (for provenance).
    pub pipeline_path: PathBuf,
    /// The pipeline's one-line description.
    pub description: String,
    /// The input.
    pub input: InputSettings,
    /// Kernel, pre-filter and tracing parameters (the derive border and
    /// epsilon are the defaults in a pipeline run).
    pub chain: BoundaryChainParams,
    /// The outputs.
    pub outputs: Outputs,
}

impl Settings {
    /// The settings of a run of `p` with `opts`: `--input` in place of the
    /// pipeline's input, file paths joined to the pipeline file's folder.
    pub fn new(p: &Pipeline, opts: &RunOptions) -> Settings {
        let base = opts.base();
        let i = &p.input;
        let source = match opts.input.clone().or_else(|| i.file.as_ref().map(|f| base.join(f))) {
            Some(file) => InputSource::File(file),
            None => InputSource::Phantom { kind: i.phantom, size: i.size, sigma: i.sigma, noise: i.noise },
        };
        let read = ReadOptions {
            nan: i.nan,
            dicom: DicomOptions { series: i.series.clone(), resample: i.resample },
            level: i.level,
        };
        let chain = BoundaryChainParams {
            kernel: p.derive.kernel,
            border: None,
            epsilon: None,
            prefilter: p.prefilter.clone(),
            boundary: p.boundary.clone(),
        };
        let histograms = match &p.histogram {
            Some(h) => Histograms { counted: true, joint: h.joint, stretched: h.stretched, hvol: h.hvol },
            None => Histograms::default(),
        };
        let pack = PackSection {
            tf: p.pack.tf.as_ref().map(|f| base.join(f)),
            gtf_from_mask: p.pack.gtf_from_mask.as_ref().map(|f| base.join(f)),
            ..p.pack.clone()
        };
        let outputs = Outputs {
            histograms,
            preview: p.preview,
            pack,
            tetra: p.tetra.clone(),
            keep: p.keep.clone(),
            keep_format: p.keep_format,
        };
        Settings {
            pipeline_path: opts.pipeline_path.clone(),
            description: p.description.clone(),
            input: InputSettings { source, read, padding: i.padding },
            chain,
            outputs,
        }
    }

    /// The profile of the pack.
    pub fn profile(&self) -> Profile {
        self.outputs.pack.profile
    }

    /// The settings as a pipeline file: what `mdtf run --print-settings`
    /// prints and the report and the pack's provenance record. The input
    /// is its file or its phantom's keys; no `[tetra]` unless the profile
    /// meshes; paths absolute, so that the file runs from any folder.
    pub fn to_table(&self) -> Result<toml::Table, String> {
        let mut table = toml::Table::try_from(self.as_pipeline()).map_err(|e| e.to_string())?;
        if self.profile() != Profile::ProjectedTetrahedra {
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

    /// The settings in the pipeline file's own shape.
    fn as_pipeline(&self) -> Pipeline {
        let (input, read) = (&self.input, &self.input.read);
        let mut section = InputSection {
            series: read.dicom.series.clone(),
            resample: read.dicom.resample,
            level: read.level,
            nan: read.nan,
            padding: input.padding,
            ..InputSection::default()
        };
        match &input.source {
            InputSource::File(f) => section.file = Some(absolute(f)),
            &InputSource::Phantom { kind, size, sigma, noise } => {
                (section.phantom, section.size, section.sigma, section.noise) = (kind, size, sigma, noise)
            }
        }
        let h = &self.outputs.histograms;
        let histogram = h.counted.then_some(HistogramSection { joint: h.joint, stretched: h.stretched, hvol: h.hvol });
        Pipeline {
            description: self.description.clone(),
            input: section,
            derive: DeriveSection { kernel: self.chain.kernel },
            prefilter: self.chain.prefilter.clone(),
            boundary: self.chain.boundary.clone(),
            histogram,
            pack: PackSection {
                tf: self.outputs.pack.tf.as_deref().map(absolute),
                gtf_from_mask: self.outputs.pack.gtf_from_mask.as_deref().map(absolute),
                ..self.outputs.pack.clone()
            },
            tetra: self.outputs.tetra.clone(),
            keep: self.outputs.keep.clone(),
            keep_format: self.outputs.keep_format,
            preview: self.outputs.preview,
        }
    }

    /// How a run of these settings is cut: as `asked` says, else in
    /// [`DEFAULT_TASK_PLANES`]-plane slabs when its passes go to tasks,
    /// else by slabs under a budget of its own when the whole volume would
    /// not fit in memory ([`crate::blocks::automatic`]); None: whole.
    pub fn slabs(&self, asked: SlabRequest, tasks: bool) -> Option<Slabs> {
        if let Some(size) = asked.size() {
            return Some(Slabs::Asked(size));
        }
        if tasks {
            return Some(Slabs::Tasks(SlabSize::Planes(DEFAULT_TASK_PLANES)));
        }
        crate::blocks::automatic(self).map(|(budget, geometry)| Slabs::TooLarge { budget, geometry })
    }
}

/// `path` made absolute against the working folder (as given where it cannot be).
fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// z-planes per task of a run whose passes go to tasks when neither a
/// budget nor a height is given.
pub const DEFAULT_TASK_PLANES: usize = 64;

/// How a run was asked to be cut (`--memory-budget`, `--slab-planes`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlabRequest {
    /// A memory budget, bytes: the tallest slabs that fit.
    pub memory_budget: Option<u64>,
    /// Slabs of this many z-planes (taken when no budget is given).
    pub slab_planes: Option<usize>,
}

impl SlabRequest {
    /// The slabs asked for, if any: the budget, else the height (at least 1).
    pub fn size(self) -> Option<SlabSize> {
        match (self.memory_budget, self.slab_planes) {
            (Some(b), _) => Some(SlabSize::Budget(b)),
            (None, Some(h)) => Some(SlabSize::Planes(h.max(1))),
            (None, None) => None,
        }
    }
}

/// Why and how a run goes by slabs.
#[derive(Debug, Clone, PartialEq)]
pub enum Slabs {
    /// The slabs asked for.
    Asked(SlabSize),
    /// The default height of a run whose passes go to tasks.
    Tasks(SlabSize),
    /// The whole volume would not fit in memory: slabs under a budget of
    /// `budget` bytes, on the input's grid.
    TooLarge {
        /// The budget, bytes.
        budget: u64,
        /// The input's grid, from its header.
        geometry: Geometry,
    },
}

impl Slabs {
    /// The slab size.
    pub fn size(&self) -> SlabSize {
        match self {
            Slabs::Asked(s) | Slabs::Tasks(s) => *s,
            Slabs::TooLarge { budget, .. } => SlabSize::Budget(*budget),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Pipeline {
        crate::file::parse(text, &[]).unwrap()
    }

    #[test]
    fn paths_join_the_pipeline_folder_and_input_replaces_the_pipelines() {
        let p =
            parse("[input]\nfile = \"ct.nii\"\nnan = \"zero\"\n[pack]\nprofile = \"gaussian-tf\"\ntf = \"a.json\"\n");
        let opts = RunOptions { pipeline_path: "jobs/run.toml".into(), ..Default::default() };
        let s = Settings::new(&p, &opts);
        assert_eq!(s.input.file(), Some(Path::new("jobs/ct.nii")));
        assert_eq!(s.input.read.nan, mdtf_volume::NanPolicy::Zero);
        assert_eq!(s.outputs.pack.tf.as_deref(), Some(Path::new("jobs/a.json")));
        let given = RunOptions { input: Some("/data/mr.nrrd".into()), ..opts };
        assert_eq!(Settings::new(&p, &given).input.file(), Some(Path::new("/data/mr.nrrd")));
    }

    #[test]
    fn no_histogram_section_counts_nothing_and_the_table_leaves_it_out() {
        let s = Settings::new(&parse("[pack]\nprofile = \"slicer-3dtf\"\n"), &RunOptions::default());
        assert_eq!(s.outputs.histograms, Histograms::default());
        assert_eq!(
            s.input.source,
            InputSource::Phantom { kind: PhantomKind::ErfSphere, size: 128, sigma: 3.0, noise: 0.0 }
        );
        let table = s.to_table().unwrap();
        assert!(table.get("histogram").is_none() && table.get("tetra").is_none(), "{table}");
        assert_eq!(table["input"]["size"].as_integer(), Some(128));
        let h = Settings::new(&parse("[pack]\nprofile = \"slicer-3dtf\"\n[histogram]\n"), &RunOptions::default());
        assert_eq!(h.outputs.histograms, Histograms { counted: true, joint: true, stretched: false, hvol: false });
    }

    #[test]
    fn the_printed_settings_read_back_as_the_same_settings() {
        let text = "[input]\nfile = \"x.nrrd\"\npadding = -2000\n[pack]\nprofile = \"distance-tf\"\n[prefilter]\n\
                    sigma_d = 2.0\n[histogram]\nstretched = true\n[boundary]\ng_min = 3.5\n";
        let s = Settings::new(&parse(text), &RunOptions::default());
        let printed = crate::file::to_toml(&s.to_table().unwrap()).unwrap();
        // run from another folder, the printed file reads the same input
        let elsewhere = RunOptions { pipeline_path: "/elsewhere/printed.toml".into(), ..Default::default() };
        let again = Settings::new(&parse(&printed), &elsewhere);
        let input = std::path::absolute("x.nrrd").unwrap();
        assert_eq!(again.input.file(), Some(input.as_path()), "{printed}");
        let same_but_the_path = Settings {
            input: InputSettings { source: InputSource::File(input), ..s.input.clone() },
            pipeline_path: elsewhere.pipeline_path.clone(),
            ..s
        };
        assert_eq!(again, same_but_the_path, "{printed}");
    }

    #[test]
    fn slabs_asked_for_win_and_tasks_default_to_their_height() {
        let s = Settings::new(&parse("[pack]\nprofile = \"slicer-3dtf\"\n"), &RunOptions::default());
        let budget = SlabRequest { memory_budget: Some(1 << 30), slab_planes: Some(8) };
        assert_eq!(s.slabs(budget, true), Some(Slabs::Asked(SlabSize::Budget(1 << 30))));
        let planes = SlabRequest { memory_budget: None, slab_planes: Some(0) };
        assert_eq!(s.slabs(planes, false).map(|s| s.size()), Some(SlabSize::Planes(1)));
        assert_eq!(s.slabs(SlabRequest::default(), true), Some(Slabs::Tasks(SlabSize::Planes(DEFAULT_TASK_PLANES))));
        // a phantom is never too large
        assert_eq!(s.slabs(SlabRequest::default(), false), None);
    }
}
