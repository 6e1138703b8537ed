//! `mdtf preview`: render a pack.

use crate::args::{IntegrationArg, PreviewArgs};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use mdtf_pipeline::stages::preview::{Camera, preview};

/// Parses the view and renders.
pub fn run(args: &PreviewArgs, progress: &Progress) -> Result<()> {
    let defaults = Camera::default();
    let (azimuth, elevation) = match &args.view {
        None => (defaults.azimuth, defaults.elevation),
        Some(view) => {
            let (az, el) =
                view.split_once(',').with_context(|| format!("--view: expected AZIMUTH,ELEVATION, got '{view}'"))?;
            let angle = |text: &str, name: &str| -> Result<f64> {
                text.trim().parse().with_context(|| format!("--view: {name} '{text}' is not a number"))
            };
            (angle(az, "azimuth")?, angle(el, "elevation")?)
        }
    };
    let cam = Camera { azimuth, elevation, size: args.size, step: args.step, shaded: !args.no_shading };
    // the library's own check, here so that a bad view fails before the pack is read
    if let Err(e) = cam.check() {
        bail!(e);
    }
    let analytic = args.integration == IntegrationArg::Analytic;
    progress.step("rendering", || preview(&args.pack, &args.output, &cam, analytic))?;
    progress.note(&format!("wrote {}", args.output.display()));
    Ok(())
}
