//! The time a pipeline takes per voxel on this machine, for `mdtf run
//! --plan --dims`: the pipeline run by slabs on two small noisy erf-sphere
//! phantoms in a temporary folder, each stage's time per voxel taken from
//! the difference of the two (a stage's fixed costs, its tables and
//! figures, drop out).

use anyhow::{Context, Result};
use mdtf_pipeline::blocks::SlabSize;
use mdtf_pipeline::file::PhantomKind;
use mdtf_pipeline::run::RunOptions;
use mdtf_pipeline::settings::{InputSource, Settings};

/// Edges of the phantoms timed, voxels.
const PHANTOMS: [usize; 2] = [64, 128];

/// Each stage's seconds per voxel of one thread, as timed here.
pub struct Timing {
    /// (stage, seconds of one thread per voxel).
    stages: Vec<(String, f64)>,
    /// Threads the timing ran on.
    threads: usize,
}

/// Times a run of `s` by slabs (16 planes) on 64^3 and 128^3 erf spheres with
/// noise, its input replaced, its preview off, in a temporary folder.
pub fn time_per_voxel(s: &Settings, opts: &RunOptions) -> Result<Timing> {
    let dir = tempfile::tempdir().context("a temporary folder for the timing runs")?;
    let mut runs = Vec::with_capacity(PHANTOMS.len());
    for n in PHANTOMS {
        let mut s = s.clone();
        s.input.source = InputSource::Phantom { kind: PhantomKind::ErfSphere, size: n, sigma: 3.0, noise: 2.0 };
        s.outputs.preview = false;
        let opts = RunOptions { input: None, output: dir.path().join(format!("timed{n}")), ..opts.clone() };
        let report = mdtf_pipeline::blocks::run(&s, &opts, SlabSize::Planes(16), &|_| {}, &|_, _| {})
            .with_context(|| format!("the timing run on a {n}^3 phantom"))?;
        runs.push(report.stages);
    }
    let threads = rayon::current_num_threads();
    let [small, large] = PHANTOMS.map(|n| (n * n * n) as f64);
    let stages = runs[1]
        .iter()
        .map(|s| {
            let before = runs[0].iter().find(|b| b.stage == s.stage).map_or(0.0, |b| b.seconds);
            (s.stage.clone(), ((s.seconds - before) * threads as f64 / (large - small)).max(0.0))
        })
        .collect();
    Ok(Timing { stages, threads })
}

impl Timing {
    /// Lines saying what a grid of `voxels` would take.
    pub fn describe(&self, voxels: u64) -> String {
        let total: f64 = self.stages.iter().map(|(_, s)| s).sum();
        let per: Vec<String> = self.stages.iter().map(|(n, s)| format!("{n} {:.3}", s * 1e6)).collect();
        let core_hours = total * voxels as f64 / 3600.0;
        format!(
            "time: {:.3} us of one core per voxel ({}; timed just now by slabs on {}^3 and {}^3 phantoms, the \
             difference, {} threads, wall time x threads): {core_hours:.1} core-hours for these {voxels} voxels, \
             or that over the cores of the workers when the tasks spread evenly (small phantoms: real data \
             traces more or fewer voxels, and a shared disk adds its own time)",
            total * 1e6,
            per.join(", "),
            PHANTOMS[0],
            PHANTOMS[1],
            self.threads
        )
    }
}
