//! `mdtf run`: a pipeline file, every stage in process.

use crate::args::RunArgs;
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_pipeline::blocks::SlabSize;
use mdtf_pipeline::file::parse;
use mdtf_pipeline::run::{RunOptions, plan as plan_pipeline, run as run_pipeline};

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
    if args.print_settings {
        let settings = mdtf_pipeline::run::resolved_settings(&pipeline, &opts).map_err(anyhow::Error::msg)?;
        print!("{}", mdtf_pipeline::file::to_toml(&settings).map_err(anyhow::Error::msg)?);
        return Ok(());
    }
    if args.plan {
        let (plan, input, geo) = plan_pipeline(&pipeline, &opts)?;
        let [nx, ny, nz] = geo.dims;
        let [sx, sy, sz] = geo.spacing;
        println!("plan of {} on {input} ({nx} x {ny} x {nz}, spacing {sx} x {sy} x {sz})", args.pipeline.display());
        println!("{plan}");
        return Ok(());
    }
    // one line per stage: the spinner names the running stage, and each stage
    // gets its own finished line with its wall time when the next one starts
    let current: std::sync::Mutex<Option<(String, std::time::Instant)>> = std::sync::Mutex::new(None);
    let finish = |next: Option<&str>| {
        let mut cur = current.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((name, start)) = cur.take() {
            progress.line(&format!("  {name} ({:.2} s)", start.elapsed().as_secs_f64()));
        }
        if let Some(n) = next {
            progress.message(&format!("running: {n}"));
            *cur = Some((n.to_string(), std::time::Instant::now()));
        }
    };
    let on_stage = |stage: &str| finish(Some(stage));
    let slabs = match (args.memory_budget, args.slab_planes) {
        (Some(b), _) => Some(SlabSize::Budget(b)),
        (None, Some(h)) => Some(SlabSize::Planes(h.max(1))),
        // a volume whose whole run would not fit goes by slabs on its own
        (None, None) => mdtf_pipeline::blocks::automatic(&pipeline, &opts).map(|(budget, geo)| {
            progress.note(&format!(
                "{} x {} x {} voxels do not fit in memory at once: running slab by slab within {} \
                 (--memory-budget sets it)",
                geo.dims[0],
                geo.dims[1],
                geo.dims[2],
                mdtf_volume::human_bytes(budget as u128)
            ));
            SlabSize::Budget(budget)
        }),
    };
    let report = match slabs {
        Some(size) => {
            let on_slab = |k: usize, slabs: usize| {
                let cur = current.lock().unwrap_or_else(|e| e.into_inner());
                if let Some((name, _)) = cur.as_ref() {
                    progress.message(&format!("running: {name}, slab {k} of {slabs}"));
                }
            };
            mdtf_pipeline::blocks::run(&pipeline, &opts, size, &on_stage, &on_slab)
        }
        None => run_pipeline(&pipeline, &opts, &on_stage),
    };
    finish(None);
    let report = report?;
    for w in &report.warnings {
        progress.note(&format!("warning: {w}"));
    }
    let mut table = format!("{:<22} {:>9} {:>12} {:>10}\n", "stage", "seconds", "Mvoxel/s", "peak MiB");
    for s in &report.stages {
        table += &format!("{:<22} {:>9.3} {:>12.1} {:>10.0}\n", s.stage, s.seconds, s.mvoxel_per_s, s.peak_mib);
    }
    table += &format!("{:<22} {:>9.3}\n", "total", report.total_seconds);
    progress.note(&table);
    progress.note(&format!(
        "wrote {} ({}; report.html to open in a browser, run_report.json)",
        args.output.display(),
        report.input
    ));
    Ok(())
}
