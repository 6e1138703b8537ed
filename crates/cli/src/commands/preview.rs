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
    let angle = |text: &str, name: &str| -> Result<f64> {
        text.trim().parse().with_context(|| format!("--view: {name} '{text}' is not a number"))
    };
    let cam = Camera {
        azimuth: angle(az, "azimuth")?,
        elevation: angle(el, "elevation")?,
        size: args.size,
        step: args.step,
        shaded: !args.no_shading,
    };
    // the library's own check, here so that a bad view fails before the pack is read
    if let Err(e) = cam.check() {
        bail!(e);
    }
    let analytic = args.integration == IntegrationArg::Analytic;
    progress.step("rendering", || preview(&args.pack, &args.output, &cam, analytic))?;
    progress.note(&format!("wrote {}", args.output.display()));
    Ok(())
}
