//! The in-process runner of pipeline files: input -> derive -> (pre-filter,
//! boundary) -> histograms -> pack, with per-stage timings and a report.
//! Everything is written into a temporary folder beside the output and
//! renamed into place at the end, so a failed run leaves the output folder
//! as it was.

use crate::channel::Channel;
use crate::plan::Plan;
use crate::progress::Progress;
use mdtf_pack::Profile;
use mdtf_volume::{OutputFolder, write_file_atomically};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::error::RunError;
pub(crate) use crate::error::{at, fail};
pub use crate::inputs::plan;
use crate::inputs::{load_input, run_inputs};
use crate::report::Stages;
pub use crate::report::{BoundarySummary, RunReport, SlabRun, StageReport};
use crate::settings::{Outputs, Settings};
use crate::whole::WholeRun;

/// Where a run reads from and writes to.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// The pipeline file (relative paths inside it are relative to its folder).
    pub pipeline_path: PathBuf,
    /// Input file replacing the pipeline's.
    pub input: Option<PathBuf>,
    /// Output folder.
    pub output: PathBuf,
    /// Set to stop the run at its next stage or slab, leaving no output
    /// (the Python package sets it on Ctrl-C).
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Where a slab-by-slab run's derive, pre-filter and tracing passes
    /// run: None in this process, else as tasks the runner hands out (see
    /// [`crate::blocks::SlabTasks`]; a whole-volume run ignores it).
    pub tasks: Option<std::sync::Arc<dyn crate::blocks::SlabTasks>>,
    /// A run with [`RunOptions::tasks`] takes over what a killed run of the
    /// same settings and input into the same output left, its finished
    /// tasks not run again (see the `blocks::resume` module).
    pub resume: bool,
}

impl RunOptions {
    /// The folder relative paths in the pipeline file start from (the file's own).
    pub fn base(&self) -> PathBuf {
        self.pipeline_path.parent().map(Path::to_path_buf).unwrap_or_default()
    }

    /// Whether [`RunOptions::cancel`] is set.
    pub fn is_cancelled(&self) -> bool {
        crate::progress::is_set(&self.cancel)
    }
}

/// Runs the pipeline of settings `s` (made from `opts`'s pipeline file)
/// into `opts.output`; `on_stage(name)` is called as each stage starts.
pub fn run(s: &Settings, opts: &RunOptions, on_stage: &(dyn Fn(&str) + Sync)) -> Result<RunReport, RunError> {
    let start = Instant::now();
    let out = OutputFolder::begin(&opts.output, &run_inputs(s)).map_err(at("output"))?;
    let progress = Progress::new(opts, on_stage, &|_, _| {});
    progress.stage("input")?;
    let t = Instant::now();
    let input = load_input(&s.input)?;
    // what the outputs need: derive items, tracing, when each channel is freed
    let field_names: Vec<String> = input.0.fields.iter().map(|f| f.name.clone()).collect();
    let geo = input.0.geometry.clone();
    let plan = Plan::resolve(s, &field_names, &geo).map_err(at("plan"))?;
    let mut run = WholeRun::new(s, plan, input, t, out.path().to_path_buf(), progress)?;
    let (traced, packed) = run.run_steps()?;
    let report = RunReport {
        fields: run.fields().to_vec(),
        value_range: run.finite_range,
        warnings: run.warnings,
        boundary: traced.boundary,
        boundaries: packed.boundaries,
        hvol_built: packed.hvol_built,
        stages: run.stages.0,
        units: run.units,
        ..RunReport::of(opts, run.input_name, &geo)
    };
    finish(s, opts, out, report, &packed.table_names, start, &run.progress)
}

/// Writes the channels the run keeps (`outputs`) into the staging folder's `volumes/`,
/// each by `write(channel, file)`, side by side (None: the run did not
/// make that channel), and `volumes/channels.json`: each file's channel, meaning,
/// units and producing stage from the channel table (`fields`: the input's
/// field names, empty for one field); the files written, relative to `dir`.
pub(crate) fn write_kept<W>(outputs: &Outputs, fields: &[String], dir: &Path, write: W) -> Result<Vec<String>, RunError>
where
    W: Fn(&str, &Path) -> Option<Result<(), RunError>> + Sync,
{
    let kdir = dir.join("volumes");
    std::fs::create_dir_all(&kdir).map_err(at("keep"))?;
    // the files are encoded (and compressed) side by side; the first error in the list's order is told
    let wrote: Vec<Result<(), RunError>> = outputs
        .keep
        .par_iter()
        .map(|c| {
            write(c, &kdir.join(outputs.keep_format.file_name(c)))
                .unwrap_or_else(|| Err(fail("keep")(format!("no channel '{c}' was computed"))))
        })
        .collect();
    wrote.into_iter().collect::<Result<(), RunError>>()?;
    let mut written = Vec::with_capacity(outputs.keep.len() + 1);
    let mut listed = Vec::with_capacity(outputs.keep.len());
    for c in &outputs.keep {
        let name = outputs.keep_format.file_name(c);
        let text = Channel::named(c, fields).map_err(|e| fail("keep")(e.to_string()))?.text(!fields.is_empty());
        listed.push(serde_json::json!({
            "channel": c,
            "file": name,
            "meaning": text.meaning,
            "units": text.units,
            "signed": text.signed,
            "stage": text.stage,
        }));
        written.push(format!("volumes/{name}"));
    }
    let sidecar = serde_json::to_string_pretty(&serde_json::json!({ "volumes": listed }))
        .map_err(|e| fail("keep")(e.to_string()))?;
    std::fs::write(kdir.join("channels.json"), sidecar + "\n").map_err(at("keep"))?;
    written.push("volumes/channels.json".into());
    Ok(written)
}

