//! `mdtf boundary`: distance to the nearest boundary.

use crate::args::BoundaryArgs;
use crate::input::{read_input, read_options};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::blocks::{self, SlabSize};
use mdtf_pipeline::boundary_chain::{BoundaryChainParams, take_traced};
use mdtf_pipeline::channel::traced_names;
use mdtf_pipeline::channels::{self, Tracing};
use mdtf_pipeline::run::BoundarySummary;
use mdtf_pipeline::stages::bilateral::BilateralParams;
use mdtf_pipeline::stages::boundary::{AlphaMap, BoundaryInput, BoundaryParams};
use mdtf_volume::{Inputs, MultiField, OutputFolder, Volume, WriteOptions, human_bytes, write};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn params(args: &BoundaryArgs) -> Result<BoundaryParams> {
    let alpha = args.alpha.iter().map(|s| s.parse::<AlphaMap>().map_err(anyhow::Error::msg)).collect::<Result<_>>()?;
    Ok(BoundaryParams {
        g_min: args.g_min,
        g_hit_min: args.g_hit_min,
        step: args.step,
        d_max: args.d_max,
        tolerance: args.tolerance,
        flipped: args.flipped,
        alpha,
    })
}

fn prefilter(text: &str) -> Result<BilateralParams> {
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--prefilter: expected SIGMA_D,SIGMA_R like 1,0.1, got '{text}'"))?;
    match parts.as_slice() {
        [d, r] if *d > 0.0 && *r > 0.0 => {
            Ok(BilateralParams { sigma_d: *d, sigma_r: *r, ..BilateralParams::default() })
        }
        _ => bail!("--prefilter: expected two positive numbers SIGMA_D,SIGMA_R like 1,0.1, got '{text}'"),
    }
}

/// The chain from a value volume: `--kernel`, `--prefilter` and the tracing's parameters `p`.
fn chain(args: &BoundaryArgs, p: BoundaryParams) -> Result<BoundaryChainParams> {
    Ok(BoundaryChainParams {
        kernel: args.kernel.unwrap_or_default(),
        prefilter: args.prefilter.as_deref().map(prefilter).transpose()?,
        boundary: p,
        ..Default::default()
    })
}

fn scalar(path: &Path, args: &BoundaryArgs) -> Result<Volume> {
    let (mf, _) = read_input(path, &args.read, &read_options(&args.read))?;
    mf.into_scalar().with_context(|| format!("{} must hold one field", path.display()))
}

/// Runs the chain (or tracing alone on given g, f'', normal) and writes the outputs.
pub fn run(args: &BoundaryArgs, progress: &Progress) -> Result<()> {
    let p = params(args)?;
    if let (Some(input), true) = (&args.input, args.plan) {
        let chain = chain(args, p)?;
        let traced = |_: &[String]| traced_names();
        return crate::input::print_channel_plan(input, &args.read, &traced, &chain);
    }
    let budget = slab_budget(args, progress)?;
    let given: Vec<&Path> =
        [&args.input, &args.g, &args.f2, &args.normal].into_iter().flatten().map(PathBuf::as_path).collect();
    let inputs = Inputs::of(&given);
    let folder = OutputFolder::begin(&args.output, &inputs)?;
    // a report inside the output folder (often the folder itself) is written with it
    let report_inside = args.report.as_ref().and_then(|r| r.strip_prefix(&args.output).ok()).map(Path::to_path_buf);
    let report_folder = match (&args.report, &report_inside) {
        (Some(d), None) => Some(OutputFolder::begin(d, &inputs)?),
        _ => None,
    };
    let start = Instant::now();
    let found = match budget {
        Some(b) => trace_by_slabs(args, p, b, folder.path(), progress)?,
        None => trace(args, p, progress)?.write(folder.path(), args.format.extension(), &given, progress)?,
    };
    let seconds = start.elapsed().as_secs_f64();
    let report_dir = match (&report_folder, &report_inside) {
        (Some(f), _) => Some(f.path().to_path_buf()),
        (None, Some(rel)) => Some(folder.path().join(rel)),
        (None, None) => None,
    };
    found.write_report(report_dir.as_deref(), progress)?;
    folder.publish(&inputs)?;
    if let Some(r) = report_folder {
        r.publish(&inputs)?;
    }
    for w in &found.warnings {
        progress.note(&format!("warning: {w}"));
    }
    progress.note(&summary(&found.summary, seconds));
    Ok(())
}

/// The budget of a slab-by-slab tracing: `--memory-budget`, or one of its
/// own when the whole volume would not fit in memory (said in a note); None
/// for a whole-volume run (and for tracing given g, f'' and normal).
fn slab_budget(args: &BoundaryArgs, progress: &Progress) -> Result<Option<u64>> {
    let value_file = args.input.as_deref().filter(|_| args.read.raw_dims.is_none());
    match (args.memory_budget, value_file) {
        (Some(_), None) => bail!(
            "--memory-budget traces from a value volume with a header, slab by slab (not from --g/--f2/--normal \
             or --raw-dims)"
        ),
        (Some(b), Some(_)) => Ok(Some(b)),
        (None, None) => Ok(None),
        (None, Some(input)) => {
            let available = mdtf_volume::available_memory();
            let auto = blocks::automatic_trace_budget(input, &read_options(&args.read), available);
            Ok(crate::input::announce_slabs(progress, "tracing", auto))
        }
    }
}

