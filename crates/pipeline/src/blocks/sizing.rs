//! A slab-by-slab or cluster run sized before it runs ("the plan on
//! paper"): for a grid of any size, each pass's tasks, the memory each
//! holds, the bytes each reads and writes, and what the shared disk must
//! hold, so that a Slurm or Kubernetes job can be sized from
//! `mdtf run PIPE --plan --dims 4096 --memory-budget 8GiB`.

use super::budget::{fixed_bytes, planes_by_pass, trace_block_bytes};
use super::passes::stored_for_the_run;
use super::slab_channels::made_by;
use super::{SlabSize, TraceBlocks, cut};
use crate::channel::Channel;
use crate::plan::Plan;
use crate::settings::Settings;
use mdtf_pack::{PackParams, texture_layouts};
use mdtf_volume::{Geometry, human_bytes};
use std::fmt;

/// One pass of a sized run.
#[derive(Debug, Clone, PartialEq)]
pub struct PassSize {
    /// The pass's stage.
    pub pass: &'static str,
    /// Its tasks (one per slab; the pack's one per fixed part of the
    /// histogram volume's slices when it counts it).
    pub tasks: usize,
    /// Memory one task holds at most, bytes.
    pub memory: u64,
    /// Bytes one task reads (its slab with the pass's halo), at most.
    pub read: u64,
    /// Bytes one task writes, at most.
    pub written: u64,
}

/// A slab-by-slab or cluster run of a pipeline on a grid, sized (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Sizing {
    /// The grid.
    pub geometry: Geometry,
    /// The memory budget of a task (None: the slab height was given).
    pub budget: Option<u64>,
    /// Planes per slab.
    pub height: usize,
    /// The tracing's blocks.
    pub trace: TraceBlocks,
    /// The passes, in order.
    pub passes: Vec<PassSize>,
    /// The channels in the run's store on the shared disk at its fullest.
    pub stored: Vec<Channel>,
    /// The pack's textures, bytes.
    pub pack_bytes: u64,
    /// The kept volumes before compression, bytes.
    pub kept_bytes: u64,
}

