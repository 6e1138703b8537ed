//! `mdtf run`: a pipeline file, every stage in process.

use crate::args::RunArgs;
use crate::progress::Progress;
use anyhow::{Context, Result};
use mdtf_pipeline::file::parse;
use mdtf_pipeline::run::{RunOptions, run as run_pipeline};

/// Parses the pipeline, runs it, prints the stage table.
pub fn run(args: &RunArgs, progress: &Progress) -> Result<()> {
    let text =
        std::fs::read_to_string(&args.pipeline).with_context(|| format!("cannot read {}", args.pipeline.display()))?;
    let pipeline = parse(&text, &args.set).map_err(|e| anyhow::anyhow!("{}: {e}", args.pipeline.display()))?;
    let opts =
        RunOptions { pipeline_path: args.pipeline.clone(), input: args.input.clone(), output: args.output.clone() };
    let report = progress
        .step("running", || run_pipeline(&pipeline, &opts, &|stage| progress.message(&format!("running: {stage}"))))?;
    let mut table = format!("{:<22} {:>9} {:>12} {:>10}\n", "stage", "seconds", "Mvoxel/s", "peak MiB");
    for s in &report.stages {
        table += &format!("{:<22} {:>9.3} {:>12.1} {:>10.0}\n", s.stage, s.seconds, s.mvoxel_per_s, s.peak_mib);
    }
    table += &format!("{:<22} {:>9.3}\n", "total", report.total_seconds);
    progress.note(&table);
    progress.note(&format!("wrote {} ({}; report in run_report.json)", args.output.display(), report.input));
    Ok(())
}
