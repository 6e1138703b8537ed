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
        let v: f64 = text.trim().parse().with_context(|| format!("--view: {name} '{text}' is not a number"))?;
        if !v.is_finite() {
            bail!("--view: {name} must be a finite number of degrees, got {v}");
        }
        Ok(v)
    };
    let cam =
        Camera { azimuth: angle(az, "azimuth")?, elevation: angle(el, "elevation")?, size: args.size, step: args.step };
    if !(8..=4096).contains(&cam.size) {
        bail!("--size {} must be 8 to 4096 pixels", cam.size);
    }
    // (a ray of a 256^3 volume at step 0.01 already takes 90 000 samples)
    if !(cam.step.is_finite() && (0.01..=16.0).contains(&cam.step)) {
        bail!("--step must be 0.01 to 16 voxels, got {}", cam.step);
    }
    let analytic = args.integration == IntegrationArg::Analytic;
    progress.step("rendering", || preview(&args.pack, &args.output, &cam, analytic))?;
    progress.note(&format!("wrote {}", args.output.display()));
    Ok(())
}