/// Why a run cannot be sized by slabs.
#[derive(Debug, thiserror::Error)]
pub enum SizingError {
    /// The run does not go slab by slab (why not).
    #[error("{0}")]
    NotBySlabs(String),
    /// The plan cannot be made.
    #[error(transparent)]
    Plan(#[from] crate::plan::PlanError),
    /// The budget cannot hold a slab or the tracing's smallest block.
    #[error(transparent)]
    Budget(#[from] super::BudgetError),
}

/// A run of `s` on `geometry` (one field) with slabs of `size`, sized.
pub fn sizing(s: &Settings, geometry: &Geometry, size: SlabSize) -> Result<Sizing, SizingError> {
    if let Some(why) = super::unsupported(s, 1) {
        return Err(SizingError::NotBySlabs(why));
    }
    let plan = Plan::resolve(s, &[], geometry)?;
    let hvol = super::slab_histograms::counts_hvol(s, s.outputs.pack.tf.is_some());
    let (height, trace) = cut(size, geometry, &plan, hvol)?;
    let [nx, ny, nz] = geometry.dims;
    let plane = (nx * ny * 4) as u64;
    let slabs = nz.div_ceil(height.max(1));
    let h = height as u64;
    let k = plan.reach.kernel[2] as u64;
    let by_pass = planes_by_pass(h, &plan, false);
    let memory = |planes: u64| fixed_bytes(hvol, geometry.voxel_count() as u64) + planes * plane;
    let mut derived: Vec<Channel> = plan.derive.iter().flat_map(|&i| made_by(i)).collect();
    if hvol {
        derived.extend([Channel::G, Channel::F2]);
    }
    let stored_derived = stored_for_the_run(&s.outputs.keep, s.outputs.keep_format, &derived);
    let mut passes = vec![
        PassSize { pass: "input", tasks: slabs, memory: memory(2 * h), read: h * plane, written: h * plane },
        PassSize {
            pass: "derive",
            tasks: slabs,
            memory: memory(by_pass.derive),
            read: (h + 2 * k) * plane,
            written: stored_derived.len() as u64 * h * plane,
        },
    ];
    let mut stored: Vec<Channel> = std::iter::once(Channel::Value).chain(stored_derived).collect();
    if plan.trace {
        let pf = if plan.prefilter { plan.reach.prefilter[2] as u64 } else { 0 };
        if plan.prefilter {
            let (read, memory) = ((h + 2 * (k + pf)) * plane, memory(by_pass.prefilter));
            passes.push(PassSize { pass: "prefilter", tasks: slabs, memory, read, written: 2 * h * plane });
            stored.extend([Channel::GPrefiltered, Channel::F2Prefiltered]);
        }
        // the select round reads the traced g (and v and g for the detection) over each slab
        let select = 3 * h * plane;
        passes.push(PassSize { pass: "select", tasks: slabs, memory: memory(3 * h), read: select, written: 0 });
        let (tp, tr) = (trace.planes as u64, trace.rows as u64);
        let [_, t_rows, t_planes] = plan.reach.trace.map(|t| t as u64);
        let grown = (tp + 2 * (t_planes + k)).min(nz as u64) * (tr + 2 * t_rows).min(ny as u64) * nx as u64 * 4;
        let read = grown * if plan.prefilter { 3 } else { 1 };
        let tasks = nz.div_ceil(trace.planes.max(1));
        let memory = trace_block_bytes(trace.planes, trace.rows, geometry, &plan);
        let traced = plan.traced_stored();
        let bytes: usize = traced.iter().map(|&c| super::store::stored_type(c).size()).sum();
        let written = bytes as u64 * tp * plane / 4;
        passes.push(PassSize { pass: "boundary", tasks, memory, read, written });
        stored.extend(traced);
    }
    passes.extend(keep_pass(s, slabs, (h, k, plane), memory(by_pass.derive)));
    let value_and_g = memory(2 * h + 2 * k);
    passes.extend(median_passes(s, &derived, slabs, value_and_g, (h + 2 * k) * plane));
    let texel = texel_bytes(s);
    let pack_planes = if hvol { nz.div_ceil(mdtf_histogram::HVOL_PARTS) as u64 } else { h };
    let pack_tasks = if hvol { mdtf_histogram::HVOL_PARTS.min(nz) } else { slabs };
    let (read, written) = pack_bytes(pack_planes, h, k, plane, &stored, (nx * ny) as u64 * texel);
    passes.push(PassSize { pass: "pack", tasks: pack_tasks, memory: memory(by_pass.pack), read, written });
    let voxels = geometry.voxel_count() as u64;
    let budget = match size {
        SlabSize::Budget(b) => Some(b),
        _ => None,
    };
    let kept_bytes = s.outputs.keep.len() as u64 * voxels * 4;
    Ok(Sizing {
        geometry: geometry.clone(),
        budget,
        height,
        trace,
        passes,
        stored,
        pack_bytes: voxels * texel,
        kept_bytes,
    })
}

/// The select passes of the whole-volume medians of g a run of `s` takes
/// (`derived`: the channels it derives), as one line of `slabs` tasks a
/// round, each holding `memory` and reading `read` bytes (the value over
/// its slab, to derive g): three rounds for the (v, 1/g) axis, and up to
/// three for gaussian-tf's default TGTF (when it finds no boundary).
fn median_passes(s: &Settings, derived: &[Channel], slabs: usize, memory: u64, read: u64) -> Option<PassSize> {
    let inverse_gradient = s.outputs.histograms.joint && derived.contains(&Channel::InvG);
    let default_tgtf = s.profile() == mdtf_pack::Profile::GaussianTf && s.outputs.pack.tf.is_none();
    let rounds = 3 * (usize::from(inverse_gradient) + usize::from(default_tgtf));
    (rounds > 0).then_some(PassSize { pass: "medians", tasks: rounds * slabs, memory, read, written: 0 })
}

/// The keep pass of a run of `s` whose tasks write its kept `.nii.gz`
/// volumes, in `slabs` tasks of `h` planes of `plane` bytes with the
/// kernel's halo `k`, each holding what a derive task holds (`derive_memory`)
/// and its kept channels: it reads the value and the stored kept channels
/// and writes at most their f32 bytes. None without such volumes.
fn keep_pass(s: &Settings, slabs: usize, (h, k, plane): (u64, u64, u64), derive_memory: u64) -> Option<PassSize> {
    let kept = s.outputs.keep.len() as u64;
    if kept == 0 || s.outputs.keep_format != crate::file::KeepFormat::NiiGz {
        return None;
    }
    let (read, written) = ((h + 2 * k) * plane + kept * h * plane, kept * h * plane);
    Some(PassSize { pass: "keep", tasks: slabs, memory: derive_memory + kept * h * plane, read, written })
}

/// Bytes a voxel of the pack textures of a run of `s` takes.
fn texel_bytes(s: &Settings) -> u64 {
    let params =
        PackParams { profile: s.profile(), ranges: Default::default(), fields: vec![], dtype: None, nifti: false };
    texture_layouts(&params).iter().map(|l| (l.components.len() * l.dtype.size()) as u64).sum()
}

/// Bytes a pack task of `planes` planes reads and writes: the value over
/// each of its slabs of `h` planes with the kernel's halo `k`, the stored
/// channels it packs over its planes; its textures (`texel_plane` bytes a plane).
fn pack_bytes(planes: u64, h: u64, k: u64, plane: u64, stored: &[Channel], texel_plane: u64) -> (u64, u64) {
    let value_planes = planes + 2 * k * planes.div_ceil(h.max(1));
    let packed_stored =
        stored.iter().filter(|c| [Channel::GHit, Channel::Hit, Channel::Distance].contains(c)).count() as u64;
    ((value_planes + packed_stored * planes) * plane, planes * texel_plane)
}

impl Sizing {
    /// Bytes of the run's channel store at its fullest.
    pub fn store_bytes(&self) -> u64 {
        let bytes: usize = self.stored.iter().map(|&c| super::store::stored_type(c).size()).sum();
        bytes as u64 * self.geometry.voxel_count() as u64
    }
}

impl fmt::Display for Sizing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = |x: u64| human_bytes(x as u128);
        let [nx, ny, nz] = self.geometry.dims;
        let within = self.budget.map_or(String::new(), |x| format!(" within {} a task", b(x)));
        writeln!(f, "by slabs or on a cluster, {nx} x {ny} x {nz} voxels{within}:")?;
        let TraceBlocks { planes, rows } = self.trace;
        writeln!(f, "  slabs of {} planes; the tracing in blocks of {planes} planes x {rows} rows", self.height)?;
        writeln!(
            f,
            "  {:<10} {:>6} {:>12} {:>12} {:>12}",
            "pass", "tasks", "memory/task", "read/task", "written/task"
        )?;
        for p in &self.passes {
            writeln!(f, "  {:<10} {:>6} {:>12} {:>12} {:>12}", p.pass, p.tasks, b(p.memory), b(p.read), b(p.written))?;
        }
        writeln!(f, "  shared disk (the output's staging folder):")?;
        let names: Vec<String> = self.stored.iter().map(|c| c.name(&[])).collect();
        writeln!(f, "    channel store at its fullest: {} ({})", b(self.store_bytes()), names.join(", "))?;
        writeln!(f, "    pack textures: {}", b(self.pack_bytes))?;
        if self.kept_bytes > 0 {
            writeln!(f, "    kept volumes: up to {} before compression", b(self.kept_bytes))?;
        }
        let kept = match (self.kept_bytes > 0, self.passes.iter().any(|p| p.pass == "keep")) {
            (false, _) => "",
            // the keep tasks compress the planes; the parts are copied, not decompressed
            (true, true) => "; it puts each kept volume's compressed parts together",
            (true, false) => " and the kept volumes (these it reads from the channel store)",
        };
        write!(f, "  the calling process merges the tasks' partial sums and writes the histograms and the tables{kept}")
    }
}
