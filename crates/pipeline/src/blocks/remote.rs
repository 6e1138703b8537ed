//! A slab-by-slab run whose heavy passes (reading an OME-Zarr input,
//! derive, pre-filter, tracing) run as tasks elsewhere: other processes,
//! other machines of a cluster (the Python package's `mdtf.dask.run` hands
//! them to Dask). A task reads the input or the run's [`ChannelStore`]
//! folder (both must be on a file system every task sees), writes only the
//! planes of its own slab, and leaves its part of the pass's whole-volume
//! reductions beside the store ([`SlabPartial`]), so a task rerun after a
//! lost worker writes the same bytes again. The run merges the parts in z
//! order, exactly as it would have merged its own slabs': the outputs are
//! the single-process run's bit for bit. The run itself still makes the
//! histograms, the pack and the kept volumes from the stored channels.

use super::partials::{SlabPartial, TracePartial};
use super::slab_channels::made_by;
use super::slab_histograms::{HistogramAxes, HistogramCounts};
use super::trace::{TraceSetup, prefilter_slab, trace_slab};
use super::{ChannelStore, SlabChannels};
use crate::run::{RunError, at, fail};
use mdtf_bilateral::BilateralParams;
use mdtf_boundary::{BoundaryParams, ReportAccumulator, ReportInput, VolumeStats};
use mdtf_derive::DeriveParams;
use mdtf_pack::TextureTarget;
use mdtf_volume::{Geometry, NanPolicy, PlaneReader, ReadOptions};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::PathBuf;

/// Runs the tasks of a pass: [`run_task`] of `job` on every slab of `slabs`,
/// wherever it likes, returning once each has finished (an error if any
/// failed for good).
pub trait SlabTasks: Send + Sync + std::fmt::Debug {
    /// Runs `job` on each of `slabs` (z-plane ranges of the whole volume).
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), String>;
}

/// One pass of a run, as its tasks need it (serialisable: it goes to them as JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlabJob {
    /// The run's channel store folder.
    pub store: PathBuf,
    /// The whole volume's grid.
    pub geometry: Geometry,
    /// What each task does to its slab.
    pub pass: SlabPass,
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
    /// Derives every channel of the derive groups from the stored value and
    /// stores them, with the statistics of the channels `summarise`.
    Derive {
        /// The derive passes (each its items, kernel and epsilon), as the run derives them.
        groups: Vec<DeriveParams>,
        /// Planes the kernel reads on each side of the slab.
        kernel_reach: usize,
        /// The channels whose statistics the run takes (g also its median's
        /// first radix pass, 1/g its smallest positive value).
        summarise: Vec<String>,
    },
    /// Pre-filters stored channels into new ones, with their statistics.
    Prefilter {
        /// The channels filtered.
        filters: Vec<Prefilter>,
        /// Planes the filter reads on each side of the slab.
        halo: usize,
    },
    /// Counts the slab's histograms and writes its planes of every pack
    /// texture, from the stored channels, a sub-slab at a time; a pack
    /// pass counting the histogram volume gives each task whole fixed
    /// parts of its slices.
    Pack {
        /// The textures, each written at its planes' place in its file.
        textures: Vec<TextureTarget>,
        /// What the histograms are counted over, when they are counted.
        histograms: Option<HistogramAxes>,
        /// The stored channels read.
        read: Vec<String>,
        /// Planes read at a time (the run's slab height).
        height: usize,
    },
    /// Traces the stored g and f'' (and normal) and stores the distance,
    /// g_hit, hit and dot, with g_hit's statistics and the slab's [`TracePartial`].
    Trace {
        /// The stored g traced.
        g: String,
        /// The stored f'' traced.
        f2: String,
        /// The tracing's parameters.
        params: BoundaryParams,
        /// The whole volume's statistics the tracing takes its defaults from.
        stats: VolumeStats,
        /// Planes a ray may reach beyond its slab (d_max plus the interpolation's support).
        halo: usize,
        /// Value range (max - min) of the input, value units.
        value_range: f64,
    },
}

/// One stored channel pre-filtered into another.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Prefilter {
    /// The stored channel read.
    pub input: String,
    /// The channel written.
    pub output: String,
    /// The filter, its range sigma in value units.
    pub params: BilateralParams,
}

/// The channels the tracing stores for each slab.
const TRACED: [&str; 4] = ["g_hit", "hit", "distance", "dot"];

impl SlabPass {
    /// The run's stage this pass belongs to (its errors and partials name it).
    pub(super) fn stage(&self) -> &'static str {
        match self {
            SlabPass::Input { .. } => "input",
            SlabPass::Derive { .. } => "derive",
            SlabPass::Prefilter { .. } => "prefilter",
            SlabPass::Trace { .. } => "boundary",
            SlabPass::Pack { .. } => "pack",
        }
    }

    /// The channels its tasks store.
    fn outputs(&self) -> Vec<String> {
        match self {
            SlabPass::Input { .. } => vec!["v".into()],
            SlabPass::Derive { groups, .. } => {
                groups.iter().flat_map(|d| d.items.iter()).flat_map(|&i| made_by(i)).collect()
            }
            SlabPass::Prefilter { filters, .. } => filters.iter().map(|f| f.output.clone()).collect(),
            SlabPass::Trace { .. } => TRACED.map(String::from).to_vec(),
            SlabPass::Pack { .. } => Vec::new(),
        }
    }
}

