//! `mdtf run`: a pipeline file, every stage in process.

use crate::args::RunArgs;
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_pipeline::blocks::SlabSize;
use mdtf_pipeline::file::parse;
use mdtf_pipeline::run::{RunOptions, RunReport, plan as plan_pipeline, run as run_pipeline};
use mdtf_pipeline::settings::{Settings, SlabRequest, Slabs};
use std::sync::Mutex;
use std::time::Instant;

/// Parses the pipeline, runs it, prints the stage table.
pub fn run(args: &RunArgs, progress: &Progress) -> Result<()> {
    let text =
        std::fs::read_to_string(&args.pipeline).with_context(|| format!("cannot read {}", args.pipeline.display()))?;
    let pipeline = parse(&text, &args.set).map_err(|e| anyhow::anyhow!("{}: {e}", args.pipeline.display()))?;
    let opts = RunOptions {
        pipeline_path: args.pipeline.clone(),
        input: args.input.clone(),
        output: args.output.clone(),
        ..Default::default()
    };
    let settings = Settings::new(&pipeline, &opts);
    if args.print_settings {
        let table = settings.to_table().map_err(anyhow::Error::msg)?;
        print!("{}", mdtf_pipeline::file::to_toml(&table).map_err(anyhow::Error::msg)?);
        return Ok(());
    }
    if args.plan {
        return print_plan(args, &settings, &opts, progress);
    }
    let lines = StageLines { progress, current: Mutex::new(None) };
    let on_stage = |stage: &str| lines.next(Some(stage));
    let report = match slab_size(args, &settings, progress) {
        Some(size) => mdtf_pipeline::blocks::run(&settings, &opts, size, &on_stage, &|k, n| lines.slab(k, n)),
        None => run_pipeline(&settings, &opts, &on_stage),
    };
    lines.next(None);
    let report = report?;
    for w in &report.warnings {
        progress.note(&format!("warning: {w}"));
    }
    progress.note(&stage_table(&report));
    progress.note(&format!(
        "wrote {} ({}; report.html to open in a browser, run_report.json)",
        args.output.display(),
        report.input
    ));
    Ok(())
}

/// Prints the plan of the run (`--plan`): what it would do, writing
/// nothing; with `--dims` on that grid, sized for a run by slabs or tasks.
fn print_plan(args: &RunArgs, settings: &Settings, opts: &RunOptions, progress: &Progress) -> Result<()> {
    let Some(dims) = &args.dims else {
        let (plan, input, geo) = plan_pipeline(settings)?;
        crate::input::print_plan(&args.pipeline.display().to_string(), &input, &geo, &plan);
        // a run by slabs asked for: sized too
        if let Some(size) = slab_size(args, settings, progress)
            && plan.fields.is_empty()
        {
            println!("{}", mdtf_pipeline::blocks::sizing(settings, &geo, size)?);
        }
        return Ok(());
    };
    let geo = mdtf_volume::Geometry::new(crate::input::parse_dims(dims, "--dims")?, [1.0; 3]);
    let plan = mdtf_pipeline::plan::Plan::resolve(settings, &[], &geo)?;
    crate::input::print_plan(&args.pipeline.display().to_string(), "a grid of --dims", &geo, &plan);
    let usable = mdtf_pipeline::blocks::usable_memory(mdtf_volume::available_memory());
    // a grid on paper: the input is not looked at for a budget of its own
    let size = slab_request(args).size().unwrap_or(SlabSize::Budget(usable));
    let sizing = mdtf_pipeline::blocks::sizing(settings, &geo, size)?;
    println!("{sizing}");
    progress.note("timing the pipeline by slabs on two small phantoms for the time per voxel ...");
    let timed = crate::commands::run_timing::time_per_voxel(settings, opts)?;
    println!("{}", timed.describe(geo.voxel_count() as u64));
    Ok(())
}

/// The slabs of the run: `--memory-budget`, `--slab-planes`, or a budget
/// of their own when the whole volume would not fit in memory (said in a
/// note); None for a whole-volume run.
fn slab_size(args: &RunArgs, settings: &Settings, progress: &Progress) -> Option<SlabSize> {
    match settings.slabs(slab_request(args), false)? {
        Slabs::TooLarge { budget, geometry } => {
            crate::input::announce_slabs(progress, "running", Some((budget, geometry))).map(SlabSize::Budget)
        }
        slabs => Some(slabs.size()),
    }
}

/// The slabs `--memory-budget` or `--slab-planes` asks for.
fn slab_request(args: &RunArgs) -> SlabRequest {
    SlabRequest { memory_budget: args.memory_budget, slab_planes: args.slab_planes.map(|h| h as usize) }
}

/// One line per stage: the spinner names the running stage (and slab), and
/// each stage gets its own finished line with its wall time when the next
/// one starts.
struct StageLines<'a> {
    progress: &'a Progress,
    /// The running stage and when it started.
    current: Mutex<Option<(String, Instant)>>,
}

impl StageLines<'_> {
    /// Ends the running stage's line and starts `next`'s (None: the run ended).
    fn next(&self, next: Option<&str>) {
        let mut cur = self.current.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((name, start)) = cur.take() {
            self.progress.line(&format!("  {name} ({:.2} s)", start.elapsed().as_secs_f64()));
        }
        if let Some(n) = next {
            self.progress.message(&format!("running: {n}"));
            *cur = Some((n.to_string(), Instant::now()));
        }
    }

    /// Shows that the running stage starts its slab `k` of `slabs`.
    fn slab(&self, k: usize, slabs: usize) {
        let cur = self.current.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((name, _)) = cur.as_ref() {
            self.progress.message(&format!("running: {name}, slab {k} of {slabs}"));
        }
    }
}

/// The run's stages with their seconds, throughput and peak memory, and the total.
fn stage_table(report: &RunReport) -> String {
    let mut table = format!("{:<22} {:>9} {:>12} {:>10}\n", "stage", "seconds", "Mvoxel/s", "peak MiB");
    for s in &report.stages {
        table += &format!("{:<22} {:>9.3} {:>12.1} {:>10.0}\n", s.stage, s.seconds, s.mvoxel_per_s, s.peak_mib);
    }
    table + &format!("{:<22} {:>9.3} {:>12} {:>10.0}\n", "total", report.total_seconds, "", report.peak_mib)
}
