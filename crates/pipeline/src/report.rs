//! What a run records: the run report (run_report.json) with its stage
//! lines, the boundary tracing's summary and how the run was cut into slabs.

use crate::run::RunOptions;
use mdtf_volume::Geometry;
use serde::Serialize;
use std::time::Instant;

/// One stage's line of the run report.
#[derive(Debug, Clone, Serialize)]
pub struct StageReport {
    /// Stage name.
    pub stage: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Voxels per second (of the input grid).
    pub mvoxel_per_s: f64,
    /// Peak resident memory of the process after the stage, MiB (Linux; 0 elsewhere).
    pub peak_mib: f64,
    /// Files written by the stage, relative to the output folder.
    pub outputs: Vec<String>,
}

/// The run report, written as run_report.json.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Pipeline file.
    pub pipeline: String,
    /// Output folder.
    pub output: String,
    /// Input (file or phantom).
    pub input: String,
    /// Grid size.
    pub dims: [usize; 3],
    /// Grid spacing, world units.
    pub spacing: [f64; 3],
    /// The units the input states for its values and lengths (absent when it states none).
    #[serde(skip_serializing_if = "mdtf_volume::Units::is_unknown")]
    pub units: mdtf_volume::Units,
    /// The input's fields, when it has more than one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub fields: Vec<String>,
    /// Finite range of the (first) field, input units.
    pub value_range: Option<[f64; 2]>,
    /// What the reader assumed or repaired (e.g. a DICOM series resampled
    /// onto a regular grid), and what a stage left out (e.g. a boundary below
    /// the tracing thresholds).
    pub warnings: Vec<String>,
    /// The boundary tracing's thresholds and counts, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary: Option<BoundarySummary>,
    /// The boundaries found in the histogram volume (empty when none was
    /// found or it was not built: see `hvol_built`): the materials they
    /// separate and their peak g.
    pub boundaries: Vec<mdtf_histogram::DetectedBoundary>,
    /// Whether the histogram volume was built (so `boundaries` says what was found).
    pub hvol_built: bool,
    /// How the run was cut into z-slabs, when it ran slab by slab.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slabs: Option<SlabRun>,
    /// The stages, in order.
    pub stages: Vec<StageReport>,
    /// Total wall time, seconds.
    pub total_seconds: f64,
    /// Peak resident memory of the whole run, MiB (Linux; 0 elsewhere): the
    /// stages' peaks and what came after the last (report, publishing).
    pub peak_mib: f64,
    /// The settings the run used, every default filled in ([`resolved_settings`](crate::inputs::resolved_settings)).
    pub settings: toml::Table,
}

/// The slabs of a slab-by-slab run.
#[derive(Debug, Clone, Serialize)]
pub struct SlabRun {
    /// z-planes per slab (the last may hold fewer).
    pub planes: usize,
    /// Number of slabs.
    pub count: usize,
    /// The memory budget they were sized for, bytes (None: the height was given).
    pub budget: Option<u64>,
    /// The passes that ran as tasks elsewhere (a cluster run), in order.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tasks: Vec<TaskPass>,
    /// The run took over what a killed run of the same settings and input left.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub resumed: bool,
}

/// One pass of a run whose work went to tasks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskPass {
    /// The pass's stage.
    pub pass: String,
    /// Its tasks (one per slab, or per fixed part of the histogram volume).
    pub tasks: usize,
    /// Task runs beyond one per task: reruns after a lost worker, or the
    /// scheduler's duplicates; each wrote the same bytes.
    pub retries: u64,
    /// Tasks that found their slab done by the run this one resumed, and did nothing.
    pub reused: usize,
}

impl RunReport {
    /// The report of a run of `opts` on `input` (its grid `geo`), with nothing done yet.
    pub(crate) fn of(opts: &RunOptions, input: String, geo: &Geometry) -> RunReport {
        RunReport {
            pipeline: opts.pipeline_path.display().to_string(),
            output: opts.output.display().to_string(),
            input,
            dims: geo.dims,
            spacing: geo.spacing,
            units: mdtf_volume::Units::default(),
            fields: Vec::new(),
            value_range: None,
            warnings: Vec::new(),
            boundary: None,
            boundaries: Vec::new(),
            hvol_built: false,
            slabs: None,
            stages: Vec::new(),
            total_seconds: 0.0,
            peak_mib: 0.0,
            settings: toml::Table::new(),
        }
    }
}

/// What the boundary tracing used and found.
#[derive(Debug, Clone, Serialize)]
pub struct BoundarySummary {
    /// Thresholds and sampling after defaults.
    pub resolved: mdtf_boundary::ResolvedParams,
    /// Voxels per hit code.
    pub counts: mdtf_boundary::TraceCounts,
    /// Boundaries the thresholds took out of the outputs.
    pub lost: Vec<mdtf_boundary::LostBoundary>,
}

/// What a run's tracing resolved and found (empty when it does not trace).
#[derive(Default)]
pub(crate) struct Traced {
    /// The report's boundary section.
    pub(crate) boundary: Option<BoundarySummary>,
    /// The tracing's largest distance, voxels (the distance code range).
    pub(crate) d_max: Option<f64>,
    /// The Fig. 2 report (a slab-by-slab tracing's, from its sums).
    pub(crate) report: Option<mdtf_boundary::Report>,
}

/// Peak resident set size of this process in MiB (VmHWM), 0 where unknown.
pub(crate) fn peak_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// The stage lines of a run report, as the stages finish.
#[derive(Default)]
pub(crate) struct Stages(pub Vec<StageReport>);

impl Stages {
    /// Records stage `name`, started at `t`, over `voxels` voxels, that wrote `outputs`.
    pub(crate) fn done(&mut self, name: &str, t: Instant, voxels: usize, outputs: Vec<String>) {
        let seconds = t.elapsed().as_secs_f64();
        self.0.push(StageReport {
            stage: name.into(),
            seconds,
            mvoxel_per_s: voxels as f64 / seconds.max(1e-9) / 1e6,
            peak_mib: peak_mib(),
            outputs,
        });
    }
}
