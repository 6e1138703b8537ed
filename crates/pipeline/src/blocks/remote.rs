//! A slab-by-slab run whose passes (reading an OME-Zarr input, derive,
//! pre-filter, the tracing's statistics, tracing, histograms and textures)
//! run as tasks elsewhere: other processes, other machines of a cluster
//! (the Python package's `mdtf.dask.run` hands them to Dask). A task reads
//! the input or the run's [`ChannelStore`] folder (both must be on a file
//! system every task sees), writes only the planes of its own slab (the
//! textures' at their place in the pack's files), and leaves its part of
//! the pass's whole-volume reductions beside the store ([`SlabPartial`]),
//! so a task rerun after a lost worker writes the same bytes again. The run
//! merges the parts in z order, exactly as it would have merged its own
//! slabs': the outputs are the single-process run's bit for bit. The run
//! itself writes the kept volumes, the histogram files, the tables and the
//! report. The task bodies are in [`super::tasks`].

use super::ChannelStore;
use super::medians::SelectPass;
use super::partials::SlabPartial;
use super::slab_histograms::HistogramAxes;
use crate::channel::Channel;
use crate::report::TaskPass;
use crate::run::{RunError, at};
use mdtf_bilateral::BilateralParams;
use mdtf_boundary::{BoundaryParams, VolumeStats};
use mdtf_derive::DeriveParams;
use mdtf_histogram::Axis;
use mdtf_pack::TextureTarget;
use mdtf_volume::{Geometry, NanPolicy};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Runs the tasks of a pass: [`run_task`] of `job` on every slab of `slabs`,
/// wherever it likes, returning once each has finished (an error if any
/// failed for good).
pub trait SlabTasks: Send + Sync + std::fmt::Debug {
    /// Runs `job` on each of `slabs` (z-plane ranges of the whole volume).
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed>;
}

/// A task of a pass failed for good (after the runner's retries), with the
/// runner's message (e.g. Dask's `KilledWorker: ...`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("a task failed: {0}")]
pub struct TaskFailed(pub String);

impl From<String> for TaskFailed {
    fn from(message: String) -> TaskFailed {
        TaskFailed(message)
    }
}

/// One pass of a run, as its tasks need it (serialisable: it goes to them as JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlabJob {
    /// The run's channel store folder.
    pub store: PathBuf,
    /// The whole volume's grid.
    pub geometry: Geometry,
    /// The channels the store holds when the pass starts (a task reads
    /// these; what it derives it remakes from the stored value, as the
    /// run's own passes do).
    pub stored: Vec<Channel>,
    /// The run's derive groups (each its items, kernel and epsilon).
    pub groups: Vec<DeriveParams>,
    /// Planes the derive kernel reads on each side of a slab.
    pub kernel_reach: usize,
    /// What each task does to its slab.
    pub pass: SlabPass,
    /// The run's token: a task whose token is no longer the one in the
    /// store (a later driver took the run over, or it ended) stops without
    /// publishing anything.
    pub token: String,
}

impl SlabJob {
    /// Where the task for the slab from plane `first` leaves its part of
    /// the pass's reductions once it has written everything (its slab is
    /// done when this file is there).
    pub fn partial_file(&self, first: usize) -> PathBuf {
        super::partials::path(&self.store, self.pass.name(), first)
    }

    /// The partial the task for the slab from plane `first` left (an error
    /// if it has not finished).
    pub fn partial(&self, first: usize) -> Result<SlabPartial, RunError> {
        SlabPartial::read(&self.store, self.pass.name(), first)
    }
}

/// How the channels a pass reads and does not find stored are derived:
/// the run's derive groups and the kernel's reach in planes.
#[derive(Debug, Clone, Copy)]
pub(super) struct Derivation<'d> {
    /// The derive groups.
    pub groups: &'d [DeriveParams],
    /// Planes the kernel reads on each side.
    pub kernel_reach: usize,
}

/// The work of a pass on one slab.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SlabPass {
    /// Reads the slab's planes of an input that reads any planes (an
    /// OME-Zarr store) and stores them as the value, with the value's
    /// statistics and the samples in the scanner padding's range.
    Input {
        /// The input store (an absolute path).
        input: PathBuf,
        /// Its multiscale level.
        level: usize,
        /// What its non-finite samples become.
        nan: NanPolicy,
        /// The scanner padding's values (inclusive, value units), if any.
        padding: Option<[f64; 2]>,
    },
    /// Derives the channels `summarise` and `store` from the stored value:
    /// the statistics of the first, the second stored (what the run reads
    /// itself later).
    Derive {
        /// The channels whose statistics the run takes (g also its median's
        /// first radix pass, 1/g its smallest positive value).
        summarise: Vec<Channel>,
        /// The channels stored.
        store: Vec<Channel>,
    },
    /// Pre-filters channels (remade from the value) into new ones, with
    /// their statistics.
    Prefilter {
        /// The channels filtered.
        filters: Vec<Prefilter>,
        /// Planes the filter reads on each side of the slab.
        halo: usize,
    },
    /// Counts what a whole-volume median needs from the slab (one pass of
    /// its radix select: the tracing's noise floor, the (v, 1/g) axis,
    /// gaussian-tf's default) and the (v, g) counts of the detection before
    /// the tracing.
    Select {
        /// The select's pass (None: no median).
        select: Option<SelectPass>,
        /// The (v, g) axes of the detection, when it runs.
        detect: Option<(Axis, Axis)>,
    },
    /// Traces g and f'' (derived, or stored pre-filtered ones) with the
    /// derived normal and stores the distance, g_hit, hit and dot, with
    /// g_hit's statistics and the slab's
    /// [`TracePartial`](super::partials::TracePartial).
    Trace {
        /// The g traced.
        g: Channel,
        /// The f'' traced.
        f2: Channel,
        /// g and f'' are stored pre-filtered ones.
        prefiltered: bool,
        /// The tracing's parameters.
        params: BoundaryParams,
        /// The whole volume's statistics the tracing takes its defaults from.
        stats: VolumeStats,
        /// Planes a ray may reach beyond its slab (d_max plus the interpolation's support).
        halo: usize,
        /// Rows a ray may reach beyond its strip, likewise.
        halo_rows: usize,
        /// Rows per strip: a task traces its slab strip by strip (all of
        /// them: one strip) under the run's memory budget.
        rows: usize,
        /// Value range (max - min) of the input, value units.
        value_range: f64,
        /// The traced channels stored (those the run reads later).
        stores: Vec<Channel>,
    },
    /// Writes the slab's planes of each kept channel (stored, or remade
    /// from the value) as gzip members, one a plane, into a part file of
    /// its own ([`kept_part`]): the run puts the parts of each `.nii.gz`
    /// together after its header, with no sample passing through it.
    Keep {
        /// The kept channels.
        channels: Vec<Channel>,
        /// The folder of the part files.
        parts: PathBuf,
        /// Planes read at a time (the run's slab height).
        height: usize,
    },
    /// Counts the slab's histograms and writes its planes of every pack
    /// texture, a sub-slab at a time; a pack pass counting the histogram
    /// volume gives each task whole fixed parts of its slices.
    Pack {
        /// The textures, each written at its planes' place in its file.
        textures: Vec<TextureTarget>,
        /// What the histograms are counted over, when they are counted.
        histograms: Option<HistogramAxes>,
        /// The channels read (stored, or remade from the value).
        read: Vec<Channel>,
        /// Planes read at a time (the run's slab height).
        height: usize,
    },
}

