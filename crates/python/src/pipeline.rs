//! Pipeline files from Python: run one (whole, or slab by slab under a
//! memory budget) into an output folder, and ask for its plan and halo.

use crate::call::run_released;
use crate::error::{mdtf_error, value_error};
use mdtf_pipeline::blocks::SlabSize;
use mdtf_pipeline::file::Pipeline;
use mdtf_pipeline::run::RunOptions;
use pyo3::prelude::*;
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
/// on its own, as `mdtf run` does. Returns run_report.json's text.
#[pyfunction]
#[pyo3(signature = (pipeline, output, input=None, overrides=vec![], memory_budget=None, slab_planes=None))]
pub fn run(
    py: Python<'_>,
    pipeline: PathBuf,
    output: PathBuf,
    input: Option<PathBuf>,
    overrides: Vec<String>,
    memory_budget: Option<u64>,
    slab_planes: Option<usize>,
) -> PyResult<String> {
    let p = load(&pipeline, &overrides)?;
    let cancel = Arc::new(AtomicBool::new(false));
    let opts = RunOptions { pipeline_path: pipeline, input, output, cancel: Some(cancel.clone()) };
    let report = run_released(py, Some(&cancel), || {
        let size = match (memory_budget, slab_planes) {
            (Some(b), _) => Some(SlabSize::Budget(b)),
            (None, Some(h)) => Some(SlabSize::Planes(h.max(1))),
            (None, None) => mdtf_pipeline::blocks::automatic(&p, &opts).map(|(b, _)| SlabSize::Budget(b)),
        };
        match size {
            Some(size) => mdtf_pipeline::blocks::run(&p, &opts, size, &|_| {}, &|_, _| {}),
            None => mdtf_pipeline::run::run(&p, &opts, &|_| {}),
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
    let (plan, _, _) = run_released(py, None, || mdtf_pipeline::run::plan(&p, &opts))?.map_err(mdtf_error)?;
    let [x, y, z] = plan.halo;
    Ok((plan.to_string(), (z, y, x)))
}