/// The chain from the value volume, slab by slab within `budget` bytes,
/// its files written into `dir` (the report waits in `dir`/boundary).
fn trace_by_slabs(
    args: &BoundaryArgs,
    p: BoundaryParams,
    budget: u64,
    dir: &Path,
    progress: &Progress,
) -> Result<Found> {
    let input = args.input.as_deref().context("--memory-budget traces from a value volume")?;
    let (chain, opts, ext) = (chain(args, p)?, read_options(&args.read), args.format.extension());
    let size = SlabSize::Budget(budget);
    let stage = |s: &str| progress.message(s);
    let t = progress
        .counted("reading, deriving, then tracing, slab by slab", 0, |tick| {
            blocks::trace_files(input, &opts, &chain, size, dir, ext, &stage, tick)
        })
        .context("cannot trace the boundaries")?;
    progress.note(&format!("traced {} slabs of {} planes within {}", t.slabs, t.height, human_bytes(budget as u128)));
    Ok(Found { summary: t.summary, warnings: t.warnings, report: t.report })
}

/// What the tracing found, its files written.
struct Found {
    summary: BoundarySummary,
    warnings: Vec<String>,
    report: mdtf_pipeline::stages::boundary::Report,
}

impl Found {
    /// The Fig. 2 report into `report_dir`, when asked for.
    fn write_report(&self, report_dir: Option<&Path>, progress: &Progress) -> Result<()> {
        let Some(report_dir) = report_dir else { return Ok(()) };
        std::fs::create_dir_all(report_dir)
            .with_context(|| format!("cannot create the report folder {}", report_dir.display()))?;
        self.report.write(report_dir).context("cannot write the report")?;
        let (mean, hits) = (self.report.mean_dot, self.report.hits);
        progress.note(&format!("mean dot product {mean:.6} over {hits} voxels with a boundary"));
        Ok(())
    }
}

/// The tracing's channels as files (distance, g_hit, hit, dot, then the
/// flipped distance and alpha maps when asked) and what it found.
struct Traced {
    files: Vec<(String, Volume)>,
    tracing: Tracing,
}

/// The tracing: the planned chain from a value volume (derive, the
/// pre-filter if asked, tracing), or the tracing alone on given g, f'' and normal.
fn trace(args: &BoundaryArgs, p: BoundaryParams, progress: &Progress) -> Result<Traced> {
    let (mut files, mut tracing) = match (&args.input, &args.g, &args.f2, &args.normal) {
        (Some(input), None, None, None) => {
            let value = progress.step("reading", || scalar(input, args))?;
            let chain = chain(args, p)?;
            let names = traced_names();
            let nz = value.geometry.dims[2] as u64;
            let computed = progress
                .counted("deriving, then tracing", nz, |tick| {
                    channels::compute_all(&MultiField::from(value), &names, &chain, tick)
                })
                .context("cannot trace the boundaries")?;
            let tracing = computed.tracing.context("the plan did not trace")?;
            (computed.channels, tracing)
        }
        (None, Some(g), Some(f2), Some(normal)) => {
            if args.kernel.is_some() || args.prefilter.is_some() {
                bail!(
                    "--kernel and --prefilter apply when deriving from a value volume, not to given --g/--f2/--normal"
                );
            }
            let (gv, f2v) = progress.step("reading", || -> Result<_> { Ok((scalar(g, args)?, scalar(f2, args)?)) })?;
            let nv = read_input(normal, &args.read, &read_options(&args.read))?.0;
            let input = BoundaryInput { g: &gv, f2: &f2v, normal: &nv, value_range: args.value_range.unwrap_or(255.0) };
            let mut out = progress.step("tracing", || mdtf_pipeline::stages::boundary::run(&input, &p))?;
            let report = out.report(&gv);
            let files = take_traced(&mut out);
            let summary = BoundarySummary { resolved: out.resolved, counts: out.counts, lost: out.lost };
            (files, Tracing { summary, warnings: out.warnings, flipped: out.flipped, alpha: out.alpha, report })
        }
        _ => bail!("give either a value volume, or all of --g, --f2 and --normal"),
    };
    files.extend(tracing.flipped.take().map(|f| ("flipped".to_string(), f)));
    files.append(&mut tracing.alpha);
    Ok(Traced { files, tracing })
}

/// What the tracing found (`summary`), in `seconds`, for the closing note.
fn summary(summary: &BoundarySummary, seconds: f64) -> String {
    let (c, r) = (&summary.counts, &summary.resolved);
    format!(
        "traced {} voxels in {seconds:.2} s: {} boundaries kept, {} rejected (g at the hit < {:.3}), {} without a zero crossing within {:.3}; \
         {} below g_min {:.3} not traced (noise floor {:.3})",
        c.traced(),
        c.hits,
        c.rejected,
        r.g_hit_min,
        c.no_crossing,
        r.d_max,
        c.not_traced,
        r.g_min,
        r.noise_floor
    )
}

impl Traced {
    /// Writes the files into `dir` with extension `ext` (never over one of `inputs`); what the tracing found.
    fn write(self, dir: &Path, ext: &str, inputs: &[&Path], progress: &Progress) -> Result<Found> {
        progress.step("writing", || -> Result<()> {
            for (name, v) in &self.files {
                let path = dir.join(format!("{name}{ext}"));
                write(&path, &MultiField::from(v.clone()), &WriteOptions::default(), inputs)
                    .context("cannot write the output")?;
            }
            Ok(())
        })?;
        let Tracing { summary, warnings, report, .. } = self.tracing;
        Ok(Found { summary, warnings, report })
    }
}
