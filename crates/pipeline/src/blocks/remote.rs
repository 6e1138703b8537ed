//! A slab-by-slab run whose heavy passes (derive, pre-filter, tracing) run
//! as tasks elsewhere: other processes, other machines of a cluster (the
//! Python package's `mdtf.dask.run` hands them to Dask). The run itself
//! reads the input, makes every whole-volume reduction and writes the
//! outputs; a task reads and writes the run's [`ChannelStore`] folder
//! (which must be on a file system every task sees) and only the planes of
//! its own slab, so a task rerun after a lost worker writes the same bytes
//! again. What a pass's tasks wrote, the run then reads back from the store
//! slab by slab, in z order, for its reductions, exactly as it would have
//! made them itself: the outputs are the single-process run's bit for bit.

use super::slab_channels::made_by;
use super::trace::{SlabTrace, TraceSetup, prefilter_slab, trace_slab};
use super::{ChannelStore, SlabChannels};
use crate::run::{RunError, at, fail};
use mdtf_bilateral::BilateralParams;
use mdtf_boundary::{BlockTrace, BoundaryParams, Crossings, ResolvedParams, TraceCounts, VolumeStats};
use mdtf_derive::DeriveParams;
use mdtf_volume::Geometry;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

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
    /// Derives every channel of the derive groups from the stored value and stores them.
    Derive {
        /// The derive passes (each its items, kernel and epsilon), as the run derives them.
        groups: Vec<DeriveParams>,
        /// Planes the kernel reads on each side of the slab.
        kernel_reach: usize,
    },
    /// Pre-filters stored channels into new ones.
    Prefilter {
        /// The channels filtered.
        filters: Vec<Prefilter>,
        /// Planes the filter reads on each side of the slab.
        halo: usize,
    },
    /// Traces the stored g and f'' (and normal) and stores the distance,
    /// g_hit, hit and dot, plus the slab's [`TracePartial`].
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

/// What a tracing task hands back besides its planes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TracePartial {
    /// The slab's hit codes, counted.
    pub counts: TraceCounts,
    /// The g at the slab's zero crossings.
    pub crossings: Crossings,
    /// The thresholds and sampling used.
    pub resolved: ResolvedParams,
}

/// The channels the tracing stores for each slab.
const TRACED: [&str; 4] = ["g_hit", "hit", "distance", "dot"];

impl SlabPass {
    /// The run's stage this pass belongs to (its errors name it).
    fn stage(&self) -> &'static str {
        match self {
            SlabPass::Derive { .. } => "derive",
            SlabPass::Prefilter { .. } => "prefilter",
            SlabPass::Trace { .. } => "boundary",
        }
    }

    /// The channels its tasks store.
    fn outputs(&self) -> Vec<String> {
        match self {
            SlabPass::Derive { groups, .. } => {
                groups.iter().flat_map(|d| d.items.iter()).flat_map(|&i| made_by(i)).collect()
            }
            SlabPass::Prefilter { filters, .. } => filters.iter().map(|f| f.output.clone()).collect(),
            SlabPass::Trace { .. } => TRACED.map(String::from).to_vec(),
        }
    }
}

/// Runs `pass` as `tasks` over `slabs` of the volume of `store`, then takes
/// the channels they stored into `store`.
pub(super) fn run_pass(
    tasks: &dyn SlabTasks,
    pass: SlabPass,
    store: &mut ChannelStore,
    slabs: &[Range<usize>],
) -> Result<(), RunError> {
    let (stage, outputs) = (pass.stage(), pass.outputs());
    let job = SlabJob { store: store.dir().to_path_buf(), geometry: store.geometry().clone(), pass };
    tasks.run(&job, slabs).map_err(fail(stage))?;
    for c in &outputs {
        store.adopt(c).map_err(at(stage))?;
    }
    Ok(())
}

/// Where the tracing task of the slab from plane `first` leaves its [`TracePartial`].
fn partial_path(store: &Path, first: usize) -> PathBuf {
    store.join(format!("trace-{first}.json"))
}

/// Runs `job` on the planes `z` of the volume: the body of one task.
pub fn run_task(job: &SlabJob, z: Range<usize>) -> Result<(), RunError> {
    let nz = job.geometry.dims[2];
    if z.start >= z.end || z.end > nz {
        return Err(fail("plan")(format!("planes {z:?} are not a slab of the volume's {nz}")));
    }
    let open = |reads: &[&str]| ChannelStore::open(job.store.clone(), job.geometry.clone(), reads).map_err(at("input"));
    match &job.pass {
        SlabPass::Derive { groups, kernel_reach } => {
            let mut chans = SlabChannels::new(open(&["v"])?, groups.clone(), *kernel_reach, nz);
            let names = job.pass.outputs();
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            for (name, v) in chans.volumes(z.clone(), &names).map_err(fail("derive"))? {
                chans.store.put_volume(&name, z.start, &v).map_err(at("derive"))?;
            }
        }
        SlabPass::Prefilter { filters, halo } => {
            let reads: Vec<&str> = filters.iter().map(|f| f.input.as_str()).collect();
            let mut chans = SlabChannels::new(open(&reads)?, vec![], 0, nz);
            for f in filters {
                let own = prefilter_slab(&mut chans, &f.input, &f.params, &z, *halo)?;
                chans.store.put_volume(&f.output, z.start, &own).map_err(at("prefilter"))?;
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
            let b = trace_slab(&mut chans, &setup, &z, &rows, None)?.trace;
            for (c, v) in TRACED.iter().zip([&b.g_hit, &b.hit, &b.distance, &b.dot]) {
                chans.store.put_volume(c, z.start, v).map_err(at("boundary"))?;
            }
            let partial = TracePartial { counts: b.counts, crossings: b.crossings, resolved: b.resolved };
            let json = serde_json::to_vec(&partial).map_err(at("boundary"))?;
            mdtf_volume::write_file_atomically(&partial_path(&job.store, z.start), |w| w.write_all(&json))
                .map_err(at("boundary"))?;
        }
    }
    Ok(())
}

/// The tracing the task of slab `z` stored, and the g it traced (`g_name`).
pub(super) fn stored_trace(chans: &mut SlabChannels, g_name: &str, z: &Range<usize>) -> Result<SlabTrace, RunError> {
    let mut v = |c: &str| chans.store.volume(c, z.clone()).map_err(at("boundary"));
    let (g_hit, hit, distance, dot, g) = (v("g_hit")?, v("hit")?, v("distance")?, v("dot")?, v(g_name)?);
    let path = partial_path(chans.store.dir(), z.start);
    let text = std::fs::read(&path).map_err(|e| fail("boundary")(format!("{}: {e}", path.display())))?;
    let TracePartial { counts, crossings, resolved } = serde_json::from_slice(&text).map_err(at("boundary"))?;
    Ok(SlabTrace { trace: BlockTrace { distance, g_hit, hit, dot, counts, crossings, resolved }, g })
}
