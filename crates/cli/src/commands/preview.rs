//! `mdtf preview`: render a pack.

use crate::args::{IntegrationArg, PreviewArgs};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_preview::{Camera, preview};

/// Parses the view and renders.
pub fn run(args: &PreviewArgs, progress: &Progress) -> Result<()> {
    let (az, el) = args
        .view
        .split_once(',')
        .with_context(|| format!("--view: expected AZIMUTH,ELEVATION, got '{}'", args.view))?;
    let cam = Camera { azimuth: az.trim().parse()?, elevation: el.trim().parse()?, size: args.size, step: args.step };
    if !(8..=4096).contains(&cam.size) {
        bail!("--size {} must be 8 to 4096 pixels", cam.size);
    }
    if !(cam.step.is_finite() && cam.step > 0.0) {
        bail!("--step must be positive, got {}", cam.step);
    }
    let analytic = args.integration == IntegrationArg::Analytic;
    progress.step("rendering", || preview(&args.pack, &args.output, &cam, analytic))?;
    progress.note(&format!("wrote {}", args.output.display()));
    Ok(())
}