/// The end of every run: the preview and the contact sheet (when asked for
/// and the pack can be previewed: `table_names` are its lookup tables),
/// run_report.json (`report` gets the preview's stage and the total time
/// since `start`), report.html, and the output folder published.
pub(crate) fn finish(
    s: &Settings,
    opts: &RunOptions,
    out: OutputFolder,
    mut report: RunReport,
    table_names: &[String],
    start: Instant,
    progress: &Progress,
) -> Result<RunReport, RunError> {
    let dir = out.path();
    let pdir = dir.join("pack");
    let previewable = match s.profile() {
        Profile::Slicer3dtf | Profile::DistanceTf => true,
        Profile::GaussianTf => true,
        // with a TF, or the default one from the boundaries found
        Profile::PeakFinding => table_names.iter().any(|l| ["tf2d", "peak_table", "product_0"].contains(&l.as_str())),
        // the mesh resampled onto a grid, with the TF of its gaussians.json
        Profile::ProjectedTetrahedra => true,
    };
    if s.outputs.preview && previewable {
        progress.stage("preview")?;
        let t = Instant::now();
        let cam = mdtf_preview::Camera::default();
        mdtf_preview::preview_named(&pdir, &dir.join("preview.png"), &cam, true, &opts.output.join("pack"))
            .map_err(at("preview"))?;
        // the contact sheet: every picture of the run side by side, named
        let pictures: Vec<(PathBuf, String)> =
            crate::report_page::figures_in(dir).into_iter().map(|f| (dir.join(&f.file), f.file)).collect();
        let refs: Vec<(&Path, &str)> = pictures.iter().map(|(p, c)| (p.as_path(), c.as_str())).collect();
        mdtf_preview::contact_sheet(&refs, 3, 384, &dir.join("contact_sheet.png")).map_err(at("preview"))?;
        let mut stages = Stages(std::mem::take(&mut report.stages));
        // the rate is of the input's voxels, as every stage's (the ray caster reads them all)
        let voxels = report.dims.iter().product();
        stages.done("preview", t, voxels, vec!["preview.png".into(), "contact_sheet.png".into()]);
        report.stages = stages.0;
    }
    report.total_seconds = start.elapsed().as_secs_f64();
    report.peak_mib = crate::report::peak_mib();
    report.settings = s.to_table().map_err(fail("report"))?;
    let json = serde_json::to_string_pretty(&report).map_err(at("report"))?;
    write_file_atomically(&dir.join("run_report.json"), |w| w.write_all(json.as_bytes())).map_err(at("report"))?;
    write_report_page(&report, dir).map_err(fail("report"))?;
    out.publish(&run_inputs(s)).map_err(at("output"))?;
    Ok(report)
}

/// Writes report.html into the staging folder `dir` from the report, the
/// settings, the pack's manifest (absent for mesh packs) and its Gaussians (gaussian-tf).
fn write_report_page(report: &RunReport, dir: &Path) -> Result<(), String> {
    let settings = crate::file::to_toml(&report.settings)?;
    let manifest_text = std::fs::read_to_string(dir.join("pack/manifest.json")).ok();
    let manifest: Option<mdtf_pack::Manifest> = manifest_text.as_ref().and_then(|t| serde_json::from_str(t).ok());
    // a mesh pack's manifest is of its own schema, with the same provenance
    let provenance: Option<mdtf_pack::Provenance> = manifest_text
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|m| serde_json::from_value(m["provenance"].clone()).ok());
    let gaussians: Option<Vec<mdtf_pack::GaussianPrimitive>> =
        std::fs::read_to_string(dir.join("pack/gaussians.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
    let figures = crate::report_page::figures_in(dir);
    let page = crate::report_page::PageInputs {
        report,
        settings: &settings,
        manifest: manifest.as_ref(),
        provenance: provenance.as_ref(),
        gaussians: gaussians.as_deref(),
        figures: &figures,
    };
    crate::report_page::write(dir, &page).map_err(|e| e.to_string())
}
