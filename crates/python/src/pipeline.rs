//! Pipeline files from Python: run one (whole, or slab by slab under a
//! memory budget) into an output folder, ask for its plan and halo, or run
//! one slab by slab with its heavy passes handed to a Python callable as
//! tasks (what `mdtf.dask.run` gives to a cluster) and run one such task.

use crate::call::run_released;
use crate::error::{mdtf_error, value_error};
use mdtf_pipeline::blocks::{SlabJob, SlabTasks, TaskFailed};
use mdtf_pipeline::file::Pipeline;
use mdtf_pipeline::run::RunOptions;
use mdtf_pipeline::settings::{Settings, SlabRequest};
use pyo3::prelude::*;
use pyo3::types::PyCFunction;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// The pipeline file at `path` with `overrides` (`"section.key=value"`, as `mdtf run --set`).
fn load(path: &Path, overrides: &[String]) -> PyResult<Pipeline> {
    let text = std::fs::read_to_string(path).map_err(|e| mdtf_error(format!("cannot read {}: {e}", path.display())))?;
    mdtf_pipeline::file::parse(&text, overrides).map_err(|e| value_error(format!("{}: {e}", path.display())))
}

/// Runs the pipeline file `pipeline` into the folder `output` (written whole
/// at the end; a failed or interrupted run leaves nothing), on `input` in
/// place of the pipeline's. `memory_budget` (bytes) or `slab_planes` run it
/// slab by slab; with neither, a volume too large for memory goes by slabs
/// on its own, as `mdtf run` does. With `submit`, the run goes slab by slab
/// (64 planes unless told) and its passes (reading an OME-Zarr input,
/// derive, pre-filter, tracing, histograms and textures) are handed to
/// `submit(job, slabs, cancelled)` as tasks (see `mdtf.dask.run` and
/// [`PythonTasks`]); the outputs are the same, byte for byte, and with
/// `resume` the run takes over what a killed run of the same settings and
/// input into `output` left, its finished tasks not run again. Returns
/// run_report.json's text.
#[pyfunction]
#[pyo3(signature = (pipeline, output, input=None, overrides=vec![], memory_budget=None, slab_planes=None, submit=None, resume=false))]
#[allow(clippy::too_many_arguments)]
pub fn run(
    py: Python<'_>,
    pipeline: PathBuf,
    output: PathBuf,
    input: Option<PathBuf>,
    overrides: Vec<String>,
    memory_budget: Option<u64>,
    slab_planes: Option<usize>,
    submit: Option<Py<PyAny>>,
    resume: bool,
) -> PyResult<String> {
    let p = load(&pipeline, &overrides)?;
    let cancel = Arc::new(AtomicBool::new(false));
    let tasks = submit.map(|submit| Arc::new(PythonTasks { submit, cancel: cancel.clone() }) as Arc<dyn SlabTasks>);
    let by_tasks = tasks.is_some();
    let opts = RunOptions { pipeline_path: pipeline, input, output, cancel: Some(cancel.clone()), tasks, resume };
    let settings = Settings::new(&p, &opts);
    let report = run_released(py, Some(&cancel), || {
        match settings.slabs(SlabRequest { memory_budget, slab_planes }, by_tasks) {
            Some(slabs) => mdtf_pipeline::blocks::run(&settings, &opts, slabs.size(), &|_| {}, &|_, _| {}),
            None => mdtf_pipeline::run::run(&settings, &opts, &|_| {}),
        }
    })?
    .map_err(mdtf_error)?;
    serde_json::to_string_pretty(&report).map_err(mdtf_error)
}

/// The plan of the pipeline file on its input (or `input`): its text as
/// `mdtf run --plan` prints it, and the halo a block needs, (z, y, x) voxels.
#[pyfunction]
#[pyo3(signature = (pipeline, input=None, overrides=vec![]))]
pub fn plan(
    py: Python<'_>,
    pipeline: PathBuf,
    input: Option<PathBuf>,
    overrides: Vec<String>,
) -> PyResult<(String, (usize, usize, usize))> {
    let p = load(&pipeline, &overrides)?;
    let opts = RunOptions { pipeline_path: pipeline, input, ..Default::default() };
    let settings = Settings::new(&p, &opts);
    let (plan, _, _) = run_released(py, None, || mdtf_pipeline::run::plan(&settings))?.map_err(mdtf_error)?;
    let [x, y, z] = plan.halo;
    Ok((plan.to_string(), (z, y, x)))
}

/// The tasks of a run handed to a Python callable `submit(job, slabs,
/// cancelled)`: `job` the pass as JSON, `slabs` a list of (first, end)
/// z-planes, `cancelled()` true once the run is interrupted (Ctrl-C); it
/// returns once [`slab_task`] has run on every slab (wherever it likes) or
/// the run is cancelled, and raises if a task failed for good.
struct PythonTasks {
    submit: Py<PyAny>,
    cancel: Arc<AtomicBool>,
}

impl std::fmt::Debug for PythonTasks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PythonTasks")
    }
}

impl SlabTasks for PythonTasks {
    fn run(&self, job: &SlabJob, slabs: &[Range<usize>]) -> Result<(), TaskFailed> {
        let json = serde_json::to_string(job).map_err(|e| TaskFailed(format!("the job is not JSON: {e}")))?;
        let slabs: Vec<(usize, usize)> = slabs.iter().map(|z| (z.start, z.end)).collect();
        let cancel = self.cancel.clone();
        Python::attach(|py| {
            let cancelled = PyCFunction::new_closure(py, Some(c"cancelled"), None, move |_, _| {
                cancel.load(std::sync::atomic::Ordering::Relaxed)
            })?;
            self.submit.call1(py, (json, slabs, cancelled)).map(drop)
        })
        .map_err(|e| TaskFailed(e.to_string()))
    }
}

/// Runs one task of a [`run`] with `submit`: `job` (the pass, as JSON) on the
/// planes `start..end`, writing them into the run's channel store, on
/// `threads` threads (0: the pool [`set_threads`](crate::call::set_threads) set, else one per core).
/// True when it ran, false when it found its slab done (a resumed run).
#[pyfunction]
#[pyo3(signature = (job, start, end, threads=0))]
pub fn slab_task(py: Python<'_>, job: &str, start: usize, end: usize, threads: usize) -> PyResult<bool> {
    let job: SlabJob = serde_json::from_str(job).map_err(|e| value_error(format!("not a slab job: {e}")))?;
    let pool = if threads > 0 { Some(crate::call::task_pool(threads)?) } else { None };
    let task = || mdtf_pipeline::blocks::run_task(&job, start..end);
    run_released(py, None, || match &pool {
        Some(pool) => pool.install(task),
        None => task(),
    })?
    .map(|outcome| outcome == mdtf_pipeline::blocks::TaskOutcome::Ran)
    .map_err(mdtf_error)
}