/// Runs `pass` as `tasks` over `slabs` of the volume of `store`, then takes
/// the channels they stored into `store`; the tasks' partials, in z order.
pub(super) fn run_pass(
    tasks: &dyn SlabTasks,
    pass: SlabPass,
    store: &mut ChannelStore,
    slabs: &[Range<usize>],
) -> Result<Vec<SlabPartial>, RunError> {
    let (stage, outputs) = (pass.stage(), pass.outputs());
    let job = SlabJob { store: store.dir().to_path_buf(), geometry: store.geometry().clone(), pass };
    tasks.run(&job, slabs).map_err(fail(stage))?;
    for c in &outputs {
        store.adopt(c).map_err(at(stage))?;
    }
    slabs.iter().map(|z| SlabPartial::read(store.dir(), stage, z.start)).collect()
}

/// Runs `job` on the planes `z` of the volume: the body of one task.
pub fn run_task(job: &SlabJob, z: Range<usize>) -> Result<(), RunError> {
    let nz = job.geometry.dims[2];
    if z.start >= z.end || z.end > nz {
        return Err(fail("plan")(format!("planes {z:?} are not a slab of the volume's {nz}")));
    }
    let voxels = job.geometry.voxel_count();
    let stage = job.pass.stage();
    let open = |reads: &[&str]| ChannelStore::open(job.store.clone(), job.geometry.clone(), reads).map_err(at("input"));
    let mut partial = SlabPartial::default();
    match &job.pass {
        SlabPass::Input { input, level, nan, padding } => {
            let read = ReadOptions { nan: *nan, level: *level, ..ReadOptions::default() };
            let not_by_planes = || fail("input")(format!("{}: not readable by planes", input.display()));
            let mut reader = PlaneReader::open(input, &read).map_err(at("input"))?.ok_or_else(not_by_planes)?;
            if reader.geometry().dims != job.geometry.dims {
                let dims = reader.geometry().dims;
                return Err(fail("input")(format!(
                    "{}: {dims:?} voxels, the run planned {:?}",
                    input.display(),
                    job.geometry.dims
                )));
            }
            let v = reader.read(z.clone()).map_err(at("input"))?;
            open(&[])?.put_volume("v", z.start, &v).map_err(at("input"))?;
            partial.summarise("v", v.samples(), voxels);
            if let Some(range) = padding {
                partial.padded = crate::inputs::count_padding(v.samples(), *range);
            }
        }
        SlabPass::Derive { groups, kernel_reach, summarise } => {
            let mut chans = SlabChannels::new(open(&["v"])?, groups.clone(), *kernel_reach, nz);
            let names = job.pass.outputs();
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            for (name, v) in chans.volumes(z.clone(), &names).map_err(fail("derive"))? {
                chans.store.put_volume(&name, z.start, &v).map_err(at("derive"))?;
                if !summarise.contains(&name) {
                    continue;
                }
                partial.summarise(&name, v.samples(), voxels);
                match name.as_str() {
                    "g" => partial.g_buckets.get_or_insert_with(mdtf_volume::KeyBuckets::new).add(v.samples()),
                    "inv_g" => partial.smallest_inv_g = Some(crate::pack_inputs::smallest_positive(v.samples())),
                    _ => {}
                }
            }
        }
        SlabPass::Prefilter { filters, halo } => {
            let reads: Vec<&str> = filters.iter().map(|f| f.input.as_str()).collect();
            let mut chans = SlabChannels::new(open(&reads)?, vec![], 0, nz);
            for f in filters {
                let own = prefilter_slab(&mut chans, &f.input, &f.params, &z, *halo)?;
                chans.store.put_volume(&f.output, z.start, &own).map_err(at("prefilter"))?;
                partial.summarise(&f.output, own.samples(), voxels);
            }
        }
        SlabPass::Trace { g, f2, params, stats, halo, value_range } => {
            let mut chans = SlabChannels::new(open(&[g, f2, "nx", "ny", "nz"])?, vec![], 0, nz);
            let setup = TraceSetup {
                g,
                f2,
                stored: true,
                prefiltered: false,
                params,
                stats,
                halo: *halo,
                halo_rows: 0,
                value_range: *value_range,
            };
            let rows = 0..chans.ny();
            let slab = trace_slab(&mut chans, &setup, &z, &rows, None)?;
            let b = &slab.trace;
            for (c, v) in TRACED.iter().zip([&b.g_hit, &b.hit, &b.distance, &b.dot]) {
                chans.store.put_volume(c, z.start, v).map_err(at("boundary"))?;
            }
            partial.summarise("g_hit", b.g_hit.samples(), voxels);
            let mut report = ReportAccumulator::new(b.resolved.report_thresholds());
            report.add(ReportInput {
                hit: b.hit.samples(),
                dot: b.dot.samples(),
                distance: b.distance.samples(),
                g: slab.g.samples(),
                g_hit: b.g_hit.samples(),
            });
            let (counts, crossings, resolved) = (b.counts, b.crossings.clone(), b.resolved);
            partial.trace = Some(TracePartial { counts, crossings, resolved, report });
        }
        SlabPass::Pack { textures, histograms, read, height } => {
            let reads: Vec<&str> = read.iter().map(String::as_str).collect();
            let mut chans = SlabChannels::new(open(&reads)?, vec![], 0, nz);
            let mut counts = HistogramCounts::default();
            for first in z.clone().step_by((*height).max(1)) {
                let planes = first..(first + height.max(&1)).min(z.end);
                let slab = chans.volumes(planes.clone(), &reads).map_err(fail("pack"))?;
                if let Some(axes) = histograms {
                    counts.of_task_slab(axes, &planes, nz, voxels, &slab)?;
                }
                for t in textures {
                    t.write_planes(planes.clone(), &slab).map_err(at("pack"))?;
                }
                chans.give_back(slab);
            }
            partial.histograms = histograms.is_some().then_some(counts);
        }
    }
    partial.write(&job.store, stage, z.start)
}