/// One stored channel pre-filtered into another.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Prefilter {
    /// The channel read (remade from the value where it is not stored).
    pub input: Channel,
    /// The channel written.
    pub output: Channel,
    /// The filter, its range sigma in value units.
    pub params: BilateralParams,
}

impl SlabPass {
    /// The run's stage this pass belongs to (its errors and partials name it).
    pub(super) fn stage(&self) -> &'static str {
        match self {
            SlabPass::Input { .. } => "input",
            SlabPass::Derive { .. } => "derive",
            SlabPass::Prefilter { .. } => "prefilter",
            SlabPass::Select { .. } | SlabPass::Trace { .. } => "boundary",
            SlabPass::Keep { .. } => "keep",
            SlabPass::Pack { .. } => "pack",
        }
    }

    /// The pass's name (in the report, and in the names of its tasks' files).
    pub(super) fn name(&self) -> &'static str {
        match self {
            SlabPass::Select { .. } => "select",
            other => other.stage(),
        }
    }

    /// The channels its tasks store.
    pub(super) fn outputs(&self) -> Vec<Channel> {
        match self {
            SlabPass::Input { .. } => vec![Channel::Value],
            SlabPass::Derive { store, .. } => store.clone(),
            SlabPass::Prefilter { filters, .. } => filters.iter().map(|f| f.output).collect(),
            SlabPass::Trace { stores, .. } => stores.clone(),
            SlabPass::Select { .. } | SlabPass::Keep { .. } | SlabPass::Pack { .. } => Vec::new(),
        }
    }
}

/// Runs `pass` as `tasks` over `slabs` of the volume of `store`, then takes
/// the channels they stored into `store`; the tasks' partials, in z order,
/// and how many tasks ran, were rerun and found their slab done already
/// (a resumed run). `token` is the run's ([`super::resume::new_token`]).
pub(super) fn run_pass(
    tasks: &dyn SlabTasks,
    pass: SlabPass,
    store: &mut ChannelStore,
    derivation: Derivation,
    slabs: &[Range<usize>],
    token: &str,
) -> Result<(Vec<SlabPartial>, TaskPass), RunError> {
    let (stage, name, outputs) = (pass.stage(), pass.name(), pass.outputs());
    let job = SlabJob {
        store: store.dir().to_path_buf(),
        geometry: store.geometry().clone(),
        stored: store.channels(),
        groups: derivation.groups.to_vec(),
        kernel_reach: derivation.kernel_reach,
        pass,
        token: token.to_string(),
    };
    // a task's runs are counted in its attempts file, across the runs a resumed run follows
    let dir = store.dir().to_path_buf();
    let runs = |z: &Range<usize>| std::fs::metadata(attempts_path(&dir, name, z.start)).map_or(0, |m| m.len());
    let before: Vec<u64> = slabs.iter().map(runs).collect();
    tasks.run(&job, slabs).map_err(at(stage))?;
    for &c in &outputs {
        store.adopt(c).map_err(at(stage))?;
    }
    let (mut retries, mut reused) = (0, 0);
    for (z, before) in slabs.iter().zip(before) {
        match runs(z).saturating_sub(before) {
            0 => reused += 1,
            ran => retries += ran - 1,
        }
    }
    let partials = slabs.iter().map(|z| SlabPartial::read(store.dir(), name, z.start)).collect::<Result<_, _>>()?;
    Ok((partials, TaskPass { pass: name.into(), tasks: slabs.len(), retries, reused }))
}

/// The part file of kept channel `c` a keep task for the slab from plane
/// `first` writes in the folder `parts`.
pub(super) fn kept_part(parts: &Path, c: Channel, first: usize) -> PathBuf {
    parts.join(format!("{}-{first}.gz", super::store::file_name(c)))
}

/// The file a task of pass `name` for the slab from plane `first` adds a
/// byte to each time it starts (its length: how often the task ran).
pub(super) fn attempts_path(store: &Path, name: &str, first: usize) -> PathBuf {
    store.join(format!("{name}-{first}.attempts"))
}
